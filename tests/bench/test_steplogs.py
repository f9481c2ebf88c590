"""bench/steplogs.py: the step logs' rows of make bench, on a few logs."""

import pytest

import bench.steplogs


def test_the_writer_has_a_row_and_its_pandas_baseline(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(bench.steplogs, "POLICIES", ("pn",))
    (name, rate, ratio), (base_name, baseline, one) = bench.steplogs.bench_steplogs(quick=True)
    assert name == "write_step_log, 12 logs"
    assert base_name == "  pandas to_csv, the same bytes"
    assert rate > 0.0
    assert baseline > 0.0
    assert ratio == f"{rate / baseline:.1f}x"
    assert one == "1x (baseline)"

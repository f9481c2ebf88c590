"""bench/line.py: LineTrace's rows of make bench, on a few lanes."""

import pytest

import bench.line
from bench.__main__ import vector_steps_per_s


def test_every_row_is_a_rate_with_its_ratio_to_a_baseline_of_the_same_run(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setattr(bench.line, "N", 4)
    monkeypatch.setattr(bench.line, "BUDGET", {True: 80, False: 80})
    rows = bench.line.bench_line_trace(True, lambda *a, **k: 1000.0, vector_steps_per_s)
    names = [name for name, _, _ in rows]
    assert names[0] == "(p) PersonFollow-v0 N=1024"
    assert "LineTrace-v0 random N=1024" in names
    assert "LineTrace-v0 single env" in names
    for _, rate, ratio in rows:
        assert rate > 0.0
        assert ratio.endswith(("(p)", "(c)"))

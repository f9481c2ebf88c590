"""bench/laws.py: the guidance laws' rows of make bench, on a few lanes."""

import pytest

import bench.laws


def test_each_law_has_a_batched_row_and_its_lane_by_lane_baseline(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setattr(bench.laws, "LANES", 8)
    rows = bench.laws.bench_laws(quick=True)
    assert [name for name, _, _ in rows] == [
        row
        for law in bench.laws.LAWS
        for row in (f"{law}, act_batch, 8 lanes", f"  {law}, act lane by lane")
    ]
    for (_, rate, ratio), (_, baseline, one) in zip(rows[::2], rows[1::2], strict=True):
        assert rate > 0.0
        assert baseline > 0.0
        assert ratio == f"{rate / baseline:.0f}x"
        assert one == "1x (baseline)"

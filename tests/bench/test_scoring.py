"""bench/scoring.py: a run's scoring rows of make bench, on a few episodes."""

import pytest

import bench.scoring


def test_the_pool_has_a_row_and_its_one_process_baseline(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(bench.scoring, "POLICIES", ("pn:thesis", "mpn:thesis"))
    (name, rate, ratio), (base_name, baseline, one) = bench.scoring.bench_scoring(quick=True)
    assert name == "scored on 2 processes, 120 episodes"  # 2 policies x 12 scenarios x 5
    assert base_name == "  in this process"
    assert rate > 0.0
    assert baseline > 0.0
    assert ratio == f"{rate / baseline:.2f}x"
    assert one == "1x (baseline)"


def test_tables_that_differ_fail_the_bench(monkeypatch: pytest.MonkeyPatch) -> None:
    real = bench.scoring.score

    def off_by_one(episodes, **kwargs):  # type: ignore[no-untyped-def]
        scored = real(episodes, **kwargs)
        if kwargs["backend"].workers == 2:
            scored.table.loc[0, "seed"] += 1
        return scored

    monkeypatch.setattr(bench.scoring, "POLICIES", ("pn:thesis",))
    monkeypatch.setattr(bench.scoring, "score", off_by_one)
    with pytest.raises(AssertionError):
        bench.scoring.bench_scoring(quick=True)

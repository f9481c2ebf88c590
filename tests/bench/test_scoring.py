"""bench/scoring.py: a run's scoring rows of make bench, on a few episodes."""

import pytest

import bench.scoring


def test_the_pool_has_a_row_and_its_one_process_baseline(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(bench.scoring, "POLICIES", ("pn:thesis", "mpn:thesis"))
    rows = bench.scoring.bench_scoring(quick=True)
    (name, rate, ratio), (base_name, baseline, one), batched, at_once, *cell = rows
    assert name == "scored on 2 processes, 120 episodes"  # 2 policies x 12 scenarios x 5
    assert base_name == "  in this process"
    assert rate > 0.0
    assert baseline > 0.0
    assert ratio == f"{rate / baseline:.2f}x"
    assert one == "1x (baseline)"
    assert batched[0] == "intervals in batches, 120 episodes"
    assert at_once[0] == "  all resamples at once (scipy)"
    assert min(batched[1], at_once[1]) > 0.0
    assert batched[2] == f"{batched[1] / at_once[1]:.2f}x"
    assert at_once[2] == "1x (baseline)"
    (fast, seconds, faster), (_, slow, _), (small, mb, less), (_, large_mb, _) = cell
    assert fast == "an interval of 2,000, batches (s)"
    assert faster == f"{slow / seconds:.1f}x faster"
    assert small == "  batches, peak memory (MB)"
    assert less == f"{large_mb / mb:.0f}x less"
    assert 0.0 < mb < large_mb  # at once, scipy holds 9,999 x 2,000 resampled values


def test_intervals_that_differ_in_batches_fail_the_bench(monkeypatch: pytest.MonkeyPatch) -> None:
    import eval.stats

    real = bench.scoring.summarize

    def shifted(table, **kwargs):  # type: ignore[no-untyped-def]
        summary = real(table, **kwargs)
        if eval.stats.BOOTSTRAP_BATCH_VALUES is not None:
            summary.iloc[0, -1] += 1.0  # another interval when resampled in batches
        return summary

    monkeypatch.setattr(bench.scoring, "POLICIES", ("pn:thesis",))
    monkeypatch.setattr(bench.scoring, "summarize", shifted)
    with pytest.raises(AssertionError):
        bench.scoring.bench_scoring(quick=True)


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

"""eval/line_tune.py: the line followers' search, on a grid of two."""

from eval.line_tune import TRACKS, TUNE_SEED0, candidates, search
from policies import make_policy


def test_the_grid_names_every_candidate_once_for_both_controllers() -> None:
    grid = candidates()
    names = [p.name for _, p in grid]
    assert len(set(names)) == len(names)
    assert {c for c, _ in grid} == {"coordinate", "pid"}


def test_the_tuned_presets_are_candidates_of_the_grid() -> None:
    params = {repr(p.params) for _, p in candidates()}  # type: ignore[attr-defined]
    for name in ("coordinate:tuned", "pid:tuned"):
        assert repr(make_policy(name).params) in params  # type: ignore[attr-defined]


def test_search_scores_each_candidate_on_the_tuning_tracks() -> None:
    grid = [next(c for c in candidates() if c[0] == k) for k in ("coordinate", "pid")]
    table = search(grid, 1, workers=1)
    assert list(table["controller"]) == ["coordinate", "pid"]
    assert table["finished"].between(0.0, 1.0).all()
    assert TUNE_SEED0 >= 1000  # disjoint from the evaluation's seeds 0..19
    assert "course" not in TRACKS

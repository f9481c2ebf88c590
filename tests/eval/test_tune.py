"""eval/tune.py: the search behind the tuned presets."""

import pytest

from eval.tune import TUNE_SEED0, candidates, search
from policies import GSMPN_TUNED, MPN_TUNED, PN_TUNED


@pytest.mark.parametrize(
    ("law", "tuned"), [("pn", PN_TUNED), ("mpn", MPN_TUNED), ("gsmpn", GSMPN_TUNED)]
)
def test_each_tuned_preset_is_a_point_of_the_committed_grid(law: str, tuned: object) -> None:
    # The presets were pasted from `python -m eval.tune`; they must be among its candidates.
    assert tuned in [c.policy.params for c in candidates() if c.law == law]  # type: ignore[attr-defined]


def test_tuning_seeds_are_disjoint_from_the_evaluation_seeds() -> None:
    assert TUNE_SEED0 >= 20  # `make eval` uses seeds 0..19


def test_search_scores_candidates_best_first_per_law() -> None:
    grid = [c for c in candidates() if c.law == "pn"][:3]
    table = search(grid, seeds=1, workers=1, progress=False)
    assert list(table["law"]) == ["pn"] * 3
    assert list(table["score"]) == sorted(table["score"], reverse=True)
    assert set(table["policy"]) == {c.policy.name for c in grid}

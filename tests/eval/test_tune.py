"""eval/tune.py: the guidance laws' committed search, follow-tune once per law."""

from __future__ import annotations

import pytest

from eval import tune
from eval.tuning.objective import TUNE_SEED0
from policies import GSMPN_TUNED, MPN_TUNED, PN_TUNED, tunable_law
from policies.space import params_in_space


@pytest.mark.parametrize(
    ("law", "tuned"), [("pn", PN_TUNED), ("mpn", MPN_TUNED), ("gsmpn", GSMPN_TUNED)]
)
def test_each_tuned_preset_lies_in_its_law_search_space(law: str, tuned: object) -> None:
    # The held-out check re-scores the preset beside the best trials, and the search starts
    # from it: it must be a point of the space.
    found = tunable_law(law)
    assert found.base == tuned
    assert params_in_space(found.space, tuned)


def test_tuning_seeds_are_disjoint_from_the_evaluation_seeds() -> None:
    assert TUNE_SEED0 >= 20  # `make eval` uses seeds 0..19


def test_the_committed_search_is_follow_tune_per_law_with_the_budget() -> None:
    runs = tune.commands()
    assert [r[0] for r in runs] == ["pn", "mpn", "gsmpn"]
    assert runs[0] == ["pn", *tune.BUDGET, "--out", "runs/tune-pn"]


def test_further_options_go_to_every_run_and_out_root_moves_the_folders() -> None:
    runs = tune.commands(["--out-root", "x", "--seeds", "4"])
    assert runs[2] == ["gsmpn", *tune.BUDGET, "--out", "x/tune-gsmpn", "--seeds", "4"]


def test_the_first_failing_run_stops_the_rest(capsys: pytest.CaptureFixture[str]) -> None:
    assert tune.main(["--trials", "0"]) == 2  # follow-tune's own one-line error
    err = capsys.readouterr().err
    assert err.count("\n") == 1
    assert err.startswith("follow-tune: error: argument --trials")

"""eval/line_tune.py: the line followers' committed search, follow-tune for both."""

from __future__ import annotations

import pytest

from eval import line_tune
from policies import make_policy, tunable_law
from policies.space import params_in_space


def test_both_controllers_run_the_same_search_on_line_trace() -> None:
    runs = line_tune.commands()
    assert [r[0] for r in runs] == ["coordinate", "pid"]
    for args in runs:
        assert args[1 : 1 + len(line_tune.BUDGET)] == list(line_tune.BUDGET)
        assert args[args.index("--task") + 1] == "line_trace"


def test_the_tuning_tracks_leave_out_the_mixed_courses_which_the_check_adds() -> None:
    assert "course" not in line_tune.TRACKS
    assert "random" not in line_tune.TRACKS
    args = line_tune.commands()[0]
    checked = args[args.index("--holdout-scenarios") + 1].split(",")
    assert set(checked) == {*line_tune.TRACKS, "course", "random"}


@pytest.mark.parametrize("law", ["coordinate", "pid"])
def test_the_tuned_presets_lie_in_their_search_spaces(law: str) -> None:
    tuned = make_policy(f"{law}:tuned").params  # type: ignore[attr-defined]
    found = tunable_law(law)
    assert found.base == tuned
    assert params_in_space(found.space, tuned)

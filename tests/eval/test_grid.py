"""eval/grid.py: one check of a grid's policies, for rollout and follow-eval run alike."""

from pathlib import Path

import pytest

from eval.grid import checked_policy, policy_spec
from eval.rollout import rollout
from policies import make_policy
from policies.learned.ppo import PPOPolicy

AGENTS = Path(__file__).parents[2] / "policies" / "agents"


def test_a_name_builds_its_policy_and_a_platform_is_split_off() -> None:
    policy, platform = checked_policy("pn:thesis@mecanum", "person_follow")
    assert (policy.name, platform) == ("pn:thesis", "mecanum")
    assert policy_spec("pn") == ("pn", None)
    law = make_policy("mpn")
    assert checked_policy(law, "person_follow") == (law, None)  # an object is taken as it is
    agent, _ = checked_policy(str(AGENTS / "ppo_law"), "person_follow")
    assert isinstance(agent, PPOPolicy)


@pytest.mark.parametrize(
    ("given", "task", "message"),
    [
        ("pn@tank", "person_follow", "tank"),  # an unknown platform names itself
        ("no_such_law", "person_follow", "no_such_law"),
        ("pn", "line_trace", "policy 'pn' is not for the line_trace task; its policies:"),
        (3.5, "person_follow", "policy 3.5 is neither a policy name nor a Policy"),
        (
            str(AGENTS / "ppo_line"),
            "person_follow",
            "was trained on LineTrace-v0, not on the person_follow task: run it on the "
            "line_trace task (--task line_trace)",
        ),
        (str(AGENTS / "ppo") + "@mecanum", "person_follow", "trained on the diff_drive platform"),
    ],
)
def test_what_cannot_run_is_refused_naming_it(given: object, task: str, message: str) -> None:
    with pytest.raises(ValueError, match=message.replace("(", r"\(").replace(")", r"\)")):
        checked_policy(given, task)  # type: ignore[arg-type]


def test_rollout_refuses_an_agent_of_another_task_before_any_episode() -> None:
    with pytest.raises(ValueError, match="was trained on LineTrace-v0"):
        rollout(["pn", str(AGENTS / "ppo_line")], ["curve"], [0])


def test_a_model_path_with_an_at_sign_is_a_path_not_a_platform(tmp_path: Path) -> None:
    folder = tmp_path / "agent@v2"
    with pytest.raises(ValueError, match="v2"):  # no such folder: an unknown platform
        policy_spec(str(folder))
    folder.mkdir()
    assert policy_spec(str(folder)) == (str(folder), None)
    assert policy_spec("pn@mecanum") == ("pn", "mecanum")

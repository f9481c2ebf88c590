"""Every built-in scenario is in the README's table and in the env's manual (its docstring):
a scenario added without them was missing from both (``lookalike``)."""

from __future__ import annotations

import re
from pathlib import Path

from follow_env.tasks.person_follow.env import PersonFollowEnv
from follow_env.tasks.person_follow.scenarios import SCENARIOS

README = Path(__file__).resolve().parents[4] / "README.md"
BUILT_IN = (
    "follow_env.tasks.person_follow.scenarios.basic",
    "follow_env.tasks.person_follow.scenarios.realistic",
)


def _built_in() -> list[str]:
    # a test or a doctest may register scenarios of its own in this process
    return [name for name, spec in SCENARIOS.items() if spec.fn.__module__ in BUILT_IN]


def test_every_built_in_scenario_is_in_the_readme_table_and_the_env_manual() -> None:
    names = _built_in()
    assert len(names) >= 12
    table = README.read_text(encoding="utf-8").split("### Scenarios", 1)[1].split("\n\n", 2)[1]
    rows = re.findall(r"^\| `(\w+)` \|", table, re.M)
    assert rows == names  # the table's order is the registry's
    manual = " ".join((PersonFollowEnv.__doc__ or "").split())
    listed = manual.split("``scenario``: a registered scenario name (", 1)[1].split(")", 1)[0]
    assert re.findall(r"``(\w+)``", listed) == names

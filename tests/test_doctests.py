"""The examples in the user-facing docstrings run as written."""

from __future__ import annotations

import doctest
import importlib

import pytest

from follow_env.tasks.person_follow.scenarios.registry import SCENARIOS

# Every module whose docstrings hold a user-facing example (doctest.testmod reads one module's
# docstrings, not its submodules': each is named here).
MODULES = [
    "follow_env.tasks.person_follow.env",
    "follow_env.tasks.person_follow.scenarios",
    "follow_env.tasks.line_trace.env",
    "follow_env",
    "policies",
]
# Run too, so that an example added later is checked, but with none yet.
WITHOUT_EXAMPLES = {"follow_env"}


@pytest.mark.parametrize("module", MODULES)
def test_docstring_examples_run(module: str) -> None:
    registered = dict(SCENARIOS)  # an example registers a scenario of its own: not for the others
    try:
        result = doctest.testmod(importlib.import_module(module), optionflags=doctest.ELLIPSIS)
    finally:
        SCENARIOS.clear()
        SCENARIOS.update(registered)
    assert result.attempted > 0 or module in WITHOUT_EXAMPLES
    assert result.failed == 0

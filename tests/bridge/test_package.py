"""bridge/: a leaf package whose examples run as written."""

from __future__ import annotations

import doctest
import importlib
import subprocess
import sys

import pytest


def test_bridge_imports_nothing_of_the_simulator_training_or_evaluation() -> None:
    # A fresh interpreter: this test process has the simulator loaded already (conftest).
    code = (
        "import sys, bridge, bridge.link, bridge.protocol\n"
        "bad = sorted({m.split('.')[0] for m in sys.modules}"
        " & {'follow_env', 'policies', 'train', 'eval', 'torch', 'gymnasium'})\n"
        "print(','.join(bad))\n"
    )
    result = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True
    )
    assert result.stdout.strip() == ""


@pytest.mark.parametrize("module", ["bridge.protocol", "bridge.link"])
def test_docstring_examples_run(module: str) -> None:
    result = doctest.testmod(importlib.import_module(module), optionflags=doctest.ELLIPSIS)
    assert result.attempted > 0
    assert result.failed == 0

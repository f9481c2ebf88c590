"""Shared fixtures."""

from __future__ import annotations

import warnings

import pytest

import follow_env  # noqa: F401  (registers PersonFollow-v0)


@pytest.fixture(autouse=True)
def _quiet_action_space_advice() -> None:
    # Gymnasium and SB3 advise a [-1, 1] action space; ours is SI by design (see README).
    warnings.filterwarnings("ignore", message=".*symmetric and normalized.*")
    warnings.filterwarnings("ignore", message=".*normalized.*action space.*")

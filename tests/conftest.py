"""Shared fixtures."""

from __future__ import annotations

import os
import warnings

import pytest
from hypothesis import settings

# The first call of a compiled function compiles it (or loads it from the cache): no deadline,
# or a property test would fail on whichever example happened to come first.
settings.register_profile("personfollow", deadline=None)
settings.load_profile("personfollow")

# render_mode="human" opens its pygame window on SDL's dummy driver: no screen needed.
os.environ.setdefault("SDL_VIDEODRIVER", "dummy")

import follow_env  # noqa: E402, F401  (registers PersonFollow-v0; after the SDL setting)


@pytest.fixture(autouse=True)
def _quiet_action_space_advice() -> None:
    # Gymnasium and SB3 advise a [-1, 1] action space; ours is SI by design (see README).
    warnings.filterwarnings("ignore", message=".*symmetric and normalized.*")
    warnings.filterwarnings("ignore", message=".*normalized.*action space.*")


@pytest.fixture(scope="session")
def local_ray():
    """A local Ray with 2 CPUs, started once for the session (about 5 s) and shut down after.

    :mod:`execution` uses the running instance instead of starting its own.
    """
    ray = pytest.importorskip("ray", reason="Ray is a dev dependency: pip install -e '.[dev]'")
    os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")
    ray.init(address="local", num_cpus=2, include_dashboard=False, logging_level="warning")
    yield ray
    ray.shutdown()

"""PersonFollow simulation: camera-only person-following robots as Gymnasium environments.

Importing this package registers every task's env (``PersonFollow-v0``) and nothing heavier::

    import gymnasium as gym
    import follow_env

    env = gym.make("PersonFollow-v0", scenario="curve")

The layers, lowest first (each imports only those below it): :mod:`follow_env.sim` (compiled
code cache, randomness, schema, config base, runner, env faces), :mod:`follow_env.world`
(geometry, line of sight, T-RRT), :mod:`follow_env.platforms` (wheels, the differential drive),
:mod:`follow_env.sensors` (camera, detector, depth) and :mod:`follow_env.tasks` (what the robot
is for: ``person_follow``). The names below are the person-following task's, loaded on first
use.
"""

from __future__ import annotations

import importlib
from typing import Any

from follow_env.tasks import register_envs

__all__ = [
    "IDEAL",
    "INFO_KEYS",
    "NOISY",
    "PRESETS",
    "RANDOMIZED",
    "SCENARIOS",
    "THESIS",
    "EnvConfig",
    "PersonFollowEnv",
    "PersonFollowVectorEnv",
    "make_sb3_vec_env",
    "register_scenario",
]

ENV_ID = "PersonFollow-v0"

_LAZY = {
    "IDEAL": "follow_env.tasks.person_follow.config",
    "NOISY": "follow_env.tasks.person_follow.config",
    "PRESETS": "follow_env.tasks.person_follow.config",
    "RANDOMIZED": "follow_env.tasks.person_follow.config",
    "THESIS": "follow_env.tasks.person_follow.config",
    "EnvConfig": "follow_env.tasks.person_follow.config",
    "SCENARIOS": "follow_env.tasks.person_follow.scenarios",
    "register_scenario": "follow_env.tasks.person_follow.scenarios",
    "PersonFollowEnv": "follow_env.tasks.person_follow.env",
    "PersonFollowVectorEnv": "follow_env.tasks.person_follow.env",
    "make_sb3_vec_env": "follow_env.tasks.person_follow.env",
}


def __getattr__(name: str) -> Any:
    if name == "INFO_KEYS":
        from follow_env.platforms import get_platform
        from follow_env.tasks.person_follow.task import TASK

        return TASK.info_keys(get_platform("diff_drive"))
    if name in _LAZY:
        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'follow_env' has no attribute {name!r}")


register_envs()

"""PersonFollow simulation: a camera-only person-following robot as Gymnasium environments.

Importing this package registers ``PersonFollow-v0``::

    import gymnasium as gym
    import follow_env

    env = gym.make("PersonFollow-v0", scenario="curve")
"""

from __future__ import annotations

import gymnasium

from follow_env.config import IDEAL, NOISY, PRESETS, THESIS, EnvConfig
from follow_env.env import INFO_KEYS, PersonFollowEnv
from follow_env.scenarios import SCENARIOS, register_scenario

__all__ = [
    "IDEAL",
    "INFO_KEYS",
    "NOISY",
    "PRESETS",
    "SCENARIOS",
    "THESIS",
    "EnvConfig",
    "PersonFollowEnv",
    "register_scenario",
]

ENV_ID = "PersonFollow-v0"

if ENV_ID not in gymnasium.registry:
    # No max_episode_steps: the core ends episodes itself (walk over or EpisodeConfig.max_steps),
    # so the single env and the batched core truncate at exactly the same step.
    gymnasium.register(id=ENV_ID, entry_point="follow_env.env:PersonFollowEnv")

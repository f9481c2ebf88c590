"""PersonFollow simulation: a camera-only person-following robot as Gymnasium environments.

Importing this package registers ``PersonFollow-v0``::

    import gymnasium as gym
    import follow_env

    env = gym.make("PersonFollow-v0", scenario="curve")
"""

from __future__ import annotations

import hashlib
from pathlib import Path

import gymnasium
import numba


def _source_keyed_numba_cache() -> str | None:
    """Point numba's on-disk cache at a folder named by a hash of this package's sources.

    numba checks a cached kernel against its own file only; the kernel in core.py inlines
    functions from the other modules here, so an edit to, say, drive.py would otherwise leave
    a stale kernel in the cache. Returns the previous setting, to restore once our modules are
    compiled-or-loaded, so the user's own numba code keeps its cache location.
    """
    here = Path(__file__).parent
    digest = hashlib.sha1()
    for path in sorted(here.glob("*.py")):
        digest.update(path.read_bytes())
    previous = numba.config.CACHE_DIR
    numba.config.CACHE_DIR = str(here / "__pycache__" / f"numba-{digest.hexdigest()[:12]}")
    return previous


_previous_cache_dir = _source_keyed_numba_cache()

from follow_env.config import IDEAL, NOISY, PRESETS, THESIS, EnvConfig  # noqa: E402  (after the cache set-up)
from follow_env.env import PersonFollowEnv  # noqa: E402  (after the cache set-up)
from follow_env.info import INFO_KEYS  # noqa: E402  (after the cache set-up)
from follow_env.scenarios import SCENARIOS, register_scenario  # noqa: E402  (after the cache set-up)
from follow_env.vector_env import PersonFollowVectorEnv  # noqa: E402  (after the cache set-up)


def make_sb3_vec_env(num_envs: int, **env_kwargs: object) -> object:
    """An SB3 ``VecEnv`` of ``num_envs`` robots over the batched core (see follow_env.sb3).

    Imported lazily so that ``import follow_env`` does not load stable-baselines3 and torch.
    """
    from follow_env.sb3 import make_sb3_vec_env as make

    return make(num_envs, **env_kwargs)


__all__ = [
    "IDEAL",
    "INFO_KEYS",
    "NOISY",
    "PRESETS",
    "SCENARIOS",
    "THESIS",
    "EnvConfig",
    "PersonFollowEnv",
    "PersonFollowVectorEnv",
    "make_sb3_vec_env",
    "register_scenario",
]

numba.config.CACHE_DIR = _previous_cache_dir

ENV_ID = "PersonFollow-v0"

if ENV_ID not in gymnasium.registry:
    # No max_episode_steps: the core ends episodes itself (walk over or EpisodeConfig.max_steps),
    # so the single env and the batched core truncate at exactly the same step.
    gymnasium.register(
        id=ENV_ID,
        entry_point="follow_env.env:PersonFollowEnv",
        vector_entry_point="follow_env.vector_env:PersonFollowVectorEnv",
    )

"""The batched core as a stable-baselines3 ``VecEnv``.

SB3 does not take a Gymnasium ``VectorEnv``; this adapter speaks SB3's protocol over the same
core: same-step autoreset, ``reset()`` returning observations only, ``step_wait()`` returning
``(obs, rewards, dones, infos)`` with ``infos`` a list of dicts in which every finished lane
holds ``terminal_observation`` and ``TimeLimit.truncated``. It works under ``VecNormalize``,
``VecMonitor``, ``evaluate_policy`` and PPO.

Seeding follows SB3: ``seed(s)`` then ``reset()`` gives lane ``i`` the seed ``s + i``; without
a seed every lane draws fresh entropy. Lane ``i`` then replays the single env reset with
``seed=s + i``, episode after episode.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import gymnasium as gym
import numpy as np
from stable_baselines3.common.vec_env import VecEnv
from stable_baselines3.common.vec_env.base_vec_env import VecEnvIndices, VecEnvStepReturn

from follow_env.config import EnvConfig
from follow_env.core import BatchedSim
from follow_env.env import resolve_config
from follow_env.info import batch_info, make_spaces, observations
from follow_env.layout import I_REASON, REASON_NAMES, S_REWARD, S_TERM, S_TRUNC

__all__ = ["PersonFollowSB3VecEnv", "make_sb3_vec_env"]


class PersonFollowSB3VecEnv(VecEnv):
    """``num_envs`` PersonFollow robots as one SB3 ``VecEnv`` (see the module docstring).

    :param num_envs: number of lanes.
    :param full_info: put every key of :data:`follow_env.INFO_KEYS` in every lane's info dict
        each step (costs about a microsecond per key and lane); by default the dicts hold only
        what SB3 needs at episode ends, plus ``termination``.
    :param env_kwargs: the single env's keyword arguments (``config``, ``scenario``, sections).
    """

    def __init__(self, num_envs: int, full_info: bool = False, **env_kwargs: Any) -> None:
        if isinstance(num_envs, bool) or not isinstance(num_envs, int) or num_envs < 1:
            raise ValueError(f"num_envs={num_envs!r} is out of range: must be an integer >= 1")
        render_mode = env_kwargs.pop("render_mode", None)
        if render_mode is not None:
            raise ValueError(
                f"render_mode={render_mode!r} is out of range: the SB3 adapter does not render; "
                "use gym.make('PersonFollow-v0', render_mode='rgb_array') for videos"
            )
        self.config: EnvConfig = resolve_config(**env_kwargs)
        self.render_mode = None
        self.full_info = full_info
        self.sim = BatchedSim(self.config, num_envs)
        self._actions = np.zeros((num_envs, 2))
        obs_space, act_space = make_spaces(self.config)
        super().__init__(num_envs, obs_space, act_space)

    # -- SB3 VecEnv API -----------------------------------------------------------------------

    def reset(self) -> np.ndarray:
        """Reset every lane (seeded by ``seed()`` if it was called since the last reset)."""
        seeded = [i for i, seed in enumerate(self._seeds) if seed is not None]
        if seeded:
            self.sim.seeds.seed(np.array(seeded), [self._seeds[i] for i in seeded])
        self.sim.reset_lanes(np.arange(self.num_envs))
        self._reset_seeds()
        self._reset_options()
        return observations(self.sim)

    def step_async(self, actions: np.ndarray) -> None:
        """Take ``[v_mps, w_radps]`` for every lane, shape (num_envs, 2)."""
        a = np.asarray(actions, dtype=np.float64).reshape(self.num_envs, 2)
        bad = ~np.isfinite(a).all(axis=1)
        if bad.any():
            raise ValueError(
                f"actions of lanes {np.flatnonzero(bad).tolist()} are out of range: must be finite"
            )
        self._actions[:] = a

    def step_wait(self) -> VecEnvStepReturn:
        """Step all lanes; finished lanes are reset at once (SB3's same-step autoreset)."""
        self.sim.step(self._actions)
        fs = self.sim.fstate
        rewards = fs[:, S_REWARD].astype(np.float32)
        terminated = fs[:, S_TERM] > 0.0
        truncated = fs[:, S_TRUNC] > 0.0
        dones = terminated | truncated
        obs = observations(self.sim)
        infos = self._infos()
        if dones.any():
            lanes = np.flatnonzero(dones)
            for i in lanes:
                infos[i]["terminal_observation"] = obs[i].copy()
                infos[i]["TimeLimit.truncated"] = bool(truncated[i] and not terminated[i])
            self.sim.reset_lanes(lanes)
            obs = observations(self.sim)
        return obs, rewards, dones, infos

    def close(self) -> None:
        """Stop the core's worker threads."""
        self.sim.close()

    def get_attr(self, attr_name: str, indices: VecEnvIndices = None) -> list[Any]:
        """The lanes share one configuration: the attribute of this env, once per index."""
        value = getattr(self, attr_name)
        return [value for _ in self._get_indices(indices)]

    def set_attr(self, attr_name: str, value: Any, indices: VecEnvIndices = None) -> None:
        """Set an attribute shared by all lanes (per-lane attributes do not exist here)."""
        setattr(self, attr_name, value)

    def env_method(
        self, method_name: str, *method_args: Any, indices: VecEnvIndices = None, **kwargs: Any
    ) -> list[Any]:
        """Call a method of this env once per index."""
        method = getattr(self, method_name)
        return [method(*method_args, **kwargs) for _ in self._get_indices(indices)]

    def env_is_wrapped(
        self, wrapper_class: type[gym.Wrapper], indices: VecEnvIndices = None
    ) -> list[bool]:
        """Lanes are not Gymnasium envs, so no lane is wrapped."""
        return [False for _ in self._get_indices(indices)]

    def get_images(self) -> Sequence[np.ndarray | None]:
        """No images: the adapter does not render."""
        return [None for _ in range(self.num_envs)]

    # -- helpers ------------------------------------------------------------------------------

    def _infos(self) -> list[dict[str, Any]]:
        if not self.full_info:
            reasons = self.sim.istate[:, I_REASON]
            return [{"termination": REASON_NAMES[r]} if r else {} for r in reasons.tolist()]
        batch = batch_info(self.sim)
        columns = {k: v.tolist() for k, v in batch.items()}
        keys = list(columns)
        return [dict(zip(keys, row, strict=True)) for row in zip(*columns.values(), strict=True)]


def make_sb3_vec_env(num_envs: int, **env_kwargs: Any) -> PersonFollowSB3VecEnv:
    """An SB3 ``VecEnv`` of ``num_envs`` PersonFollow robots over the batched core.

    ``env_kwargs`` are the single env's (``config``, ``scenario``, config sections) plus
    ``full_info``. Wrap it as usual: ``VecMonitor(make_sb3_vec_env(16))``,
    ``VecNormalize(...)``.
    """
    return PersonFollowSB3VecEnv(num_envs, **env_kwargs)

"""The runner of any task as a stable-baselines3 ``VecEnv``.

SB3 does not take a Gymnasium ``VectorEnv``; this adapter speaks SB3's protocol over the same
core: same-step autoreset, ``reset()`` returning observations only, ``step_wait()`` returning
``(obs, rewards, dones, infos)`` with ``infos`` a list of dicts in which every finished lane
holds ``terminal_observation`` and ``TimeLimit.truncated``. It works under ``VecNormalize``,
``VecMonitor``, ``evaluate_policy`` and PPO.

Seeding follows SB3: ``seed(s)`` then ``reset()`` gives lane ``i`` the seed ``s + i``; without
a seed every lane draws fresh entropy. Lane ``i`` then replays the single env reset with
``seed=s + i``, episode after episode.

The lanes are one env, not ``num_envs`` Gymnasium envs: ``get_attr`` reads the shared
attribute for each index, ``set_attr`` and ``env_method`` act on every lane at once and so take
only indices that cover every lane (``ValueError`` otherwise), except ``env_method("reset",
indices=...)``, which resets just those lanes (as ``DummyVecEnv`` resets those envs).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.error import ResetNeeded
from stable_baselines3.common.vec_env import VecEnv
from stable_baselines3.common.vec_env.base_vec_env import VecEnvIndices, VecEnvStepReturn

from follow_env.sim.checks import is_integer, out_of_range
from follow_env.sim.faces import action_array, max_episode_steps_error, options_error
from follow_env.sim.runner import BatchedSim

__all__ = ["TaskSB3VecEnv"]


class TaskSB3VecEnv(VecEnv):
    """``num_envs`` lanes of a task as one SB3 ``VecEnv`` (see the module docstring).

    :param task: the task model (e.g. ``follow_env.tasks.person_follow.task.TASK``).
    :param num_envs: number of lanes.
    :param full_info: put every info key in every lane's info dict each step (costs about a
        microsecond per key and lane); by default the dicts hold only what SB3 needs at episode
        ends, plus ``termination``, and the keys :meth:`include_info` asked for. The same holds
        for ``reset_infos`` (a lane's info after its last reset, as ``DummyVecEnv`` keeps it):
        every key, or only those asked for (empty dicts by default).
    :param env_kwargs: the single env's keyword arguments (``config``, shorthands, sections).
    """

    def __init__(
        self, task: Any, num_envs: int, full_info: bool = False, **env_kwargs: Any
    ) -> None:
        if not is_integer(num_envs) or num_envs < 1:
            raise out_of_range("num_envs", num_envs, "an integer >= 1")
        render_mode = env_kwargs.pop("render_mode", None)
        if render_mode is not None:
            raise out_of_range(
                "render_mode",
                render_mode,
                f"None: the SB3 adapter does not render; use gym.make({task.spec.env_id!r}, "
                "render_mode='rgb_array') for videos",
            )
        max_episode_steps = env_kwargs.pop("max_episode_steps", None)
        self.task = task
        self.config = task.resolve_config(**env_kwargs)
        if max_episode_steps is not None:
            raise max_episode_steps_error(self.config, max_episode_steps, "the SB3 adapter")
        self.render_mode = None
        self.full_info = full_info
        #: Info keys put in every lane's dict each step besides SB3's (:meth:`include_info`).
        self.info_keys: tuple[str, ...] = ()
        self.sim = BatchedSim(task, self.config, int(num_envs))
        obs_space, act_space = task.spaces(self.config, self.sim.platform)
        self._actions = np.zeros((int(num_envs), act_space.shape[0]))
        self._action_names = "[" + ", ".join(a.name for a in self.sim.platform.actions) + "]"
        super().__init__(int(num_envs), obs_space, act_space)
        # Until its first reset a lane holds zeroed records, no episode.
        self._started = np.zeros(self.num_envs, dtype=np.bool_)
        self._needs_reset = True

    # -- SB3 VecEnv API -----------------------------------------------------------------------

    def reset(self) -> np.ndarray:
        """Reset every lane (seeded by ``seed()`` if it was called since the last reset).

        :raises ValueError: when ``set_options`` gave options: the task takes none (the single
            env refuses them too, rather than ignore them).
        """
        given = [options for options in self._options if options]
        if given:
            self._reset_options()
            raise options_error(given[0])
        seeded = [i for i, seed in enumerate(self._seeds) if seed is not None]
        if seeded:
            self.sim.seeds.seed(np.array(seeded), [self._seeds[i] for i in seeded])
        self.sim.reset_lanes(np.arange(self.num_envs))
        self._reset_seeds()
        self._reset_options()
        self._started[:] = True
        self._needs_reset = False
        self.reset_infos = self._infos()
        return self.task.observations(self.sim)

    def step_async(self, actions: np.ndarray) -> None:
        """Take the platform's action for every lane: shape (num_envs, action size), as SB3's
        algorithms and ``DummyVecEnv`` pass it (row ``i`` is lane ``i``'s action).

        :raises ValueError: for another shape (a transposed or flat array would give lanes
            each other's entries), or entries that are not finite real numbers.
        """
        self._actions[:] = action_array(actions, self._actions.shape, self._action_names)

    def step_wait(self) -> VecEnvStepReturn:
        """Step all lanes; finished lanes are reset at once (SB3's same-step autoreset).

        :raises gymnasium.error.ResetNeeded: before the first ``reset()`` (as the envs of
            SB3's ``DummyVecEnv`` do).
        """
        if self._needs_reset:
            raise ResetNeeded("call reset() before step()")
        self.sim.step(self._actions)
        ep = self.sim.episode
        rewards = ep["reward"].astype(np.float32)
        terminated = ep["terminated"] > 0.0
        truncated = ep["truncated"] > 0.0
        dones = terminated | truncated
        obs = self.task.observations(self.sim)
        infos = self._infos()
        if dones.any():
            lanes = np.flatnonzero(dones)
            for i in lanes:
                infos[i]["terminal_observation"] = obs[i].copy()
                infos[i]["TimeLimit.truncated"] = bool(truncated[i] and not terminated[i])
            self.sim.reset_lanes(lanes)
            obs = self.task.observations(self.sim)
            for i, info in zip(lanes.tolist(), self._infos(lanes), strict=True):
                self.reset_infos[i] = info
        return obs, rewards, dones, infos

    def close(self) -> None:
        """Stop the core's worker threads."""
        self.sim.close()

    def get_attr(self, attr_name: str, indices: VecEnvIndices = None) -> list[Any]:
        """The lanes share one configuration: the attribute of this env, once per index."""
        value = getattr(self, attr_name)
        return [value for _ in self._lanes(indices)]

    def set_attr(self, attr_name: str, value: Any, indices: VecEnvIndices = None) -> None:
        """Set an attribute shared by all lanes (per-lane attributes do not exist here).

        :raises ValueError: when ``indices`` leave a lane out (it would be set too).
        """
        self._every_lane(indices, f"set_attr({attr_name!r})")
        setattr(self, attr_name, value)

    def env_method(
        self, method_name: str, *method_args: Any, indices: VecEnvIndices = None, **kwargs: Any
    ) -> list[Any]:
        """Call a method of this env once, its result given for each index; ``"reset"``
        resets the lanes of ``indices`` only and returns ``(obs, info)`` for each, as the
        single env's ``reset`` does (``seed=s`` seeds every one of them with ``s``).

        :raises ValueError: when ``indices`` leave a lane out of another method (it acts on
            every lane), or for arguments ``reset`` does not take.
        """
        if method_name == "reset":
            return self._reset_some(self._lanes(indices), *method_args, **kwargs)
        self._every_lane(indices, f"env_method({method_name!r})")
        result = getattr(self, method_name)(*method_args, **kwargs)
        return [result for _ in self._lanes(indices)]

    def env_is_wrapped(
        self, wrapper_class: type[gym.Wrapper], indices: VecEnvIndices = None
    ) -> list[bool]:
        """Lanes are not Gymnasium envs, so no lane is wrapped."""
        return [False for _ in self._lanes(indices)]

    def get_images(self) -> Sequence[np.ndarray | None]:
        """No images: the adapter does not render."""
        return [None for _ in range(self.num_envs)]

    def include_info(self, keys: Sequence[str]) -> None:
        """Put the info ``keys`` in every lane's info dict from the next step on (a wrapper's
        way to read, say, the ground truth a training reward charges): the values of the state
        each step reached; on a lane whose episode ended, those of its final state (before the
        reset), as ``terminal_observation`` is.

        :raises ValueError: for a key the task's info does not have (naming the known ones).
        """
        known = self.task.info_keys(self.sim.platform)
        for key in keys:
            if key not in known:
                raise ValueError(f"info key {key!r} is not one of {', '.join(known)}")
        self.info_keys = tuple(dict.fromkeys((*self.info_keys, *keys)))

    # -- helpers ------------------------------------------------------------------------------

    def _lanes(self, indices: VecEnvIndices) -> list[int]:
        """``indices`` as lane numbers; ``ValueError`` for one outside ``[0, num_envs)``."""
        lanes = list(self._get_indices(indices))
        bad = [i for i in lanes if not is_integer(i) or not 0 <= i < self.num_envs]
        if bad:
            raise out_of_range("indices", indices, f"lanes in [0, {self.num_envs})")
        return [int(i) for i in lanes]

    def _every_lane(self, indices: VecEnvIndices, call: str) -> None:
        """``ValueError`` unless ``indices`` name every lane: ``call`` acts on all of them."""
        if set(self._lanes(indices)) != set(range(self.num_envs)):
            raise out_of_range(
                "indices",
                indices,
                f"None or every lane 0..{self.num_envs - 1}: the lanes share one env, so "
                f"{call} acts on all of them (get_attr reads for some; env_method('reset') "
                "resets some)",
            )

    def _reset_some(
        self, lanes: list[int], *args: Any, seed: int | None = None, **kwargs: Any
    ) -> list[tuple[np.ndarray, dict[str, Any]]]:
        """Reset ``lanes`` (each seeded with ``seed`` if given): the single env's ``reset``
        for each, ``[(obs, info), ...]`` with the full info."""
        options = kwargs.pop("options", None)
        if args or kwargs:
            raise ValueError(
                f"env_method('reset') takes only seed= and options=, as the single env's reset "
                f"does (got {args!r}, {kwargs!r})"
            )
        if options:
            raise options_error(options)
        chosen = np.array(sorted(set(lanes)), dtype=np.int64)
        self.sim.reset_lanes(chosen, None if seed is None else [seed] * len(chosen))
        self._started[chosen] = True
        self._needs_reset = not self._started.all()
        obs = self.task.observations(self.sim)
        return [(obs[i].copy(), self.task.lane_info(self.sim, i)) for i in lanes]

    def _infos(self, lanes: np.ndarray | None = None) -> list[dict[str, Any]]:
        """Every lane's info dict (or those of ``lanes``), as :meth:`step_wait` gives them."""
        if not self.full_info:
            names = self.task.spec.terminations
            reasons = self.sim.episode["reason"]
            if lanes is not None:
                reasons = reasons[lanes]
            infos: list[dict[str, Any]] = [
                {"termination": names[r]} if r else {} for r in reasons.tolist()
            ]
            if self.info_keys:
                batch = self.task.batch_info(self.sim, lanes)
                for key in self.info_keys:
                    for info, value in zip(infos, batch[key].tolist(), strict=True):
                        info[key] = value
            return infos
        batch = self.task.batch_info(self.sim, lanes)
        columns = {k: v.tolist() for k, v in batch.items()}
        keys = list(columns)
        return [dict(zip(keys, row, strict=True)) for row in zip(*columns.values(), strict=True)]

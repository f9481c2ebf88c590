"""A VecEnv of several VecEnvs, and what an env says about its platform.

:class:`ConcatVecEnv` joins several VecEnvs, here one batched core per scenario (a core runs one
scenario for all its lanes), into one VecEnv whose lanes are the sub-envs' lanes in order.
``seed(s)`` gives lane ``j`` of the whole the seed ``s + j``, as for one VecEnv.
:func:`env_action_names` and :func:`env_platform` read the platform's action entries and name
from any env down a wrapper stack (the wrappers of :mod:`train.wrappers` use them too).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import gymnasium as gym
import numpy as np
from stable_baselines3.common.vec_env import VecEnv, VecEnvWrapper
from stable_baselines3.common.vec_env.base_vec_env import VecEnvIndices, VecEnvObs, VecEnvStepReturn

__all__ = ["ConcatVecEnv", "env_action_names", "env_platform"]


def _platform(venv: VecEnv) -> Any:
    base = venv.unwrapped if isinstance(venv, VecEnvWrapper) else venv
    return getattr(getattr(base, "sim", None), "platform", None)


def env_action_names(venv: VecEnv) -> tuple[str, ...] | None:
    """The names of ``venv``'s action entries (the platform's, e.g. ``v_mps, vy_mps, w_radps``),
    or None if the env does not say: an ``action_names`` attribute anywhere down the wrapper
    stack, else the platform of a task's batched core (``sim.platform``)."""
    names = getattr(venv, "action_names", None)
    if names is None:
        actions = getattr(_platform(venv), "actions", None)
        names = None if actions is None else [a.name for a in actions]
    return None if names is None else tuple(names)


def env_platform(venv: VecEnv) -> str | None:
    """The name of the platform ``venv`` simulates (``"mecanum"``), or None if it does not say:
    a ``platform_name`` attribute down the wrapper stack, else its batched core's platform."""
    name = getattr(venv, "platform_name", None)
    if name is None:
        name = getattr(_platform(venv), "name", None)
    return None if name is None else str(name)


class ConcatVecEnv(VecEnv):
    """Several VecEnvs with equal spaces as one: lanes are the sub-envs' lanes, in order.

    Used to train on several scenarios at once: one batched core per scenario, stepped one after
    the other each step (a core's kernel is fast enough that threads would not pay off at a few
    lanes per scenario).

    SB3's VecEnv conventions hold for the whole as for each part: ``reset_infos`` is the
    parts' ``reset_infos`` in lane order (after ``reset()``, and for a lane its part reset in
    ``step_wait``), a finished lane's info keeps its part's ``terminal_observation`` and
    ``TimeLimit.truncated``, and ``seed``, ``set_options``, ``get_attr``, ``set_attr``,
    ``env_method`` and ``close`` reach the parts (lane ``j`` of the whole is lane ``j - start``
    of its part).

    :param venvs: the sub-envs; their observation and action spaces must be equal, and so
        their platforms and action entries (:func:`env_platform`, :func:`env_action_names`),
        which it reports as its own ``platform_name`` and ``action_names``.
    """

    def __init__(self, venvs: Sequence[VecEnv]) -> None:
        if not venvs:
            raise ValueError("ConcatVecEnv needs at least one VecEnv")
        first = venvs[0]
        for v in venvs[1:]:
            if v.observation_space != first.observation_space:
                raise ValueError(
                    f"observation spaces differ: {v.observation_space} != {first.observation_space}"
                )
            if v.action_space != first.action_space:
                raise ValueError(f"action spaces differ: {v.action_space} != {first.action_space}")
        names = {env_action_names(v) for v in venvs}
        platforms = {env_platform(v) for v in venvs}
        if len(names) > 1 or len(platforms) > 1:
            raise ValueError(f"platforms differ: {platforms}, action entries {names}")
        #: The action entries' names (the sub-envs' platform's), or None if they do not say.
        self.action_names = names.pop()
        #: The sub-envs' platform, or None if they do not say.
        self.platform_name = platforms.pop()
        self.venvs = list(venvs)
        self._bounds = np.cumsum([0, *(v.num_envs for v in self.venvs)])
        super().__init__(int(self._bounds[-1]), first.observation_space, first.action_space)

    def _slices(self) -> list[slice]:
        return [slice(a, b) for a, b in zip(self._bounds[:-1], self._bounds[1:], strict=True)]

    def seed(self, seed: int | None = None) -> Sequence[int | None]:
        """Lane ``j`` of the whole gets ``seed + j`` at the next reset."""
        seeds = super().seed(seed)
        for venv, part in zip(self.venvs, self._slices(), strict=True):
            venv.seed(seeds[part][0])
        self._reset_seeds()
        return seeds

    def set_options(self, options: list[dict] | dict | None = None) -> None:
        """Options for the next reset, passed on to the sub-envs (SB3's convention: one dict
        for every lane, or a list of one per lane of the whole; a sub-env that takes no options
        refuses them at its reset, as it would alone)."""
        if options is None or isinstance(options, dict):
            for venv in self.venvs:
                venv.set_options(options)
            return
        if len(options) != self.num_envs:
            raise ValueError(
                f"set_options: {len(options)} option dicts for {self.num_envs} lanes; give "
                "one per lane, or one dict for all"
            )
        for venv, part in zip(self.venvs, self._slices(), strict=True):
            venv.set_options(list(options[part]))

    def reset(self) -> VecEnvObs:
        """Reset every sub-env; ``reset_infos`` is then their ``reset_infos`` in lane order."""
        obs = np.concatenate([v.reset() for v in self.venvs])
        self.reset_infos = [info for v in self.venvs for info in v.reset_infos]
        return obs

    def step_async(self, actions: np.ndarray) -> None:
        for venv, part in zip(self.venvs, self._slices(), strict=True):
            venv.step_async(actions[part])

    def step_wait(self) -> VecEnvStepReturn:
        results = [v.step_wait() for v in self.venvs]
        obs = np.concatenate([r[0] for r in results])
        rewards = np.concatenate([r[1] for r in results])
        dones = np.concatenate([r[2] for r in results])
        infos = [info for r in results for info in r[3]]
        # A lane that ended was reset by its sub-env (SB3's same-step autoreset): its new
        # episode's reset info is in the sub-env's reset_infos, as DummyVecEnv keeps it.
        for j in np.flatnonzero(dones).tolist():
            k = int(np.searchsorted(self._bounds, j, side="right")) - 1
            self.reset_infos[j] = self.venvs[k].reset_infos[j - int(self._bounds[k])]
        return obs, rewards, dones, infos

    def close(self) -> None:
        for venv in self.venvs:
            venv.close()

    def _split(self, indices: VecEnvIndices) -> list[tuple[VecEnv, list[int]]]:
        """Group global lane indices by sub-env, as local indices.

        :raises ValueError: for an index outside ``[0, num_envs)`` (it would name a lane of
            another part, or none).
        """
        groups: list[tuple[VecEnv, list[int]]] = []
        for j in self._get_indices(indices):
            if isinstance(j, bool) or not isinstance(j, int | np.integer):
                raise ValueError(f"indices={indices!r}: {j!r} is not a lane number")
            if not 0 <= j < self.num_envs:
                raise ValueError(
                    f"indices={indices!r} is out of range: must be lanes in [0, {self.num_envs})"
                )
            k = int(np.searchsorted(self._bounds, j, side="right")) - 1
            local = j - int(self._bounds[k])
            if groups and groups[-1][0] is self.venvs[k]:
                groups[-1][1].append(local)
            else:
                groups.append((self.venvs[k], [local]))
        return groups

    def get_attr(self, attr_name: str, indices: VecEnvIndices = None) -> list[Any]:
        return [x for v, idx in self._split(indices) for x in v.get_attr(attr_name, idx)]

    def set_attr(self, attr_name: str, value: Any, indices: VecEnvIndices = None) -> None:
        for v, idx in self._split(indices):
            v.set_attr(attr_name, value, idx)

    def env_method(
        self, method_name: str, *method_args: Any, indices: VecEnvIndices = None, **kwargs: Any
    ) -> list[Any]:
        return [
            x
            for v, idx in self._split(indices)
            for x in v.env_method(method_name, *method_args, indices=idx, **kwargs)
        ]

    def env_is_wrapped(
        self, wrapper_class: type[gym.Wrapper], indices: VecEnvIndices = None
    ) -> list[bool]:
        return [x for v, idx in self._split(indices) for x in v.env_is_wrapped(wrapper_class, idx)]

    def get_images(self) -> Sequence[np.ndarray | None]:
        return [img for v in self.venvs for img in v.get_images()]

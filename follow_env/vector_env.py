"""``PersonFollowVectorEnv``: N robots in one batched core, as a Gymnasium ``VectorEnv``.

No physics lives here: every lane is stepped by the same compiled kernel as the single env, so
lane ``i`` after ``reset(seed=s)`` is bit-for-bit the single env after ``reset(seed=s + i)``,
through every autoreset (each lane's next episode takes the next child of its own
``SeedSequence``, exactly as a single env's ``reset()`` without a seed does).
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from follow_env.config import EnvConfig
from follow_env.core import BatchedSim
from follow_env.env import resolve_config
from follow_env.info import batch_info, make_spaces, observations
from follow_env.layout import S_REWARD, S_TERM, S_TRUNC

__all__ = ["PersonFollowVectorEnv", "lane_seeds"]


def lane_seeds(num_envs: int, seed: int | list[int | None] | None) -> list[int | None]:
    """Root seed of every lane: an int ``s`` gives lane ``i`` the seed ``s + i`` (Gymnasium's
    convention), a list gives one seed per lane, ``None`` fresh OS entropy."""
    if seed is None:
        seeds: list[int | None] = [None] * num_envs
    elif isinstance(seed, int | np.integer):
        seeds = [int(seed) + i for i in range(num_envs)]
    else:
        seeds = list(seed)
        if len(seeds) != num_envs:
            raise ValueError(
                f"seed has {len(seeds)} entries: must be an int, None, or a list of "
                f"num_envs={num_envs} seeds"
            )
    return seeds


class PersonFollowVectorEnv(VectorEnv):
    """``num_envs`` independent PersonFollow robots stepped together by the batched core.

    Made by ``gym.make_vec("PersonFollow-v0", num_envs=N,
    vectorization_mode="vector_entry_point")`` or directly. Takes every keyword argument of
    the single env (``config``, ``scenario``, config sections, ``render_mode``) plus
    ``autoreset_mode`` (``AutoresetMode.NEXT_STEP``, the default, ``SAME_STEP`` or
    ``DISABLED``), declared in ``metadata["autoreset_mode"]`` and followed exactly as
    Gymnasium's ``SyncVectorEnv`` does:

    * ``NEXT_STEP``: the step after a lane ends resets it (its action is ignored) and returns
      the new first observation with reward 0 and both flags False.
    * ``SAME_STEP``: a lane that ends is reset within the same step; the returned observation
      is the new episode's, the final one is in ``info["final_obs"]`` and its info in
      ``info["final_info"]`` (with masks ``_final_obs`` and ``_final_info``).
    * ``DISABLED``: ended lanes must be reset with ``reset(options={"reset_mask": mask})``.

    Seeding: ``reset(seed=s)`` gives lane ``i`` the seed stream of ``s + i`` (a list gives one
    seed per lane), so lane ``i`` replays the single env reset with ``seed=s + i``.

    ``info`` is Gymnasium's dict of arrays: every key of :data:`follow_env.INFO_KEYS` with one
    entry per lane and its ``_key`` mask (all True: every lane reports every key every step).
    """

    def __init__(
        self,
        num_envs: int = 1,
        config: EnvConfig | str | dict[str, Any] | None = None,
        scenario: str | None = None,
        render_mode: str | None = None,
        autoreset_mode: AutoresetMode | str = AutoresetMode.NEXT_STEP,
        **overrides: Any,
    ) -> None:
        if isinstance(num_envs, bool) or not isinstance(num_envs, int) or num_envs < 1:
            raise ValueError(f"num_envs={num_envs!r} is out of range: must be an integer >= 1")
        try:
            mode = AutoresetMode(autoreset_mode)
        except ValueError:
            raise ValueError(
                f"autoreset_mode={autoreset_mode!r} is out of range: must be one of "
                + ", ".join(m.name for m in AutoresetMode)
            ) from None
        if render_mode not in (None, "rgb_array"):
            raise ValueError(
                f"render_mode={render_mode!r} is out of range: must be None or 'rgb_array'"
            )
        self.config = resolve_config(config, scenario, **overrides)
        self.num_envs = num_envs
        self.render_mode = render_mode
        self.autoreset_mode = mode
        self.metadata = {"render_modes": ["rgb_array"], "render_fps": 10, "autoreset_mode": mode}
        self.single_observation_space, self.single_action_space = make_spaces(self.config)
        self.observation_space = batch_space(self.single_observation_space, num_envs)
        self.action_space = batch_space(self.single_action_space, num_envs)
        self.sim = BatchedSim(self.config, num_envs)
        self._autoreset = np.zeros(num_envs, dtype=np.bool_)
        self._actions = np.zeros((num_envs, 2))
        self._mask = np.ones(num_envs, dtype=np.bool_)
        self._renderers: list[Any] = []

    # -- Gymnasium API ------------------------------------------------------------------------

    def reset(
        self, *, seed: int | list[int | None] | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """Reset all lanes, or those in ``options["reset_mask"]`` (bool array of num_envs)."""
        options = dict(options or {})
        mask = options.pop("reset_mask", None)
        if options:
            raise ValueError(f"options={options!r} is out of range: only 'reset_mask' is taken")
        if mask is None:
            mask = np.ones(self.num_envs, dtype=np.bool_)
        elif (
            not isinstance(mask, np.ndarray)
            or mask.shape != (self.num_envs,)
            or mask.dtype != np.bool_
            or not mask.any()
        ):
            raise ValueError(
                f"options['reset_mask']={mask!r} is out of range: must be a bool numpy array "
                f"of shape ({self.num_envs},) with at least one True"
            )
        lanes = np.flatnonzero(mask)
        seeds = None if seed is None else [lane_seeds(self.num_envs, seed)[i] for i in lanes]
        self._reset_lanes(lanes, seeds)
        self._autoreset[lanes] = False
        info = self._info()
        if mask.all():
            return observations(self.sim), info
        # Only the reset lanes report an info, as in SyncVectorEnv.
        for key in list(info):
            if not key.startswith("_"):
                info["_" + key] = mask
        return observations(self.sim), info

    def step(
        self, actions: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        """Step every lane with its ``[v_mps, w_radps]`` row of ``actions`` (num_envs, 2)."""
        a = np.asarray(actions, dtype=np.float64)
        if a.shape != (self.num_envs, 2):
            raise ValueError(
                f"actions has shape {a.shape}: must be ({self.num_envs}, 2) [v_mps, w_radps]"
            )
        bad = ~np.isfinite(a).all(axis=1)
        if bad.any():
            raise ValueError(
                f"actions of lanes {np.flatnonzero(bad).tolist()} are out of range: must be finite"
            )
        self._actions[:] = a
        fs = self.sim.fstate
        info_extra: dict[str, Any] = {}
        if self.autoreset_mode == AutoresetMode.NEXT_STEP:
            restart = self._autoreset.copy()
            if restart.all():
                self._reset_lanes(np.arange(self.num_envs))
            else:
                self.sim.step(self._actions, ~restart if restart.any() else None)
                if restart.any():
                    self._reset_lanes(np.flatnonzero(restart))
        elif self.autoreset_mode == AutoresetMode.DISABLED:
            if self._autoreset.any():
                raise ValueError(
                    f"lanes {np.flatnonzero(self._autoreset).tolist()} ended and were not reset: "
                    "with AutoresetMode.DISABLED call reset(options={'reset_mask': ...}) first"
                )
            self.sim.step(self._actions)
        else:  # SAME_STEP
            self.sim.step(self._actions)
            ended = (fs[:, S_TERM] > 0.0) | (fs[:, S_TRUNC] > 0.0)
            if ended.any():
                lanes = np.flatnonzero(ended)
                final_obs = np.full(self.num_envs, None, dtype=object)
                obs_now = observations(self.sim)
                for i in lanes:
                    final_obs[i] = obs_now[i]
                final_info = self._info(mask=ended)
                reward = fs[:, S_REWARD].copy()
                terminated = fs[:, S_TERM] > 0.0
                truncated = fs[:, S_TRUNC] > 0.0
                self._reset_lanes(lanes)
                info_extra = {
                    "final_obs": final_obs,
                    "_final_obs": ended,
                    "final_info": final_info,
                    "_final_info": ended,
                }
                info = self._info()
                info.update(info_extra)
                self._render_record()
                return observations(self.sim), reward, terminated, truncated, info
        terminated = fs[:, S_TERM] > 0.0
        truncated = fs[:, S_TRUNC] > 0.0
        if self.autoreset_mode != AutoresetMode.SAME_STEP:
            self._autoreset = terminated | truncated
        self._render_record()
        return observations(self.sim), fs[:, S_REWARD].copy(), terminated, truncated, self._info()

    def render(self) -> tuple[np.ndarray, ...] | None:
        """One ``rgb_array`` frame per lane (as ``SyncVectorEnv`` returns them)."""
        if self.render_mode is None:
            gym.logger.warn("render() called without a render_mode; returning None")
            return None
        self._ensure_renderers()
        return tuple(r.draw(view) for r, view in self._renderers)

    def close_extras(self, **kwargs: Any) -> None:
        """Stop the core's worker threads and drop the renderers."""
        self.sim.close()
        self._renderers = []

    # -- helpers ------------------------------------------------------------------------------

    def _reset_lanes(self, lanes: np.ndarray, seeds: list[int | None] | None = None) -> None:
        """Start each lane's next episode (with new root seeds if given)."""
        self.sim.reset_lanes(lanes, seeds)
        for i in lanes if self._renderers else ():
            self._renderers[i][0].reset()

    def _info(self, mask: np.ndarray | None = None) -> dict[str, Any]:
        """Dict-of-arrays info for all lanes, with ``_key`` masks (``mask`` or all lanes)."""
        info: dict[str, Any] = batch_info(self.sim)
        m = self._mask if mask is None else mask
        for key in list(info):
            info["_" + key] = m
        return info

    def _ensure_renderers(self) -> None:
        if self._renderers:
            return
        from types import SimpleNamespace

        from follow_env.render import Renderer

        sim = self.sim
        for i in range(self.num_envs):
            # A one-lane view of the core: the renderer reads lane 0 of whatever it is given.
            rows = slice(i, i + 1)
            view = SimpleNamespace(
                sim=SimpleNamespace(
                    params=sim.params[rows],
                    fstate=sim.fstate[rows],
                    istate=sim.istate[rows],
                    pstate=sim.pstate[rows],
                    walls=sim.walls[rows],
                ),
                config=self.config,
            )
            renderer = Renderer(self.config)
            renderer.record(view)
            self._renderers.append((renderer, view))

    def _render_record(self) -> None:
        for renderer, view in self._renderers:
            renderer.record(view)

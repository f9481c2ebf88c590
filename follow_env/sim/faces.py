"""The Gymnasium faces of any task: the single env (one lane) and the native vector env.

No physics lives here: both step the runner (:mod:`follow_env.sim.runner`), so lane ``i`` of the
vector env after ``reset(seed=s)`` is bit-for-bit the single env after ``reset(seed=s + i)``,
through every autoreset. A task's env classes subclass :class:`TaskEnv` and
:class:`TaskVectorEnv`, set ``task`` (its model) and write their manual in the docstring; the
task model supplies the configuration, the spaces, the observations, the info and the renderer.
"""

from __future__ import annotations

import sys
from typing import Any, ClassVar

import gymnasium as gym
import numpy as np
from gymnasium.error import ResetNeeded
from gymnasium.utils import seeding
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space
from gymnasium.wrappers import TimeLimit

from follow_env.sim.checks import REAL_KINDS, is_integer, out_of_range, real_array
from follow_env.sim.runner import BatchedSim

__all__ = [
    "TaskEnv",
    "TaskVectorEnv",
    "action_array",
    "lane_seeds",
    "longer_episodes",
    "max_episode_steps_error",
    "options_error",
    "render_fps",
]

RENDER_MODES = ["rgb_array", "human"]


def lane_seeds(num_envs: int, seed: int | list[int | None] | None) -> list[int | None]:
    """Root seed of every lane: an int ``s`` gives lane ``i`` the seed ``s + i`` (Gymnasium's
    convention), a list gives one seed per lane, ``None`` fresh OS entropy."""
    if isinstance(seed, np.ndarray) and seed.ndim == 0:  # np.array(5): one number, not a list
        seed = seed.item()
    if seed is None:
        seeds: list[int | None] = [None] * num_envs
    elif is_integer(seed):
        seeds = [int(seed) + i for i in range(num_envs)]  # type: ignore[arg-type]
    elif not isinstance(seed, list | tuple | np.ndarray):
        # A float, a bool or a string is no seed (a string would be read as a list of letters).
        raise out_of_range("seed", seed, f"an int, None, or a list of num_envs={num_envs} seeds")
    else:
        seeds = list(seed)
        if len(seeds) != num_envs:
            raise ValueError(
                f"seed has {len(seeds)} entries: must be an int, None, or a list of "
                f"num_envs={num_envs} seeds"
            )
    return seeds


def action_array(action: Any, shape: tuple[int, ...], names: str) -> np.ndarray:
    """``action`` as a float64 array of exactly ``shape``, finite; ``ValueError`` naming the
    expected and the received shape (or the bad entries, or entries that are not real numbers:
    :func:`~follow_env.sim.checks.real_array`) otherwise."""
    arr = real_array(action)
    if arr is None:
        raise ValueError(
            f"action={action!r} is out of range: must be an array of real numbers of shape "
            f"{shape} {names}"
        )
    if arr.shape != shape:
        raise ValueError(f"action has shape {arr.shape}: must be {shape} {names} (got {action!r})")
    if not np.isfinite(arr).all():
        if arr.ndim == 2:
            bad = np.flatnonzero(~np.isfinite(arr).all(axis=1)).tolist()
            raise ValueError(f"actions of lanes {bad} are out of range: must be finite")
        raise ValueError(f"action={action!r} is out of range: must be finite {names}")
    return arr


def render_fps(config: Any) -> int:
    """Frames a second that play an episode in real time: one frame a control step, so
    ``round(1 / control_dt_s)`` (10 for PersonFollow's 0.1 s, 50 for LineTrace's 0.02 s), at
    least 1. The human window keeps to it and Gymnasium's ``RecordVideo`` writes it."""
    return max(1, round(1.0 / float(config.control_dt_s)))


def options_error(options: Any) -> ValueError:
    """The refusal of reset ``options``: no task env takes any."""
    return ValueError(f"options={options!r} is out of range: this env takes no options")


def step_cap(sim: BatchedSim) -> int:
    """The step at which the task's kernel truncates an episode itself (its ``max_steps``
    parameter: ``episode.max_steps``, or ``episode.max_time_s`` in control steps)."""
    return int(sim.base_params["task"]["max_steps"])


def longer_episodes(config: Any, steps: int) -> str:
    """The config argument that makes episodes ``steps`` control steps long, as ``gym.make``
    takes it: ``episode__max_steps=...``, or ``episode__max_time_s=...`` for a task whose cap is
    a time."""
    episode = config.episode
    if hasattr(episode, "max_time_s") and not hasattr(episode, "max_steps"):
        return f"episode__max_time_s={steps * float(config.control_dt_s):g}"
    return f"episode__max_steps={steps}"


def max_episode_steps_error(config: Any, value: Any, what: str) -> ValueError:
    """The refusal of ``max_episode_steps=value`` by ``what`` (no ``TimeLimit`` wraps its
    lanes): the episode length is the config's."""
    hint = longer_episodes(config, value) if is_integer(value) and value > 0 else ""
    return out_of_range(
        "max_episode_steps",
        value,
        f"None: {what} ends episodes itself (no TimeLimit wraps its lanes); set the episode "
        f"length in the config" + (f", e.g. {hint}" if hint else " (episode section)"),
    )


def _time_limit_over(env: gym.Env) -> TimeLimit | None:
    """The ``TimeLimit`` wrapper of ``env`` whose ``reset`` is calling ``env.reset`` now, if
    any: the env itself is never told of the wrappers ``gym.make`` puts around it (its
    ``spec.max_episode_steps`` is None), so the reset looks up the calling frames (a few
    microseconds a reset)."""
    try:
        frame = sys._getframe(3)  # 0: here, 1: _check_time_limit, 2: reset, 3: its caller
    except ValueError:  # called from a stack shallower than that (no Python caller)
        return None
    for _ in range(64):  # gym.make's stack is about 8 frames deep; a user's wrappers add more
        if frame is None:
            return None
        if frame.f_code.co_name == "reset":
            caller = frame.f_locals.get("self")
            if isinstance(caller, TimeLimit) and caller.unwrapped is env:
                return caller
        frame = frame.f_back
    return None


def _check_render_mode(cls: type, render_mode: str | None) -> None:
    if render_mode is not None and render_mode not in cls.metadata["render_modes"]:
        raise out_of_range(
            "render_mode",
            render_mode,
            "None or one of " + ", ".join(repr(m) for m in cls.metadata["render_modes"]),
        )


class TaskEnv(gym.Env[np.ndarray, np.ndarray]):
    """One lane of the runner as a Gymnasium env (the base of every task's single env).

    :param config: a preset name, a config object, or a dict of section overrides.
    :param render_mode: ``"rgb_array"``, ``"human"`` (a window) or ``None``.
    :param kwargs: the task's shorthands (e.g. ``scenario=``) and config sections.
    """

    task: ClassVar[Any]
    # The class's frame rate is PersonFollow's 0.1 s step; each env sets its own (render_fps).
    metadata: ClassVar[dict[str, Any]] = {"render_modes": RENDER_MODES, "render_fps": 10}

    def __init__(self, config: Any = None, render_mode: str | None = None, **kwargs: Any) -> None:
        self.config = self.task.resolve_config(config, **kwargs)
        _check_render_mode(type(self), render_mode)
        self.metadata = {**type(self).metadata, "render_fps": render_fps(self.config)}
        self.render_mode = render_mode
        self.sim = BatchedSim(self.task, self.config, 1)
        self.observation_space, self.action_space = self.task.spaces(self.config, self.sim.platform)
        self._action_names = "[" + ", ".join(a.name for a in self.sim.platform.actions) + "]"
        self._action = np.zeros((1, self.action_space.shape[0]))
        self._action_shape = self.action_space.shape
        self._lane = np.zeros(1, dtype=np.int64)
        self._renderer: Any = None
        self._window: Any = None
        self._needs_reset = True

    # -- Gymnasium API -------------------------------------------------------------------------

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """Start an episode. ``seed`` seeds the episode streams; later resets without a seed
        continue from it (each episode spawns the next child ``SeedSequence``)."""
        self._check_time_limit()
        super().reset(seed=seed)
        if options:
            raise options_error(options)
        self.sim.reset_lanes(self._lane, None if seed is None else [seed])
        self._needs_reset = False
        if self.render_mode is not None:
            self._ensure_renderer().reset()
            self._renderer.record(self.sim.lane(0))
            if self.render_mode == "human":
                self.render()
        return self._obs(), self._info()

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        """Apply ``action`` (the platform's, in SI) for one control step."""
        if self._needs_reset:
            raise ResetNeeded("call reset() before step()")
        if (
            type(action) is np.ndarray
            and action.shape == self._action_shape
            and action.dtype.kind in REAL_KINDS
        ):
            self._action[0] = action  # the common case, checked below for NaN and inf
            if not np.isfinite(self._action).all():
                action_array(action, self._action_shape, self._action_names)  # raises
        else:
            self._action[0] = action_array(action, self._action_shape, self._action_names)
        self.sim.step(self._action)
        reward, terminated, truncated = self.sim.outcome(0)
        if self._renderer is not None:
            self._renderer.record(self.sim.lane(0))
            if self.render_mode == "human":
                self.render()
        return self._obs(), reward, terminated, truncated, self._info()

    def render(self) -> np.ndarray | None:
        """``rgb_array``: the frame (H x W x 3 uint8). ``human``: shows it in a window."""
        if self.render_mode is None:
            gym.logger.warn("render() called without a render_mode; returning None")
            return None
        frame = self._ensure_renderer().draw(self.sim.lane(0))
        if self.render_mode == "human":
            from follow_env.sim.window import Window

            if self._window is None:
                self._window = Window(type(self).__name__, frame.shape[1], frame.shape[0])
            self._window.show(frame, self.metadata["render_fps"])
            return None
        return frame

    def close(self) -> None:
        """Release the renderer and the window."""
        self._renderer = None
        if self._window is not None:
            self._window.close()
            self._window = None
        self.sim.close()

    def __getstate__(self) -> dict[str, Any]:
        """A copy (``copy.deepcopy``, pickle) opens its own window when it renders."""
        state = self.__dict__.copy()
        state["_window"] = None
        return state

    # -- helpers --------------------------------------------------------------------------------

    def _check_time_limit(self) -> None:
        """``ValueError`` if a ``TimeLimit`` over this env (``gym.make(...,
        max_episode_steps=n)``) allows more steps than the env's own cap: the env would
        truncate first, while ``env.spec.max_episode_steps`` says ``n``."""
        wrapper = _time_limit_over(self)
        if wrapper is None:
            return
        limit, cap = wrapper._max_episode_steps, step_cap(self.sim)
        if limit > cap:
            raise out_of_range(
                "max_episode_steps",
                limit,
                f"<= {cap}, the step at which {type(self).__name__} truncates its episodes "
                f"itself; for longer episodes give gym.make({longer_episodes(self.config, limit)})"
                " instead (a smaller max_episode_steps truncates earlier, through TimeLimit)",
            )

    def _ensure_renderer(self) -> Any:
        if self._renderer is None:
            self._renderer = self.task.renderer(self.config)
            self._renderer.record(self.sim.lane(0))
        return self._renderer

    def _obs(self) -> np.ndarray:
        return self.task.observation(self.sim, 0)

    def _info(self) -> dict[str, Any]:
        return self.task.lane_info(self.sim, 0)


class TaskVectorEnv(VectorEnv):
    """``num_envs`` independent lanes of the runner as a Gymnasium ``VectorEnv``.

    Takes every keyword argument of the task's single env plus ``autoreset_mode``
    (``AutoresetMode.NEXT_STEP``, the default, ``SAME_STEP`` or ``DISABLED``), declared in
    ``metadata["autoreset_mode"]`` and followed exactly as Gymnasium's ``SyncVectorEnv`` does:

    * ``NEXT_STEP``: the step after a lane ends resets it (its action is ignored) and returns
      the new first observation with reward 0 and both flags False.
    * ``SAME_STEP``: a lane that ends is reset within the same step; the returned observation
      is the new episode's, the final one is in ``info["final_obs"]`` and its info in
      ``info["final_info"]`` (with masks ``_final_obs`` and ``_final_info``).
    * ``DISABLED``: ended lanes must be reset with ``reset(options={"reset_mask": mask})``.

    Seeding: ``reset(seed=s)`` gives lane ``i`` the seed stream of ``s + i`` (a list gives one
    seed per lane), so lane ``i`` replays the single env reset with ``seed=s + i``; an int
    ``s`` also seeds ``np_random`` (``np_random_seed == s``), as Gymnasium's ``VectorEnv`` does
    (the lanes never draw from it). ``info`` is Gymnasium's dict of arrays with ``_key`` masks;
    where a mask is False (``final_info`` of lanes that did not end, the info of a masked
    reset) an entry is 0 (False) or None, as in ``SyncVectorEnv``. ``max_episode_steps`` is
    refused (``ValueError``): the lanes end their episodes themselves (``episode__max_steps``).
    """

    task: ClassVar[Any]

    def __init__(
        self,
        num_envs: int = 1,
        config: Any = None,
        render_mode: str | None = None,
        autoreset_mode: AutoresetMode | str = AutoresetMode.NEXT_STEP,
        max_episode_steps: int | None = None,
        **kwargs: Any,
    ) -> None:
        if not is_integer(num_envs) or num_envs < 1:
            raise out_of_range("num_envs", num_envs, "an integer >= 1")
        try:
            mode = AutoresetMode(autoreset_mode)
        except ValueError:
            raise out_of_range(
                "autoreset_mode",
                autoreset_mode,
                "one of " + ", ".join(m.name for m in AutoresetMode),
            ) from None
        if render_mode not in (None, "rgb_array"):
            raise out_of_range("render_mode", render_mode, "None or 'rgb_array'")
        self.config = self.task.resolve_config(config, **kwargs)
        if max_episode_steps is not None:  # gym.make_vec passes it here
            raise max_episode_steps_error(self.config, max_episode_steps, "the vector env")
        self.num_envs = int(num_envs)
        self.render_mode = render_mode
        self.autoreset_mode = mode
        self.metadata = {
            "render_modes": ["rgb_array"],
            "render_fps": render_fps(self.config),
            "autoreset_mode": mode,
        }
        self.sim = BatchedSim(self.task, self.config, self.num_envs)
        self.single_observation_space, self.single_action_space = self.task.spaces(
            self.config, self.sim.platform
        )
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self._action_names = "[" + ", ".join(a.name for a in self.sim.platform.actions) + "]"
        self._autoreset = np.zeros(self.num_envs, dtype=np.bool_)
        # Lanes reset at least once: a lane never reset holds zeroed records, no episode.
        self._started = np.zeros(self.num_envs, dtype=np.bool_)
        self._actions = np.zeros((self.num_envs, self.single_action_space.shape[0]))
        self._mask = np.ones(self.num_envs, dtype=np.bool_)
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
        if is_integer(seed) or (isinstance(seed, np.ndarray) and seed.ndim == 0):
            # As VectorEnv.reset does; the lanes' streams come from their own seeds.
            self._np_random, self._np_random_seed = seeding.np_random(int(seed))  # type: ignore[arg-type]
        self._autoreset[lanes] = False
        self._started[lanes] = True
        # Only the reset lanes report an info, as in SyncVectorEnv.
        info = self._info() if mask.all() else self._info(mask=mask)
        return self.task.observations(self.sim), info

    def step(
        self, actions: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        """Step every lane with its row of ``actions`` (num_envs, action size); raises
        ``ResetNeeded`` while a lane was never reset (as ``SyncVectorEnv``'s envs do)."""
        if not self._started.all():
            raise ResetNeeded(
                f"lanes {np.flatnonzero(~self._started).tolist()} were never reset: call "
                "reset() before step()"
            )
        self._actions[:] = action_array(actions, self._actions.shape, self._action_names)
        ep = self.sim.episode
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
            ended = (ep["terminated"] > 0.0) | (ep["truncated"] > 0.0)
            if ended.any():
                lanes = np.flatnonzero(ended)
                final_obs = np.full(self.num_envs, None, dtype=object)
                obs_now = self.task.observations(self.sim)
                for i in lanes:
                    final_obs[i] = obs_now[i]
                final_info = self._info(mask=ended)
                reward = ep["reward"].copy()
                terminated = ep["terminated"] > 0.0
                truncated = ep["truncated"] > 0.0
                self._reset_lanes(lanes)
                info = self._info()
                info.update(
                    {
                        "final_obs": final_obs,
                        "_final_obs": ended,
                        "final_info": final_info,
                        "_final_info": ended,
                    }
                )
                self._render_record()
                return self.task.observations(self.sim), reward, terminated, truncated, info
        terminated = ep["terminated"] > 0.0
        truncated = ep["truncated"] > 0.0
        if self.autoreset_mode != AutoresetMode.SAME_STEP:
            self._autoreset = terminated | truncated
        self._render_record()
        obs = self.task.observations(self.sim)
        return obs, ep["reward"].copy(), terminated, truncated, self._info()

    def render(self) -> tuple[np.ndarray, ...] | None:
        """One ``rgb_array`` frame per lane (as ``SyncVectorEnv`` returns them)."""
        if self.render_mode is None:
            gym.logger.warn("render() called without a render_mode; returning None")
            return None
        self._ensure_renderers()
        return tuple(r.draw(self.sim.lane(i)) for i, r in enumerate(self._renderers))

    def close_extras(self, **kwargs: Any) -> None:
        """Stop the runner's worker threads and drop the renderers."""
        self.sim.close()
        self._renderers = []

    # -- helpers ------------------------------------------------------------------------------

    def _reset_lanes(self, lanes: np.ndarray, seeds: list[int | None] | None = None) -> None:
        """Start each lane's next episode (with new root seeds if given)."""
        self.sim.reset_lanes(lanes, seeds)
        if self.render_mode is not None:
            self._ensure_renderers()
            for i in lanes:
                self._renderers[i].reset()
                self._renderers[i].record(self.sim.lane(int(i)))

    def _info(self, mask: np.ndarray | None = None) -> dict[str, Any]:
        """Dict-of-arrays info with ``_key`` masks: of all lanes, or of the lanes in ``mask``
        only, the others' entries 0 (False) or None as ``SyncVectorEnv`` leaves them."""
        if mask is None:
            info: dict[str, Any] = self.task.batch_info(self.sim)
            for key in list(info):
                info["_" + key] = self._mask
            return info
        lanes = np.flatnonzero(mask)
        info = {}
        for key, values in self.task.batch_info(self.sim, lanes).items():
            if values.dtype == object:
                full = np.full(self.num_envs, None, dtype=object)
            else:
                full = np.zeros(self.num_envs, dtype=values.dtype)
            full[lanes] = values
            info[key] = full
            info["_" + key] = mask
        return info

    def _ensure_renderers(self) -> None:
        if not self._renderers:
            self._renderers = [self.task.renderer(self.config) for _ in range(self.num_envs)]
            for i, renderer in enumerate(self._renderers):
                renderer.record(self.sim.lane(i))

    def _render_record(self) -> None:
        for i, renderer in enumerate(self._renderers):
            renderer.record(self.sim.lane(i))

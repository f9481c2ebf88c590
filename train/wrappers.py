"""VecEnv wrappers between the batched env and PPO, and a VecEnv of several scenarios.

Each wrapper is an SB3 ``VecEnvWrapper``, listed by name under ``vec_env_wrapper`` in
``train/configs/ppo.yaml`` (so rl-zoo3 can build the same stack); innermost first:

- :class:`VecRescaleAction`: the agent acts in ``[-1, 1]``, mapped linearly onto SI speeds. PPO
  explores with one standard deviation for both outputs, so the range should be the useful one:
  ``w_max_radps`` 2 rad/s covers every turn rate the tuned laws command in any scenario (at most
  1.5 rad/s), where the platform's 7.4 rad/s would make most of the agent's range and most of
  its exploration spin the person out of view.
- :class:`VecShapedReward`: the training reward: the env's, floored and shifted so that no way
  of ending an episode early pays (a fresh agent otherwise learns to lose the person on
  purpose), minus penalties on command changes (smoothness) and on the observed offset.
  Training-only: the policy leaves it out, and every evaluation scores the env's own reward.
- :class:`VecObservationAge`: appends how long the observation has been held (the perception
  repeats its last values while the detector sees nothing), so the agent can tell a fresh
  offset from a stale one.
- :class:`VecScaleObservation`: fixed scaling that keeps signed entries centred on 0 (needed by
  the mirror-symmetric policy, :mod:`train.mirror`).
- :class:`VecIncrementalAction`: the agent changes the command by at most a set step, and sees
  the command in force: smooth by construction, and the missing robot state (its own speed
  command) becomes part of the observation. The observation ``[distance_m, offset_px]`` alone is
  not Markov (a frame of detector latency, held values, unobserved robot speed); the config's
  ``frame_stack`` adds the recent history on top.

:class:`ConcatVecEnv` joins several VecEnvs, here one batched core per scenario (a core runs one
scenario for all its lanes), into one VecEnv whose lanes are the sub-envs' lanes in order.
``seed(s)`` gives lane ``j`` of the whole the seed ``s + j``, as for one VecEnv.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from stable_baselines3.common.vec_env import VecEnv, VecEnvWrapper
from stable_baselines3.common.vec_env.base_vec_env import VecEnvIndices, VecEnvObs, VecEnvStepReturn

__all__ = [
    "ConcatVecEnv",
    "VecIncrementalAction",
    "VecObservationAge",
    "VecRescaleAction",
    "VecScaleObservation",
    "VecShapedReward",
    "agent_to_si",
]


def agent_to_si(action: np.ndarray, low: np.ndarray, high: np.ndarray) -> np.ndarray:
    """Map an agent action in ``[-1, 1]`` (clipped first) linearly onto ``[low, high]``.

    :param action: shape (..., 2), agent units.
    :param low: the SI box's lower bounds, e.g. ``[-1.44 m/s, -7.2 rad/s]``.
    :param high: the SI box's upper bounds.
    """
    a = np.clip(np.asarray(action, dtype=np.float64), -1.0, 1.0)
    return low + (a + 1.0) * 0.5 * (high - low)


def _numbers(values: Any) -> np.ndarray | None:
    """``values`` as a float64 array of numbers, or None if they are not numbers (a string,
    a bool, a mapping, a ragged list): wrappers then name their argument in the error."""
    items = values if isinstance(values, list | tuple | np.ndarray) else [values]
    flat = np.asarray(items, dtype=object).ravel()
    if any(isinstance(v, bool) or not isinstance(v, int | float | np.number) for v in flat):
        return None
    try:
        return np.asarray(values, dtype=np.float64)
    except (TypeError, ValueError):
        return None


class VecRescaleAction(VecEnvWrapper):
    """The agent acts in ``[-1, 1]^2``; the wrapped env receives SI actions (module docstring).

    ``[-1, 1]`` maps linearly onto ``[-v_max_mps, v_max_mps] x [-w_max_radps, w_max_radps]``,
    by default the env's whole action box. A smaller range than the platform's is a choice about
    the agent, not the robot: every unit of the agent's output then means a useful command, and
    PPO's exploration noise (one standard deviation for both outputs) is scaled to match.

    :param venv: a VecEnv with a bounded, symmetric ``Box(2,)`` action space (the env's SI box).
    :param v_max_mps: the agent's largest speed [m/s]; None or at most the env's bound.
    :param w_max_radps: the agent's largest turn rate [rad/s]; None or at most the env's bound.
    """

    def __init__(
        self, venv: VecEnv, v_max_mps: float | None = None, w_max_radps: float | None = None
    ) -> None:
        box = venv.action_space
        if (
            not isinstance(box, spaces.Box)
            or box.shape != (2,)
            or not np.all(np.isfinite([box.low, box.high]))
            or not np.allclose(box.low, -box.high)
        ):
            raise ValueError(f"VecRescaleAction needs a bounded symmetric Box(2,), got {box}")
        high = box.high.astype(np.float64).copy()
        for k, (name, value) in enumerate((("v_max_mps", v_max_mps), ("w_max_radps", w_max_radps))):
            if value is None:
                continue
            number = isinstance(value, int | float) and not isinstance(value, bool)
            if not (number and 0 < value <= high[k]):
                raise ValueError(
                    f"VecRescaleAction.{name}={value!r} is out of range: must be in "
                    f"(0, {high[k]:g}] (the env's bound)"
                )
            high[k] = float(value)
        self.si_low, self.si_high = -high, high
        agent_box = spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float32)
        super().__init__(venv, action_space=agent_box)

    def step_async(self, actions: np.ndarray) -> None:
        self.venv.step_async(agent_to_si(actions, self.si_low, self.si_high))

    def reset(self) -> VecEnvObs:
        return self.venv.reset()

    def step_wait(self) -> VecEnvStepReturn:
        return self.venv.step_wait()


class VecObservationAge(VecEnvWrapper):
    """Observation ``[obs..., age]``: how many steps the observation has not changed, scaled.

    The perception holds its last values while the detector sees nothing (SPEC.md §1.4), so a
    repeated observation is stale, not a person standing still in the image: the filtered depth
    of a fresh detection never repeats to the last bit. ``age = min(k, max_age_steps) /
    max_age_steps``, where ``k`` is the number of steps since the observation last changed (0 on
    a fresh one). It uses only what the robot publishes, so the real robot can compute it too;
    without it an agent cannot tell a 0.3 s gap from a 3 s one and keeps turning towards where
    the person was.

    :param venv: a VecEnv with a ``Box`` observation space.
    :param max_age_steps: where the age saturates at 1 (30 steps = the env's 3 s lost timeout).
    """

    def __init__(self, venv: VecEnv, max_age_steps: int = 30) -> None:
        obs_box = venv.observation_space
        if not isinstance(obs_box, spaces.Box) or len(obs_box.shape) != 1:
            raise ValueError("VecObservationAge needs a flat Box observation space")
        is_int = isinstance(max_age_steps, int) and not isinstance(max_age_steps, bool)
        if not is_int or max_age_steps < 1:
            raise ValueError(
                f"VecObservationAge.max_age_steps={max_age_steps!r} is out of range: must be >= 1"
            )
        self.max_age_steps = max_age_steps
        observation_space = spaces.Box(
            low=np.append(obs_box.low, 0.0).astype(np.float32),
            high=np.append(obs_box.high, 1.0).astype(np.float32),
            dtype=np.float32,
        )
        super().__init__(venv, observation_space=observation_space)
        self._last = np.zeros((venv.num_envs, *obs_box.shape), dtype=np.float32)
        self._age = np.zeros(venv.num_envs, dtype=np.int64)

    def reset(self) -> VecEnvObs:
        obs = np.asarray(self.venv.reset(), dtype=np.float32)
        self._last = obs.copy()
        self._age[:] = 0
        return self._join(obs, self._age)

    def step_wait(self) -> VecEnvStepReturn:
        obs, rewards, dones, infos = self.venv.step_wait()
        obs = np.asarray(obs, dtype=np.float32)
        age = np.where(np.all(obs == self._last, axis=1), self._age + 1, 0)
        for i in np.flatnonzero(dones):
            if "terminal_observation" in infos[i]:
                terminal = np.asarray(infos[i]["terminal_observation"], dtype=np.float32)
                stale = np.array_equal(terminal, self._last[i])
                infos[i]["terminal_observation"] = self._join(
                    terminal[None], np.array([self._age[i] + 1 if stale else 0])
                )[0]
        age[dones] = 0  # the lanes that ended were reset: obs is a new episode's first
        self._last = obs.copy()
        self._age = age
        return self._join(obs, age), rewards, dones, infos

    def _join(self, obs: np.ndarray, age: np.ndarray) -> np.ndarray:
        scaled = np.minimum(age, self.max_age_steps) / self.max_age_steps
        return np.concatenate([obs, scaled[:, None].astype(np.float32)], axis=1)


class VecScaleObservation(VecEnvWrapper):
    """Observation ``obs * scale``, entry by entry: a fixed normalisation that keeps 0 at 0.

    ``VecNormalize`` shifts every entry by its running mean; a mirror-symmetric policy
    (:mod:`train.mirror`) needs the offset and the turn command to stay signed around 0, so they
    are scaled instead (e.g. the offset by 1/100 px).

    :param venv: a VecEnv with a flat ``Box`` observation space.
    :param scale: one positive factor per observation entry.
    """

    def __init__(self, venv: VecEnv, scale: Sequence[float] = ()) -> None:
        obs_box = venv.observation_space
        factors = _numbers(scale)
        if factors is None or not isinstance(obs_box, spaces.Box) or factors.shape != obs_box.shape:
            raise ValueError(
                f"VecScaleObservation.scale={scale!r} is out of range: must be one factor per "
                f"observation entry {obs_box.shape}"
            )
        if not np.all(np.isfinite(factors) & (factors > 0)):
            raise ValueError(
                f"VecScaleObservation.scale={scale!r} is out of range: must be positive numbers"
            )
        self.scale = factors.astype(np.float32)
        observation_space = spaces.Box(
            (obs_box.low * self.scale).astype(np.float32),
            (obs_box.high * self.scale).astype(np.float32),
            dtype=np.float32,
        )
        super().__init__(venv, observation_space=observation_space)

    def reset(self) -> VecEnvObs:
        return np.asarray(self.venv.reset(), dtype=np.float32) * self.scale

    def step_wait(self) -> VecEnvStepReturn:
        obs, rewards, dones, infos = self.venv.step_wait()
        for i in np.flatnonzero(dones):
            if "terminal_observation" in infos[i]:
                terminal = np.asarray(infos[i]["terminal_observation"], dtype=np.float32)
                infos[i]["terminal_observation"] = terminal * self.scale
        return np.asarray(obs, dtype=np.float32) * self.scale, rewards, dones, infos


class VecIncrementalAction(VecEnvWrapper):
    """The agent changes the command by at most ``max_change`` a step; observation gets the command.

    The wrapped env receives the command ``u_t = clip(u_{t-1} + max_change * clip(a_t, -1, 1))``
    (clipped to the wrapped action space), starting from ``u = 0`` (the robot at rest) at every
    reset. The observation is ``[obs..., u_{t-1}...]``, the command in force when the observation
    was taken, so the agent knows what it is changing. Smoothness is then built in: the
    commanded acceleration can never exceed ``max_change / dt``, and PPO's exploration noise
    becomes a random walk of the command instead of a new random command every 0.1 s.

    :param venv: a VecEnv with ``Box`` observation and action spaces (here the ``[-1, 1]``
        space of :class:`VecRescaleAction`).
    :param max_change: the largest change per step of each action component, in the units of
        the wrapped action space, e.g. ``[0.1, 0.1]``.
    :param reading_index: the observation entry holding the distance, or None. While it is
        <= 0 (follow_env: no distance reading yet) the command does not change, so the robot
        stays at rest until it first measures the person, as the reference robot and every
        guidance law do (``policies.base``).
    """

    def __init__(
        self,
        venv: VecEnv,
        max_change: Sequence[float] = (0.1, 0.1),
        reading_index: int | None = None,
    ) -> None:
        obs_box, act_box = venv.observation_space, venv.action_space
        if not (isinstance(obs_box, spaces.Box) and isinstance(act_box, spaces.Box)):
            raise ValueError("VecIncrementalAction needs Box observation and action spaces")
        change = _numbers(max_change)
        if (
            change is None
            or change.shape != act_box.shape
            or not np.all(np.isfinite(change) & (change > 0))
        ):
            raise ValueError(
                f"VecIncrementalAction.max_change={max_change!r} is out of range: must "
                f"be {act_box.shape[0]} positive numbers"
            )
        n_obs = obs_box.shape[0] if len(obs_box.shape) == 1 else 0
        index_ok = isinstance(reading_index, int) and not isinstance(reading_index, bool)
        if reading_index is not None and not (index_ok and 0 <= reading_index < n_obs):
            raise ValueError(
                f"VecIncrementalAction.reading_index={reading_index!r} is out of range: must be "
                f"None or an observation index in [0, {n_obs - 1}]"
            )
        self.max_change = change
        self.reading_index = reading_index
        self._low = act_box.low.astype(np.float64)
        self._high = act_box.high.astype(np.float64)
        observation_space = spaces.Box(
            low=np.concatenate([obs_box.low, act_box.low]).astype(np.float32),
            high=np.concatenate([obs_box.high, act_box.high]).astype(np.float32),
            dtype=np.float32,
        )
        agent_box = spaces.Box(-1.0, 1.0, shape=act_box.shape, dtype=np.float32)
        super().__init__(venv, observation_space=observation_space, action_space=agent_box)
        self._command = np.zeros((venv.num_envs, act_box.shape[0]))
        self._reading = np.ones(venv.num_envs, dtype=bool)

    def reset(self) -> VecEnvObs:
        self._command[:] = 0.0
        obs = self.venv.reset()
        self._note_reading(obs)
        return self._join(obs, self._command)

    def step_async(self, actions: np.ndarray) -> None:
        a = np.clip(np.asarray(actions, dtype=np.float64).reshape(self._command.shape), -1, 1)
        a[~self._reading] = 0.0
        self._command = np.clip(self._command + self.max_change * a, self._low, self._high)
        self.venv.step_async(self._command.astype(np.float32))

    def _note_reading(self, obs: np.ndarray) -> None:
        if self.reading_index is not None:
            self._reading = np.asarray(obs)[:, self.reading_index] > 0

    def step_wait(self) -> VecEnvStepReturn:
        obs, rewards, dones, infos = self.venv.step_wait()
        self._note_reading(obs)
        for i in np.flatnonzero(dones):
            if "terminal_observation" in infos[i]:
                infos[i]["terminal_observation"] = self._join(
                    infos[i]["terminal_observation"], self._command[i]
                )
        self._command[dones] = 0.0
        return self._join(obs, self._command), rewards, dones, infos

    @staticmethod
    def _join(obs: np.ndarray, command: np.ndarray) -> np.ndarray:
        return np.concatenate(
            [np.asarray(obs, dtype=np.float32), command.astype(np.float32)], axis=-1
        )


class VecShapedReward(VecEnvWrapper):
    """Training-only reward: ``max(r, reward_floor) + alive_bonus - rate terms``.

    The env's reward is meant for scoring a controller; three changes make it learnable:

    - ``reward_floor``: the env's distance term ``-|d - 1 m|`` is unbounded, so a step far
      behind the person (-8 at 10 m) costs more than losing the person (about -2 a step, then
      the episode ends after 3 s). A fresh agent, which cannot follow yet, learns the cheapest
      exit: lose the person at once. Clipping a step's reward from below makes "far behind" no
      worse than "lost"; the step that ends an episode by termination is not clipped, so a
      collision keeps its full -50.
    - ``alive_bonus``: a constant per step. With the floor at -1 and the bonus at 1 every step is
      worth at least 0, so no exit (lost, collision) is ever better than going on; following
      well is worth about 1.8 a step.
    - ``v_rate_weight |dv| + w_rate_weight |dw|``: ``dv, dw`` are the change of the (clipped)
      action since the previous step, in the units of the wrapped action space (``[-1, 1]``
      above :class:`VecRescaleAction`); the first step of an episode compares with 0 (the robot
      starts at rest). The env's own reward charges 0.02 per m/s² of acceleration, a few
      hundredths of its distance and offset terms, which leaves the agent little reason to be
      smooth; the evaluation's StdAccel asks for exactly that.

    Put a ``VecMonitor`` below this wrapper to log the env's own episode returns.

    :param venv: a VecEnv with a ``Box(2,)`` action space whose infos mark truncation with
        ``TimeLimit.truncated`` (SB3's convention, as the PersonFollow adapter does).
    :param reward_floor: lower clip of a step's env reward, except on terminations; None: none.
    :param alive_bonus: added to every step's reward.
    :param v_rate_weight: weight on ``|dv|`` [reward per agent unit], >= 0.
    :param w_rate_weight: weight on ``|dw|`` [reward per agent unit], >= 0.
    :param offset_weight: weight on ``min(|observed offset| / (width / 2), 1)``, >= 0.
    """

    #: Changes rewards only: :func:`train.envs.agent_env` leaves it out at inference.
    training_only = True

    def __init__(
        self,
        venv: VecEnv,
        reward_floor: float | None = None,
        alive_bonus: float = 0.0,
        v_rate_weight: float = 0.0,
        w_rate_weight: float = 0.0,
        offset_weight: float = 0.0,
    ) -> None:
        numbers = {"alive_bonus": alive_bonus, "v_rate_weight": v_rate_weight}
        numbers |= {"w_rate_weight": w_rate_weight, "offset_weight": offset_weight}
        if reward_floor is not None:
            numbers["reward_floor"] = reward_floor
        for name, value in numbers.items():
            ok = isinstance(value, int | float) and not isinstance(value, bool)
            if not (ok and np.isfinite(value) and (value >= 0 or not name.endswith("weight"))):
                raise ValueError(
                    f"VecShapedReward.{name}={value!r} is out of range: must be a finite number"
                    + (" >= 0" if name.endswith("weight") else "")
                )
        act_box = venv.action_space
        if not isinstance(act_box, spaces.Box) or act_box.shape != (2,):
            raise ValueError(f"VecShapedReward needs a Box(2,) action space, got {act_box}")
        super().__init__(venv)
        self.reward_floor = -np.inf if reward_floor is None else float(reward_floor)
        self.alive_bonus = float(alive_bonus)
        self.rate_weights = np.array([v_rate_weight, w_rate_weight], dtype=np.float64)
        self.offset_weight = float(offset_weight)
        self._half_width_px = float(venv.observation_space.high[1]) + 1.0
        self._low, self._high = act_box.low, act_box.high
        self._prev = np.zeros((venv.num_envs, 2))
        self._change = np.zeros((venv.num_envs, 2))

    def reset(self) -> VecEnvObs:
        self._prev[:] = 0.0
        return self.venv.reset()

    def step_async(self, actions: np.ndarray) -> None:
        a = np.asarray(actions, dtype=np.float64).reshape(self._prev.shape)
        a = np.clip(a, self._low, self._high)
        self._change = np.abs(a - self._prev)
        self._prev = a
        self.venv.step_async(actions)

    def step_wait(self) -> VecEnvStepReturn:
        obs, rewards, dones, infos = self.venv.step_wait()
        truncated = np.array([info.get("TimeLimit.truncated", False) for info in infos])
        terminated = np.asarray(dones, dtype=bool) & ~truncated
        r = np.asarray(rewards, dtype=np.float64)
        shaped = np.where(terminated, r, np.maximum(r, self.reward_floor))
        shaped += self.alive_bonus - self._change @ self.rate_weights
        if self.offset_weight:
            offset = np.abs(np.asarray(obs, dtype=np.float64)[:, 1]) / self._half_width_px
            shaped -= self.offset_weight * np.minimum(offset, 1.0)
        self._prev[dones] = 0.0
        return obs, shaped.astype(np.float32), dones, infos


class ConcatVecEnv(VecEnv):
    """Several VecEnvs with equal spaces as one: lanes are the sub-envs' lanes, in order.

    Used to train on several scenarios at once: one batched core per scenario, stepped one after
    the other each step (a core's kernel is fast enough that threads would not pay off at a few
    lanes per scenario).

    :param venvs: the sub-envs; their observation and action spaces must be equal.
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

    def reset(self) -> VecEnvObs:
        return np.concatenate([v.reset() for v in self.venvs])

    def step_async(self, actions: np.ndarray) -> None:
        for venv, part in zip(self.venvs, self._slices(), strict=True):
            venv.step_async(actions[part])

    def step_wait(self) -> VecEnvStepReturn:
        results = [v.step_wait() for v in self.venvs]
        obs = np.concatenate([r[0] for r in results])
        rewards = np.concatenate([r[1] for r in results])
        dones = np.concatenate([r[2] for r in results])
        infos = [info for r in results for info in r[3]]
        return obs, rewards, dones, infos

    def close(self) -> None:
        for venv in self.venvs:
            venv.close()

    def _split(self, indices: VecEnvIndices) -> list[tuple[VecEnv, list[int]]]:
        """Group global lane indices by sub-env, as local indices."""
        groups: list[tuple[VecEnv, list[int]]] = []
        for j in self._get_indices(indices):
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

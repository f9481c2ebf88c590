"""How a learned agent sees the env: its feature pipeline, numpy only, batched over lanes.

Each step is a small class with its own per-lane memory. Observations flow outwards (env to
agent), actions inwards (agent to env), innermost step first, in the order of the agent's
``vec_env_wrapper`` list (then observation normalisation and frame stacking, rl-zoo3's order):

- :class:`RescaleAction`: the agent acts in ``[-1, 1]``, mapped linearly onto SI speeds over the
  useful range (``w_max_radps`` 2 rad/s covers every turn rate the tuned laws command), not the
  platform's 7.4 rad/s, over most of which the agent would spin the person out of view.
- :class:`ObservationAge`: appends how long the detection has been held (the perception repeats
  its last values while the detector sees nothing): a fresh offset or a stale one.
- :class:`~policies.learned.hint.LawHint`: appends a guidance law's command on the observation
  (in the agent's units), which :class:`IncrementalAction` with ``prior_index`` can track.
- :class:`ScaleObservation`: fixed scaling that keeps signed entries centred on 0 (needed by the
  mirror-symmetric policy, :mod:`policies.learned.mirror`).
- :class:`IncrementalAction`: the agent changes the command by at most a set step and sees the
  command in force: smooth by construction, and the missing robot state (its own speed command)
  becomes part of the observation.
- :class:`NormalizeObservation`: ``VecNormalize``'s observation normalisation with frozen
  statistics (when the agent was trained with it).
- :class:`FrameStack`: the last ``n`` observations side by side, as ``VecFrameStack`` does: the
  raw observation is not Markov (a frame of detector latency, held values, the robot's own speed
  unobserved). The agent's ``frame_stack`` pads an episode's start with zeros, as ``VecFrameStack``
  does; the wrapper ``VecStackFrames`` (outermost) can repeat the first observation instead.

The arithmetic is exactly that of the training wrappers (they call these classes), so an agent's
actions are bitwise the same in training, in an env, and on a robot; :class:`Pipeline` chains.
Training-only wrappers (:meth:`Pipeline.view_entries`) have no step: the reward shaping, and
the truth that an asymmetric critic reads beside the agent's view (:mod:`train.privileged`).
The other way round, a step listed with ``in_training: false`` (:mod:`policies.learned.feature`)
is in the agent's view but not in its training env: a filter added in front of an agent trained
without it, such as :class:`JumpGate` in ``train/configs/ppo_ahead_gated.yaml``.

The action is the platform's, of any width: the differential drive's ``[v_mps, w_radps]``, the
mecanum base's ``[v_mps, vy_mps, w_radps]``. A :class:`Box` carries the entries' names (the
platform's), every step keeps them, and every per-action parameter has one value per entry
(``max_change``; ``v_max_mps`` / ``w_max_radps`` per entry of their unit). A box without
names is an agent saved before names were recorded: two entries, :data:`LEGACY_ACTION_NAMES`.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, ClassVar

import numpy as np

from follow_env.sim.checks import check_number, is_integer, out_of_range
from policies.learned.boxes import LEGACY_ACTION_NAMES, Box, agent_to_si, as_numbers
from policies.learned.feature import Feature, split_in_training
from policies.learned.gate import JumpGate
from policies.learned.hint import LawHint
from policies.learned.incremental import IncrementalAction

__all__ = [
    "FEATURES",
    "LEGACY_ACTION_NAMES",
    "Box",
    "Feature",
    "FrameStack",
    "IncrementalAction",
    "JumpGate",
    "LawHint",
    "NormalizeObservation",
    "ObservationAge",
    "Pipeline",
    "RescaleAction",
    "ScaleObservation",
    "agent_to_si",
]


class RescaleAction(Feature):
    """The agent acts in ``[-1, 1]^m``; the env receives SI actions (module docstring).

    Entry ``k`` of ``[-1, 1]`` maps linearly onto ``[-max_k, max_k]``, by default the env's
    bound of that entry. The agent's ranges are given by unit: ``v_max_mps`` for the entries in
    m/s (their names end in ``_mps``: the differential drive's ``v_mps``, the mecanum base's
    ``v_mps`` and ``vy_mps``), ``w_max_radps`` for those in rad/s (``w_radps``). Each is one
    number for all its entries, or a list of one value per entry, in the platform's order (null:
    the env's bound), e.g. ``v_max_mps: [null, 1.0]`` for the mecanum base's vx and vy.

    :param v_max_mps: the agent's largest speed(s) [m/s]; None, or each at most the env's bound.
    :param w_max_radps: the agent's largest turn rate(s) [rad/s]; None, or each at most the
        env's bound.
    :param reverse_max_mps: the agent's largest backward speed [m/s] on the forward-speed
        entry ``v_mps``, in (0, its forward bound]; None: as fast back as forward. The camera
        looks forward, so backing up is driving blind: a robot builder may want less of it
        than the platform allows. The agent's box for ``v_mps`` is then ``[-reverse / v_max,
        1]`` (the same metres per second per agent unit both ways, so an incremental command
        steps as finely back as forward and rests at 0).
    """

    #: The limits, and the unit suffix of the action entries each bounds.
    UNITS: ClassVar[dict[str, str]] = {"v_max_mps": "_mps", "w_max_radps": "_radps"}

    def __init__(
        self,
        v_max_mps: float | Sequence[float | None] | None = None,
        w_max_radps: float | Sequence[float | None] | None = None,
        reverse_max_mps: float | None = None,
    ) -> None:
        self.limits = (v_max_mps, w_max_radps)
        self.reverse_max_mps = reverse_max_mps

    def bind(self, obs: Box, act: Box, n: int) -> tuple[Box, Box]:
        if not np.all(np.isfinite([act.low, act.high])) or not np.allclose(act.low, -act.high):
            raise ValueError(f"{self.owner} needs a bounded symmetric Box, got {act}")
        names = act.entry_names()
        high = act.high.astype(np.float64).copy()
        for (field, unit), value in zip(self.UNITS.items(), self.limits, strict=True):
            if value is None:
                continue
            entries = [k for k, name in enumerate(names) if name.endswith(unit)]
            listed = [names[k] for k in entries]
            if isinstance(value, list | tuple):
                if len(value) != len(entries):
                    raise ValueError(
                        f"{self.owner}.{field}={value!r} is out of range: must be a number or "
                        f"{len(entries)} entries, one per action entry in {unit[1:]} "
                        f"[{', '.join(listed)}] (a number or null)"
                    )
                pairs = [(f"{field}[{i}] ({names[k]})", k, v) for i, (k, v) in
                         enumerate(zip(entries, value, strict=True))]  # fmt: skip
            elif not entries:
                raise ValueError(
                    f"{self.owner}.{field}: the env's action [{', '.join(names)}] has no entry "
                    f"in {unit[1:]}"
                )
            else:
                pairs = [(field, k, value) for k in entries]
            for label, k, v in pairs:
                if v is not None:
                    high[k] = check_number(
                        f"{self.owner}.{label}", v, 0.0, float(high[k]), lo_open=True
                    )
        self.si_low, self.si_high = -high, high
        self.agent_low = -np.ones(len(names))
        if self.reverse_max_mps is not None:
            if "v_mps" not in names:
                raise ValueError(
                    f"{self.owner}.reverse_max_mps: the env's action [{', '.join(names)}] has "
                    "no forward-speed entry v_mps"
                )
            k = names.index("v_mps")
            where = f"{self.owner}.reverse_max_mps"
            reverse = check_number(where, self.reverse_max_mps, 0.0, float(high[k]), lo_open=True)
            self.agent_low[k] = -reverse / high[k]
        return obs, Box(self.agent_low, np.ones(len(names)), act.names)

    def act(self, action: np.ndarray) -> np.ndarray:
        if self.reverse_max_mps is None:
            return agent_to_si(action, self.si_low, self.si_high)
        # The box is asymmetric on v_mps: the same scale both ways (a * v_max), clipped to it.
        return np.clip(np.asarray(action, dtype=np.float64), self.agent_low, 1.0) * self.si_high


class ObservationAge(Feature):
    """Observation ``[obs..., age]``: how many steps the observation has not changed, scaled.

    A repeated observation is stale, not a person standing still in the image: the filtered
    depth of a fresh detection never repeats to the last bit. ``age = min(k, max_age_steps) /
    max_age_steps``, where ``k`` is the number of steps since the observation last changed (0 on
    a fresh one). It uses only what the robot publishes, so the real robot can compute it too.

    :param max_age_steps: where the age saturates at 1 (30 steps = the env's 3 s lost timeout).
    :param entries: compare only the first this many entries (2: the detection's, not the
        reading ahead, which is fresh every frame); None: all.
    """

    def __init__(self, max_age_steps: int = 30, entries: int | None = None) -> None:
        self.max_age_steps, self.entries = max_age_steps, entries

    def bind(self, obs: Box, act: Box, n: int) -> tuple[Box, Box]:
        steps, entries = self.max_age_steps, self.entries
        # Bounded so that the int64 age compares with it (2**63 once raised OverflowError in
        # the first reset); 10**9 steps is years of control at 10 Hz.
        if not is_integer(steps) or not 1 <= steps <= 10**9:
            raise out_of_range(f"{self.owner}.max_age_steps", steps, "an integer in [1, 10**9]")
        if entries is not None and not (is_integer(entries) and 1 <= entries <= obs.shape[0]):
            raise out_of_range(f"{self.owner}.entries", entries, f"None or 1 to {obs.shape[0]}")
        self.max_age_steps, self._k = int(steps), obs.shape[0] if entries is None else int(entries)
        self._last = np.zeros((n, *obs.shape), dtype=np.float32)
        self._age = np.zeros(n, dtype=np.int64)
        return Box(np.append(obs.low, 0.0), np.append(obs.high, 1.0)), act

    def start(self, obs: np.ndarray) -> np.ndarray:
        obs = np.asarray(obs, dtype=np.float32)
        self._last = obs.copy()
        self._age[:] = 0
        return self._join(obs, self._age)

    def observe(self, obs: np.ndarray, done: np.ndarray) -> np.ndarray:
        obs = np.asarray(obs, dtype=np.float32)
        k = self._k
        age = np.where(np.all(obs[:, :k] == self._last[:, :k], axis=1), self._age + 1, 0)
        age[done] = 0  # the lanes that ended were reset: obs is a new episode's first
        self._last = obs.copy()
        self._age = age
        return self._join(obs, age)

    def terminal(self, obs: np.ndarray, lane: int) -> np.ndarray:
        terminal = np.asarray(obs, dtype=np.float32)
        stale = np.array_equal(terminal[: self._k], self._last[lane, : self._k])
        return self._join(terminal[None], np.array([self._age[lane] + 1 if stale else 0]))[0]

    def _join(self, obs: np.ndarray, age: np.ndarray) -> np.ndarray:
        scaled = np.minimum(age, self.max_age_steps) / self.max_age_steps
        return np.concatenate([obs, scaled[:, None].astype(np.float32)], axis=1)


class ScaleObservation(Feature):
    """Observation ``obs * scale``, entry by entry: a fixed normalisation that keeps 0 at 0.

    ``VecNormalize`` shifts every entry by its running mean; a mirror-symmetric policy needs the
    offset and the turn command to stay signed around 0, so they are scaled instead (e.g. the
    offset by 1/100 px).

    :param scale: one positive factor per observation entry.
    """

    def __init__(self, scale: Sequence[float] = ()) -> None:
        self.given = scale

    def bind(self, obs: Box, act: Box, n: int) -> tuple[Box, Box]:
        factors = as_numbers(self.given)
        if factors is None or factors.shape != obs.shape:
            raise ValueError(
                f"{self.owner}.scale={self.given!r} is out of range: must be one factor per "
                f"observation entry {obs.shape}"
            )
        # The factors act in float32: 1e308 became inf there, with numpy's warning on a line
        # of its own before the error.
        with np.errstate(over="ignore"):
            scale = factors.astype(np.float32)
        if not np.all(np.isfinite(scale) & (scale > 0)):
            raise ValueError(
                f"{self.owner}.scale={self.given!r} is out of range: must be positive numbers "
                "a float32 holds (at most 3.4e38)"
            )
        self.scale = scale
        with np.errstate(over="ignore"):  # bounds past float32 are infinite: unbounded
            return Box(obs.low * self.scale, obs.high * self.scale), act

    def observe(self, obs: np.ndarray, done: np.ndarray) -> np.ndarray:
        return np.asarray(obs, dtype=np.float32) * self.scale

    def terminal(self, obs: np.ndarray, lane: int) -> np.ndarray:
        return np.asarray(obs, dtype=np.float32) * self.scale


class NormalizeObservation(Feature):
    """``(obs - mean) / sqrt(var + epsilon)``, clipped to ``+-clip_obs``, with frozen statistics:
    ``VecNormalize``'s observation normalisation at inference, term for term.

    :param mean: running mean of each entry. :param var: running variance of each entry.
    :param epsilon: added to the variance. :param clip_obs: bound of the result.
    """

    def __init__(self, mean: np.ndarray, var: np.ndarray, epsilon: float, clip_obs: float) -> None:
        self.mean, self.var = np.asarray(mean), np.asarray(var)
        self.epsilon, self.clip_obs = epsilon, clip_obs

    def observe(self, obs: np.ndarray, done: np.ndarray) -> np.ndarray:
        z = np.clip(
            (obs - self.mean) / np.sqrt(self.var + self.epsilon), -self.clip_obs, self.clip_obs
        )
        return z.astype(np.float32)

    terminal = Feature.terminal


class FrameStack(Feature):
    """The last ``n_stack`` observations side by side (oldest first), as ``VecFrameStack`` with
    the stack on the last axis.

    ``pad`` says what stands before an episode's first observation: ``"zeros"``, as in
    ``VecFrameStack`` (the agent's ``frame_stack``), or ``"first"``, that observation repeated
    (the training wrapper ``VecStackFrames``). With zeros, the first frames of every episode
    read as a distance that jumped from 0 m (no reading) to the person's, a person moving
    away fast, and an agent learns to set off before the person does; repeated, they read as a
    person standing still, which is what the robot has seen.

    :param n_stack: frames kept (an integer >= 1).
    :param pad: ``"zeros"`` or ``"first"``.
    """

    PADS = ("zeros", "first")

    def __init__(self, n_stack: int, pad: str = "zeros") -> None:
        self.n_stack = n_stack
        self.pad = pad

    def _check(self) -> None:
        if not is_integer(self.n_stack) or self.n_stack < 1:
            raise out_of_range(f"{self.owner}.n_stack", self.n_stack, "an integer >= 1")
        self.n_stack = int(self.n_stack)
        if self.pad not in self.PADS:
            raise out_of_range(f"{self.owner}.pad", self.pad, "'zeros' or 'first'")

    def bind(self, obs: Box, act: Box, n: int) -> tuple[Box, Box]:
        self._check()  # here, not in __init__: a training wrapper gives its name first
        self._k = obs.shape[0]
        self._stack = np.zeros((n, self._k * self.n_stack), dtype=np.float32)
        return Box(np.tile(obs.low, self.n_stack), np.tile(obs.high, self.n_stack)), act

    def start(self, obs: np.ndarray) -> np.ndarray:
        return self.observe(obs, np.ones(len(obs), dtype=bool))

    def observe(self, obs: np.ndarray, done: np.ndarray) -> np.ndarray:
        self._stack = np.roll(self._stack, shift=-self._k, axis=-1)
        if self.pad == "first":
            self._stack[done] = np.tile(np.asarray(obs, dtype=np.float32)[done], self.n_stack)
        else:
            self._stack[done] = 0
        self._stack[:, -self._k :] = obs
        return self._stack.copy()

    def terminal(self, obs: np.ndarray, lane: int) -> np.ndarray:
        # VecFrameStack's: the lane's stack with its final observation pushed on
        stack = np.roll(self._stack[lane], shift=-self._k)
        stack[-self._k :] = obs
        return stack


FEATURES: dict[str, type[Feature]] = {
    "RescaleAction": RescaleAction,
    "ObservationAge": ObservationAge,
    "ScaleObservation": ScaleObservation,
    "IncrementalAction": IncrementalAction,
    "StackFrames": FrameStack,
    "JumpGate": JumpGate,
    "LawHint": LawHint,
}
"""Feature steps by name (an agent's ``vec_env_wrapper`` entry ``train.wrappers.VecX`` names
step ``X``)."""


class Pipeline:
    """The steps of an agent's view, innermost first, for ``n`` lanes.

    :param steps: the steps (each used by this pipeline only).
    :param obs: the env's observation box. :param act: the env's action box.
    :param n: lanes.
    """

    def __init__(self, steps: Sequence[Feature], obs: Box, act: Box, n: int) -> None:
        self.steps = list(steps)
        self.n = n
        for step in self.steps:
            obs, act = step.bind(obs, act, n)
        self.observation_box, self.action_box = obs, act

    def start(self, obs: np.ndarray) -> np.ndarray:
        """Every lane starts an episode: the agent's first observation."""
        for step in self.steps:
            obs = step.start(obs)
        return obs

    def observe(self, obs: np.ndarray, done: np.ndarray | None = None) -> np.ndarray:
        """The agent's observation after a step (``done``: lanes that were just reset)."""
        flags = np.zeros(len(obs), dtype=bool) if done is None else done
        for step in self.steps:
            obs = step.observe(obs, flags)
        return obs

    def act(self, action: np.ndarray) -> np.ndarray:
        """The env's action for the agent's ``action`` (outermost step first)."""
        for step in reversed(self.steps):
            action = step.act(action)
        return np.asarray(action)

    @staticmethod
    def view_entries(entries: Sequence[tuple[str, dict]]) -> list[tuple[str, str, dict]]:
        """``(name, step, kwargs)`` of the ``vec_env_wrapper`` entries that make up an agent's
        view (``train.wrappers.VecX`` is step ``X``; the training-only ones are left out: the
        reward shaping, and the truth an asymmetric critic reads)."""
        steps = [(name, name.rsplit(".", 1)[-1].removeprefix("Vec"), kw) for name, kw in entries]
        return [entry for entry in steps if entry[1] not in ("ShapedReward", "PrivilegedCritic")]

    @classmethod
    def from_wrappers(cls, entries: Sequence[tuple[str, dict[str, Any]]]) -> list[Feature]:
        """The inference steps of an agent's ``vec_env_wrapper`` list (training-only ones, such
        as the reward shaping, left out: :meth:`view_entries`; ones left out of training with
        ``in_training: false`` kept): ``[(name, kwargs), ...]``."""
        steps: list[Feature] = []
        for name, short, kwargs in cls.view_entries(entries):
            if short not in FEATURES:
                raise ValueError(f"unknown feature {name!r}; known: {', '.join(FEATURES)}")
            # A step left out of training (in_training: false) is part of the view all the same.
            _, own = split_in_training(kwargs, name)
            steps.append(FEATURES[short](**own))
        return steps

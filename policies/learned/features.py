"""How a learned agent sees the env: its feature pipeline, numpy only, batched over lanes.

Each step is a small class with its own per-lane memory. Observations flow outwards (env to
agent), actions inwards (agent to env), innermost step first, in the order of the agent's
``vec_env_wrapper`` list (then observation normalisation and frame stacking, rl-zoo3's order):

- :class:`RescaleAction`: the agent acts in ``[-1, 1]``, mapped linearly onto SI speeds over the
  useful range (``w_max_radps`` 2 rad/s covers every turn rate the tuned laws command), not the
  platform's 7.4 rad/s, over most of which the agent would spin the person out of view.
- :class:`ObservationAge`: appends how long the detection has been held (the perception repeats
  its last values while the detector sees nothing): a fresh offset or a stale one.
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

__all__ = [
    "FEATURES",
    "LEGACY_ACTION_NAMES",
    "Box",
    "Feature",
    "FrameStack",
    "IncrementalAction",
    "JumpGate",
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
        if not is_integer(steps) or steps < 1:
            raise out_of_range(f"{self.owner}.max_age_steps", steps, "an integer >= 1")
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
        if not np.all(np.isfinite(factors) & (factors > 0)):
            raise ValueError(
                f"{self.owner}.scale={self.given!r} is out of range: must be positive numbers"
            )
        self.scale = factors.astype(np.float32)
        return Box(obs.low * self.scale, obs.high * self.scale), act

    def observe(self, obs: np.ndarray, done: np.ndarray) -> np.ndarray:
        return np.asarray(obs, dtype=np.float32) * self.scale

    def terminal(self, obs: np.ndarray, lane: int) -> np.ndarray:
        return np.asarray(obs, dtype=np.float32) * self.scale


class IncrementalAction(Feature):
    """The agent changes the command by at most ``max_change`` a step; observation gets the
    command.

    The inner action is ``u_t = clip(u_{t-1} + max_change * clip(a_t, -1, 1))`` (clipped to the
    inner action box), from ``u = 0`` (the robot at rest) at every episode start. The observation
    is ``[obs..., u_{t-1}...]``, the command in force when the observation was taken. The
    commanded acceleration can never exceed ``max_change / dt``, and PPO's exploration noise
    becomes a random walk of the command instead of a new random command every 0.1 s.

    :param max_change: the largest change per step of each action entry, in inner units (one
        per entry of the platform's action, in its order).
    :param reading_index: the observation entry holding the distance, or None. While it is <= 0
        (no distance reading yet) the command does not change, so the robot stays at rest until
        it first measures the person, as the reference robot and every guidance law do.
    :param brake_change: the largest change per step towards rest, one per entry (inner
        units), or None: ``max_change`` both ways. Given, an action against the command's sign
        takes ``|u|`` down by up to ``brake_change * |a|``, stopping at rest (README, "Tried
        on top of ppo_fast.yaml": it did not stop the overshoot at stops).
    :param held_index: the observation entry that is > 0 while the detection is held (not
        fresh), :class:`ObservationAge`'s age; or None. Needs ``held_floor``.
    :param held_floor: while the detection is held, the lowest command of each entry (inner
        units; None: the box's), one per entry. ``[0, null]``: no backing up while the person
        is not seen, the robot's camera looking forward. A command below the floor when the
        detection goes stale rises to it by ``max_change`` a step, so the acceleration bound
        holds (README, "No backing up blind").
    :param held_keep: while the detection is held, the entries whose command stays as it was
        (one bool per entry), or None: none. ``[false, true]`` keeps turning at the rate the
        robot turned when the person was last seen, as the laws do on a stale offset: a
        person walking round the robot behind something is still in view when they come out.
        Needs ``held_index``; the floor, if given, still applies to the others.
    :param ahead_index: with ``held_keep``, the observation entry holding the reading ahead, or
        None: keep in every gap. Given, the entries are kept only in a gap in which the reading
        ahead has read nearer than the held distance (entry ``reading_index``) by more than
        ``behind_margin_m``: something came between the robot and the person, who is then
        taken to walk on as they did. A gap with nothing nearer (the detector missed the person)
        leaves the agent free to turn back towards where it last saw them.
    :param behind_margin_m: how much nearer than the held distance the reading ahead must read
        (m, > 0).
    """

    def __init__(
        self,
        max_change: Sequence[float] = (0.1, 0.1),
        reading_index: int | None = None,
        brake_change: Sequence[float] | None = None,
        held_index: int | None = None,
        held_floor: Sequence[float | None] | None = None,
        held_keep: Sequence[bool] | None = None,
        ahead_index: int | None = None,
        behind_margin_m: float = 0.2,
    ) -> None:
        self.given = max_change
        self.reading_index = reading_index
        self.given_brake = brake_change
        self.held_index = held_index
        self.given_floor = held_floor
        self.given_keep = held_keep
        self.ahead_index = ahead_index
        self.behind_margin_m = behind_margin_m

    def bind(self, obs: Box, act: Box, n: int) -> tuple[Box, Box]:
        change = self._steps("max_change", self.given, act)
        brake = (
            None if self.given_brake is None else self._steps("brake_change", self.given_brake, act)
        )
        n_obs = obs.shape[0]
        for field in ("reading_index", "held_index", "ahead_index"):
            index = getattr(self, field)
            if index is not None and not (is_integer(index) and 0 <= index < n_obs):
                raise ValueError(
                    f"{self.owner}.{field}={index!r} is out of range: must be None or an "
                    f"observation index in [0, {n_obs - 1}]"
                )
        self.max_change = change
        self.brake_change = brake
        self._low = act.low.astype(np.float64)
        self._high = act.high.astype(np.float64)
        self._floor = self._held_floor(act)
        self._keep = self._held_keep(act)
        if self.ahead_index is not None:
            if self._keep is None or self.reading_index is None:
                raise ValueError(
                    f"{self.owner}.ahead_index={self.ahead_index!r}: needs held_keep and "
                    "reading_index"
                )
            self.behind_margin_m = check_number(
                f"{self.owner}.behind_margin_m", self.behind_margin_m, 0.0, None, lo_open=True
            )
        self._behind = np.zeros(n, dtype=bool)
        self._command = np.zeros((n, act.shape[0]))
        self._reading = np.ones(n, dtype=bool)
        self._held = np.zeros(n, dtype=bool)
        outer_obs = Box(np.concatenate([obs.low, act.low]), np.concatenate([obs.high, act.high]))
        return outer_obs, Box(-np.ones(act.shape), np.ones(act.shape), act.names)

    def _steps(self, field: str, given: Any, act: Box) -> np.ndarray:
        """``given`` as one positive step per action entry, or a ValueError naming ``field``."""
        steps = as_numbers(given)
        good = steps is not None and steps.shape == act.shape
        if not (good and np.all(np.isfinite(steps) & (steps > 0))):
            may = "None or " if field == "brake_change" else ""
            raise ValueError(
                f"{self.owner}.{field}={given!r} is out of range: must be {may}{act.shape[0]} "
                f"positive numbers, one per action entry [{', '.join(act.entry_names())}]"
            )
        return steps

    def _held_keep(self, act: Box) -> np.ndarray | None:
        """``held_keep`` as one bool per entry, or None."""
        given = self.given_keep
        if given is None:
            return None
        names = act.entry_names()
        ok = isinstance(given, list | tuple) and all(isinstance(b, bool) for b in given)
        if not ok or len(given) != len(names):
            raise ValueError(
                f"{self.owner}.held_keep={given!r} is out of range: must be {len(names)} "
                f"booleans, one per action entry [{', '.join(names)}]"
            )
        return np.array(given, dtype=bool)

    def _held_floor(self, act: Box) -> np.ndarray | None:
        """``held_floor`` as one lower bound per entry (the box's for null), or None."""
        given, index = self.given_floor, self.held_index
        held = {"held_floor": given, "held_keep": self.given_keep}
        uses = [f"{name}={value!r}" for name, value in held.items() if value is not None]
        if uses and index is None:
            raise ValueError(f"{self.owner}.{' and '.join(uses)}: needs held_index")
        if index is not None and not uses:
            raise ValueError(
                f"{self.owner}.held_index={index!r} serves nothing: give held_floor or "
                "held_keep, or leave held_index out"
            )
        if given is None:
            return None
        names = act.entry_names()
        if not isinstance(given, list | tuple) or len(given) != len(names):
            raise ValueError(
                f"{self.owner}.held_floor={given!r} is out of range: must be {len(names)} "
                f"entries, one per action entry [{', '.join(names)}] (a number or null)"
            )
        floor = act.low.astype(np.float64).copy()
        for k, value in enumerate(given):
            if value is not None:
                label = f"{self.owner}.held_floor[{k}] ({names[k]})"
                floor[k] = check_number(label, value, float(act.low[k]), float(act.high[k]))
        return floor

    def start(self, obs: np.ndarray) -> np.ndarray:
        self._command[:] = 0.0
        self._note_reading(obs)
        return self._join(obs, self._command)

    def act(self, action: np.ndarray) -> np.ndarray:
        a = np.clip(np.asarray(action, dtype=np.float64).reshape(self._command.shape), -1, 1)
        a[~self._reading] = 0.0
        u = self._command
        moved = u + self.max_change * a
        if self.brake_change is not None:  # towards rest: down by up to brake_change, to zero
            slowed = np.sign(u) * np.maximum(np.abs(u) - self.brake_change * np.abs(a), 0.0)
            moved = np.where(a * u < 0.0, slowed, moved)
        if self._floor is not None and self._held.any():
            # held: no lower than the floor, or than a command rising to it at the largest step
            low = np.minimum(self._floor, u + self.max_change)
            moved[self._held] = np.maximum(moved[self._held], low[self._held])
        if self._keep is not None and self._held.any():
            gap = self._held if self.ahead_index is None else self._held & self._behind
            kept = gap[:, None] & self._keep[None, :]
            moved[kept] = u[kept]
        self._command = np.clip(moved, self._low, self._high)
        return self._command.astype(np.float32)

    def observe(self, obs: np.ndarray, done: np.ndarray) -> np.ndarray:
        self._note_reading(obs)
        self._command[done] = 0.0
        return self._join(obs, self._command)

    def terminal(self, obs: np.ndarray, lane: int) -> np.ndarray:
        return self._join(obs, self._command[lane])

    def _note_reading(self, obs: np.ndarray) -> None:
        if self.reading_index is not None:
            self._reading = np.asarray(obs)[:, self.reading_index] > 0
        if self.held_index is not None:
            self._held = np.asarray(obs)[:, self.held_index] > 0
        if self.ahead_index is not None:
            # latched for the rest of the gap: turning, the robot may leave the occluder's side
            rows = np.asarray(obs)
            nearer = rows[:, self.ahead_index] < rows[:, self.reading_index] - self.behind_margin_m
            self._behind = self._held & (self._behind | nearer)

    @staticmethod
    def _join(obs: np.ndarray, command: np.ndarray) -> np.ndarray:
        return np.concatenate(
            [np.asarray(obs, dtype=np.float32), command.astype(np.float32)], axis=-1
        )


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

"""The contract every policy keeps, and the shared parts of the guidance laws.

Policies see the task only through its spec (:mod:`follow_env.tasks.person_follow.spec`: names
and units, no simulation import), which gives the observation's size; nothing here imports the
simulator, training code, torch or stable-baselines3.

## Observation
float32 array, shape (2,) (reference §1.4, step 5):

| index | name       | unit | meaning                                                      |
|-------|------------|------|--------------------------------------------------------------|
| 0     | distance_m | m    | filtered distance to the person; 0 means no valid reading yet |
| 1     | offset_px  | px   | box centre minus image centre; > 0 means right of centre     |

With the reading ahead configured (``PerceptionConfig.ahead_rays > 0``) the observation has a
third entry, ``ahead_m`` (m): the nearest valid depth across the image's middle row. The laws
read the first two entries and ignore it; a learned agent trained with it needs it.

## Before the first reading
``distance_m <= 0`` means the perception has not measured the person yet (reference §1.4: the
distance filter starts from nothing, and invalid depth reads as 0). The reference robot did not
move before its first detection, so every guidance law then commands a zero action and leaves
its memory untouched; without this, ``V = kv (0 - 1.0)`` would drive backwards at full speed.

## Action
float32 array, shape (2,), SI:

| index | name    | unit  | meaning                                |
|-------|---------|-------|----------------------------------------|
| 0     | v_mps   | m/s   | forward speed                          |
| 1     | w_radps | rad/s | yaw rate, counter-clockwise positive   |

A law that strafes too (:mod:`policies.holonomic`) acts ``[v_mps, vy_mps, w_radps]`` (vy to the
left). Every policy names its entries in ``action_names`` (default :data:`LAW_ACTION_NAMES`);
:func:`policies.adapt.for_platform` fits it to a platform's action by those names.

## Sign convention (reference §1.5 "Sign")
Image u grows to the right and w is counter-clockwise positive, so a person right of centre
(offset_px > 0) needs a clockwise turn: w < 0. The thesis hid this sign in its motor wiring; each
law here applies it with one commented minus sign.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import Any, Protocol, runtime_checkable

import numpy as np
from numpy.typing import ArrayLike

from follow_env.sim.checks import check_number
from follow_env.tasks.person_follow.spec import AHEAD, SPEC, observation_names

# A distance at or below this means "no valid reading yet" (reference §1.4: invalid depth is 0).
NO_READING_M = 0.0
OBS_SIZE = SPEC.observation_size
"""Entries of an observation (the task spec's)."""
OBS_SIZES = (OBS_SIZE, len(observation_names(ahead=True)))
"""Entries of an observation without and with the reading ahead."""
OBS_NAMES = "[" + ", ".join(SPEC.observation_names) + "]"
_SHAPES = f"({OBS_SIZE},) = {OBS_NAMES} or ({OBS_SIZES[1]},) with {AHEAD.name}"
LAW_ACTION_NAMES = ("v_mps", "w_radps")
"""What a guidance law commands: forward speed and yaw rate (the differential drive's action)."""


@runtime_checkable
class Policy(Protocol):
    """Anything that maps an observation to an action: a guidance law or a learned agent.

    :param name: the name the policy is known by in tables and logs (e.g. ``"pn:tuned"``).

    Optional: ``env_overrides``, configuration sections the policy needs of an env on top of
    a run's (``{"perception": {"ahead_rays": 5}}``: a learned agent that reads the reading
    ahead); evaluation applies them to that policy's episodes.
    """

    name: str

    def reset(self) -> None:
        """Forget everything remembered from earlier steps; call at the start of an episode."""
        ...

    def act(self, obs: np.ndarray) -> np.ndarray:
        """Map ``[distance_m, offset_px]`` to ``[v_mps, w_radps]`` (see the module docstring).

        ``offset_px > 0`` (person right of centre) must give ``w_radps < 0``.
        """
        ...


@runtime_checkable
class BatchPolicy(Policy, Protocol):
    """A policy that also acts for many robots at once, each with its own memory.

    ``reset_batch(n)`` starts ``n`` episodes; ``act_batch(obs[n, k]) -> actions[n, m]`` then
    gives each lane exactly the action :meth:`Policy.act` would give that lane's episode alone
    (evaluation relies on it: batched and one-by-one rollouts are bit-identical).
    """

    def reset_batch(self, n: int) -> None:
        """Start ``n`` lanes' episodes (forget every lane's memory)."""
        ...

    def act_batch(self, obs: np.ndarray) -> np.ndarray:
        """Actions ``(n, m)`` float32 for observations ``(n, k)``."""
        ...


def validate_obs(obs: ArrayLike) -> tuple[float, float]:
    """Check an observation and return it as ``(distance_m, offset_px)`` Python floats.

    :param obs: ``[distance_m, offset_px]``, shape (2,), or with ``ahead_m`` after them,
        shape (3,); finite.
    :raises ValueError: on a wrong shape or a NaN/inf entry.
    """
    arr = validate_obs_row(obs)
    return float(arr[0]), float(arr[1])


def validate_obs_row(obs: ArrayLike) -> np.ndarray:
    """Check one observation of either size (:data:`OBS_SIZES`); returns it as float64.

    :raises ValueError: on a wrong shape or a NaN/inf entry.
    """
    arr = np.asarray(obs, dtype=np.float64)
    if arr.ndim != 1 or arr.shape[0] not in OBS_SIZES:
        raise ValueError(f"obs must have shape {_SHAPES}, got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"obs must be finite, got {arr.tolist()}")
    return arr


def validate_obs_batch(obs: ArrayLike) -> np.ndarray:
    """Check a batch of observations ``(n, k)``, k of :data:`OBS_SIZES`; returns it as float64.

    :raises ValueError: on a wrong shape or a NaN/inf entry (naming the lanes).
    """
    arr = np.asarray(obs, dtype=np.float64)
    if arr.ndim != 2 or arr.shape[1] not in OBS_SIZES:
        raise ValueError(f"obs must have shape (n, k): rows of {_SHAPES}, got shape {arr.shape}")
    bad = ~np.isfinite(arr).all(axis=1)
    if bad.any():
        raise ValueError(f"obs of lanes {np.flatnonzero(bad).tolist()} must be finite")
    return arr


def make_action(
    v_mps: float, w_radps: float, v_max_mps: float | None, w_max_radps: float | None
) -> np.ndarray:
    """Pack ``(v, w)`` into a float32 action, clipping each to ``±limit`` when a limit is set.

    :param v_mps: forward speed [m/s].
    :param w_radps: yaw rate [rad/s], counter-clockwise positive.
    :param v_max_mps: symmetric speed limit [m/s], or None for no clip.
    :param w_max_radps: symmetric yaw-rate limit [rad/s], or None for no clip.
    """
    if v_max_mps is not None:
        v_mps = min(max(v_mps, -v_max_mps), v_max_mps)
    if w_max_radps is not None:
        w_radps = min(max(w_radps, -w_max_radps), w_max_radps)
    return np.array([v_mps, w_radps], dtype=np.float32)


def check_range(
    owner: object,
    field: str,
    *,
    gt: float | None = None,
    ge: float | None = None,
    optional: bool = False,
) -> None:
    """Raise a ValueError naming ``Class.field``, its value and the allowed range.

    :param owner: the dataclass instance being validated.
    :param field: the field name.
    :param gt: exclusive lower bound, if any.
    :param ge: inclusive lower bound, if any.
    :param optional: None is also allowed.
    """
    lo = gt if gt is not None else ge
    check_number(
        f"{type(owner).__name__}.{field}",
        getattr(owner, field),
        lo,
        None,
        lo_open=gt is not None,
        optional=optional,
    )


@dataclass(frozen=True, kw_only=True)
class LawParams:
    """Output limits shared by every guidance law.

    :param v_max_mps: clip ``|v|`` to this [m/s]; None (default) leaves it to the env.
    :param w_max_radps: clip ``|w|`` to this [rad/s]; None (default) leaves it to the env.
    """

    v_max_mps: float | None = None
    w_max_radps: float | None = None

    def __post_init__(self) -> None:
        check_range(self, "v_max_mps", gt=0, optional=True)
        check_range(self, "w_max_radps", gt=0, optional=True)


class LaneMemory:
    """Batched acting for a scalar law: :meth:`act` per lane, each lane with its own memory, so
    each lane's actions equal a run of its episode alone (the scalar arithmetic is reused, not
    re-derived in numpy, for bitwise equality). A law with memory overrides :meth:`_memory` and
    :meth:`_set_memory`; its class provides ``act``, ``reset`` and ``action_names``."""

    action_names: tuple[str, ...]
    act: Any  # the law's own: one observation to one action

    def reset(self) -> None:
        """Forget remembered state; a memoryless law has nothing to forget."""

    def _memory(self) -> Any:
        """What the law remembers between steps (restored per lane by ``act_batch``)."""
        return None

    def _set_memory(self, memory: Any) -> None:
        """Restore what :meth:`_memory` returned."""

    def reset_batch(self, n: int) -> None:
        """Start ``n`` lanes' episodes: every lane's memory as after :meth:`reset`."""
        self.reset()
        self._lanes = [self._memory() for _ in range(n)]

    def reset_lanes(self, lanes: np.ndarray) -> None:
        """Start new episodes in the lanes flagged in ``lanes`` (bool, one per lane): their
        memory as after :meth:`reset`, the others' kept."""
        self.reset()
        for i in np.flatnonzero(lanes):
            self._lanes[i] = self._memory()

    def peek(self, obs: np.ndarray, lane: int) -> np.ndarray:
        """The action lane ``lane`` would take on ``obs``, its memory left as it was."""
        self._set_memory(self._lanes[lane])
        return np.asarray(self.act(obs), dtype=np.float32)

    def _act_lanes(self, rows: np.ndarray) -> np.ndarray:
        """Actions ``(n, m)`` float32 for validated observation rows ``(n, k)``."""
        lanes = getattr(self, "_lanes", None)
        if lanes is None or len(lanes) != len(rows):
            raise ValueError(
                f"act_batch got {len(rows)} observations: call reset_batch({len(rows)}) first"
            )
        out = np.empty((len(rows), len(self.action_names)), dtype=np.float32)
        for i, row in enumerate(rows):
            self._set_memory(lanes[i])
            out[i] = self.act(row)
            lanes[i] = self._memory()
        return out


class GuidanceLaw(LaneMemory, ABC):
    """Base of the classical laws: validates the observation, runs the law, clips the output.

    A new law subclasses this, sets ``params`` (a :class:`LawParams` subclass) and ``name``,
    and implements :meth:`_command`; it overrides :meth:`reset` if it keeps memory.
    """

    name: str
    params: LawParams
    action_names: tuple[str, ...] = LAW_ACTION_NAMES

    def act(self, obs: np.ndarray) -> np.ndarray:
        """Map ``[distance_m, offset_px]`` to ``[v_mps, w_radps]``; offset > 0 gives w < 0.

        ``distance_m <= 0`` (no reading yet) gives ``[0, 0]`` and leaves the memory untouched
        (module docstring, "Before the first reading").

        :raises ValueError: if ``obs`` is not a finite array of shape (2,) (or (3,), with the
            reading ahead, which the law ignores). A rejected observation leaves the law's
            memory untouched.
        """
        distance_m, offset_px = validate_obs(obs)
        if distance_m <= NO_READING_M:
            return np.zeros(len(self.action_names), dtype=np.float32)
        command = self._command(distance_m, offset_px)
        vw = make_action(command[0], command[-1], self.params.v_max_mps, self.params.w_max_radps)
        if len(command) == 2:
            return vw
        # [v, vy, w]: the sideways speed between, unclipped (the env bounds it).
        return np.array([vw[0], command[1], vw[1]], dtype=np.float32)

    @abstractmethod
    def _command(self, distance_m: float, offset_px: float) -> tuple[float, ...]:
        """Return ``(v [m/s], w [rad/s, counter-clockwise positive])`` before clipping (a law
        whose ``action_names`` has three entries: ``(v, vy [m/s, left], w)``)."""

    # -- many lanes at once: the same scalar law per lane, each with its own memory ---------

    def act_batch(self, obs: np.ndarray) -> np.ndarray:
        """Actions ``(n, m)`` float32 for observations ``(n, 2)``: :meth:`act` for each lane
        with that lane's memory (:class:`LaneMemory`)."""
        return self._act_lanes(validate_obs_batch(obs))

    def __repr__(self) -> str:
        return f"{type(self).__name__}(name={self.name!r}, params={self.params!r})"


class OffsetRateLaw(GuidanceLaw):
    """Base of the laws with a derivative term: remembers the previous offset for
    ``rate = (o - o_prev) / dt`` (reference §1.5); the first step after a reset has rate 0."""

    def __init__(self) -> None:
        self._prev_offset_px: float | None = None

    def reset(self) -> None:
        """Forget the previous offset, so the next step's rate is 0."""
        self._prev_offset_px = None

    def _memory(self) -> float | None:
        return self._prev_offset_px

    def _set_memory(self, memory: float | None) -> None:
        self._prev_offset_px = memory

    def _offset_rate(self, offset_px: float, dt_s: float) -> float:
        """The offset's rate (px/s) since the previous step, remembering this offset."""
        prev = offset_px if self._prev_offset_px is None else self._prev_offset_px
        self._prev_offset_px = offset_px
        return (offset_px - prev) / dt_s

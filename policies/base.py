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
from collections.abc import Sized
from dataclasses import dataclass
from typing import Any, Protocol, runtime_checkable

import numpy as np
from numpy.typing import ArrayLike

from follow_env.sim.checks import check_number, real_array
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
    arr = real_obs(obs)
    if arr.ndim != 1 or arr.shape[0] not in OBS_SIZES:
        raise ValueError(f"obs must have shape {_SHAPES}, got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"obs must be finite, got {arr.tolist()}")
    return arr


def real_obs(obs: ArrayLike) -> np.ndarray:
    """``obs`` as float64 if it holds real numbers only: bools, integers, floats, or an object
    array of such numbers (:func:`follow_env.sim.checks.real_array`); ``np.asarray(obs,
    dtype=np.float64)`` alone would parse strings and cut complex numbers to their real part,
    silently. Every policy's check of an observation starts here.

    :raises ValueError: naming the dtype (and an object array's first item that is no number).
    """
    arr = real_array(obs)
    if arr is not None:
        return arr
    try:
        given = np.asarray(obs)
    except (TypeError, ValueError) as e:  # a ragged list
        raise ValueError(f"obs must be real numbers in an array ({e})") from None
    held = ""
    if given.dtype.kind == "O":  # name the first item that is no real number
        odd = [x for x in given.flat if real_array(x) is None][:1]
        if odd:
            held = f" holding {odd[0]!r} ({type(odd[0]).__name__})"
    raise ValueError(f"obs must be real numbers, got dtype {given.dtype}{held}")


def validate_obs_batch(obs: ArrayLike) -> np.ndarray:
    """Check a batch of observations ``(n, k)``, k of :data:`OBS_SIZES`; returns it as float64.

    :raises ValueError: on a wrong shape or a NaN/inf entry (naming the lanes).
    """
    arr = real_obs(obs)
    if arr.ndim != 2 or arr.shape[1] not in OBS_SIZES:
        raise ValueError(f"obs must have shape (n, k): rows of {_SHAPES}, got shape {arr.shape}")
    bad = ~np.isfinite(arr).all(axis=1)
    if bad.any():
        raise ValueError(f"obs of lanes {np.flatnonzero(bad).tolist()} must be finite")
    return arr


def lane_flags(lanes: ArrayLike, n: int | None, pending: np.ndarray | None = None) -> np.ndarray:
    """``lanes`` (a bool per lane, for ``reset_lanes``) checked against the ``n`` lanes of
    ``reset_batch``, added to the lanes already ``pending`` a restart.

    :raises ValueError: before ``reset_batch``, or for flags of another length.
    """
    flags = np.asarray(lanes, dtype=bool)
    if n is None or flags.shape != (n,):
        raise ValueError(
            f"reset_lanes got flags of shape {flags.shape}: call reset_batch(n) first and give "
            "one flag per lane"
        )
    return flags if pending is None else pending | flags


def clip_to(value: np.ndarray, limit: float | None) -> np.ndarray:
    """``value`` clipped to ``±limit`` (float64, elementwise), or as it is when ``limit`` is
    None."""
    return value if limit is None else np.minimum(np.maximum(value, -limit), limit)


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


class LaneActing(ABC):
    """A law that acts for many lanes at once, each lane with its own memory (what
    :class:`~policies.learned.hint.LawHint` drives): ``act`` for one episode, ``reset_batch``
    / ``act_batch`` for ``n``, ``reset_lanes`` to start some lanes' episodes again, ``peek``
    to ask a lane without moving its memory on."""

    action_names: tuple[str, ...]

    @abstractmethod
    def reset_batch(self, n: int) -> None:
        """Start ``n`` lanes' episodes: every lane's memory as after :meth:`reset`."""

    @abstractmethod
    def reset_lanes(self, lanes: np.ndarray) -> None:
        """Start new episodes in the lanes flagged in ``lanes`` (bool, one per lane): their
        memory as after :meth:`reset`, the others' kept."""

    @abstractmethod
    def peek(self, obs: np.ndarray, lane: int) -> np.ndarray:
        """The action lane ``lane`` would take on ``obs``, its memory left as it was."""

    @abstractmethod
    def act_batch(self, obs: np.ndarray) -> np.ndarray:
        """Actions ``(n, m)`` float32 for observations ``(n, k)``, lane by lane as
        :meth:`act` would give each lane's episode alone."""

    def _check_lanes(self, rows: int, lanes: Sized | None) -> None:
        """Refuse ``rows`` observations unless :meth:`reset_batch` started as many ``lanes``."""
        if lanes is None or len(lanes) != rows:
            raise ValueError(f"act_batch got {rows} observations: call reset_batch({rows}) first")


class LaneMemory(LaneActing):
    """Batched acting for a scalar law: :meth:`act` per lane, each lane with its own memory, so
    each lane's actions equal a run of its episode alone (the scalar arithmetic is reused, not
    re-derived in numpy, for bitwise equality). A law with memory overrides :meth:`_memory` and
    :meth:`_set_memory` (its memory an immutable value: tuples, numbers); its class provides
    ``act``, ``reset`` and ``action_names``. The lanes' memory is kept apart from the episode
    :meth:`act` runs: batches and :meth:`peek` leave that episode as it was."""

    act: Any  # the law's own: one observation to one action

    def reset(self) -> None:
        """Forget remembered state; a memoryless law has nothing to forget."""

    def _memory(self) -> Any:
        """What the law remembers between steps (restored per lane by ``act_batch``)."""
        return None

    def _set_memory(self, memory: Any) -> None:
        """Restore what :meth:`_memory` returned."""

    def _fresh_memory(self) -> Any:
        """A new episode's memory, the episode :meth:`act` runs left as it was (the lanes'
        memory is kept apart from it, as :class:`GuidanceLaw`'s is)."""
        episode = self._memory()
        self.reset()
        fresh = self._memory()
        self._set_memory(episode)
        return fresh

    def reset_batch(self, n: int) -> None:
        fresh = self._fresh_memory()  # immutable: every lane may hold the same one
        self._lanes = [fresh] * n

    def reset_lanes(self, lanes: np.ndarray) -> None:
        fresh = self._fresh_memory()
        for i in np.flatnonzero(lanes):
            self._lanes[i] = fresh

    def peek(self, obs: np.ndarray, lane: int) -> np.ndarray:
        episode = self._memory()  # the episode act() runs is not the lane's: kept as it was
        try:
            self._set_memory(self._lanes[lane])
            return np.asarray(self.act(obs), dtype=np.float32)
        finally:
            self._set_memory(episode)

    def _act_lanes(self, rows: np.ndarray) -> np.ndarray:
        """Actions ``(n, m)`` float32 for observation rows ``(n, k)`` already checked whole
        (a bad row found midway would leave the lanes before it moved on)."""
        lanes = getattr(self, "_lanes", None)
        self._check_lanes(len(rows), lanes)
        out = np.empty((len(rows), len(self.action_names)), dtype=np.float32)
        episode = self._memory()  # the episode act() runs, kept apart from the lanes'
        try:
            for i, row in enumerate(rows):
                self._set_memory(lanes[i])
                out[i] = self.act(row)
                lanes[i] = self._memory()
        finally:
            self._set_memory(episode)
        return out


class GuidanceLaw(LaneActing):
    """Base of the classical laws: validates the observation, runs the law, clips the output.

    The law's arithmetic runs on arrays of lanes: :meth:`act` is one lane, :meth:`act_batch`
    all lanes at once through the same numpy code, so a lane's actions are bit-identical
    either way (elementwise IEEE arithmetic does not depend on the array's length). What the
    law remembers is an array with one row per lane (:meth:`_fresh_memory`; a memoryless law's
    rows are empty): one row for the episode :meth:`act` runs, ``n`` for the lanes of
    :meth:`reset_batch`.

    A new law subclasses this, sets ``params`` (a :class:`LawParams` subclass) and ``name``
    (``super().__init__(params, name)``), and implements :meth:`_command` on arrays; a law
    with memory implements :meth:`_fresh_memory` and reads and writes ``self._rows`` (the
    memory of the lanes being computed) in :meth:`_command`.
    """

    name: str
    params: LawParams
    action_names: tuple[str, ...] = LAW_ACTION_NAMES

    def __init__(self, params: LawParams, name: str) -> None:
        self.params = params
        self.name = name
        self._lanes = self._fresh_memory(0)  # the memory of reset_batch's lanes: none yet
        self._rows = self._lanes  # the memory of the lanes _command computes
        self.reset()

    def _fresh_memory(self, n: int) -> np.ndarray:
        """The memory of ``n`` lanes after a reset, one row per lane (memoryless: empty rows)."""
        return np.empty((n, 0))

    def reset(self) -> None:
        """Forget what the episode :meth:`act` runs remembers (a memoryless law: nothing)."""
        self._episode = self._fresh_memory(1)

    def act(self, obs: np.ndarray) -> np.ndarray:
        """Map ``[distance_m, offset_px]`` to ``[v_mps, w_radps]``; offset > 0 gives w < 0.

        ``distance_m <= 0`` (no reading yet) gives ``[0, 0]`` and leaves the memory untouched
        (module docstring, "Before the first reading").

        :raises ValueError: if ``obs`` is not a finite array of shape (2,) (or (3,), with the
            reading ahead, which the law ignores). A rejected observation leaves the law's
            memory untouched.
        """
        return self._act_rows(validate_obs_row(obs)[None, :], self._episode)[0]

    @abstractmethod
    def _command(self, distance_m: np.ndarray, offset_px: np.ndarray) -> tuple[np.ndarray, ...]:
        """Return ``(v [m/s], w [rad/s, counter-clockwise positive])`` before clipping, one
        value per lane of ``distance_m`` (> 0) and ``offset_px`` (float64); a law whose
        ``action_names`` has three entries: ``(v, vy [m/s, left], w)``."""

    def _act_rows(self, rows: np.ndarray, memory: np.ndarray) -> np.ndarray:
        """Actions ``(n, m)`` float32 for validated rows ``(n, k)``, moving ``memory`` (one
        row per lane, updated in place) on for the lanes with a reading."""
        distance_m, offset_px = rows[:, 0], rows[:, 1]
        out = np.zeros((len(rows), len(self.action_names)), dtype=np.float32)
        seen = distance_m > NO_READING_M
        count = int(np.count_nonzero(seen))
        if count == 0:
            return out
        every = count == len(rows)
        # The lanes without a reading keep their memory (module docstring).
        self._rows = memory if every else memory[seen]
        if not every:
            distance_m, offset_px = distance_m[seen], offset_px[seen]
        command = self._command(distance_m, offset_px)
        if not every:
            memory[seen] = self._rows
        # Clipped in float64, rounded once to float32; [v, vy, w]: the sideways speed between,
        # unclipped (the env bounds it).
        acts = out if every else np.empty((count, out.shape[1]), dtype=np.float32)
        acts[:, 0] = clip_to(command[0], self.params.v_max_mps)
        acts[:, -1] = clip_to(command[-1], self.params.w_max_radps)
        if len(command) == 3:
            acts[:, 1] = command[1]
        if not every:
            out[seen] = acts
        return out

    # -- many lanes at once ----------------------------------------------------------------

    def reset_batch(self, n: int) -> None:
        self._lanes = self._fresh_memory(n)

    def reset_lanes(self, lanes: np.ndarray) -> None:
        flags = np.asarray(lanes, dtype=bool)
        if flags.any():
            self._lanes[flags] = self._fresh_memory(int(flags.sum()))

    def peek(self, obs: np.ndarray, lane: int) -> np.ndarray:
        row = validate_obs_row(obs)[None, :]
        return self._act_rows(row, self._lanes[lane : lane + 1].copy())[0]

    def act_batch(self, obs: np.ndarray) -> np.ndarray:
        """Actions ``(n, m)`` float32 for observations ``(n, 2)`` (or ``(n, 3)``): each lane
        as :meth:`act` would act on its episode alone, with that lane's memory."""
        rows = validate_obs_batch(obs)
        self._check_lanes(len(rows), self._lanes)
        return self._act_rows(rows, self._lanes)

    def __repr__(self) -> str:
        return f"{type(self).__name__}(name={self.name!r}, params={self.params!r})"


class OffsetRateLaw(GuidanceLaw):
    """Base of the laws with a derivative term: remembers the previous offset for
    ``rate = (o - o_prev) / dt`` (reference §1.5); the first step after a reset has rate 0."""

    def _fresh_memory(self, n: int) -> np.ndarray:
        # The previous offset [px] per lane; NaN: none yet.
        return np.full(n, np.nan)

    def _offset_rate(self, offset_px: np.ndarray, dt_s: float) -> np.ndarray:
        """The offset's rate (px/s) since each lane's previous step, remembering this offset."""
        prev = np.where(np.isnan(self._rows), offset_px, self._rows)
        self._rows[:] = offset_px
        return (offset_px - prev) / dt_s

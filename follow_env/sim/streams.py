"""The one randomness table: every random stream, derived key and allocation of counters.

An episode's ``SeedSequence`` yields one 64-bit key per :class:`Stream`; a draw is a pure
function of ``(key, counter)`` (:mod:`follow_env.sim.rng`). Identical rollouts, our central
promise, need two things: draws never depend on the actions (counters count time, not events
caused by the robot), and no two draws ever read the same ``(key, counter)`` (or one draw would
be a copy of another). This module holds the second promise: every component declares, at
import, the counters it reads (:func:`per_step` and :func:`per_episode`), and an allocation that
overlaps an earlier one raises at once. ``tests/follow_env/sim/test_streams.py`` checks the whole
table after importing everything.

Two counter spaces share a key: uniform draws read counter ``c`` of the key, normal draws read
counters ``2c`` and ``2c + 1`` of the key's *normal domain* (the key xor a constant, see
``rng._NORMAL_DOMAIN``). A :class:`Domain` is a further key derived the same way (``stream key
^ constant``), declared here with its purpose, never as a loose constant in a kernel.

Counters below :data:`EPISODE_COUNTER0` belong to per-step draws (``step * stride + offset``),
counters from it on to draws made once per episode, at reset.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

__all__ = [
    "ALLOCATIONS",
    "EPISODE_COUNTER0",
    "KEYS",
    "MAX_STEPS",
    "N_STREAMS",
    "Allocation",
    "Domain",
    "Stream",
    "check_table",
    "domain",
    "per_episode",
    "per_step",
]

EPISODE_COUNTER0 = 1 << 40
"""First counter of the draws made once per episode (scenario paths, randomisation)."""

MAX_STEPS = 1_000_000
"""The most control steps an episode can have (``EpisodeConfig.max_steps``'s upper bound)."""

Space = Literal["uniform", "normal", "both"]


@dataclass(frozen=True)
class Stream:
    """A root key of every episode: column ``index`` of a lane's keys."""

    name: str
    index: int
    doc: str


@dataclass(frozen=True)
class Domain:
    """A key derived from a stream's key: ``keys[stream.index] ^ constant``."""

    name: str
    stream: Stream
    constant: int
    doc: str


Key = Stream | Domain

PERSON = Stream("person", 0, "the target's path and pace: scenario functions")
DETECTOR = Stream("detector", 1, "detector misses, bursts, box jitter, appearance noise")
DEPTH = Stream("depth", 2, "depth noise and invalid pixels")
MOTOR = Stream("motor", 3, "per-episode motor gain spread")
WORLD = Stream("world", 4, "maps, obstacles and bystanders of a scenario")
RANDOMIZE = Stream("randomize", 5, "domain randomisation and disturbances")
# Streams added later take the next columns: an episode's first keys stay what they were (the
# words of SeedSequence.generate_state do not depend on how many are asked for), so adding one
# changes no earlier draw.
LIGHT = Stream("light", 6, "light sensors on the floor: reading noise, ambient light, gains")
TRACK = Stream("track", 7, "a course on the floor: random tracks and the start pose on them")
STREAMS: tuple[Stream, ...] = (PERSON, DETECTOR, DEPTH, MOTOR, WORLD, RANDOMIZE, LIGHT, TRACK)
N_STREAMS = len(STREAMS)
"""Keys per episode (words drawn from its ``SeedSequence``)."""

KEYS: list[Key] = list(STREAMS)
"""Every key that draws are made from: the streams, then every declared domain."""


@dataclass(frozen=True)
class Allocation:
    """Counters of one key read by one component.

    Per-step draws (``stride`` set) read ``step * stride + offset + j`` for ``j < count``;
    per-episode draws read ``start + j`` (``count=None``: every counter from ``start`` on).
    """

    name: str
    key: Key
    space: Space
    start: int
    count: int | None
    stride: int | None = None
    doc: str = ""

    @property
    def offset(self) -> int:
        """Per-step draws: the first counter within a step's stride."""
        return self.start

    def counters(self) -> tuple[int, float]:
        """The half-open counter range ``[lo, hi)`` this allocation can ever read."""
        if self.stride is not None:
            assert self.count is not None
            return self.start, MAX_STEPS * self.stride + self.start + self.count
        return self.start, float("inf") if self.count is None else self.start + self.count


ALLOCATIONS: list[Allocation] = []
"""Every allocation, in the order the components declared them."""


def domain(name: str, stream: Stream, constant: int, doc: str) -> Domain:
    """Declare a derived key; its constant must differ from every other domain's."""
    for key in KEYS:
        if isinstance(key, Domain) and (key.name == name or key.constant == constant):
            raise ValueError(f"domain {name!r} clashes with domain {key.name!r}")
    d = Domain(name, stream, constant, doc)
    KEYS.append(d)
    return d


def _overlaps(a: Allocation, b: Allocation) -> bool:
    if a.key != b.key or ("both" not in (a.space, b.space) and a.space != b.space):
        return False
    if a.stride is not None and b.stride is not None:
        if a.stride != b.stride:
            return True  # different strides on one key: refused rather than reasoned about
        a_hi, b_hi = a.start + (a.count or 0), b.start + (b.count or 0)
        return a.start < b_hi and b.start < a_hi
    a_lo, a_hi = a.counters()
    b_lo, b_hi = b.counters()
    return a_lo < b_hi and b_lo < a_hi


def _register(alloc: Allocation) -> Allocation:
    for other in ALLOCATIONS:
        if other.name == alloc.name:
            if other == alloc:
                return other  # a module imported twice (e.g. by path): same declaration
            raise ValueError(f"allocation {alloc.name!r} is declared twice")
        if _overlaps(alloc, other):
            raise ValueError(
                f"allocation {alloc.name!r} overlaps {other.name!r} on key {alloc.key.name!r}: "
                "two draws would read the same counter"
            )
    ALLOCATIONS.append(alloc)
    return alloc


def per_step(
    name: str,
    key: Key,
    offset: int,
    count: int,
    *,
    stride: int = 256,
    space: Space = "both",
    doc: str = "",
) -> Allocation:
    """Declare draws made every control step: counters ``step * stride + offset + j``.

    :param name: who draws (``"detector.person"``).
    :param key: the stream or domain.
    :param offset: first counter within the step's stride.
    :param count: counters per step.
    :param stride: counters reserved per step for this key.
    :param space: ``"uniform"``, ``"normal"`` or ``"both"`` (see the module docstring).
    """
    if not (offset >= 0 and offset + count <= stride):
        raise ValueError(
            f"allocation {name!r}: [{offset}, {offset + count}) is not within stride {stride}"
        )
    if stride * (MAX_STEPS + 1) > EPISODE_COUNTER0:
        raise ValueError(f"allocation {name!r}: stride {stride} reaches the per-episode counters")
    return _register(Allocation(name, key, space, offset, count, stride, doc))


def per_episode(
    name: str,
    key: Key,
    offset: int,
    count: int | None,
    *,
    space: Space = "both",
    doc: str = "",
    absolute: bool = False,
) -> Allocation:
    """Declare draws made once per episode: counters ``EPISODE_COUNTER0 + offset + j``
    (``absolute=True``: counters ``offset + j``, for a domain read by nothing else).

    ``count=None`` takes every counter from there on (a scenario function drawing as it goes).
    """
    start = offset if absolute else EPISODE_COUNTER0 + offset
    return _register(Allocation(name, key, space, start, count, None, doc))


def check_table() -> None:
    """Re-check every pair of allocations (the test calls it after importing everything)."""
    for i, a in enumerate(ALLOCATIONS):
        for b in ALLOCATIONS[i + 1 :]:
            if _overlaps(a, b):
                raise AssertionError(f"allocations {a.name!r} and {b.name!r} overlap")

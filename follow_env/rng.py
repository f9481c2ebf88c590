"""Counter-based random numbers, keyed by per-episode ``SeedSequence`` streams.

Every random draw of an episode is a pure function of ``(stream key, counter)``: the key comes
from the episode's ``numpy.random.SeedSequence`` (one key per stream: person path, detector,
depth noise, motor variation), the counter from *when* the draw happens (control-step index and
a fixed slot), never from what the robot did. So two policies run on the same seed meet the same
person and the same sensor noise, draw for draw, and a lane of the batched core needs no random
state besides its keys. The generator is SplitMix64's finaliser applied twice (key and counter
mixed separately), the construction behind counter-based generators such as Random123.
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = [
    "N_STREAMS",
    "STREAM_DEPTH",
    "STREAM_DETECTOR",
    "STREAM_MOTOR",
    "STREAM_PERSON",
    "LaneRandom",
    "episode_keys",
    "normal_at",
    "uniform_at",
]

STREAM_PERSON = 0
STREAM_DETECTOR = 1
STREAM_DEPTH = 2
STREAM_MOTOR = 3
STREAM_WORLD = 4  # reserved for world/scenario extras (obstacles, bystanders)
N_STREAMS = 5

_U = np.uint64
_C1 = _U(0xBF58476D1CE4E5B9)
_C2 = _U(0x94D049BB133111EB)
_GOLDEN = _U(0x9E3779B97F4A7C15)
_ONE = _U(1)
_INV_2_53 = 1.0 / 9007199254740992.0
# Normal draws read a key-tweaked copy of the stream, so the same counter gives independent
# uniform and normal draws.
_NORMAL_DOMAIN = _U(0xD1B54A32D192ED03)


@njit(cache=True, inline="always")
def _mix64(z: np.uint64) -> np.uint64:
    z = (z ^ (z >> _U(30))) * _C1
    z = (z ^ (z >> _U(27))) * _C2
    return z ^ (z >> _U(31))


@njit(cache=True, inline="always")
def uniform_at(key: np.uint64, counter: int) -> float:
    """Uniform draw in [0, 1) for ``counter`` of the stream ``key`` (53-bit resolution)."""
    h = _mix64(key ^ _mix64(_U(counter) * _GOLDEN + _ONE))
    return float(h >> _U(11)) * _INV_2_53


@njit(cache=True, inline="always")
def normal_at(key: np.uint64, counter: int) -> float:
    """Standard normal draw for ``counter`` (Box-Muller on two draws of the normal domain)."""
    k = key ^ _NORMAL_DOMAIN
    u1 = 1.0 - uniform_at(k, 2 * counter)  # in (0, 1]: log is finite
    u2 = uniform_at(k, 2 * counter + 1)
    return np.sqrt(-2.0 * np.log(u1)) * np.cos(2.0 * np.pi * u2)


@njit(cache=True)
def _uniform_block(keys: np.ndarray, counter0: int, n: int) -> np.ndarray:
    out = np.empty((keys.shape[0], n))
    for i in range(keys.shape[0]):
        for j in range(n):
            out[i, j] = uniform_at(keys[i], counter0 + j)
    return out


@njit(cache=True)
def _normal_block(keys: np.ndarray, counter0: int, n: int) -> np.ndarray:
    out = np.empty((keys.shape[0], n))
    for i in range(keys.shape[0]):
        for j in range(n):
            out[i, j] = normal_at(keys[i], counter0 + j)
    return out


def episode_keys(seed_seq: np.random.SeedSequence) -> np.ndarray:
    """One 64-bit key per stream for the episode seeded by ``seed_seq``: shape (N_STREAMS,).

    The keys are successive words of the sequence's hashed output (``generate_state``), which
    SeedSequence makes independent of each other; one call per episode keeps resets cheap.
    """
    return seed_seq.generate_state(N_STREAMS, np.uint64)


class LaneRandom:
    """Draws for a batch of lanes, each from its own stream: the numpy face of the generator.

    Scenario functions use it to build paths for many lanes in one vectorised call while every
    lane's draws depend on its own key only. Each call advances a shared counter, so the n-th
    call of a scenario function reads the same numbers for a lane whatever the batch holds.

    :param keys: one key per lane, shape (n,), dtype uint64.
    """

    # Counters below this belong to the per-step draws of the kernel; scenario draws start here.
    _COUNTER0 = 1 << 40

    def __init__(self, keys: np.ndarray) -> None:
        self.keys = np.ascontiguousarray(keys, dtype=np.uint64)
        self._counter = self._COUNTER0

    @property
    def n(self) -> int:
        """Number of lanes."""
        return self.keys.shape[0]

    def reserve(self, count: int) -> int:
        """Reserve ``count`` counters for a compiled helper that draws with
        :func:`uniform_at` / :func:`normal_at` itself; returns the first."""
        c = self._counter
        self._counter += count
        return c

    def uniform(self, *shape: int, low: float = 0.0, high: float = 1.0) -> np.ndarray:
        """Uniform draws in [low, high), shape (n, *shape)."""
        size = int(np.prod(shape)) if shape else 1
        u = _uniform_block(self.keys, self.reserve(size), size)
        return (low + (high - low) * u).reshape((self.n, *shape))

    def normal(self, *shape: int, scale: float = 1.0) -> np.ndarray:
        """Normal draws with standard deviation ``scale``, shape (n, *shape)."""
        size = int(np.prod(shape)) if shape else 1
        z = _normal_block(self.keys, self.reserve(size), size)
        return (scale * z).reshape((self.n, *shape))

"""Counter-based random numbers, keyed by per-episode ``SeedSequence`` streams.

Every random draw of an episode is a pure function of ``(stream key, counter)``: the key comes
from the episode's ``numpy.random.SeedSequence`` (one key per stream, see
:mod:`follow_env.sim.streams`, which also allocates every counter), the counter from *when* the
draw happens (control-step index and a fixed slot), never from what the robot did. So two
policies run on the same seed meet the same person and the same sensor noise, draw for draw, and
a lane of the batched core needs no random state besides its keys. The generator is
SplitMix64's finaliser applied twice (key and counter mixed separately), the construction behind
counter-based generators such as Random123.
"""

from __future__ import annotations

import numpy as np

from follow_env.sim.jit import njit
from follow_env.sim.streams import EPISODE_COUNTER0, N_STREAMS, Allocation

__all__ = ["LaneRandom", "LaneSeeds", "episode_keys", "normal_at", "normal_pair_at", "uniform_at"]

_U = np.uint64
_C1 = _U(0xBF58476D1CE4E5B9)
_C2 = _U(0x94D049BB133111EB)
_GOLDEN = _U(0x9E3779B97F4A7C15)
_ONE = _U(1)
_INV_2_53 = 1.0 / 9007199254740992.0
# Normal draws read a key-tweaked copy of the stream, so the same counter gives independent
# uniform and normal draws.
_NORMAL_DOMAIN = _U(0xD1B54A32D192ED03)


@njit(inline="always")
def _mix64(z: np.uint64) -> np.uint64:
    z = (z ^ (z >> _U(30))) * _C1
    z = (z ^ (z >> _U(27))) * _C2
    return z ^ (z >> _U(31))


@njit(inline="always")
def uniform_at(key: np.uint64, counter: int) -> float:
    """Uniform draw in [0, 1) for ``counter`` of the stream ``key`` (53-bit resolution)."""
    h = _mix64(key ^ _mix64(_U(counter) * _GOLDEN + _ONE))
    return float(h >> _U(11)) * _INV_2_53


@njit(inline="always")
def normal_at(key: np.uint64, counter: int) -> float:
    """Standard normal draw for ``counter`` (Box-Muller on two draws of the normal domain)."""
    k = key ^ _NORMAL_DOMAIN
    u1 = 1.0 - uniform_at(k, 2 * counter)  # in (0, 1]: log is finite
    u2 = uniform_at(k, 2 * counter + 1)
    return np.sqrt(-2.0 * np.log(u1)) * np.cos(2.0 * np.pi * u2)


@njit(inline="always")
def normal_pair_at(key: np.uint64, counter: int) -> tuple[float, float]:
    """Two independent standard normal draws for ``counter`` (both outputs of one Box-Muller
    transform; the first equals :func:`normal_at` of the same counter)."""
    k = key ^ _NORMAL_DOMAIN
    u1 = 1.0 - uniform_at(k, 2 * counter)
    u2 = uniform_at(k, 2 * counter + 1)
    r = np.sqrt(-2.0 * np.log(u1))
    return r * np.cos(2.0 * np.pi * u2), r * np.sin(2.0 * np.pi * u2)


@njit
def _uniform_block(keys: np.ndarray, counter0: int, n: int) -> np.ndarray:
    out = np.empty((keys.shape[0], n))
    for i in range(keys.shape[0]):
        for j in range(n):
            out[i, j] = uniform_at(keys[i], counter0 + j)
    return out


@njit
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
    lane's draws depend on its own key only. Each call advances a shared counter (from
    ``EPISODE_COUNTER0``: the per-step draws of the kernel use the counters below), so the n-th
    call of a scenario function reads the same numbers for a lane whatever the batch holds.
    ``at=`` reads the counters of a declared :class:`~follow_env.sim.streams.Allocation`
    instead, so components that share a stream never depend on each other's draws.

    :param keys: one key per lane, shape (n,), dtype uint64.
    :param start: draw sequentially from this per-episode allocation's first counter on
        (default: from ``EPISODE_COUNTER0``), for a component that shares its stream.
    """

    def __init__(self, keys: np.ndarray, start: Allocation | None = None) -> None:
        self.keys = np.ascontiguousarray(keys, dtype=np.uint64)
        self._counter = EPISODE_COUNTER0 if start is None else start.start

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

    def _first(self, size: int, at: Allocation | None) -> int:
        if at is None:
            return self.reserve(size)
        if at.count is not None and size > at.count:
            raise ValueError(f"{size} draws exceed allocation {at.name!r} ({at.count})")
        return at.start

    def uniform(
        self, *shape: int, low: float = 0.0, high: float = 1.0, at: Allocation | None = None
    ) -> np.ndarray:
        """Uniform draws in [low, high), shape (n, *shape)."""
        size = int(np.prod(shape)) if shape else 1
        u = _uniform_block(self.keys, self._first(size, at), size)
        return (low + (high - low) * u).reshape((self.n, *shape))

    def normal(self, *shape: int, scale: float = 1.0, at: Allocation | None = None) -> np.ndarray:
        """Normal draws with standard deviation ``scale``, shape (n, *shape)."""
        size = int(np.prod(shape)) if shape else 1
        z = _normal_block(self.keys, self._first(size, at), size)
        return (scale * z).reshape((self.n, *shape))


# --- numpy's SeedSequence, compiled --------------------------------------------------------
# Each episode k of a lane seeded with s draws from SeedSequence(s, spawn_key=(k,)), the k-th
# child that SeedSequence(s).spawn() hands out. numpy computes it in about 12 us of mostly
# Python overhead; a vector env of 1024 lanes resets several lanes every step, so the same
# algorithm (O'Neill's seed_seq_fe as numpy implements it: pool of 4 words, hashmix and mix,
# spawn key appended after the entropy padded to the pool) runs here compiled. The tests check
# it word for word against numpy.

_M32 = np.uint64(0xFFFFFFFF)
_INIT_A = np.uint64(0x43B0D7E5)
_MULT_A = np.uint64(0x931E8875)
_INIT_B = np.uint64(0x8B51F9DD)
_MULT_B = np.uint64(0x58F38DED)
_MIX_L = np.uint64(0xCA01F9DD)
_MIX_R = np.uint64(0x4973F715)
_XSHIFT = np.uint64(16)
_POOL = 4
_MAX_WORDS = 8  # seeds below 2**256


@njit(inline="always")
def _hashmix(value: np.uint64, hash_const: np.uint64) -> tuple[np.uint64, np.uint64]:
    value = (value ^ hash_const) & _M32
    hash_const = (hash_const * _MULT_A) & _M32
    value = (value * hash_const) & _M32
    return value ^ (value >> _XSHIFT), hash_const


@njit(inline="always")
def _mix(x: np.uint64, y: np.uint64) -> np.uint64:
    r = ((_MIX_L * x) - (_MIX_R * y)) & _M32
    return r ^ (r >> _XSHIFT)


@njit
def _spawned_keys(
    words: np.ndarray, n_words: np.ndarray, episode: np.ndarray, out: np.ndarray
) -> None:
    """``out[j] = SeedSequence(entropy, spawn_key=(episode[j],)).generate_state(n, uint64)``
    for each lane j, the entropy given as ``n_words[j]`` little-endian 32-bit ``words[j]``."""
    n_out = out.shape[1]
    entropy = np.zeros(_MAX_WORDS + _POOL + 2, dtype=np.uint64)
    pool = np.zeros(_POOL, dtype=np.uint64)
    for j in range(out.shape[0]):
        n = n_words[j]
        for i in range(n):
            entropy[i] = np.uint64(words[j, i])
        # The spawn key follows the entropy padded with zeros to the pool size.
        while n < _POOL:
            entropy[n] = np.uint64(0)
            n += 1
        k = np.uint64(episode[j])
        entropy[n] = k & _M32
        n += 1
        if k > _M32:
            entropy[n] = k >> np.uint64(32)
            n += 1
        hc = _INIT_A
        for i in range(_POOL):
            pool[i], hc = _hashmix(entropy[i] if i < n else np.uint64(0), hc)
        for i_src in range(_POOL):
            for i_dst in range(_POOL):
                if i_src != i_dst:
                    h, hc = _hashmix(pool[i_src], hc)
                    pool[i_dst] = _mix(pool[i_dst], h)
        for i_src in range(_POOL, n):
            for i_dst in range(_POOL):
                h, hc = _hashmix(entropy[i_src], hc)
                pool[i_dst] = _mix(pool[i_dst], h)
        hb = _INIT_B
        for i in range(2 * n_out):
            v = pool[i % _POOL] ^ hb
            hb = (hb * _MULT_B) & _M32
            v = (v * hb) & _M32
            v ^= v >> _XSHIFT
            if i % 2 == 0:
                out[j, i // 2] = v
            else:
                out[j, i // 2] |= v << np.uint64(32)


def _seed_words(seed: int | None) -> list[int]:
    """A seed as numpy's SeedSequence reads it: little-endian 32-bit words (``None`` draws
    fresh OS entropy, as ``SeedSequence()`` does)."""
    entropy = np.random.SeedSequence().entropy if seed is None else seed
    if isinstance(entropy, bool) or not isinstance(entropy, int | np.integer) or entropy < 0:
        raise ValueError(f"seed={seed!r} is out of range: must be a non-negative int or None")
    entropy = int(entropy)
    words = []
    while True:
        words.append(entropy & 0xFFFFFFFF)
        entropy >>= 32
        if entropy == 0:
            break
    if len(words) > _MAX_WORDS:
        raise ValueError(f"seed={seed!r} is out of range: must be below 2**{32 * _MAX_WORDS}")
    return words


class LaneSeeds:
    """The seed streams of N lanes: a root seed per lane and a count of its episodes.

    Episode k of a lane seeded with s uses the keys of ``SeedSequence(s, spawn_key=(k,))``,
    i.e. the k-th child of ``SeedSequence(s).spawn()``: a single env reset with ``seed=s``
    and then reset k more times without a seed, and lane i of a vector env reset with
    ``seed=s - i``, meet the same episode.
    """

    def __init__(self, num_lanes: int) -> None:
        self.words = np.zeros((num_lanes, _MAX_WORDS), dtype=np.uint32)
        self.n_words = np.zeros(num_lanes, dtype=np.int64)  # 0: not seeded yet
        self.episode = np.zeros(num_lanes, dtype=np.int64)

    def seed(self, lanes: np.ndarray, seeds: list[int | None]) -> None:
        """Give ``lanes`` new root seeds (``None``: fresh OS entropy); episodes count anew."""
        for lane, seed in zip(lanes, seeds, strict=True):
            words = _seed_words(seed)
            self.words[lane, : len(words)] = words
            self.n_words[lane] = len(words)
            self.episode[lane] = 0

    def next_keys(self, lanes: np.ndarray) -> np.ndarray:
        """Stream keys (len(lanes), N_STREAMS) of each lane's next episode. Lanes never seeded
        are seeded from OS entropy first."""
        lanes = np.asarray(lanes, dtype=np.int64)
        unseeded = lanes[self.n_words[lanes] == 0]
        if unseeded.size:
            self.seed(unseeded, [None] * unseeded.size)
        keys = np.empty((lanes.size, N_STREAMS), dtype=np.uint64)
        _spawned_keys(self.words[lanes], self.n_words[lanes], self.episode[lanes], keys)
        self.episode[lanes] += 1
        return keys

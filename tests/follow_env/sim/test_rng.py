"""Counter-based random streams keyed by SeedSequence."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from follow_env.sim.rng import (
    LaneRandom,
    LaneSeeds,
    episode_keys,
    normal_at,
    normal_pair_at,
    uniform_at,
)
from follow_env.sim.streams import N_STREAMS


def test_draws_are_pure_functions_of_key_and_counter() -> None:
    key = episode_keys(np.random.SeedSequence(7))[0]
    assert uniform_at(key, 12345) == uniform_at(key, 12345)
    assert normal_at(key, 3) == normal_at(key, 3)
    assert uniform_at(key, 1) != uniform_at(key, 2)


def test_each_episode_stream_gets_its_own_key() -> None:
    keys = episode_keys(np.random.SeedSequence(0))
    assert keys.shape == (N_STREAMS,)
    assert len(set(keys.tolist())) == N_STREAMS
    assert np.array_equal(keys, episode_keys(np.random.SeedSequence(0)))
    assert not np.array_equal(keys, episode_keys(np.random.SeedSequence(1)))


def test_uniform_draws_are_uniform() -> None:
    u = LaneRandom(episode_keys(np.random.SeedSequence(3))[:1]).uniform(20000)[0]
    assert stats.kstest(u, "uniform").pvalue > 1e-3
    assert u.min() >= 0.0
    assert u.max() < 1.0


def test_normal_draws_are_standard_normal_and_independent_of_uniforms() -> None:
    key = episode_keys(np.random.SeedSequence(4))[:1]
    z = LaneRandom(key).normal(20000)[0]
    assert stats.kstest(z, "norm").pvalue > 1e-3
    u = LaneRandom(key).uniform(20000)[0]  # same counters, uniform domain
    assert abs(np.corrcoef(u, z)[0, 1]) < 0.03


def test_a_lane_draws_the_same_numbers_whatever_else_is_in_the_batch() -> None:
    keys = episode_keys(np.random.SeedSequence(5))
    alone = LaneRandom(keys[:1]).uniform(10)
    together = LaneRandom(keys).uniform(10)
    assert np.array_equal(alone[0], together[0])


@pytest.mark.parametrize(
    "seed", [0, 1, 7, 2**32 - 1, 2**32 + 5, 2**64 + 3, 12345678901234567890123]
)
def test_lane_seeds_replay_numpy_seed_sequence_spawn_exactly(seed: int) -> None:
    seeds = LaneSeeds(1)
    seeds.seed(np.zeros(1, dtype=np.int64), [seed])
    root = np.random.SeedSequence(seed)
    for _ in range(4):  # episode k is the k-th spawned child
        expected = root.spawn(1)[0].generate_state(N_STREAMS, np.uint64)
        assert np.array_equal(seeds.next_keys(np.zeros(1, dtype=np.int64))[0], expected)


def test_lane_seeds_handle_large_episode_counts_and_many_lanes() -> None:
    seeds = LaneSeeds(3)
    seeds.seed(np.arange(3), [10, 11, 12])
    seeds.episode[:] = [0, 2**32 + 1, 5]
    keys = seeds.next_keys(np.arange(3))
    for lane, (seed, k) in enumerate([(10, 0), (11, 2**32 + 1), (12, 5)]):
        expected = np.random.SeedSequence(seed, spawn_key=(k,)).generate_state(N_STREAMS, np.uint64)
        assert np.array_equal(keys[lane], expected)


def test_lane_seeds_refuse_bad_seeds() -> None:
    seeds = LaneSeeds(1)
    for bad in (-1, 1.5, "3", 2**256):
        with pytest.raises(ValueError, match="seed="):
            seeds.seed(np.zeros(1, dtype=np.int64), [bad])  # type: ignore[list-item]


def test_normal_pairs_are_independent_standard_normals() -> None:
    key = episode_keys(np.random.SeedSequence(8))[0]
    pairs = np.array([normal_pair_at(key, c) for c in range(20000)])
    assert stats.kstest(pairs[:, 0], "norm").pvalue > 1e-3
    assert stats.kstest(pairs[:, 1], "norm").pvalue > 1e-3
    assert abs(np.corrcoef(pairs[:, 0], pairs[:, 1])[0, 1]) < 0.03
    assert pairs[5, 0] == normal_at(key, 5)

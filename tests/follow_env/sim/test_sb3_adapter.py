"""The SB3 adapter keeps the parts of SB3's ``VecEnv`` contract that ``DummyVecEnv`` over the
single env shows: ``reset_infos``, ``env_method``/``set_attr`` with ``indices``, and the
shape of the actions ``step_async`` takes."""

from __future__ import annotations

import re
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.error import ResetNeeded
from stable_baselines3.common.vec_env import DummyVecEnv

import follow_env
from follow_env import INFO_KEYS

N = 2
KWARGS: dict[str, Any] = {"scenario": "random", "episode__max_steps": 2}


def _pair(**adapter: Any) -> tuple[Any, DummyVecEnv]:
    """The adapter and DummyVecEnv over single envs, both seeded 0 and reset."""
    ours = follow_env.make_sb3_vec_env(N, **adapter, **KWARGS)
    theirs = DummyVecEnv([lambda: gym.make("PersonFollow-v0", **KWARGS) for _ in range(N)])
    for venv in (ours, theirs):
        venv.seed(0)
        venv.reset()
    return ours, theirs


def _assert_same_info(ours: dict[str, Any], theirs: dict[str, Any], keys: Any) -> None:
    assert set(ours) == set(keys)
    for key in keys:
        assert ours[key] == theirs[key], key


# -- reset_infos -----------------------------------------------------------------------------


def test_reset_infos_hold_each_lanes_info_after_reset_and_autoreset() -> None:
    ours, theirs = _pair(full_info=True)
    # They stayed [{}, {}]: DummyVecEnv keeps every env's reset info.
    for i in range(N):
        _assert_same_info(ours.reset_infos[i], theirs.reset_infos[i], INFO_KEYS)
    a = np.full((N, 2), 0.3, np.float32)
    for _ in range(2):  # both lanes end at step 2 and are reset
        ours.step(a)
        theirs.step(a)
    for i in range(N):
        assert ours.reset_infos[i]["step"] == 0
        _assert_same_info(ours.reset_infos[i], theirs.reset_infos[i], INFO_KEYS)


def test_reset_infos_hold_only_the_keys_asked_for_by_default() -> None:
    ours, theirs = _pair()
    assert ours.reset_infos == [{}, {}]  # what the step infos hold of a running lane
    ours.include_info(["true_distance_m"])
    a = np.zeros((N, 2), np.float32)
    for _ in range(2):
        ours.step(a)
        theirs.step(a)
    for i in range(N):
        _assert_same_info(ours.reset_infos[i], theirs.reset_infos[i], ["true_distance_m"])


# -- env_method and set_attr with indices ------------------------------------------------------


def test_env_method_reset_resets_only_the_lanes_of_indices_as_dummy_vec_env_does() -> None:
    ours = follow_env.make_sb3_vec_env(N, full_info=True)
    theirs = DummyVecEnv([lambda: gym.make("PersonFollow-v0") for _ in range(N)])
    a = np.full((N, 2), 0.5, np.float32)
    for venv in (ours, theirs):
        venv.seed(0)
        venv.reset()
        for _ in range(3):
            venv.step(a)
    # It reset every lane: the step counters went [1, 1] where DummyVecEnv's go [1, 4].
    (mine,) = ours.env_method("reset", indices=[0])
    (dummy,) = theirs.env_method("reset", indices=[0])
    np.testing.assert_array_equal(mine[0], dummy[0])  # lane 0's next episode, as env 0's
    _assert_same_info(mine[1], dummy[1], INFO_KEYS)
    steps = [[info["step"] for info in venv.step(a)[3]] for venv in (ours, theirs)]
    assert steps == [[1, 4], [1, 4]]
    # seed= seeds each lane reset, as the single env's reset(seed=...)
    (seeded,) = ours.env_method("reset", indices=1, seed=5)
    np.testing.assert_array_equal(seeded[0], gym.make("PersonFollow-v0").reset(seed=5)[0])
    with pytest.raises(ValueError, match="takes no options"):
        ours.env_method("reset", indices=[0], options={"difficulty": 3})


def test_env_method_reset_of_some_lanes_before_reset_still_needs_the_others() -> None:
    venv = follow_env.make_sb3_vec_env(N)
    a = np.zeros((N, 2), np.float32)
    venv.env_method("reset", indices=[0])
    with pytest.raises(ResetNeeded):
        venv.step(a)
    results = venv.env_method("reset", indices=[1])
    assert len(results) == 1
    obs, *_ = venv.step(a)
    assert obs.shape == (N, 2)


def test_set_attr_and_env_method_refuse_indices_that_leave_a_lane_out() -> None:
    venv = follow_env.make_sb3_vec_env(N)
    # They set or called for every lane, whatever the indices said.
    with pytest.raises(ValueError, match=r"indices=\[0\] is out of range: .*acts on all of them"):
        venv.set_attr("full_info", True, indices=[0])
    assert venv.full_info is False
    with pytest.raises(ValueError, match=r"indices=1 is out of range: .*include_info"):
        venv.env_method("include_info", ["true_distance_m"], indices=1)
    assert venv.info_keys == ()
    with pytest.raises(ValueError, match=r"indices=\[0, 2\] is out of range: must be lanes in"):
        venv.get_attr("full_info", indices=[0, 2])
    # every lane (None, or all of them): set once, called once, a result per index
    venv.set_attr("full_info", True, indices=[1, 0])
    assert venv.get_attr("full_info", indices=[1]) == [True]
    assert venv.env_method("include_info", ["true_distance_m"]) == [None, None]
    assert venv.info_keys == ("true_distance_m",)


# -- the shape of the actions ----------------------------------------------------------------


@pytest.mark.parametrize("shape", [(2, 3), (6,), (1, 6), (3,), (3, 2, 1)])
def test_step_async_takes_only_one_row_per_lane(shape: tuple[int, ...]) -> None:
    venv = follow_env.make_sb3_vec_env(3, scenario="straight")
    venv.reset()
    # A transposed (2, 3) array was reshaped into (3, 2): lanes got each other's entries.
    with pytest.raises(ValueError, match=re.escape(f"shape {shape}: must be (3, 2)")):
        venv.step_async(np.zeros(shape, np.float32))
    venv.step_async([[1.0, 0.0], [0.0, 2.0], [0.5, -0.5]])  # (3, 2) as a list
    np.testing.assert_array_equal(venv._actions, [[1.0, 0.0], [0.0, 2.0], [0.5, -0.5]])
    obs, *_ = venv.step_wait()
    assert obs.shape == (3, 2)

"""``max_episode_steps``: the envs end their episodes themselves (``episode.max_steps``, or
LineTrace's ``episode.max_time_s``), so a Gymnasium ``TimeLimit`` may only cut them shorter. A
longer one is refused, naming the config field that makes episodes longer, rather than
silently truncating at the env's own cap while ``env.spec.max_episode_steps`` says otherwise."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import follow_env
from follow_env.tasks.line_trace.env import make_sb3_vec_env as line_sb3_vec_env

# (env id, its own cap in steps, a longer TimeLimit, the config argument for it, its value)
LONGER = [
    ("PersonFollow-v0", 1000, 1500, "episode__max_steps", 1500),
    ("LineTrace-v0", 3000, 4000, "episode__max_time_s", 80),  # 4000 steps of 0.02 s
]


@pytest.mark.parametrize(("env_id", "cap", "limit", "field", "value"), LONGER)
def test_a_time_limit_past_the_envs_own_cap_is_refused_naming_the_way(
    env_id: str, cap: int, limit: int, field: str, value: int
) -> None:
    env = gym.make(env_id, max_episode_steps=limit)
    assert env.spec is not None
    assert env.spec.max_episode_steps == limit
    # It used to truncate at the env's own cap, cap steps in, without a word.
    message = rf"max_episode_steps={limit} is out of range: must be <= {cap}.*{field}={value}\b"
    with pytest.raises(ValueError, match=message):
        env.reset(seed=0)
    # the way it names works: the env's own cap is then the limit
    longer = gym.make(env_id, max_episode_steps=limit, **{field: value})
    longer.reset(seed=0)
    assert int(longer.unwrapped.sim.base_params["task"]["max_steps"]) == limit


@pytest.mark.parametrize(("env_id", "cap"), [(e, c) for e, c, *_ in LONGER])
def test_a_time_limit_at_or_below_the_cap_works_through_time_limit(env_id: str, cap: int) -> None:
    gym.make(env_id, max_episode_steps=cap).reset(seed=0)  # the same step as the env's own
    env = gym.make(env_id, max_episode_steps=3)
    env.reset(seed=0)
    a = np.zeros(env.action_space.shape, np.float32)
    flags = [env.step(a)[2:4] for _ in range(3)]
    assert flags == [(False, False), (False, False), (False, True)]
    env.reset()  # a later reset is checked again, and passes
    env.close()


def test_a_time_limit_put_on_by_hand_is_checked_too() -> None:
    env = gym.wrappers.TimeLimit(follow_env.PersonFollowEnv(), max_episode_steps=1001)
    with pytest.raises(ValueError, match="max_episode_steps=1001"):
        env.reset(seed=0)
    # and one deeper in the stack, under another wrapper
    env = gym.wrappers.ClipAction(gym.make("PersonFollow-v0", max_episode_steps=1001))
    with pytest.raises(ValueError, match="max_episode_steps=1001"):
        env.reset(seed=0)


def test_the_vector_faces_refuse_a_longer_time_limit() -> None:
    sync = gym.make_vec(
        "PersonFollow-v0", num_envs=2, vectorization_mode="sync", max_episode_steps=1500
    )
    with pytest.raises(ValueError, match=r"episode__max_steps=1500"):
        sync.reset(seed=0)
    # The native vector env and the SB3 adapter have no TimeLimit over their lanes: they refuse
    # any, naming the way (it used to be "unknown config section 'max_episode_steps'").
    message = r"max_episode_steps=500 is out of range: must be None.*episode__max_steps=500\b"
    with pytest.raises(ValueError, match=message):
        gym.make_vec(
            "PersonFollow-v0",
            num_envs=2,
            vectorization_mode="vector_entry_point",
            max_episode_steps=500,
        )
    with pytest.raises(ValueError, match=message):
        follow_env.make_sb3_vec_env(2, max_episode_steps=500)
    with pytest.raises(ValueError, match=r"max_episode_steps=500 .*episode__max_time_s=10\b"):
        line_sb3_vec_env(2, max_episode_steps=500)

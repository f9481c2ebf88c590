"""LineTrace-v0: the env's contract (spaces, checkers, starts, ends, seeding, arguments)."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env as gym_check_env
from stable_baselines3.common.env_checker import check_env as sb3_check_env

import follow_env  # noqa: F401  (registers the envs)
from follow_env.tasks.line_trace.env import LineTraceVectorEnv, make_sb3_vec_env
from follow_env.tasks.line_trace.task import TASK

AHEAD = np.array([0.3, 0.0, 0.0], dtype=np.float32)


def _run(env: gym.Env, actions: list[np.ndarray]) -> list[np.ndarray]:
    out = []
    for a in actions:
        obs, *_ = env.step(a)
        out.append(obs)
    return out


def test_both_platforms_give_their_action_and_25_readings() -> None:
    mecanum = gym.make("LineTrace-v0")
    assert mecanum.observation_space.shape == (25,)
    assert mecanum.observation_space.dtype == np.float32
    assert float(mecanum.observation_space.low.min()) == 0.0
    assert float(mecanum.observation_space.high.max()) == 1.0
    assert mecanum.action_space.shape == (3,)
    assert gym.make("LineTrace-v0", platform="diff_drive").action_space.shape == (2,)


def test_gymnasium_check_env_passes_on_both_platforms() -> None:
    gym_check_env(gym.make("LineTrace-v0", render_mode="rgb_array").unwrapped)
    gym_check_env(gym.make("LineTrace-v0", platform="diff_drive").unwrapped)


def test_sb3_check_env_passes() -> None:
    sb3_check_env(gym.make("LineTrace-v0").unwrapped)


def test_the_start_reads_the_line_under_the_middle_column() -> None:
    env = gym.make("LineTrace-v0", track="straight", config="ideal")
    obs, info = env.reset(seed=0)
    grid = obs.reshape(5, 5)
    assert np.all(grid[:, 2] == 1.0)
    assert np.all(grid[:, [0, 4]] == 0.0)
    assert info["active_cells"] == 5
    assert info["progress_m"] == pytest.approx(0.15)
    assert info["cross_track_m"] == pytest.approx(0.0)
    assert info["line_seen"]
    assert not info["in_gap"]


def test_info_has_every_key_of_the_spec_with_the_platforms_in_place() -> None:
    env = gym.make("LineTrace-v0")
    _, info = env.reset(seed=0)
    keys = TASK.info_keys(env.unwrapped.sim.platform)
    assert tuple(info) == keys
    assert keys.index("duty_fl") < keys.index("progress_m")
    assert keys.index("accel_mps2") < keys.index("wheel_target_fl_mps")


def test_same_seed_and_actions_give_bit_identical_episodes() -> None:
    rng = np.random.default_rng(1)
    actions = [rng.uniform(-0.4, 0.4, 3).astype(np.float32) for _ in range(50)]
    runs = []
    for _ in range(2):
        env = gym.make("LineTrace-v0", track="course")
        env.reset(seed=7)
        runs.append(np.array(_run(env, actions)))
    assert np.array_equal(runs[0], runs[1])


def test_sensor_noise_does_not_depend_on_the_actions() -> None:
    ambient = []
    for action in (AHEAD, np.array([0.0, 0.3, 0.5], np.float32)):
        env = gym.make("LineTrace-v0", track="straight")
        env.reset(seed=3)
        seq = []
        for _ in range(20):
            env.step(action)
            seq.append(float(env.unwrapped.sim.state["task"]["grid"]["ambient_now"][0]))
        ambient.append(seq)
    assert ambient[0] == ambient[1]
    assert len(set(ambient[0])) > 1  # it does flicker


def test_vector_lanes_replay_single_envs() -> None:
    vec = LineTraceVectorEnv(num_envs=3, track="random")
    obs, _ = vec.reset(seed=10)
    singles = [gym.make("LineTrace-v0", track="random") for _ in range(3)]
    first = [env.reset(seed=10 + i)[0] for i, env in enumerate(singles)]
    assert np.array_equal(obs, np.array(first))
    for _ in range(30):
        obs, *_ = vec.step(np.tile(AHEAD, (3, 1)))
        single = [env.step(AHEAD)[0] for env in singles]
        assert np.array_equal(obs, np.array(single))


def test_the_sb3_adapter_steps_lanes() -> None:
    env = make_sb3_vec_env(4, track="straight")
    env.seed(0)
    obs = env.reset()
    assert obs.shape == (4, 25)
    obs, rewards, _dones, infos = env.step(np.tile(AHEAD, (4, 1)))
    assert obs.shape == (4, 25)
    assert rewards.shape == (4,)
    assert len(infos) == 4


def test_driving_off_the_line_loses_it_after_the_timeout() -> None:
    env = gym.make("LineTrace-v0", track="straight", config="ideal")
    env.reset(seed=0)
    sideways = np.array([0.0, 0.35, 0.0], dtype=np.float32)
    for _ in range(500):
        _, reward, terminated, truncated, info = env.step(sideways)
        if terminated or truncated:
            break
    assert terminated
    assert info["termination"] == "lost"
    assert info["lost_s"] > 1.0
    assert reward < -40.0  # the lost penalty


def test_leaving_the_field_terminates() -> None:
    env = gym.make(
        "LineTrace-v0", track="straight", config="ideal", episode={"lost_timeout_s": 60.0}
    )
    env.reset(seed=0)
    for _ in range(2000):
        _, _, terminated, truncated, info = env.step(np.array([0.0, 0.35, 0.0], np.float32))
        if terminated or truncated:
            break
    assert terminated
    assert info["termination"] == "left_field"
    assert info["robot_y_m"] > 0.9  # the field is three tiles wide


def test_reaching_the_end_terminates_with_the_bonus() -> None:
    # The track's end is the goal, paid by the finish bonus: terminated, not truncated (a
    # learner bootstraps past a truncation as past a time limit).
    env = gym.make("LineTrace-v0", track="straight", config="ideal", platform="diff_drive")
    env.reset(seed=0)
    for _ in range(3000):
        _, reward, terminated, truncated, info = env.step(np.array([0.3, 0.0], np.float32))
        if terminated or truncated:
            break
    assert terminated
    assert not truncated
    assert info["termination"] == "track_end"
    assert info["progress_m"] >= info["track_length_m"] - 0.02
    assert reward > 40.0


def test_the_sb3_adapter_does_not_mark_the_tracks_end_as_a_time_limit() -> None:
    venv = make_sb3_vec_env(1, track="straight", config="ideal", platform="diff_drive")
    venv.seed(0)
    venv.reset()
    for _ in range(3000):
        _, reward, done, infos = venv.step(np.array([[0.3, 0.0]], np.float32))
        if done[0]:
            break
    assert infos[0]["termination"] == "track_end"
    assert infos[0]["TimeLimit.truncated"] is False
    assert reward[0] > 40.0


def test_the_time_limit_truncates() -> None:
    env = gym.make("LineTrace-v0", episode__max_time_s=0.5)
    env.reset(seed=0)
    for k in range(100):  # noqa: B007 - k is checked after the loop
        _, _, terminated, truncated, info = env.step(np.zeros(3, np.float32))
        if terminated or truncated:
            break
    assert truncated
    assert info["termination"] == "time_limit"
    assert k == 24


def test_progress_is_rewarded() -> None:
    env = gym.make("LineTrace-v0", track="straight", config="ideal", platform="diff_drive")
    env.reset(seed=0)
    rewards = [env.step(np.array([0.3, 0.0], np.float32))[1] for _ in range(40)]
    still = gym.make("LineTrace-v0", track="straight", config="ideal", platform="diff_drive")
    still.reset(seed=0)
    idle = [still.step(np.zeros(2, np.float32))[1] for _ in range(40)]
    assert sum(rewards[10:]) > sum(idle[10:]) + 10.0


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"track": "nope"}, "TrackConfig.name='nope' is out of range"),
        ({"sensor": {"pitch_m": -1.0}}, "LightGridConfig.pitch_m=-1.0 is out of range"),
        ({"sensor": {"nope": 1}}, "unknown field sensor.nope"),
        ({"platform": "tank"}, "platform='tank' is out of range"),
        ({"config": "thesis"}, "config='thesis' is out of range"),
        (
            {
                "config": {
                    "track": {"name": "straight", "tile_m": 0.1, "gap_m": 0.05},
                    "start": {"distance_m": 0.9},
                }
            },
            "StartConfig.distance_m=0.9 is out of range",
        ),
    ],
)
def test_bad_arguments_raise_value_error_naming_them(kwargs: dict, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        gym.make("LineTrace-v0", **kwargs)

"""PersonFollow-v0: registration, spaces, seeding, episode end, info, checkers."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env as gym_check_env
from stable_baselines3.common.env_checker import check_env as sb3_check_env

import follow_env
from follow_env import INFO_KEYS


def _run(env: gym.Env, actions: np.ndarray, seed: int) -> dict[str, list]:
    obs, info = env.reset(seed=seed)
    log: dict[str, list] = {"obs": [obs], "person": [], "reward": [], "burst": []}
    for a in actions:
        obs, r, te, tr, info = env.step(a)
        log["obs"].append(obs)
        log["reward"].append(r)
        log["person"].append((info["person_x_m"], info["person_y_m"]))
        log["burst"].append(int(env.unwrapped.sim.state["task"]["detector"]["burst"][0, 0]))
        if te or tr:
            break
    return log


def test_both_ids_make_the_env() -> None:
    assert isinstance(gym.make("PersonFollow-v0").unwrapped, follow_env.PersonFollowEnv)
    assert isinstance(gym.make("follow_env:PersonFollow-v0").unwrapped, follow_env.PersonFollowEnv)


def test_spaces_are_float32_boxes_of_shape_2_in_si_units() -> None:
    env = gym.make("PersonFollow-v0")
    assert env.observation_space.shape == (2,)
    assert env.observation_space.dtype == np.float32
    assert env.action_space.shape == (2,)
    assert env.action_space.dtype == np.float32
    cfg = env.unwrapped.config
    assert np.isclose(env.action_space.high[0], cfg.platform.max_speed_mps)
    assert np.isclose(env.action_space.high[1], 2 * cfg.platform.max_wheel_speed_mps / 0.4)
    assert env.observation_space.low[1] == -320
    assert env.observation_space.high[1] == 319


def test_reset_matches_the_thesis_start() -> None:
    env = gym.make("PersonFollow-v0", config="ideal")
    obs, info = env.reset(seed=0)
    assert np.isclose(info["true_distance_m"], 1.0)
    assert np.isclose(info["true_offset_px"], 0.0)
    assert np.isclose(obs[0], 1.0, atol=0.002)
    assert obs[1] == 0.0
    assert info["in_frame"]
    assert info["detected"]


def test_info_carries_every_documented_key() -> None:
    env = gym.make("PersonFollow-v0")
    _, info = env.reset(seed=0)
    assert set(info) == set(INFO_KEYS)
    *_, info = env.step(np.zeros(2, dtype=np.float32))
    assert set(info) == set(INFO_KEYS)


def test_gymnasium_check_env_passes() -> None:
    gym_check_env(gym.make("PersonFollow-v0", render_mode="rgb_array").unwrapped)


def test_sb3_check_env_passes() -> None:
    sb3_check_env(gym.make("PersonFollow-v0").unwrapped)


@pytest.mark.parametrize("bad", [[np.nan, 0.0], [0.0, np.inf]])
def test_a_non_finite_action_raises(bad: list[float]) -> None:
    env = gym.make("PersonFollow-v0")
    env.reset(seed=0)
    with pytest.raises(ValueError, match="action"):
        env.unwrapped.step(np.array(bad, dtype=np.float32))


def test_same_seed_and_actions_give_bit_identical_episodes() -> None:
    actions = np.random.default_rng(1).uniform(-1, 1, (80, 2)).astype(np.float32)
    a = _run(gym.make("PersonFollow-v0", scenario="random"), actions, seed=3)
    b = _run(gym.make("PersonFollow-v0", scenario="random"), actions, seed=3)
    assert np.array_equal(np.array(a["obs"]), np.array(b["obs"]))
    assert a["reward"] == b["reward"]


def test_different_seeds_give_different_noise() -> None:
    actions = np.zeros((30, 2), dtype=np.float32)
    a = _run(gym.make("PersonFollow-v0"), actions, seed=1)
    b = _run(gym.make("PersonFollow-v0"), actions, seed=2)
    assert not np.array_equal(np.array(a["obs"]), np.array(b["obs"]))


def test_person_and_noise_do_not_depend_on_the_actions() -> None:
    rng = np.random.default_rng(0)
    still = np.zeros((120, 2), dtype=np.float32)
    wild = rng.uniform(-0.3, 0.3, (120, 2)).astype(np.float32)
    cfg = {"perception": {"burst_start_prob": 0.2}}
    a = _run(gym.make("PersonFollow-v0", config=cfg, scenario="random"), still, seed=5)
    b = _run(gym.make("PersonFollow-v0", config=cfg, scenario="random"), wild, seed=5)
    n = min(len(a["person"]), len(b["person"]))
    assert n > 20
    assert a["person"][:n] == b["person"][:n]  # the same person path
    assert a["burst"][:n] == b["burst"][:n]  # the same detector occlusion bursts
    assert any(a["burst"][:n])
    assert not np.array_equal(np.array(a["obs"][:n]), np.array(b["obs"][:n]))


def test_reset_without_seed_continues_the_seeded_sequence() -> None:
    env = gym.make("PersonFollow-v0", scenario="random")
    env.reset(seed=11)
    _, second = env.reset()
    env.reset(seed=11)
    _, again = env.reset()
    assert second["robot_x_m"] == again["robot_x_m"]
    _, first = env.reset(seed=11)
    assert first["robot_x_m"] != second["robot_x_m"]


def test_missed_detections_hold_the_observation() -> None:
    env = gym.make("PersonFollow-v0", config="ideal")
    obs0, _ = env.reset(seed=0)
    # From now on the detector misses every frame.
    env.unwrapped.sim.params["task"]["detector"]["miss_p"][0] = 1.0
    for _ in range(10):
        obs, _, te, _, info = env.step(np.array([0.0, 0.5], dtype=np.float32))
        assert not te
        assert not info["detected"]
        assert np.array_equal(obs, obs0)
    assert abs(info["true_offset_px"]) > 50  # the person did move in the image


def test_losing_the_person_for_3_s_terminates() -> None:
    env = gym.make("PersonFollow-v0", config="ideal")
    env.reset(seed=0)
    seen_until = 0.0
    for k in range(200):
        turn = 3.0 if k < 10 else 0.0  # turn about 170 deg away from the person, then wait
        *_, te, tr, info = env.step(np.array([0.0, turn], dtype=np.float32))
        if info["detected"]:
            seen_until = info["time_s"]
        if te or tr:
            break
    assert te
    assert info["termination"] == "lost"
    assert 3.0 < info["time_s"] - seen_until <= 3.1 + 1e-9


def test_driving_into_the_person_is_a_collision() -> None:
    env = gym.make("PersonFollow-v0", config="ideal")
    env.reset(seed=0)
    for _ in range(100):
        *_, te, tr, info = env.step(np.array([1.4, 0.0], dtype=np.float32))
        if te or tr:
            break
    assert te
    assert info["termination"] == "collision_person"
    assert info["person_clearance_m"] < 0.3


def test_the_bystander_clearance_is_inf_alone_and_zero_at_a_bystander_collision() -> None:
    """``bystander_clearance_m``: the footprint to the nearest bystander's body (inf with no
    bystander). Bystanders do not react to the robot, so one walks into a robot standing still
    in ``crowd`` (seed 1, step 71), which ends touching them (clearance <= 0)."""
    env = gym.make("PersonFollow-v0", scenario="straight")
    _, info = env.reset(seed=0)
    assert info["bystander_clearance_m"] == np.inf
    env = gym.make("PersonFollow-v0", scenario="crowd", episode__lost_timeout_s=100.0)
    _, info = env.reset(seed=1)
    seen = [info["bystander_clearance_m"]]
    for _ in range(100):
        *_, te, tr, info = env.step(np.zeros(2, dtype=np.float32))
        seen.append(info["bystander_clearance_m"])
        if te or tr:
            break
    assert np.all(np.isfinite(seen))
    assert len(set(seen)) > 30  # people move: it changes
    assert info["termination"] == "collision_bystander"
    assert info["bystander_clearance_m"] <= 0.0 < min(seen[:-1])


def test_driving_into_a_wall_is_a_collision() -> None:
    env = gym.make("PersonFollow-v0", config="ideal", episode__lost_timeout_s=100.0)
    env.reset(seed=0)
    for _ in range(100):
        *_, te, tr, info = env.step(np.array([-1.4, 0.0], dtype=np.float32))
        if te or tr:
            break
    assert te
    assert info["termination"] == "collision_wall"
    assert info["wall_clearance_m"] <= 0.0


def test_the_walk_ending_truncates_after_the_settle_time() -> None:
    env = gym.make("PersonFollow-v0", config="ideal")
    obs, info = env.reset(seed=0)
    for _ in range(400):
        d, o = float(obs[0]), float(obs[1])
        obs, _, te, tr, info = env.step(np.array([1.5 * (d - 1.0), -0.005 * o], dtype=np.float32))
        if te or tr:
            break
    assert tr
    assert not te
    assert info["termination"] == "walk_over"
    assert 11.0 < info["time_s"] < 16.0


def test_the_step_limit_truncates() -> None:
    env = gym.make("PersonFollow-v0", episode={"max_steps": 5})
    env.reset(seed=0)
    for _k in range(5):
        *_, _te, tr, info = env.step(np.zeros(2, dtype=np.float32))
    assert tr
    assert info["termination"] == "step_limit"
    assert info["step"] == 5


def test_kwargs_map_onto_the_config() -> None:
    env = gym.make(
        "PersonFollow-v0", scenario="curve", perception={"latency_frames": 2}, camera__width_px=320
    )
    cfg = env.unwrapped.config
    assert cfg.scenario.name == "curve"
    assert cfg.perception.latency_frames == 2
    assert cfg.camera.width_px == 320
    assert env.observation_space.high[1] == 159


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"colour": "red"}, "unknown config section 'colour'"),
        ({"perception": {"latency": 1}}, "unknown field perception.latency"),
        ({"scenario": "moonwalk"}, "ScenarioConfig.name='moonwalk'.*'curve'"),
        ({"perception": {"miss_prob": 1.5}}, r"PerceptionConfig.miss_prob=1.5.*\[0, 1\]"),
        ({"config": "fast"}, "config='fast'.*'thesis'"),
        ({"render_mode": "ansi"}, "render_mode='ansi'"),
    ],
)
@pytest.mark.filterwarnings("ignore:.*possible render_modes")
def test_bad_kwargs_raise_value_error_naming_them(kwargs: dict, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        gym.make("PersonFollow-v0", **kwargs)


# -- bad actions (a regression test for each shape that used to slip through) ----------------


@pytest.mark.parametrize(
    "action",
    [
        np.zeros(3, dtype=np.float32),  # an extra value was ignored
        np.zeros(1, dtype=np.float32),
        np.zeros((2, 1), dtype=np.float32),
        0.5,
        None,
        {"v": 0.5, "w": 0.0},
        "fast",
    ],
    ids=["3", "1", "2x1", "scalar", "None", "dict", "str"],
)
def test_an_action_of_the_wrong_shape_raises_naming_both_shapes(action: object) -> None:
    env = gym.make("PersonFollow-v0").unwrapped
    env.reset(seed=0)
    with pytest.raises(ValueError, match=r"\(2,\)"):
        env.step(action)


def test_a_list_action_of_the_right_shape_is_taken() -> None:
    env = gym.make("PersonFollow-v0").unwrapped
    env.reset(seed=0)
    obs, *_ = env.step([0.5, 0.0])
    assert obs.shape == (2,)


def test_the_unwrapped_env_refuses_step_before_reset() -> None:
    env = gym.make("PersonFollow-v0").unwrapped
    with pytest.raises(gym.error.ResetNeeded):
        env.step(np.zeros(2, dtype=np.float32))


@pytest.mark.parametrize(
    "kwargs",
    [{"episode__max_steps": np.int64(3)}, {"camera__vfov_deg": np.float32(40.0)}],
    ids=["int64", "float32"],
)
def test_numpy_scalars_are_taken_as_config_values(kwargs: dict) -> None:
    env = gym.make("PersonFollow-v0", **kwargs).unwrapped
    ((section_field, value),) = kwargs.items()
    section, field = section_field.split("__")
    stored = getattr(getattr(env.config, section), field)
    assert stored == value
    assert type(stored) in (int, float)  # stored as a Python number
    env.reset(seed=0)
    env.step(np.zeros(2, dtype=np.float32))

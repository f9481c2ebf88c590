"""follow_env/tasks/config.py and sim/config.py: how gym.make's keyword arguments, presets and a
named platform combine, the same for every task."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import follow_env  # noqa: F401  (registers the envs)
from follow_env.platforms.diff_drive import DiffDriveConfig
from follow_env.platforms.mecanum import MecanumConfig
from follow_env.platforms.unicycle import UnicycleConfig
from follow_env.tasks.line_trace.config import IDEAL as LINE_IDEAL
from follow_env.tasks.person_follow.config import IDEAL as FOLLOW_IDEAL


def _config(env_id: str, **kwargs: object) -> object:
    env = gym.make(env_id, **kwargs)
    try:
        return env.unwrapped.config  # type: ignore[attr-defined]
    finally:
        env.close()


@pytest.mark.parametrize(
    "platform", ["mecanum", {"name": "mecanum"}, {"name": "mecanum", "drive": {"mode": "pid"}}]
)
def test_naming_the_presets_own_platform_keeps_the_presets_settings_of_it(platform: object) -> None:
    # `ideal` has no motor or floor spread; naming its platform used to bring them back
    cfg = _config("LineTrace-v0", config="ideal", platform=platform)
    assert cfg.platform.motor == LINE_IDEAL.platform.motor
    assert cfg.platform.floor == LINE_IDEAL.platform.floor
    if isinstance(platform, dict) and "drive" in platform:
        assert cfg.platform.drive.mode == "pid"
    same = _config("LineTrace-v0", config={"platform": platform, "sensor": {"noise_std": 0.0}})
    assert same.platform.motor.gain_spread > 0  # the default preset keeps its own spreads


def test_naming_the_presets_platform_in_a_config_mapping_keeps_its_settings_too() -> None:
    cfg = _config("PersonFollow-v0", config=FOLLOW_IDEAL, platform="diff_drive")
    assert cfg.platform == FOLLOW_IDEAL.platform
    assert cfg.platform.motor.gain_spread == 0.0


def test_naming_another_platform_starts_from_that_platforms_defaults() -> None:
    cfg = _config("PersonFollow-v0", config="thesis", platform="mecanum")
    assert cfg.platform == MecanumConfig()
    cfg = _config("LineTrace-v0", config="noisy", platform="diff_drive")
    assert cfg.platform == DiffDriveConfig()
    cfg = _config("PersonFollow-v0", config="ideal", platform="unicycle")
    assert cfg.platform == UnicycleConfig()


def test_a_preset_without_spread_keeps_none_on_another_platform() -> None:
    # `ideal` is "every motor alike"; on another platform it used to take that platform's
    # default spreads (5 % motor gains, 10 % static friction and floor on the mecanum base)
    cfg = _config("PersonFollow-v0", config="ideal", platform="mecanum")
    assert cfg.platform == MecanumConfig().without_spread()
    assert set(cfg.platform.spread().values()) == {0.0}
    assert cfg.platform.motor.start_duty == MecanumConfig().motor.start_duty  # the rest default
    cfg = _config("LineTrace-v0", config="ideal", platform={"name": "diff_drive", "motor": {}})
    assert cfg.platform == DiffDriveConfig().without_spread()
    # a spread given after the platform is named is the user's
    cfg = _config("LineTrace-v0", config="ideal", platform="diff_drive", motor__gain_spread=0.1)
    assert cfg.platform.motor.gain_spread == 0.1


@pytest.mark.parametrize(
    ("env_id", "platform"),
    [(e, p) for e in ("PersonFollow-v0", "LineTrace-v0") for p in ("diff_drive", "mecanum")],
)
def test_ideal_moves_every_seed_alike_on_every_platform(env_id: str, platform: str) -> None:
    # what the spread would change: the same constant action from the same start
    poses = []
    for seed in range(3):
        env = gym.make(env_id, config="ideal", platform=platform)
        _, start = env.reset(seed=seed)
        action = np.full(env.action_space.shape, 0.5, np.float32)
        for _ in range(30):
            _, _, _, _, info = env.step(action)
        poses.append([info["robot_x_m"], info["robot_y_m"], info["robot_theta_rad"]])
        moved = np.hypot(
            info["robot_x_m"] - start["robot_x_m"], info["robot_y_m"] - start["robot_y_m"]
        )
        assert moved > 0.05  # it moved (m)
        env.close()
    np.testing.assert_array_equal(poses[1], poses[0])
    np.testing.assert_array_equal(poses[2], poses[0])


@pytest.mark.parametrize(
    "kwargs",
    [
        {"track__gap_m": 0.1, "track__tile_m": 0.15},
        {"track__tile_m": 0.15, "track__gap_m": 0.1},
        {"motor__start_duty": 60.0, "motor__friction_duty": 50.0},
        {"motor__friction_duty": 50.0, "motor__start_duty": 60.0},
        {"config": {"motor.friction_duty": 50.0, "platform.motor.start_duty": 60.0}},
    ],
)
def test_fields_of_one_section_are_checked_together_in_any_order(kwargs: dict) -> None:
    # each field used to be applied on its own, so a check across fields saw a state in
    # between and refused, naming a field the user had not set
    cfg = _config("LineTrace-v0", **kwargs)
    if "track__tile_m" in kwargs:
        assert (cfg.track.tile_m, cfg.track.gap_m) == (0.15, 0.1)
    else:
        assert (cfg.platform.motor.friction_duty, cfg.platform.motor.start_duty) == (50.0, 60.0)


def test_a_field_given_twice_takes_the_last_and_a_bad_whole_is_still_refused() -> None:
    cfg = _config("LineTrace-v0", config={"track.tile_m": 0.5, "track": {"tile_m": 0.4}})
    assert cfg.track.tile_m == 0.4
    with pytest.raises(ValueError, match=r"MecanumMotorConfig.start_duty=41.0 is out of range"):
        _config("LineTrace-v0", motor__friction_duty=50.0)

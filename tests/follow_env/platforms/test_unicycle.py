"""platforms/unicycle.py: the ideal body does exactly what it is told."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import follow_env  # noqa: F401  (registers the envs)
from follow_env.platforms import available_platforms
from follow_env.platforms.unicycle import UnicycleBody, UnicycleConfig


def test_it_is_registered_and_passes_the_checker() -> None:
    assert "unicycle" in available_platforms()
    env = gym.make("PersonFollow-v0", platform="unicycle")
    check_env(env.unwrapped)
    assert env.action_space.high.tolist() == pytest.approx([1.48, 7.42])


def test_the_body_moves_by_the_commanded_twist() -> None:
    env = gym.make("PersonFollow-v0", platform="unicycle", scenario="straight")
    _, info = env.reset(seed=0)
    x0, y0 = info["robot_x_m"], info["robot_y_m"]
    _, _, _, _, info = env.step(np.array([0.5, 0.0]))
    assert info["robot_x_m"] - x0 == pytest.approx(0.05, abs=1e-12)  # 0.5 m/s for 0.1 s
    assert info["robot_v_mps"] == 0.5
    assert info["encoder_speed_mps"] == 0.5  # its "encoders" are perfect
    assert info["accel_mps2"] == pytest.approx(5.0)  # from rest to 0.5 m/s in one step
    for _ in range(9):  # 9 steps of 0.1 s at 1 rad/s: 0.9 rad
        _, _, _, _, info = env.step(np.array([0.0, 1.0]))
    th = info["robot_theta_rad"]
    assert th == pytest.approx(0.9, abs=1e-9)
    assert info["robot_y_m"] == pytest.approx(y0, abs=1e-9)  # turning in place


def test_it_clips_to_its_bounds_and_checks_its_config() -> None:
    cfg = UnicycleConfig(body=UnicycleBody(max_speed_mps=0.3))
    env = gym.make("PersonFollow-v0", platform=cfg)
    env.reset(seed=1)
    _, _, _, _, info = env.step(np.array([1.0, 0.0]))
    assert info["robot_v_mps"] == 0.3
    with pytest.raises(ValueError, match=r"UnicycleBody\.max_speed_mps=0 is out of range"):
        UnicycleBody(max_speed_mps=0)
    with pytest.raises(ValueError, match="integration_steps"):
        UnicycleBody(integration_steps=0)

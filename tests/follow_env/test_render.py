"""The ``rgb_array`` renderer of PersonFollow-v0 (follow_env/render.py)."""

from __future__ import annotations

from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.wrappers import RecordVideo

import follow_env  # noqa: F401  (registers PersonFollow-v0)

FORWARD = np.array([0.5, 0.0], dtype=np.float32)  # 0.5 m/s straight ahead


@pytest.fixture
def env():
    e = gym.make("PersonFollow-v0", render_mode="rgb_array")
    yield e
    e.close()


def test_render_returns_rgb_uint8_of_constant_shape(env):
    env.reset(seed=0)
    first = env.render()
    assert first.dtype == np.uint8
    assert first.ndim == 3
    assert first.shape[2] == 3
    assert first.flags["C_CONTIGUOUS"]
    for _ in range(5):
        env.step(FORWARD)
        assert env.render().shape == first.shape


def test_frame_changes_as_the_robot_moves(env):
    _, info0 = env.reset(seed=0)
    before = env.render()
    for _ in range(10):
        _, _, _, _, info = env.step(FORWARD)
    after = env.render()
    assert info["robot_x_m"] != info0["robot_x_m"]  # the robot did move
    assert not np.array_equal(before, after)


def test_reset_clears_trails(env):
    env.reset(seed=0)
    start = env.render()
    for _ in range(10):
        env.step(FORWARD)
    env.render()
    env.reset(seed=0)
    # Same seed, same start: only a trail left over from the last episode could differ.
    assert np.array_equal(env.render(), start)


def test_render_without_render_mode_warns_and_returns_none():
    e = gym.make("PersonFollow-v0")
    e.reset(seed=0)
    with pytest.warns(UserWarning, match="without a render_mode"):
        assert e.render() is None
    e.close()


def test_record_video_writes_mp4(tmp_path: Path):
    folder = tmp_path / "videos"  # RecordVideo warns when the folder already exists
    e = RecordVideo(
        gym.make("PersonFollow-v0", render_mode="rgb_array", episode={"max_steps": 15}),
        video_folder=str(folder),
        episode_trigger=lambda _: True,
        disable_logger=True,
    )
    e.reset(seed=0)
    done = False
    while not done:
        _, _, terminated, truncated, _ = e.step(FORWARD)
        done = terminated or truncated
    e.close()
    videos = list(folder.glob("*.mp4"))
    assert len(videos) == 1
    assert videos[0].stat().st_size > 0

"""The renderer of PersonFollow-v0 (follow_env/tasks/person_follow/render*.py)."""

from __future__ import annotations

from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.wrappers import RecordVideo

import follow_env  # noqa: F401  (registers PersonFollow-v0)
from follow_env.tasks.person_follow.render import (
    C_STOLEN,
    FRAME_HEIGHT_PX,
    FRAME_WIDTH_PX,
    SIGHT_CLEAR,
    SIGHT_HIDDEN,
    SIGHT_OUT_OF_VIEW,
    SIGHT_PARTLY,
    sight_state,
)
from follow_env.world.geometry import box_walls, room_walls, wall_loops

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


# -- the realistic world: obstacles, bystanders, occlusion, stolen targets ------------------------


def follow(obs: np.ndarray) -> np.ndarray:
    """A simple follower: keep 1 m and turn towards the published box (SI action)."""
    d, offset = float(obs[0]), float(obs[1])
    return np.array([1.5 * (d - 1.0), -0.005 * offset], dtype=np.float32)


def stolen_pixels(frame: np.ndarray) -> int:
    """How many pixels are (within a few levels) the colour of a stolen target."""
    return int(np.all(np.abs(frame.astype(int) - C_STOLEN) <= 6, axis=-1).sum())


@pytest.mark.parametrize("scenario", ["crossing", "random_world"])
def test_world_scenarios_render_at_the_frame_size(scenario: str):
    e = gym.make("PersonFollow-v0", scenario=scenario, render_mode="rgb_array")
    obs, _ = e.reset(seed=0)
    for _ in range(5):
        obs, *_ = e.step(follow(obs))
    frame = e.render()
    assert frame.shape == (FRAME_HEIGHT_PX, FRAME_WIDTH_PX, 3)
    assert frame.dtype == np.uint8
    e.close()


def test_a_stolen_target_is_drawn_in_red():
    # Under the first-detection rule the crossing bystander, nearer and larger, steals the
    # target (seed 0 does so about 3.7 s in).
    e = gym.make("PersonFollow-v0", scenario="crossing", render_mode="rgb_array")
    obs, info = e.reset(seed=0)
    assert info["detected_person"] == 0
    assert stolen_pixels(e.render()) == 0  # the target is followed: no red marks
    for _ in range(150):
        obs, _, terminated, truncated, info = e.step(follow(obs))
        if info["detected_person"] == 1 or terminated or truncated:
            break
    assert info["detected_person"] == 1, "the bystander never stole the target"
    # The map's ring and "followed: bystander 1" label (a filled red box) at least.
    assert stolen_pixels(e.render()) > 200
    e.close()


def test_sight_state_reads_the_visible_share():
    min_vis = 0.3
    assert sight_state(0.0, 0.0, min_vis) == SIGHT_OUT_OF_VIEW
    assert sight_state(0.0, 0.8, min_vis) == SIGHT_HIDDEN
    assert sight_state(0.8, 0.8, min_vis) == SIGHT_CLEAR  # all of it in the image is in sight
    assert sight_state(0.5, 0.8, min_vis) == SIGHT_PARTLY  # something blocks part of it
    assert sight_state(0.2, 0.2, min_vis) == SIGHT_PARTLY  # too little to detect


def test_wall_loops_finds_closed_outlines_only():
    room = room_walls(10.0, 8.0)
    pillar = box_walls(1.0, 2.0, 0.4, 0.4, 0.3, 3.0)
    partition = np.array([[0.0, -4.0, 0.0, -1.0, 3.0], [0.0, -1.0, 0.0, 0.5, 3.0]])  # open
    walls = np.vstack([room, partition, pillar])
    assert wall_loops(walls) == [(0, 4), (6, 10)]


def test_trails_are_recorded_before_the_first_frame_is_drawn() -> None:
    # Regression: trails used to start at the first render() call, not at the reset.
    env = gym.make("PersonFollow-v0", render_mode="rgb_array").unwrapped
    env.reset(seed=0)
    for _ in range(30):
        env.step(FORWARD)
    env.render()
    assert env._renderer.robot_trail.n == 31  # the reset pose and 30 steps
    assert env._renderer.target_trail.n == 31


def test_human_mode_shows_every_step_in_a_window() -> None:
    env = gym.make("PersonFollow-v0", render_mode="human")
    env.reset(seed=0)
    for _ in range(3):
        env.step(FORWARD)
    assert env.render() is None  # Gymnasium's convention: human mode draws, returns nothing
    window = env.unwrapped._window
    assert window is not None
    assert window._screen.get_size() == (FRAME_WIDTH_PX, FRAME_HEIGHT_PX)
    env.close()
    assert env.unwrapped._window is None


def test_human_mode_without_a_display_says_so(monkeypatch: pytest.MonkeyPatch) -> None:
    import follow_env.sim.window as window

    for name in ("SDL_VIDEODRIVER", "DISPLAY", "WAYLAND_DISPLAY"):
        monkeypatch.delenv(name, raising=False)
    monkeypatch.setattr(window, "_warned_hidden", False)
    env = gym.make("PersonFollow-v0", render_mode="human")
    # As Gymnasium's own envs: pygame draws offscreen, and a warning says nothing is shown
    # (tests/follow_env/sim/test_window.py has the rest).
    with pytest.warns(RuntimeWarning, match="no display was found"):
        env.reset(seed=0)
    assert env.unwrapped._window is not None
    env.close()

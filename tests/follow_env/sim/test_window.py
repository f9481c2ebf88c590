"""``render_mode="human"`` behaves as Gymnasium's own envs do on a machine without a display:
pygame picks its driver (offscreen), the env renders, ``check_env`` passes, and one warning
says nothing is shown; it fails only where pygame's display cannot be set up at all.

``tests/conftest.py`` sets ``SDL_VIDEODRIVER=dummy``; these tests take it (and any display)
away for themselves."""

from __future__ import annotations

import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import follow_env.sim.window as window


@pytest.fixture
def headless(monkeypatch: pytest.MonkeyPatch) -> None:
    """No display and no driver chosen, and the one-time warning not yet given."""
    for name in ("DISPLAY", "WAYLAND_DISPLAY", "SDL_VIDEODRIVER"):
        monkeypatch.delenv(name, raising=False)
    monkeypatch.setattr(window, "_warned_hidden", False, raising=False)


@pytest.mark.usefixtures("headless")
def test_check_env_passes_headless_with_one_warning_that_nothing_is_shown() -> None:
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        for env_id in ("PersonFollow-v0", "LineTrace-v0"):
            # It raised "needs a display" here, where CartPole-v1 passes.
            check_env(gym.make(env_id, render_mode="rgb_array").unwrapped)
    hidden = [w for w in caught if "no display was found" in str(w.message)]
    assert len(hidden) == 1  # once a process, not once a window
    assert "offscreen" in str(hidden[0].message)


@pytest.mark.usefixtures("headless")
def test_a_human_env_steps_headless() -> None:
    env = gym.make("PersonFollow-v0", render_mode="human")
    with pytest.warns(RuntimeWarning, match="no display was found"):
        env.reset(seed=0)
    obs, *_ = env.step(np.zeros(2, np.float32))
    assert env.observation_space.contains(obs)
    env.close()


def test_a_driver_that_cannot_be_set_up_raises_saying_what_to_do(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setenv("SDL_VIDEODRIVER", "no_such_driver")
    env = gym.make("PersonFollow-v0", render_mode="human")
    message = r"could not open a pygame window .*SDL_VIDEODRIVER='no_such_driver'.*rgb_array"
    with pytest.raises(RuntimeError, match=message):
        env.reset(seed=0)


def test_a_driver_chosen_on_purpose_gives_no_warning(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("SDL_VIDEODRIVER", "dummy")
    monkeypatch.setattr(window, "_warned_hidden", False, raising=False)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a warning here fails the test
        shown = window.Window("test", 40, 30)
        shown.show(np.zeros((30, 40, 3), np.uint8), 1000.0)
        shown.close()
    assert not window._warned_hidden

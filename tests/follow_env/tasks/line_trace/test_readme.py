"""The README's line-tracing section: its example runs with every law its comment offers, and
what it says of the ``ideal`` preset holds."""

from __future__ import annotations

import re
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import follow_env  # noqa: F401  (registers the envs)
from follow_env.tasks.line_trace.config import IDEAL
from follow_env.tasks.line_trace.env import LineTraceEnv
from policies import for_platform, make_policy

README = Path(__file__).resolve().parents[4] / "README.md"
SECTION = "## A second task: line tracing (`LineTrace-v0`)"
CHOICE = re.compile(r'make_policy\("([^"]+)"\), actions\)  # or (.*), \.\.\.')


def _example() -> str:
    """The section's first Python example."""
    text = README.read_text(encoding="utf-8")
    section = text[text.index(SECTION) :]
    return re.search(r"```python\n(.*?)```", section, re.S).group(1)  # type: ignore[union-attr]


def _choices() -> list[str]:
    """The law the example makes, and those its comment offers instead."""
    match = CHOICE.search(_example())
    assert match is not None, "the example's law line changed: update CHOICE"
    return [match.group(1), *re.findall(r'"([^"]+)"', match.group(2))]


def test_the_example_offers_the_pid_law() -> None:
    assert "pid" in _choices()[1:]


@pytest.mark.parametrize("law", _choices())
def test_the_line_tracing_example_runs_with_every_law_it_offers(law: str) -> None:
    # "pid" acts in [v, w]: the example used to hand that to the mecanum base's [v, vy, w].
    code = _example()
    first = _choices()[0]
    code = code.replace(f'make_policy("{first}")', f'make_policy("{law}")', 1)
    namespace: dict[str, object] = {}
    exec(compile(code, f"README.md ({law})", "exec"), namespace)
    info = namespace["info"]
    assert isinstance(info, dict)
    assert info["termination"] in ("track_end", "lost", "left_field", "time_limit")
    assert info["progress_m"] > 0.5  # it drove along the line


def _straight(action: list[float], **kwargs: object) -> dict:
    env = gym.make("LineTrace-v0", track="straight", config="ideal", **kwargs)
    env.reset(seed=0)
    for _ in range(50):  # 1 s
        _, _, _, _, info = env.step(np.array(action, np.float32))
    return info


def test_ideal_keeps_the_gear_friction_the_manual_names() -> None:
    # The manual and the README: no wheel starts under 16 % duty (41 of 255), a straight
    # command under 0.24 m/s on the open-loop base.
    base = IDEAL.platform
    start = base.motor.start_duty / base.duty_per_radps * base.body.wheel_radius_m  # m/s
    motor = base.motor
    assert f"{motor.start_duty / motor.max_duty:.0%}".replace("%", " %") in LineTraceEnv.__doc__
    assert f"under {start:.2f} m/s" in LineTraceEnv.__doc__
    assert f"under {start:.2f} m/s" in README.read_text(encoding="utf-8")
    assert _straight([start - 0.01, 0.0, 0.0])["progress_m"] == pytest.approx(0.15, abs=1e-6)
    assert _straight([start + 0.02, 0.0, 0.0])["progress_m"] > 0.2


def test_under_ideal_the_tuned_pid_stands_still_and_runs_with_wheel_pids() -> None:
    for kwargs, moves in (({}, False), ({"drive": {"mode": "pid"}}, True)):
        env = gym.make("LineTrace-v0", track="straight", config="ideal", **kwargs)
        names = [a.name for a in env.unwrapped.sim.platform.actions]
        law = for_platform(make_policy("pid"), names)
        obs, info = env.reset(seed=0)
        law.reset()
        for _ in range(500):  # 10 s
            obs, _, terminated, truncated, info = env.step(law.act(obs))
            if terminated or truncated:
                break
        assert (info["progress_m"] > 1.0) is moves

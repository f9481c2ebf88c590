"""LineTrace-v0's rows in ``make bench``: its speed beside PersonFollow-v0's, in this process.

Each rate is set against a baseline measured the same way just before it (PersonFollow-v0's
native vector env at N = 1024, and CartPole-v1 for the single env), so the ratios hold on any
machine. A LineTrace step is one 0.02 s control period (PersonFollow's is 0.1 s): per simulated
second it takes five steps.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import gymnasium as gym
import numpy as np

__all__ = ["bench_line_trace"]

N = 1024
#: Env-steps per measurement, quick and full (as ``bench/__main__.py``'s vector rows).
BUDGET = {True: 200_000, False: 2_000_000}


def bench_line_trace(
    quick: bool,
    single_env_steps_per_s: Callable[..., float],
    vector_steps_per_s: Callable[[Any, Any, int], float],
) -> list[tuple[str, float, str]]:
    """LineTrace-v0 at N = 1024 (mecanum and differential drive, a fixed and a random track)
    against PersonFollow-v0 at N = 1024, and its single env against CartPole-v1, timed by
    ``make bench``'s own measuring functions (passed in: ``bench/__main__.py``'s)."""

    def _vector(env_id: str, action: np.ndarray, budget: int, **kwargs: object) -> float:
        env = gym.make_vec(env_id, num_envs=N, vectorization_mode="vector_entry_point", **kwargs)
        return vector_steps_per_s(env, np.tile(action, (N, 1)), max(20, budget // N))

    budget = BUDGET[quick]
    follow = np.array([0.5, 0.0], dtype=np.float32)
    ahead = np.array([0.2, 0.0, 0.0], dtype=np.float32)
    person = _vector("PersonFollow-v0", follow, budget)
    person_mecanum = _vector(
        "PersonFollow-v0", np.array([0.5, 0.0, 0.0], np.float32), budget, platform="mecanum"
    )
    rows = [
        ("(p) PersonFollow-v0 N=1024", person, "1.00x (p)"),
        ("PersonFollow-v0 mecanum N=1024", person_mecanum, f"{person_mecanum / person:.2f}x (p)"),
    ]
    for track in ("course", "random"):
        rate = _vector("LineTrace-v0", ahead, budget, track=track)
        rows.append((f"LineTrace-v0 {track} N=1024", rate, f"{rate / person:.2f}x (p)"))
    rate = _vector("LineTrace-v0", ahead[:2], budget, track="course", platform="diff_drive")
    rows.append(("LineTrace-v0 diff_drive N=1024", rate, f"{rate / person:.2f}x (p)"))
    steps = 5_000 if quick else 50_000
    cartpole = single_env_steps_per_s("CartPole-v1", 1, steps)
    single = single_env_steps_per_s("LineTrace-v0", ahead, steps, track="course")
    rows.append(("CartPole-v1 single env (c)", cartpole, "1.00x (c)"))
    rows.append(("LineTrace-v0 single env", single, f"{cartpole / single:.2f}x slower (c)"))
    return rows

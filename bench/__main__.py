"""``make bench``: speed of the simulation against Gymnasium yardsticks, measured in one run.

Every figure is a rate measured in this process, next to a baseline measured the same way in
the same process, so the ratios hold on any machine even when the absolute rates do not.

    python -m bench            # all benchmarks
    python -m bench --quick    # shorter runs (for a smoke test)
"""

from __future__ import annotations

import argparse
import time
import warnings
from collections.abc import Callable

import gymnasium as gym
import numpy as np

import follow_env  # noqa: F401  (registers PersonFollow-v0)


def single_env_steps_per_s(env_id: str, action: object, steps: int, **kwargs: object) -> float:
    """Steps per second of ``gym.make(env_id)`` (with its default wrappers), resets included."""
    env = gym.make(env_id, **kwargs)
    env.reset(seed=0)
    for _ in range(200):  # warm up (compilation, caches)
        _, _, te, tr, _ = env.step(action)
        if te or tr:
            env.reset()
    best = 0.0
    for _ in range(3):  # best of three: the least disturbed by the other core's load
        t0 = time.perf_counter()
        for _ in range(steps):
            _, _, te, tr, _ = env.step(action)
            if te or tr:
                env.reset()
        best = max(best, steps / (time.perf_counter() - t0))
    env.close()
    return best


def bench_single_env(quick: bool) -> list[tuple[str, float, str]]:
    """PersonFollow-v0 against CartPole-v1, single env, default wrappers of ``gym.make``."""
    steps = 5_000 if quick else 50_000
    cartpole = single_env_steps_per_s("CartPole-v1", 1, steps)
    rows = [("CartPole-v1 (baseline)", cartpole, "1.00x")]
    follow = np.array([0.5, 0.0], dtype=np.float32)
    for scenario in ("straight", "curve", "random"):
        rate = single_env_steps_per_s("PersonFollow-v0", follow, steps, scenario=scenario)
        rows.append((f"PersonFollow-v0 {scenario}", rate, f"{cartpole / rate:.2f}x slower"))
    return rows


BENCHMARKS: dict[str, Callable[[bool], list[tuple[str, float, str]]]] = {
    "single env (steps/s)": bench_single_env
}


def main() -> None:
    parser = argparse.ArgumentParser(prog="python -m bench", description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="shorter runs")
    args = parser.parse_args()
    warnings.filterwarnings("ignore")
    for title, fn in BENCHMARKS.items():
        rows = fn(args.quick)
        print(f"\n## {title}\n")
        print(f"| {'what':<34} | {'rate':>14} | {'vs baseline':>16} |")
        print(f"|{'-' * 36}|{'-' * 16}|{'-' * 18}|")
        for name, rate, ratio in rows:
            print(f"| {name:<34} | {rate:>14,.0f} | {ratio:>16} |")
    print()


if __name__ == "__main__":
    main()

"""Compile every (task, platform) pair's simulation kernel ahead of time, several at once.

::

    python -m follow_env.tasks.warm              # one process per core
    python -m follow_env.tasks.warm --workers 1

A task and a platform compose into one compiled kernel, cached per source version
(:mod:`follow_env.sim.jit`): the first env of a pair otherwise compiles it where it is first
made, one to two minutes for PersonFollow's on one core. This compiles every pair the tasks
accept, each in its own process (:mod:`execution`'s local pool), so a machine with two cores
compiles two at a time. ``make test`` runs it before the tests; on a cluster, run it once on
every node (or let the first episodes there compile).
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from collections.abc import Sequence

from execution import Backend, execute

__all__ = ["compile_pair", "main", "pairs"]


def pairs() -> list[tuple[str, str]]:
    """Every (Gymnasium id, platform) pair: each task's ids x every registered platform,
    PersonFollow's first (its kernels take longest, so a pool starts them first)."""
    from follow_env.platforms import available_platforms
    from follow_env.tasks import env_ids

    ids = sorted(env_ids(), key=lambda env_id: not env_id.startswith("PersonFollow"))
    return [(env_id, platform) for env_id in ids for platform in available_platforms()]


def compile_pair(pair: tuple[str, str]) -> tuple[str, str, float, str]:
    """Make the pair's env and step it once (compiling, or loading, its kernel).

    :returns: (env id, platform, seconds, "ready" or why the task does not take the platform).
    """
    import gymnasium as gym
    import numpy as np

    import follow_env  # noqa: F401  (registers the ids)

    env_id, platform = pair
    started = time.perf_counter()
    try:
        env = gym.make(env_id, platform=platform)
    except ValueError as e:  # the task does not run on this platform
        return env_id, platform, 0.0, f"not a pair: {e}"
    env.reset(seed=0)
    env.step(np.zeros(env.action_space.shape, dtype=env.action_space.dtype))
    env.close()
    return env_id, platform, time.perf_counter() - started, "ready"


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m follow_env.tasks.warm``; returns the exit status."""
    parser = argparse.ArgumentParser(
        prog="python -m follow_env.tasks.warm", description=__doc__.split("\n")[0]
    )
    parser.add_argument("--workers", type=int, default=os.cpu_count() or 1, help="processes")
    args = parser.parse_args(argv)
    if not 1 <= args.workers <= 64:
        print(
            f"{parser.prog}: error: --workers {args.workers} is out of range: 1..64",
            file=sys.stderr,
        )
        return 2
    started = time.perf_counter()
    done = execute(compile_pair, pairs(), Backend("local", workers=args.workers))
    for env_id, platform, seconds, status in done:
        print(f"{env_id:16s} {platform:11s} {seconds:6.1f} s  {status}")
    ready = sum(status == "ready" for *_, status in done)
    print(
        f"{ready} kernels ready in {time.perf_counter() - started:.0f} s ({args.workers} processes)"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())

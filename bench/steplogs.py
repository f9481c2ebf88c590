"""The step logs' row in ``make bench``: ``write_step_log`` against pandas' ``to_csv`` writing
the same bytes, in this process.

``follow-eval run`` writes one log per episode after the episodes, in the command's own process,
so the writer's speed is part of every evaluation's tail. The logs are simulated episodes of
every scenario, one law and the shipped agent.
"""

from __future__ import annotations

import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import pandas as pd

from eval.rollout import run_episode
from eval.steplog import FLOAT_FORMAT, write_step_log
from follow_env.tasks import get_task

__all__ = ["bench_steplogs"]

POLICIES = ("pn", "ppo_law")
REPEATS = 3
"""Timed passes over the logs per writer; the rows give each writer's fastest."""


def _logs(seeds: int) -> list[pd.DataFrame]:
    scenarios = get_task("person_follow").variants()
    return [
        run_episode(policy, scenario, seed).log
        for policy in POLICIES
        for scenario in scenarios
        for seed in range(seeds)
    ]


def bench_steplogs(quick: bool) -> list[tuple[str, float, str]]:
    """Rows ``(what, logs/s, ratio to pandas)``: each writer's fastest of :data:`REPEATS`
    passes; the two writers must give the same bytes."""
    logs = _logs(1 if quick else 4)
    with tempfile.TemporaryDirectory() as folder:
        ours, theirs = Path(folder) / "ours.csv", Path(folder) / "pandas.csv"
        writers: dict[str, Callable[[pd.DataFrame], object]] = {
            "pandas": lambda log: log.to_csv(
                theirs, index=False, float_format=FLOAT_FORMAT, lineterminator="\n"
            ),
            "ours": lambda log: write_step_log(log, ours),
        }
        best = dict.fromkeys(writers, float("inf"))
        for _ in range(REPEATS):  # interleaved, each one's best: a single pass varied by up to 1.5x
            for name, write in writers.items():
                start = time.perf_counter()
                for log in logs:
                    write(log)
                best[name] = min(best[name], time.perf_counter() - start)
        rates = {name: len(logs) / seconds for name, seconds in best.items()}
        for log in logs:  # outside the timing: every log, the same bytes from both
            for write in writers.values():
                write(log)
            if ours.read_bytes() != theirs.read_bytes():
                raise AssertionError("write_step_log and to_csv wrote different bytes")
    return [
        (
            f"write_step_log, {len(logs)} logs",
            rates["ours"],
            f"{rates['ours'] / rates['pandas']:.1f}x",
        ),
        ("  pandas to_csv, the same bytes", rates["pandas"], "1x (baseline)"),
    ]

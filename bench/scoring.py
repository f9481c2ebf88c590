"""A run's scoring in ``make bench``: :func:`eval.scoring.score` on a pool of two processes
against this process alone, the same episodes, in this process.

After its episodes ``follow-eval run`` writes their step logs and computes the episode table,
the bootstrap intervals and the paired comparisons; on a large grid that tail costs about as
much as the episodes. It runs by scenario on the run's backend; the tables must come out equal.
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

import pandas as pd

from eval.metrics import METRICS
from eval.rollout import Episode, rollout
from eval.scoring import Scored, score
from execution.backend import Backend, shutdown_pools
from follow_env.tasks import get_task

__all__ = ["bench_scoring"]

POLICIES = ("pn:thesis", "mpn:thesis", "gsmpn:thesis", "pn:tuned")


def _scored(episodes: list[Episode], workers: int) -> tuple[float, Scored]:
    """Seconds to score ``episodes`` and write their logs on ``workers`` processes."""
    with tempfile.TemporaryDirectory() as folder:
        paths = {id(ep): Path(folder) / f"{k}.csv" for k, ep in enumerate(episodes)}
        start = time.perf_counter()
        scored = score(
            episodes,
            metrics=METRICS,
            log_path=lambda ep: paths[id(ep)],
            backend=Backend(workers=workers),
        )
        return time.perf_counter() - start, scored


def bench_scoring(quick: bool) -> list[tuple[str, float, str]]:
    """Rows ``(what, episodes/s, ratio to one process)``; both must give the same tables."""
    scenarios = get_task("person_follow").variants()
    episodes = rollout(list(POLICIES), scenarios, list(range(5 if quick else 50)))
    alone, serial = _scored(episodes, 1)
    shutdown_pools()  # a new pool: its start is part of the cost
    pooled, parallel = _scored(episodes, 2)
    for name in ("table", "summary", "comparisons"):
        pd.testing.assert_frame_equal(getattr(parallel, name), getattr(serial, name))
    n = len(episodes)
    return [
        (f"scored on 2 processes, {n} episodes", n / pooled, f"{alone / pooled:.2f}x"),
        ("  in this process", n / alone, "1x (baseline)"),
    ]

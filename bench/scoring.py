"""A run's scoring in ``make bench``: :func:`eval.scoring.score` on a pool of two processes
against this process alone, the same episodes, in this process.

After its episodes ``follow-eval run`` writes their step logs and computes the episode table,
the bootstrap intervals and the paired comparisons; on a large grid that tail costs about as
much as the episodes. It runs by scenario on the run's backend; the tables must come out equal.
The intervals alone are timed too, scipy's resamples drawn in batches of
:data:`eval.stats.BOOTSTRAP_BATCH_VALUES` values against all at once (scipy's default), on the
same table, in this process; they must come out equal as well.
"""

from __future__ import annotations

import contextlib
import tempfile
import time
import tracemalloc
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pandas as pd

import eval.stats
from eval.metrics import METRICS
from eval.rollout import Episode, rollout
from eval.scoring import Scored, score
from eval.stats import compare, summarize
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
    batched, at_once = _intervals(serial.table), _intervals(serial.table, batch=None)
    for got, expected in zip(batched[1], at_once[1], strict=True):
        pd.testing.assert_frame_equal(got, expected)
    cell = 2_000 if quick else 10_000  # one cell of a large run (--no-logs)
    (fast, small, got), (slow, large, expected) = _one_interval(cell), _one_interval(cell, None)
    if got != expected:
        raise AssertionError(f"the interval of {cell} values differs in batches: {got} {expected}")
    return [
        (f"scored on 2 processes, {n} episodes", n / pooled, f"{alone / pooled:.2f}x"),
        ("  in this process", n / alone, "1x (baseline)"),
        (f"intervals in batches, {n} episodes", n / batched[0], f"{at_once[0] / batched[0]:.2f}x"),
        ("  all resamples at once (scipy)", n / at_once[0], "1x (baseline)"),
        (f"an interval of {cell:,}, batches (s)", fast, f"{slow / fast:.1f}x faster"),
        ("  all at once (s)", slow, "1x (baseline)"),
        ("  batches, peak memory (MB)", small / 1e6, f"{large / small:.0f}x less"),
        ("  all at once, peak memory (MB)", large / 1e6, "1x (baseline)"),
    ]


def _one_interval(
    n: int, batch: int | None = eval.stats.BOOTSTRAP_BATCH_VALUES
) -> tuple[float, int, tuple[float, float]]:
    """Seconds and peak traced bytes (numpy's buffers included) of the BCa interval of ``n``
    values, resampled in batches of ``batch`` values (None: all at once), and the interval;
    timed untraced."""
    values = np.random.default_rng(0).normal(size=n)
    with _resampling(batch):
        start = time.perf_counter()
        interval = eval.stats.mean_ci(values, 0, "bench")
        seconds = time.perf_counter() - start
        tracemalloc.start()
        try:
            if eval.stats.mean_ci(values, 0, "bench") != interval:
                raise AssertionError("an interval changed between two runs")
            peak = tracemalloc.get_traced_memory()[1]
        finally:
            tracemalloc.stop()
    return seconds, peak, interval


def _intervals(
    table: pd.DataFrame, batch: int | None = eval.stats.BOOTSTRAP_BATCH_VALUES
) -> tuple[float, tuple[pd.DataFrame, pd.DataFrame]]:
    """Seconds of the summary's and comparisons' intervals of ``table``, resampled in batches
    of ``batch`` values (None: all at once), and the two tables."""
    with _resampling(batch):
        start = time.perf_counter()
        tables = summarize(table, metrics=list(METRICS)), compare(table, metrics=list(METRICS))
        return time.perf_counter() - start, tables


@contextlib.contextmanager
def _resampling(batch: int | None) -> Iterator[None]:
    """Inside, :mod:`eval.stats` resamples ``batch`` values a call (None: all at once)."""
    kept = eval.stats.BOOTSTRAP_BATCH_VALUES
    eval.stats.BOOTSTRAP_BATCH_VALUES = batch
    try:
        yield
    finally:
        eval.stats.BOOTSTRAP_BATCH_VALUES = kept

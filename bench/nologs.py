"""A run without step logs in ``make bench``: ``follow-eval run --no-logs`` against the same run
with its step logs, the same grid, in this process.

A run with step logs holds every episode's log until its tables are written, and writes one CSV
per episode; that is what caps it at 50,000 episodes. ``--no-logs`` reduces each episode to its
table row where it ran. Two figures: the wall time of the whole command (both must write the
same tables), and the memory an episode holds once it has run, as a step log or as a row: the
traced bytes (``tracemalloc``, which sees numpy's and pandas' buffers) that a rollout's result
keeps, per episode. The run also keeps the plot seed's episodes whole, one per policy and
scenario, whatever the number of seeds.
"""

from __future__ import annotations

import contextlib
import io
import tempfile
import time
import tracemalloc
from pathlib import Path
from typing import Any

from eval.cli import main
from eval.metrics import METRICS
from eval.rollout import rollout
from eval.stats import TableRow
from follow_env.tasks import get_task

__all__ = ["bench_no_logs"]

LAWS = ("pn:thesis", "mpn:thesis", "gsmpn:thesis")
TABLES = ("summary.csv", "episodes.csv", "comparisons.csv")


def _run(out: Path, seeds: int, logs: bool) -> float:
    """Seconds of one ``follow-eval run`` of :data:`LAWS` on every scenario into ``out`` (one
    process, its output silenced)."""
    scenarios = ",".join(get_task("person_follow").variants())
    args = ["run", "--policies", ",".join(LAWS), "--scenarios", scenarios, "--out", str(out)]
    args += ["--episodes", str(seeds), "--workers", "1", *([] if logs else ["--no-logs"])]
    start = time.perf_counter()
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
        status = main(args)
    if status != 0:
        raise RuntimeError(f"follow-eval {' '.join(args)} exited with {status}")
    return time.perf_counter() - start


def _held(seeds: int, reduce: Any) -> float:
    """Traced bytes per episode that the rollout's result holds: :data:`LAWS`' first on every
    scenario, as episodes with their logs or (``reduce``) as rows."""
    tracemalloc.start()
    try:
        before = tracemalloc.get_traced_memory()[0]
        episodes = rollout(
            LAWS[:1], get_task("person_follow").variants(), range(seeds), workers=1, reduce=reduce
        )
        held = tracemalloc.get_traced_memory()[0] - before
    finally:
        tracemalloc.stop()
    return held / len(episodes)


def bench_no_logs(quick: bool) -> list[tuple[str, float, str]]:
    """Rows: episodes/s of the run with and without logs, and bytes held per episode."""
    seeds = 2 if quick else 10
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        _run(folder / "warm", 1, logs=False)  # imports and compiled kernels
        with_logs = _run(folder / "logs", seeds, logs=True)
        without = _run(folder / "rows", seeds, logs=False)
        for name in TABLES:
            if (folder / "logs" / name).read_bytes() != (folder / "rows" / name).read_bytes():
                raise AssertionError(f"--no-logs wrote another {name}")
    logs, rows = _held(seeds, None), _held(seeds, TableRow(METRICS))
    n = len(LAWS) * len(get_task("person_follow").variants()) * seeds
    return [
        (f"run with logs, {n} episodes (ep/s)", n / with_logs, "1x (baseline)"),
        ("  --no-logs (ep/s)", n / without, f"{with_logs / without:.2f}x faster"),
        ("an episode with its log (bytes)", logs, "1x (baseline)"),
        ("  as its table row (bytes)", rows, f"{logs / rows:.0f}x less"),
    ]

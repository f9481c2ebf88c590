"""Metrics of one line-tracing episode (LineTrace-v0), each one function over its step log.

The columns are those of :mod:`follow_env.tasks.line_trace.steplog`; every metric is from the
simulation's ground truth (the line's centreline):

- ``completion_pct``: how much of the line from the start to its end the robot covered: the
  largest progress reached, as a share of the line's length from the start on (100 when the
  episode ended at the track's end).
- ``lap_time_s``: the time to the track's end; NaN for an episode that did not get there.
- ``cross_track_mean_mm``, ``cross_track_rms_mm``, ``max_deviation_mm``: mean, root mean
  square and largest |cross-track error|, the robot's distance to the line's centre (gaps
  included), over every row, in mm: how accurately the robot traced.
- ``line_lost_count``: times the grid lost the line, i.e. rows where no spot overlaps the line
  (gaps counted as line) after a row where one did.
- ``failed_pct``: 100 when the episode ended with the line lost or the field left, else 0 (over
  episodes a failure rate).
- ``mean_speed_mps``: progress over time, the speed along the line.

They live in their own registry (:data:`LINE_METRICS`, built with :class:`eval.metrics.Metric`)
so that PersonFollow's tables keep exactly their columns; :data:`LINE_TABLES` hands them to
:mod:`eval.report`. A new line metric is one decorated function here.
"""

from __future__ import annotations

from collections.abc import Callable
from types import MappingProxyType

import numpy as np
import pandas as pd

from eval.metrics import Metric
from eval.report import Tables

__all__ = [
    "LINE_HEADLINE_METRICS",
    "LINE_METRICS",
    "LINE_TABLES",
    "LINE_TASK_METRICS",
    "line_episode_metrics",
    "line_metric",
]

_REGISTRY: dict[str, Metric] = {}
FAILURE_ENDINGS = frozenset({"lost", "left_field"})


def line_metric(
    name: str, unit: str, label: str, *, binary: bool = False
) -> Callable[[Callable], Callable]:
    """Register a line-tracing metric function under ``name`` (``binary``: each episode's
    value is 0 or 100, as :class:`~eval.metrics.Metric` says)."""

    def register(fn: Callable[[pd.DataFrame], float]) -> Callable[[pd.DataFrame], float]:
        if name in _REGISTRY:
            raise ValueError(f"line metric {name!r} is already registered")
        _REGISTRY[name] = Metric(name, unit, label, fn, binary=binary)
        return fn

    return register


def _ending(log: pd.DataFrame) -> str | None:
    """The episode's ending (its last non-blank termination; "" for none), or None when the
    log has no termination column (a robot's log: the ending is unknown)."""
    if "termination" not in log:
        return None
    endings = [str(e) for e in log["termination"] if isinstance(e, str) and e]
    return endings[-1] if endings else ""


def _cte_mm(log: pd.DataFrame) -> np.ndarray:
    values = 1000.0 * log["cross_track_m"].to_numpy(dtype=np.float64)
    return values[np.isfinite(values)]


@line_metric("completion_pct", "%", "completion (%)")
def completion_pct(log: pd.DataFrame) -> float:
    """Largest progress from the start, as a share of the line from the start on [%]."""
    if _ending(log) == "track_end":
        return 100.0
    progress = log["progress_m"].to_numpy(dtype=np.float64)
    start = progress[0]
    length = float(log["track_length_m"].iloc[0]) - start
    return float(np.clip(100.0 * (progress.max() - start) / length, 0.0, 100.0))


@line_metric("lap_time_s", "s", "lap time (s)")
def lap_time_s(log: pd.DataFrame) -> float:
    """Time to the track's end [s]; NaN if the episode did not get there."""
    return float(log["time_s"].iloc[-1]) if _ending(log) == "track_end" else float("nan")


@line_metric("cross_track_mean_mm", "mm", "cross-track mean (mm)")
def cross_track_mean_mm(log: pd.DataFrame) -> float:
    """Mean |cross-track error| [mm]."""
    e = _cte_mm(log)
    return float(np.mean(np.abs(e))) if e.size else float("nan")


@line_metric("cross_track_rms_mm", "mm", "cross-track RMS (mm)")
def cross_track_rms_mm(log: pd.DataFrame) -> float:
    """Root mean square of the cross-track error [mm]."""
    e = _cte_mm(log)
    return float(np.sqrt(np.mean(e**2))) if e.size else float("nan")


@line_metric("max_deviation_mm", "mm", "max deviation (mm)")
def max_deviation_mm(log: pd.DataFrame) -> float:
    """Largest |cross-track error| [mm]."""
    e = _cte_mm(log)
    return float(np.max(np.abs(e))) if e.size else float("nan")


@line_metric("line_lost_count", "", "line lost (count)")
def line_lost_count(log: pd.DataFrame) -> float:
    """Times the line was lost: rows without any spot over it after a row with one."""
    seen = log["line_seen"].to_numpy(dtype=np.float64) > 0.5
    return float(np.count_nonzero(seen[:-1] & ~seen[1:]))


@line_metric("failed_pct", "%", "failed (%)", binary=True)
def failed_pct(log: pd.DataFrame) -> float:
    """100 if the episode ended with the line lost or the field left, else 0; NaN when the log
    has no termination column."""
    ending = _ending(log)
    return float("nan") if ending is None else 100.0 * (ending in FAILURE_ENDINGS)


@line_metric("mean_speed_mps", "m/s", "speed along the line (m/s)")
def mean_speed_mps(log: pd.DataFrame) -> float:
    """(final progress - start) / episode time [m/s]."""
    t = float(log["time_s"].iloc[-1])
    progress = log["progress_m"].to_numpy(dtype=np.float64)
    return float((progress[-1] - progress[0]) / t) if t > 0.0 else float("nan")


LINE_METRICS: MappingProxyType[str, Metric] = MappingProxyType(_REGISTRY)
"""Every line-tracing metric by name, in table order."""
#: The six metrics of the task's definition, in its order (the bar chart's).
LINE_TASK_METRICS: tuple[str, ...] = (
    "completion_pct",
    "lap_time_s",
    "cross_track_mean_mm",
    "cross_track_rms_mm",
    "max_deviation_mm",
    "line_lost_count",
)
#: The line-tracing table's leading metrics (the task's, then failures).
LINE_HEADLINE_METRICS: tuple[str, ...] = (*LINE_TASK_METRICS, "failed_pct")
LINE_TABLES = Tables(
    LINE_METRICS,
    LINE_HEADLINE_METRICS,
    "Line tracing (LineTrace-v0, reference §2): completion, lap time, cross-track error, losses",
)
"""LineTrace's tables for :mod:`eval.report`."""


def line_episode_metrics(log: pd.DataFrame) -> dict[str, float]:
    """Every line metric of one step log, by name, in table order."""
    return {name: float(m.fn(log)) for name, m in LINE_METRICS.items()}

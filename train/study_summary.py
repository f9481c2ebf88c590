"""A study's summary: ``seeds.csv``, ``summary.json`` and ``summary.md``.

One row per training seed (its folder, env steps, wall time, env-steps/s, final held-out
return), and across seeds the mean, standard deviation, median and interquartile mean of the
final held-out return, with a bootstrap 95 % CI of the mean (scipy), written atomically by
``follow-train --seeds`` (:mod:`train.seeds`) once every seed has finished.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from follow_env.sim.atomic import atomic_write_text

__all__ = ["SEEDS_CSV", "SUMMARY_JSON", "SUMMARY_MD", "write_summary"]

SEEDS_CSV = "seeds.csv"
SUMMARY_MD = "summary.md"
SUMMARY_JSON = "summary.json"


def write_summary(study: Path, rows: Sequence[dict[str, Any]]) -> pd.DataFrame:
    """``seeds.csv``, ``summary.json`` and ``summary.md`` of a study (atomically); returns the
    one-row summary."""
    table = pd.DataFrame(list(rows))
    returns = table["heldout_return"].to_numpy(dtype=float)
    returns = returns[np.isfinite(returns)]
    summary = {
        "seeds": len(table),
        "heldout_return_mean": _num(returns.mean()) if len(returns) else None,
        "heldout_return_std": _num(returns.std(ddof=1)) if len(returns) > 1 else None,
        "heldout_return_median": _num(np.median(returns)) if len(returns) else None,
        "heldout_return_iqm": _num(_iqm(returns)) if len(returns) else None,
        "heldout_return_mean_ci95": _ci(returns),
        "env_steps_per_s_mean": _num(table["env_steps_per_s"].astype(float).mean()),
    }
    atomic_write_text(study / SEEDS_CSV, table.to_csv(index=False))
    atomic_write_text(study / SUMMARY_JSON, json.dumps(summary, indent=2) + "\n")
    ci = summary["heldout_return_mean_ci95"]
    lines = [
        f"# {study.name}: {summary['seeds']} training seeds",
        "",
        "Final held-out return (the mean over the held-out episodes of the last evaluation), per "
        "seed and across seeds. The interval is a bootstrap 95 % CI of the mean over seeds.",
        "",
        table.to_markdown(index=False),
        "",
        f"- mean {_fmt(summary['heldout_return_mean'])}"
        + (f" [{_fmt(ci[0])}, {_fmt(ci[1])}]" if ci else "")
        + f", std {_fmt(summary['heldout_return_std'])}, median "
        f"{_fmt(summary['heldout_return_median'])}, IQM {_fmt(summary['heldout_return_iqm'])}",
        "",
    ]
    atomic_write_text(study / SUMMARY_MD, "\n".join(lines))
    return pd.DataFrame([summary])


def _num(x: float) -> float | None:
    return None if not np.isfinite(x) else round(float(x), 3)


def _fmt(x: float | None) -> str:
    return "n/a" if x is None else f"{x:.1f}"


def _iqm(x: np.ndarray) -> float:
    """The interquartile mean: the mean of the middle 50 % (scipy's trimmed mean)."""
    from scipy.stats import trim_mean

    return float(trim_mean(x, 0.25))


def _ci(x: np.ndarray) -> list[float] | None:
    if len(x) < 2 or np.ptp(x) == 0.0:
        return None
    from scipy.stats import bootstrap

    res = bootstrap((x,), np.mean, confidence_level=0.95, n_resamples=10_000, random_state=0)
    return [
        round(float(res.confidence_interval.low), 3),
        round(float(res.confidence_interval.high), 3),
    ]

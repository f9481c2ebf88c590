"""Statistics over episodes: means with bootstrap intervals, and paired comparisons.

- :func:`episode_table`: one row per episode (policy, scenario, seed, ending, every metric).
- :func:`summarize`: per policy x scenario cell, the mean of each metric over its episodes and a
  95 % bootstrap confidence interval of that mean (``scipy.stats.bootstrap``, BCa).
- :func:`compare`: per scenario and pair of policies, the paired difference A - B on the same
  seeds (identical rollouts make the pairing valid): its mean, a bootstrap CI, and the Wilcoxon
  signed-rank p-value (``scipy.stats.wilcoxon``, two-sided).

Episodes where a metric is NaN (e.g. ``reacquire_time_s`` when the person was never lost) are
left out of that metric's mean, interval and test; ``<metric>_n`` in the episode counts says how
many were used.

Every interval is drawn from its own random stream, keyed by the bootstrap seed and the cell's
names (policy, scenario, metric; for a comparison both policies, in name order, so A - B and
B - A resample alike), over the cell's episodes in seed order. So an interval depends only on
the episodes it summarises: not on the other cells of the table, nor on the order the episodes
or log files came in (``follow-eval run`` and ``follow-eval metrics`` on its logs print the
same intervals).

Another task's metrics (LineTrace's, :mod:`eval.line_metrics`) are passed as ``metrics=``; its
tables then name their variant column as its logs do (``track`` for ``scenario``).
"""

from __future__ import annotations

import itertools
import warnings
import zlib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd
from scipy import stats

from eval.metrics import METRICS, THESIS_METRICS, Metric, episode_metrics, extra_metrics
from eval.rollout import Episode

__all__ = [
    "CONFIDENCE",
    "EpisodeRow",
    "TableRow",
    "compare",
    "episode_table",
    "mean_ci",
    "metric_columns",
    "summarize",
    "variant_column",
]

#: Confidence level of every interval.
CONFIDENCE = 0.95
#: Bootstrap resamples (scipy's default); 9999 keeps the interval ends stable to ~1 % here.
N_RESAMPLES = 9999
#: Values one vectorised call of the bootstrap's statistic may take (``scipy.stats.bootstrap``'s
#: ``batch`` is this over the sample's size): 2 MB of float64. All at once, scipy holds
#: ``N_RESAMPLES x n`` resampled values and BCa's ``n x (n - 1)`` jackknife, 8.2 GB for a cell
#: of 20,000 episodes; in batches, 0.2 GB. The intervals are the same to the last bit (the
#: resamples are drawn from the stream in the same order; tested), and faster, since a batch
#: stays in the cache: 0.11 s against 0.37 s an interval at 2,000 episodes, 2.1 s against 10.5
#: at 20,000 (measured once, in one process); ``make bench``'s "a run's scoring" rows time an
#: interval of 10,000 both ways.
BOOTSTRAP_BATCH_VALUES: int | None = 2**18
KEY_COLUMNS = ("policy", "scenario")
#: Names a table's variant column may have (PersonFollow's scenario, LineTrace's track).
VARIANT_COLUMNS = ("scenario", "track")


def variant_column(table: pd.DataFrame) -> str:
    """The column of ``table`` naming the grid's variant: ``scenario`` or ``track``."""
    for name in VARIANT_COLUMNS:
        if name in table:
            return name
    return VARIANT_COLUMNS[0]


def metric_columns() -> list[str]:
    """Metric columns in table order: the thesis's five, then the others."""
    return [*THESIS_METRICS, *extra_metrics()]


@dataclass(frozen=True)
class EpisodeRow:
    """An episode reduced to its row of :func:`episode_table`, without its step log: what a run
    without step logs keeps (``follow-eval run --no-logs``, :class:`TableRow`).

    :param policy: the policy's label, as :class:`~eval.rollout.Episode`'s.
    :param scenario: the scenario (the task's variant: LineTrace's track).
    :param seed: the episode's seed.
    :param values: ``steps``, ``termination`` and each metric's value, by column name.
    """

    policy: str
    scenario: str
    seed: int
    values: dict[str, Any]


def _row_values(ep: Episode | EpisodeRow, metrics: Mapping[str, Metric] | None) -> dict[str, Any]:
    """An episode's ``steps``, ``termination`` and metrics (a row's own, if it is one)."""
    if isinstance(ep, EpisodeRow):
        return ep.values
    scores = (
        episode_metrics(ep.log)
        if metrics is None
        else {name: float(m.fn(ep.log)) for name, m in metrics.items()}
    )
    return {"steps": ep.steps, "termination": ep.termination, **scores}


@dataclass(frozen=True)
class TableRow:
    """A rollout's reducer (``rollout(reduce=TableRow(...))``): each episode as its
    :class:`EpisodeRow`, computed in the process that ran it, so that its step log is let go
    there; the episodes of ``keep_seed`` are returned whole (a run's plots draw them).

    :param metrics: the metrics by name, as for :func:`episode_table`.
    :param keep_seed: the seed whose episodes keep their step logs (None: none).
    """

    metrics: Mapping[str, Metric] | None = None
    keep_seed: int | None = None

    def __post_init__(self) -> None:
        if self.metrics is not None:  # a task's metrics are a read-only view, which no pool
            object.__setattr__(self, "metrics", dict(self.metrics))  # can send: a copy

    def __call__(self, ep: Episode) -> Episode | EpisodeRow:
        if ep.seed == self.keep_seed:
            return ep
        return EpisodeRow(ep.policy, ep.scenario, ep.seed, _row_values(ep, self.metrics))


def episode_table(
    episodes: Sequence[Episode | EpisodeRow],
    *,
    metrics: Mapping[str, Metric] | None = None,
    variant: str = "scenario",
) -> pd.DataFrame:
    """One row per episode: ``policy, scenario, seed, steps, termination`` and every metric.

    :param episodes: episodes, or episodes already reduced to their rows (:class:`TableRow`,
        with the same ``metrics``); the table is the same either way.
    :param metrics: the metrics by name, in table order (default: :data:`eval.metrics.METRICS`).
    :param variant: the name of the ``scenario`` column (``"track"`` for LineTrace).
    """
    rows = [
        {"policy": ep.policy, variant: ep.scenario, "seed": ep.seed, **_row_values(ep, metrics)}
        for ep in episodes
    ]
    names = list(METRICS if metrics is None else metrics)
    return pd.DataFrame(rows, columns=["policy", variant, "seed", "steps", "termination", *names])


def _stream(seed: int, *names: str) -> np.random.Generator:
    """The bootstrap stream of one cell: ``seed`` and a stable hash of its names.

    crc32, not ``hash``: Python salts string hashes per process.
    """
    return np.random.default_rng([seed, zlib.crc32("\x1f".join(names).encode("utf-8"))])


def _batch(n: int) -> int | None:
    """Resamples of ``n`` values per vectorised call, :data:`BOOTSTRAP_BATCH_VALUES` values in
    all; None (the constant set to None, as the bench does to compare) is scipy's default, every
    resample at once."""
    if BOOTSTRAP_BATCH_VALUES is None:
        return None
    return max(1, BOOTSTRAP_BATCH_VALUES // max(n, 1))


def _ci(values: np.ndarray, rng: np.random.Generator) -> tuple[float, float]:
    """Bootstrap CI of the mean of ``values`` (NaN-free); degenerate cases handled by hand."""
    if values.size < 2:
        return (np.nan, np.nan)  # one episode gives no interval
    if np.ptp(values) == 0.0:
        return (float(values[0]), float(values[0]))  # every resample has the same mean
    with warnings.catch_warnings():
        # BCa warns and may give NaN when nearly every value is equal (e.g. one collision in
        # twenty); fall back to the percentile interval then.
        warnings.simplefilter("ignore", stats.DegenerateDataWarning)
        res = stats.bootstrap(
            (values,),
            np.mean,
            confidence_level=CONFIDENCE,
            n_resamples=N_RESAMPLES,
            method="BCa",
            random_state=rng,
            batch=_batch(values.size),
        )
        low, high = res.confidence_interval
        if not (np.isfinite(low) and np.isfinite(high)):
            res = stats.bootstrap(
                (values,),
                np.mean,
                confidence_level=CONFIDENCE,
                n_resamples=N_RESAMPLES,
                method="percentile",
                random_state=rng,
                batch=_batch(values.size),
            )
            low, high = res.confidence_interval
    return (float(low), float(high))


def mean_ci(values: np.ndarray, seed: int, *names: str) -> tuple[float, float]:
    """The 95 % bootstrap CI (BCa) of the mean of ``values`` (NaNs dropped), resampled from the
    stream keyed by ``seed`` and ``names`` (as every interval of the tables is); (NaN, NaN) for
    fewer than two values."""
    values = np.asarray(values, dtype=np.float64)
    return _ci(values[np.isfinite(values)], _stream(seed, *names))


def summarize(
    table: pd.DataFrame, *, seed: int = 0, metrics: Sequence[str] | None = None
) -> pd.DataFrame:
    """Mean and 95 % bootstrap CI of every metric per (policy, scenario).

    :param table: an :func:`episode_table`.
    :param seed: seeds the bootstrap resampling, so a report is reproducible.
    :param metrics: the metric columns, in order (default: :func:`metric_columns`).
    :returns: columns ``policy, scenario, episodes``, the metric means in
        :func:`metric_columns` order, then ``<metric>_ci_low`` and ``<metric>_ci_high`` for each
        metric. Rows keep the order the cells first appear in ``table``.
    """
    metrics = [m for m in (metrics or metric_columns()) if m in table]
    variant = variant_column(table)
    rows = []
    for (policy, scenario), cell in table.groupby(["policy", variant], sort=False):
        if "seed" in cell:
            cell = cell.sort_values("seed", kind="stable")
        row: dict[str, object] = {"policy": policy, variant: scenario, "episodes": len(cell)}
        bounds: dict[str, float] = {}
        for m in metrics:
            values = cell[m].to_numpy(dtype=np.float64)
            values = values[np.isfinite(values)]
            row[m] = float(values.mean()) if values.size else np.nan
            rng = _stream(seed, str(policy), str(scenario), m)
            bounds[f"{m}_ci_low"], bounds[f"{m}_ci_high"] = _ci(values, rng)
        rows.append({**row, **bounds})
    columns = ["policy", variant, "episodes", *metrics]
    columns += [f"{m}_ci_{end}" for m in metrics for end in ("low", "high")]
    return pd.DataFrame(rows, columns=columns)


def compare(
    table: pd.DataFrame,
    *,
    metrics: Sequence[str] | None = None,
    seed: int = 0,
    policies: Sequence[str] | None = None,
) -> pd.DataFrame:
    """Paired comparison of every pair of policies per scenario, on the seeds both ran.

    :param table: an :func:`episode_table`.
    :param metrics: the metrics to compare (default: all in :func:`metric_columns` order).
    :param seed: seeds the bootstrap resampling.
    :param policies: the policies' order, which names each pair's A and B (default: the order
        they first appear in ``table``); policies of ``table`` missing here are not compared.
    :returns: one row per (scenario, policy_a, policy_b, metric) with ``n`` (paired seeds with
        both values finite), ``mean_a``, ``mean_b``, ``mean_diff`` (A - B), ``diff_ci_low``,
        ``diff_ci_high`` and ``wilcoxon_p`` (NaN when every difference is 0 or n < 2).
    """
    metrics = [m for m in (metrics or metric_columns()) if m in table]
    variant = variant_column(table)
    if policies is None:
        policies = list(dict.fromkeys(table["policy"]))
    rows = []
    for scenario in dict.fromkeys(table[variant]):
        in_scenario = table[table[variant] == scenario]
        for a, b in itertools.combinations(policies, 2):
            pa = in_scenario[in_scenario["policy"] == a].set_index("seed")
            pb = in_scenario[in_scenario["policy"] == b].set_index("seed")
            seeds = pa.index.intersection(pb.index).sort_values()
            if seeds.empty:
                continue
            for m in metrics:
                va = pa.loc[seeds, m].to_numpy(dtype=np.float64)
                vb = pb.loc[seeds, m].to_numpy(dtype=np.float64)
                ok = np.isfinite(va) & np.isfinite(vb)
                diff = va[ok] - vb[ok]
                low, high = _ci(diff, _stream(seed, str(scenario), *sorted((str(a), str(b))), m))
                rows.append(
                    {
                        variant: scenario,
                        "policy_a": a,
                        "policy_b": b,
                        "metric": m,
                        "n": int(ok.sum()),
                        "mean_a": float(va[ok].mean()) if ok.any() else np.nan,
                        "mean_b": float(vb[ok].mean()) if ok.any() else np.nan,
                        "mean_diff": float(diff.mean()) if diff.size else np.nan,
                        "diff_ci_low": low,
                        "diff_ci_high": high,
                        "wilcoxon_p": _wilcoxon_p(diff),
                    }
                )
    columns = [variant, "policy_a", "policy_b", "metric", "n", "mean_a", "mean_b"]
    columns += ["mean_diff", "diff_ci_low", "diff_ci_high", "wilcoxon_p"]
    return pd.DataFrame(rows, columns=columns)


def _wilcoxon_p(diff: np.ndarray) -> float:
    """Two-sided Wilcoxon signed-rank p-value of paired differences; NaN if undefined."""
    if diff.size < 2 or not np.any(diff != 0.0):
        return np.nan
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # small-sample and tie notices; the p-value stands
        return float(stats.wilcoxon(diff).pvalue)

"""Statistics over episodes: means with bootstrap intervals, and paired comparisons.

- :func:`episode_table`: one row per episode (policy, scenario, seed, ending, every metric).
- :func:`summarize`: per policy x scenario cell, the mean of each metric over its episodes and a
  95 % confidence interval of that mean: ``scipy.stats.bootstrap``'s BCa, or for a rate whose
  every episode is 0 or 100 (a metric registered ``binary``: collisions, losses, success) the
  Wilson score interval of the proportion (``scipy.stats.binomtest``), which does not collapse
  to [0, 0] when no episode had the event.
- :func:`compare`: per scenario and pair of policies, the paired difference A - B on the seeds
  both ran (identical rollouts make the pairing valid): its mean, a bootstrap CI, the Wilcoxon
  signed-rank p-value (``scipy.stats.wilcoxon``, two-sided), the p-value of a paired
  sign-flip permutation test of the mean difference (:func:`paired_test`) and that p adjusted
  by Holm's method over the metric's comparisons (:func:`with_holm`).

**Significance.** A paired difference is significant (:attr:`PairedTest.direction`) when its
95 % bootstrap CI excludes zero *and* the sign-flip permutation test gives p < :data:`ALPHA` on
the same side. The CI alone is not enough: on paired seeds whose differences are mostly about 0
with a few large ones (most seeds play alike, a few diverge), BCa's interval of the mean
excludes zero in 12-31 % of datasets with no true difference, at a nominal 5 %. Flipping the
signs of the differences is exact under the null of a difference symmetric about zero, so the
rule keeps the false-positive rate at or below 5 % there (README, "Evaluation").

Episodes where a metric is NaN (e.g. ``reacquire_time_s`` when the person was never lost) are
left out of that metric's mean, interval and test; ``<metric>_n`` in the summary says how many
were used.

Every interval (and every permutation test) is drawn from its own random stream, keyed by the
bootstrap seed and the cell's names (policy, scenario, metric; for a comparison both policies,
in name order, so A - B and B - A resample alike), over the cell's episodes in seed order. So an
interval depends only on the episodes it summarises: not on the other cells of the table, nor on
the order the episodes or log files came in (``follow-eval run`` and ``follow-eval metrics`` on
its logs print the same intervals).

Another task's metrics (LineTrace's, :mod:`eval.line_metrics`) are passed as ``metrics=``; its
tables then name their variant column as its logs do (``track`` for ``scenario``).
"""

from __future__ import annotations

import itertools
import warnings
import zlib
from collections.abc import Collection, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd
from scipy import stats

from eval.metrics import METRICS, THESIS_METRICS, Metric, episode_metrics, extra_metrics
from eval.rollout import Episode

__all__ = [
    "ALPHA",
    "CONFIDENCE",
    "SMALL_CELL",
    "EpisodeRow",
    "PairedTest",
    "TableRow",
    "binary_metrics",
    "compare",
    "episode_table",
    "error_bars",
    "holm",
    "mean_ci",
    "metric_columns",
    "paired_test",
    "pairing_notes",
    "smallest_p",
    "summarize",
    "variant_column",
    "with_holm",
]

#: Confidence level of every interval.
CONFIDENCE = 0.95
#: Significance level of the paired tests (two-sided): ``1 - CONFIDENCE``.
ALPHA = 0.05
#: A cell with fewer values than this has its interval marked in the reports: a bootstrap
#: interval of a few values covers less than it says (about 80 % at 5 normal values, 89 % at 10).
SMALL_CELL = 10
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
#: Sign flips of the paired permutation test, as many as the bootstrap's resamples; where
#: ``2**n`` is no more, all ``2**n`` are enumerated and the test is exact.
N_SIGN_FLIPS = N_RESAMPLES
#: The name that keys a permutation test's stream beside its cell's names (so that the test
#: draws from a stream of its own, and the bootstrap's intervals stay as they were).
_SIGN_FLIP = "sign-flip"
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
    # A log without a termination column (a robot's) has no known ending: blank in the table,
    # and its ending metrics are NaN.
    ending = ep.termination if "termination" in ep.log else ""
    return {"steps": ep.steps, "termination": ending, **scores}


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


def _wilson(values: np.ndarray) -> tuple[float, float] | None:
    """The 95 % Wilson score interval, in %, of a rate whose values (NaN-free) are each 0 or
    100; None when some value is neither (then the rate is no proportion of episodes)."""
    if values.size < 2:
        return (np.nan, np.nan)  # as for every other metric: one episode gives no interval
    events = values == 100.0
    if not np.all(events | (values == 0.0)):
        return None
    ci = stats.binomtest(int(events.sum()), values.size).proportion_ci(CONFIDENCE, "wilson")
    return (100.0 * float(ci.low), 100.0 * float(ci.high))


def binary_metrics(metrics: Mapping[str, Metric] | None = None) -> frozenset[str]:
    """The names of ``metrics`` (default: :data:`eval.metrics.METRICS`) registered ``binary``:
    each episode's value is 0 or 100, so their mean is a rate of episodes."""
    return frozenset(name for name, m in (METRICS if metrics is None else metrics).items()
                     if m.binary)  # fmt: skip


def _sign_flip_p(diff: np.ndarray, rng: np.random.Generator) -> float:
    """Two-sided p-value of the paired sign-flip permutation test of the mean of ``diff``
    (NaN-free; NaN when empty): the share of sign assignments whose sum is at least as far
    from zero on each side as the observed one, doubled, as ``scipy.stats.permutation_test``
    with ``permutation_type="samples"`` on one sample gives it (tested). All ``2**n``
    assignments when that is at most :data:`N_SIGN_FLIPS` (exact), else that many drawn from
    ``rng`` (with the ``+1`` that keeps a drawn test's p valid), in batches of
    :data:`BOOTSTRAP_BATCH_VALUES` values. scipy's own takes 3.4 s a test at 3,200 pairs
    here, against 15 ms this way (one measurement, this machine).
    """
    n = diff.size
    if n == 0:
        return np.nan
    observed = float(diff.sum())
    # Sums within rounding of the observed one count as ties, on both sides (conservative).
    gamma = 1e-12 * float(np.abs(diff).sum())
    exact = n < 63 and 2**n <= N_SIGN_FLIPS
    draws = 2**n if exact else N_SIGN_FLIPS
    batch = draws if _batch(n) is None else _batch(n)
    at_least = at_most = 0
    for start in range(0, draws, batch):
        k = min(batch, draws - start)
        if exact:  # row i flips the values whose bit is set in i
            flips = (np.arange(start, start + k)[:, None] >> np.arange(n)) & 1
        else:
            # whole 64-bit words a row, so that the flips do not depend on the batch size
            raw = np.frombuffer(rng.bytes(k * 8 * ((n + 63) // 64)), dtype=np.uint8)
            flips = np.unpackbits(raw.reshape(k, -1), axis=1, count=n)
        null = observed - 2.0 * (flips.astype(np.float64) @ diff)
        at_least += int(np.count_nonzero(null >= observed - gamma))
        at_most += int(np.count_nonzero(null <= observed + gamma))
    extra = 0 if exact else 1
    one_sided = (min(at_least, at_most) + extra) / (draws + extra)
    return min(1.0, 2.0 * one_sided)


def smallest_p(n: int) -> float:
    """The smallest p :func:`_sign_flip_p` can give on ``n`` pairs: ``2 / 2**n`` when it is
    exact, ``2 / (N_SIGN_FLIPS + 1)`` when drawn. A family of ``m`` lines adjusted by
    :func:`holm` can hold none of them when ``m`` times this is at least :data:`ALPHA`."""
    exact = n < 63 and 2**n <= N_SIGN_FLIPS
    return 2.0 / 2**n if exact else 2.0 / (N_SIGN_FLIPS + 1)


@dataclass(frozen=True)
class PairedTest:
    """A paired difference's mean, 95 % bootstrap CI and sign-flip permutation p-value.

    :param mean: the mean difference (in the metric's unit; NaN without pairs).
    :param low: the CI's lower end (NaN for fewer than two pairs).
    :param high: the CI's upper end.
    :param p: the two-sided sign-flip permutation p-value (NaN without pairs).
    """

    mean: float
    low: float
    high: float
    p: float

    @property
    def direction(self) -> int:
        """+1 / -1 when the difference is significantly above / below zero (the CI excludes
        zero on that side, and ``p`` < :data:`ALPHA` with the mean on the same side), else 0."""
        if not self.p < ALPHA:
            return 0
        if self.low > 0.0 and self.mean > 0.0:
            return 1
        if self.high < 0.0 and self.mean < 0.0:
            return -1
        return 0


def paired_test(diff: np.ndarray, seed: int, *names: str) -> PairedTest:
    """:class:`PairedTest` of paired differences ``diff`` (NaNs dropped): the CI as
    :func:`mean_ci` gives it (the same stream), the permutation test from a stream keyed by
    ``seed``, the same ``names`` and ``"sign-flip"``. Identical values on every pair give the
    point ``[0, 0]`` and p = 1."""
    diff = np.asarray(diff, dtype=np.float64)
    diff = diff[np.isfinite(diff)]
    low, high = _ci(diff, _stream(seed, *names))
    p = _sign_flip_p(diff, _stream(seed, *names, _SIGN_FLIP))
    return PairedTest(float(diff.mean()) if diff.size else np.nan, low, high, p)


def error_bars(mean: np.ndarray, low: np.ndarray, high: np.ndarray) -> np.ndarray:
    """The ``(2, n)`` distances from each mean down to its interval's low end and up to its
    high end, as matplotlib's ``yerr`` takes them: 0 where an interval is missing (NaN), and 0
    where the mean lies outside its interval. That happens: ``np.mean`` of identical values
    can differ from them in the last bit (the interval is then the value itself), and a BCa
    interval of skewed values can exclude their mean; matplotlib refuses negative lengths."""
    mean = np.asarray(mean, dtype=np.float64)
    err = np.vstack([mean - np.asarray(low, np.float64), np.asarray(high, np.float64) - mean])
    return np.where(np.isfinite(err), np.maximum(err, 0.0), 0.0)


def holm(p: Sequence[float] | np.ndarray) -> np.ndarray:
    """Holm's step-down adjustment of a family of p-values (it keeps the chance of any false
    positive among them at or below the level, whatever their dependence).

    The ``i``-th smallest of the ``m`` finite p-values becomes the running maximum of
    ``(m - j) * p_(j)`` over ``j <= i`` (0-based), capped at 1; NaNs (lines not tested) stay
    NaN and do not count in ``m``. A line is significant at the family's level ``ALPHA`` when
    its adjusted p is below it. As ``statsmodels.stats.multitest.multipletests(p, method="holm")``
    gives it (not a dependency; the test checks published values).
    """
    p = np.asarray(p, dtype=np.float64)
    out = np.full(p.shape, np.nan)
    tested = np.flatnonzero(np.isfinite(p))
    order = tested[np.argsort(p[tested], kind="stable")]
    m = order.size
    scaled = (m - np.arange(m)) * p[order]
    out[order] = np.minimum(1.0, np.maximum.accumulate(scaled)) if m else scaled
    return out


def mean_ci(values: np.ndarray, seed: int, *names: str) -> tuple[float, float]:
    """The 95 % bootstrap CI (BCa) of the mean of ``values`` (NaNs dropped), resampled from the
    stream keyed by ``seed`` and ``names`` (as every interval of the tables is); (NaN, NaN) for
    fewer than two values."""
    values = np.asarray(values, dtype=np.float64)
    return _ci(values[np.isfinite(values)], _stream(seed, *names))


def summarize(
    table: pd.DataFrame,
    *,
    seed: int = 0,
    metrics: Sequence[str] | None = None,
    rates: Collection[str] | None = None,
) -> pd.DataFrame:
    """Mean and 95 % CI of every metric per (policy, scenario).

    :param table: an :func:`episode_table`.
    :param seed: seeds the bootstrap resampling, so a report is reproducible.
    :param metrics: the metric columns, in order (default: :func:`metric_columns`).
    :param rates: the metrics whose every episode is 0 or 100 (default:
        :func:`binary_metrics` of PersonFollow's registry); their interval is the Wilson score
        interval of the proportion, in % (BCa where a cell holds some other value).
    :returns: columns ``policy, scenario, episodes``, the metric means in
        :func:`metric_columns` order, then ``<metric>_ci_low`` and ``<metric>_ci_high`` for each
        metric, then ``<metric>_n`` for each (the episodes with a finite value, which the mean
        and interval are of). Rows keep the order the cells first appear in ``table``.
    """
    metrics = [m for m in (metrics or metric_columns()) if m in table]
    rates = binary_metrics() if rates is None else frozenset(rates)
    variant = variant_column(table)
    rows = []
    for (policy, scenario), cell in table.groupby(["policy", variant], sort=False):
        if "seed" in cell:
            cell = cell.sort_values("seed", kind="stable")
        row: dict[str, object] = {"policy": policy, variant: scenario, "episodes": len(cell)}
        bounds: dict[str, float] = {}
        counts: dict[str, int] = {}
        for m in metrics:
            values = cell[m].to_numpy(dtype=np.float64)
            values = values[np.isfinite(values)]
            row[m] = float(values.mean()) if values.size else np.nan
            wilson = _wilson(values) if m in rates else None
            if wilson is None:
                wilson = _ci(values, _stream(seed, str(policy), str(scenario), m))
            bounds[f"{m}_ci_low"], bounds[f"{m}_ci_high"] = wilson
            counts[f"{m}_n"] = int(values.size)
        rows.append({**row, **bounds, **counts})
    columns = ["policy", variant, "episodes", *metrics]
    columns += [f"{m}_ci_{end}" for m in metrics for end in ("low", "high")]
    columns += [f"{m}_n" for m in metrics]
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
    :param seed: seeds the bootstrap resampling and the permutation tests.
    :param policies: the policies' order, which names each pair's A and B (default: the order
        they first appear in ``table``); policies of ``table`` missing here are not compared.
    :returns: one row per (scenario, policy_a, policy_b, metric) with ``n`` (paired seeds with
        both values finite), ``mean_a``, ``mean_b``, ``mean_diff`` (A - B), ``diff_ci_low``,
        ``diff_ci_high``, ``wilcoxon_p`` (NaN when every difference is 0 or n < 2),
        ``perm_p`` (the sign-flip permutation test's, :func:`paired_test`; NaN when n = 0),
        ``holm_p`` (``perm_p`` adjusted over the metric's rows, :func:`with_holm`), and the
        pairing: ``seeds_a`` and ``seeds_b`` (the seeds each policy ran on the
        scenario) and ``seeds_both`` (those both ran). A pair that shares no seed keeps its
        rows, with n = 0 and NaN statistics (:func:`pairing_notes` says so).
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
            if pa.empty or pb.empty:
                continue  # a policy that did not run this scenario: no pair here
            seeds = pa.index.intersection(pb.index).sort_values()
            pairing = {"seeds_a": len(pa), "seeds_b": len(pb), "seeds_both": len(seeds)}
            for m in metrics:
                va = pa.loc[seeds, m].to_numpy(dtype=np.float64)
                vb = pb.loc[seeds, m].to_numpy(dtype=np.float64)
                ok = np.isfinite(va) & np.isfinite(vb)
                diff = va[ok] - vb[ok]
                test = paired_test(diff, seed, str(scenario), *sorted((str(a), str(b))), m)
                rows.append(
                    {
                        variant: scenario,
                        "policy_a": a,
                        "policy_b": b,
                        "metric": m,
                        "n": int(ok.sum()),
                        "mean_a": float(va[ok].mean()) if ok.any() else np.nan,
                        "mean_b": float(vb[ok].mean()) if ok.any() else np.nan,
                        "mean_diff": test.mean,
                        "diff_ci_low": test.low,
                        "diff_ci_high": test.high,
                        "wilcoxon_p": _wilcoxon_p(diff),
                        "perm_p": test.p,
                        **pairing,
                    }
                )
    columns = [variant, "policy_a", "policy_b", "metric", "n", "mean_a", "mean_b"]
    columns += ["mean_diff", "diff_ci_low", "diff_ci_high", "wilcoxon_p", "perm_p"]
    columns += ["seeds_a", "seeds_b", "seeds_both"]
    return with_holm(pd.DataFrame(rows, columns=columns))


def with_holm(comparisons: pd.DataFrame) -> pd.DataFrame:
    """``comparisons`` (:func:`compare`'s) with ``holm_p`` after ``perm_p`` (replaced if it
    has one): :func:`holm` over each metric's rows, every scenario and pair of the table.

    A metric is one question asked of every pair on every scenario ("which collides less?"),
    and a table of many pairs asks it many times: at 5 % each, one line in twenty of a table
    with no real difference would be starred. A difference significant by
    :attr:`PairedTest.direction` with ``holm_p`` in place of ``perm_p`` stands under the
    correction: the chance of any false one among the metric's lines stays at or below 5 %.
    Another family (one scenario, one pair) is :func:`holm` of those rows' ``perm_p``.
    """
    out = comparisons.drop(columns="holm_p", errors="ignore")
    p = out["perm_p"].to_numpy(dtype=np.float64)
    adjusted = np.full(p.shape, np.nan)
    for rows in out.groupby("metric", sort=False).indices.values():
        adjusted[rows] = holm(p[rows])
    out.insert(out.columns.get_loc("perm_p") + 1, "holm_p", adjusted)
    return out


def pairing_notes(comparisons: pd.DataFrame) -> list[str]:
    """One sentence per (scenario, pair) of :func:`compare` whose two policies ran different
    seeds: the comparison pairs only the seeds both ran, or, sharing none, compares nothing.

    :param comparisons: :func:`compare` output (a table without its pairing columns, written
        before they existed, gives no note).
    """
    if comparisons.empty or "seeds_both" not in comparisons:
        return []
    variant = variant_column(comparisons)
    keys = [variant, "policy_a", "policy_b"]
    pairs = comparisons.drop_duplicates(keys)
    notes = []
    for row in pairs.to_dict("records"):
        a, b, both = int(row["seeds_a"]), int(row["seeds_b"]), int(row["seeds_both"])
        if a == both and b == both:
            continue
        ran = f"{row['policy_a']} ran {a} seeds and {row['policy_b']} {b}"
        what = "they share none: not compared" if both == 0 else f"compared on the {both} both ran"
        notes.append(f"{variant} {row[variant]}: {ran}; {what}")
    return notes


def _wilcoxon_p(diff: np.ndarray) -> float:
    """Two-sided Wilcoxon signed-rank p-value of paired differences; NaN if undefined."""
    if diff.size < 2 or not np.any(diff != 0.0):
        return np.nan
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # small-sample and tie notices; the p-value stands
        return float(stats.wilcoxon(diff).pvalue)

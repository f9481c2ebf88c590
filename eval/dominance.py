"""Does a learner dominate the laws? Each scenario and criterion against the best law there.

A learned controller *dominates* when, on every scenario, it is at least as good as the best
law on the outcome criteria (keeps the person in frame as often, loses them and collides no
more often, holds the distance as well), and on most scenarios (more than half) significantly
better on the quality criteria (centres the person and moves more smoothly; :data:`RULE`): the
bar the learned-controller work set. The quality criteria are asked on most scenarios rather
than every one because a criterion can be out of any controller's reach on a scenario
(MeanOffset is the *observed* offset, most of it the detector's jitter on a straight walk),
while an outcome lost on one scenario is a robot that crashes there. "The best law" is taken
per scenario and per criterion: the law whose mean is best on that criterion there, from
whichever laws the run compared (the thesis and tuned presets of pn / mpn / gsmpn, say), so
the learner meets the strongest opponent on each line of the table.

Every comparison is paired over the seeds both ran (identical rollouts): its 95 % CI is
:func:`eval.stats.mean_ci` of the per-seed differences and its p-value a paired sign-flip
permutation test of their mean (:func:`eval.stats.paired_test`), both drawn from streams keyed
by the cell's names, so a table is reproducible. Each line carries two judgements:

- ``verdict``: ``better`` / ``worse`` when the difference ``learner - best law`` is significant
  in that direction (:data:`RULE`: the CI excludes zero on that side *and* the permutation p
  < 0.05), else ``tie`` (no significant difference). The CI alone calls too many differences
  significant on paired seeds whose differences are mostly about 0 with a few large ones (most
  seeds play alike and a few diverge): 12-31 % of the time with no true difference, at a
  nominal 5 % (:mod:`eval.stats`);
- ``meets``: the criterion's requirement. ``at_least`` criteria ask that the learner's mean be
  no worse than the best law's (a strict reading: a lost person in 1 of 20 episodes against
  none does not meet it, significant or not); ``better`` criteria ask for ``verdict ==
  "better"``.

Each criterion is then held to its scope (:func:`criterion_summary`): met on ``every``
scenario, or on ``most`` of them; the learner dominates when every criterion holds
(:func:`dominates`). The report (:mod:`eval.dominance_report`) also counts the (scenario,
criterion) lines met, which shows progress where the verdict is still no, and the lines on
which the learner is significantly better or significantly worse than the best law
(:func:`tally`): the strict reading counts a one-episode difference as a miss, the tally only
what the paired tests can tell apart.

An episode that ends early (a collision, a lost person) stops counting frames, distance and
offset where it ends, so a law that crashes early can keep a better in-frame rate or distance
error on that episode than a learner that avoids the crash and goes on. :func:`finished_view`
asks each missed line again over the seeds on which both the learner and that line's law
finished (neither lost nor collided: :func:`finished`); the report prints it after the
table, as an explanation, and the verdict does not change. The two endings are alike: an
episode that has ended in a collision cannot lose the person and one that has lost the person
cannot collide, so a side that collides more is charged with fewer losses, and one that loses
the person more with fewer collisions. A missed lost line is asked again over the seeds on
which neither collided, a missed collision line over those on which neither lost the person.

How high that bar is shows in :func:`calibration`: each law put through the same test against
the other laws (the best of the rest on each line). The report gives those counts beside the
learner's, so a reader can tell a near miss from a bar no controller clears.

::

    follow-eval run --policies ppo,pn:thesis,mpn:thesis,gsmpn:thesis,pn,mpn,gsmpn \\
        --scenarios <all> --episodes 20 --seed 0 --out runs/dom
    follow-eval dominance runs/dom --learner ppo
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import pandas as pd

from eval.stats import ALPHA, holm, paired_test, variant_column

__all__ = [
    "CRITERIA",
    "RULE",
    "Criterion",
    "calibration",
    "criterion_summary",
    "default_laws",
    "dominance",
    "dominates",
    "finished_view",
    "tally",
]


@dataclass(frozen=True)
class Criterion:
    """One line of the dominance table.

    :param metric: the episode-table column (an :data:`eval.metrics.METRICS` name).
    :param higher_is_better: the metric's direction.
    :param need: ``"at_least"`` (mean no worse than the best law's) or ``"better"``
        (significantly better, :data:`RULE`).
    :param scope: on how many scenarios the requirement must be met: ``"every"`` one, or
        ``"most"`` (more than half).
    """

    metric: str
    higher_is_better: bool
    need: str
    scope: str = "every"

    def __post_init__(self) -> None:
        if self.need not in ("at_least", "better"):
            raise ValueError(f"Criterion.need: {self.need!r} is not one of 'at_least', 'better'")
        if self.scope not in SCOPES:
            raise ValueError(f"Criterion.scope: {self.scope!r} is not one of 'every', 'most'")

    def needed(self, scenarios: int) -> int:
        """How many of ``scenarios`` scenarios must meet the requirement for it to hold."""
        return scenarios if self.scope == "every" else scenarios // 2 + 1


#: A criterion's scope: met on every scenario, or on more than half of them.
SCOPES = ("every", "most")


#: The requirement of a dominating agent, in table order.
CRITERIA = (
    Criterion("in_frame_rate_pct", True, "at_least"),
    Criterion("lost_rate_pct", False, "at_least"),
    Criterion("collision_rate_pct", False, "at_least"),
    Criterion("rms_distance_error_m", False, "at_least"),
    Criterion("mean_offset_px", False, "better", "most"),
    Criterion("std_accel_mm_s2", False, "better", "most"),
)

#: How a line's verdict is decided, as the report says it.
RULE = (
    "significant: the paired 95 % CI excludes zero and a sign-flip permutation test of the "
    "mean difference gives p < 0.05, on the same side"
)

COLUMNS = [
    "criterion",
    "need",
    "scope",
    "learner_mean",
    "best_law",
    "law_mean",
    "diff",
    "diff_ci_low",
    "diff_ci_high",
    "perm_p",
    "holm_p",
    "n",
    "verdict",
    "meets",
]


def dominance(
    table: pd.DataFrame,
    learner: str,
    laws: Sequence[str] | None = None,
    *,
    criteria: Sequence[Criterion] = CRITERIA,
    seed: int = 0,
) -> pd.DataFrame:
    """The learner against the best law, per scenario and criterion.

    :param table: an :func:`eval.stats.episode_table` (``episodes.csv`` of a ``follow-eval run``).
    :param learner: the learner's policy label in ``table``.
    :param laws: the laws' labels (default: every other policy in ``table`` with the learner's
        label suffix: a run with ``--ideal-baseline`` sets ``ppo`` against ``pn``, ``gsmpn``,
        ... and ``ppo+ideal`` against ``pn+ideal``, ...).
    :param criteria: the lines of the table (default: :data:`CRITERIA`).
    :param seed: seeds the bootstrap resampling.
    :returns: one row per (scenario, criterion) with the columns ``scenario`` and
        :data:`COLUMNS`; ``diff`` is ``learner - best law`` over the ``n`` paired seeds.
    :raises ValueError: if the learner or a law is not in the table, no law is left, or a
        criterion's metric is not a column.
    """
    policies = list(dict.fromkeys(table["policy"]))
    if learner not in policies:
        raise ValueError(f"learner {learner!r} is not in the table (policies: {policies})")
    laws = default_laws(table, learner) if laws is None else list(laws)
    missing = [law for law in laws if law not in policies]
    if missing:
        raise ValueError(f"laws {missing} are not in the table (policies: {policies})")
    if not laws or learner in laws:
        raise ValueError(f"dominance needs at least one law other than the learner, got {laws}")
    for c in criteria:
        if c.metric not in table:
            raise ValueError(f"criterion {c.metric!r} is not a column of the episode table")
    variant = variant_column(table)
    rows = []
    for scenario in dict.fromkeys(table[variant]):
        cell = table[table[variant] == scenario]
        by_policy = {p: cell[cell["policy"] == p].set_index("seed") for p in (learner, *laws)}
        for c in criteria:
            sign = 1.0 if c.higher_is_better else -1.0
            best, best_score = None, -np.inf
            for law in laws:
                values = by_policy[law][c.metric].to_numpy(dtype=np.float64)
                values = values[np.isfinite(values)]
                if values.size and sign * values.mean() > best_score:
                    best, best_score = law, sign * values.mean()
            theirs = None if best is None else by_policy[best]
            rows.append(
                _line(scenario, c, by_policy[learner], best, theirs, seed, variant, learner)
            )
    return _with_holm(pd.DataFrame(rows, columns=[variant, *COLUMNS]))


def _with_holm(frame: pd.DataFrame) -> pd.DataFrame:
    """``frame`` with ``holm_p``: :func:`eval.stats.holm` over the table's tested lines, one
    family (the report's counts of significant lines are claims about the whole table)."""
    frame["holm_p"] = holm(frame["perm_p"].to_numpy(dtype=np.float64))
    return frame


def default_laws(table: pd.DataFrame, learner: str) -> list[str]:
    """The laws :func:`dominance` meets by default: the table's other policies under the
    learner's own sensing (``pn``, ``gsmpn``, ... for ``ppo``; ``pn+ideal``, ... for
    ``ppo+ideal``)."""
    policies = dict.fromkeys(table["policy"])
    return [p for p in policies if p != learner and _sensing(p) == _sensing(learner)]


def calibration(
    table: pd.DataFrame,
    laws: Sequence[str],
    *,
    criteria: Sequence[Criterion] = CRITERIA,
    seed: int = 0,
) -> dict[str, dict[str, int]]:
    """How each law fares against the others (the bar :func:`dominance` sets, applied to the
    laws themselves).

    :param table: the episode table :func:`dominance` reads.
    :param laws: the laws' labels, at least two.
    :returns: ``{law: tally}`` in ``laws`` order, each law's :func:`tally` against the best of
        the others on each line (``met`` of ``scenarios x criteria``, ``better``, ``worse``).
    :raises ValueError: with fewer than two laws, or as :func:`dominance` does.
    """
    laws = list(laws)
    if len(laws) < 2:
        raise ValueError(f"calibration needs at least two laws, got {laws}")
    return {
        law: tally(
            dominance(
                table, law, [other for other in laws if other != law], criteria=criteria, seed=seed
            )
        )
        for law in laws
    }


def tally(frame: pd.DataFrame) -> dict[str, int]:
    """The lines of :func:`dominance`'s table counted three ways.

    :param frame: :func:`dominance` output.
    :returns: ``met`` (requirements met), ``better`` and ``worse`` (lines whose difference
        ``learner - best law`` is significant, :data:`RULE`, in the learner's favour / against
        it), and ``better_holm`` and ``worse_holm``: those of them whose p stays below 0.05
        after Holm's adjustment over the table's lines (``holm_p``).
    """
    family = frame["holm_p"].to_numpy(dtype=np.float64) < ALPHA
    return {
        "met": int(frame["meets"].astype(bool).sum()),
        "better": int((frame["verdict"] == "better").sum()),
        "worse": int((frame["verdict"] == "worse").sum()),
        "better_holm": int(((frame["verdict"] == "better") & family).sum()),
        "worse_holm": int(((frame["verdict"] == "worse") & family).sum()),
    }


def _sensing(label: str) -> str:
    """A label's ``+suffix`` (``"+ideal"`` for ``pn+ideal``), or ``""``."""
    _, plus, tail = label.rpartition("+")
    return plus + tail if plus and tail.isidentifier() else ""


def _line(
    scenario: str,
    c: Criterion,
    mine: pd.DataFrame,
    best: str | None,
    theirs: pd.DataFrame | None,
    seed: int,
    variant: str,
    learner: str,
) -> dict[str, object]:
    """One (scenario, criterion) row: the paired difference against the best law."""
    row: dict[str, object] = {
        variant: scenario,
        "criterion": c.metric,
        "need": c.need,
        "scope": c.scope,
    }
    if best is None or theirs is None:  # no law has a finite value here (e.g. never lost)
        row.update(best_law="", n=0, verdict="n/a", meets=False)
        return row
    seeds = mine.index.intersection(theirs.index).sort_values()
    a = mine.loc[seeds, c.metric].to_numpy(dtype=np.float64)
    b = theirs.loc[seeds, c.metric].to_numpy(dtype=np.float64)
    ok = np.isfinite(a) & np.isfinite(b)
    if not ok.any():  # no seed with a value from both (e.g. none both finished)
        row.update(best_law=best, n=0, verdict="n/a", meets=False)
        return row
    diff = a[ok] - b[ok]
    test = paired_test(diff, seed, "dominance", str(scenario), learner, best, c.metric)
    low, high = test.low, test.high
    sign = 1.0 if c.higher_is_better else -1.0
    # "At least as good" compares the two means themselves: the mean of the differences can
    # come out a rounding error off zero (4.6e-18) when the means are equal. fsum sums exactly
    # (then rounds once), so equal values in another seed order give equal means.
    no_worse = sign * (math.fsum(a[ok]) - math.fsum(b[ok])) >= 0.0
    if np.all(diff == 0.0):
        low = high = 0.0  # identical on every seed: the interval is the point
    good = test.direction * int(sign)  # +1: significantly in the learner's favour
    verdict = "better" if good > 0 else "worse" if good < 0 else "tie"
    meets = no_worse if c.need == "at_least" else verdict == "better"
    row.update(
        learner_mean=float(a[ok].mean()),
        best_law=best,
        law_mean=float(b[ok].mean()),
        diff=float(diff.mean()),
        diff_ci_low=low,
        diff_ci_high=high,
        perm_p=test.p,
        n=int(ok.sum()),
        verdict=verdict,
        meets=meets,
    )
    return row


#: The criteria that end an episode: an episode is finished when both are 0 (neither lost nor
#: collided); :func:`finished_view` asks each of them again where the other is 0.
ENDINGS = ("lost_rate_pct", "collision_rate_pct")


def finished(table: pd.DataFrame) -> pd.Series:
    """Which episodes of ``table`` finished: neither lost nor collided (both :data:`ENDINGS`
    0; an episode without an ending, a robot's log, did not).

    Not ``success_pct``, which also asks that the perception kept the person, not a stranger:
    an episode that followed a stranger to the end of the walk is finished here.
    """
    return (table[list(ENDINGS)] <= 0.0).all(axis=1)


def finished_view(
    table: pd.DataFrame,
    frame: pd.DataFrame,
    learner: str,
    *,
    criteria: Sequence[Criterion] = CRITERIA,
    seed: int = 0,
) -> pd.DataFrame:
    """The lines ``frame`` misses, again over the seeds both the learner and the line's law
    finished (module docstring): the same law, the same test, fewer seeds. A missed line of one
    of the :data:`ENDINGS` is asked again over the seeds on which neither ended by the other
    (a lost line where neither collided, a collision line where neither lost the person): an
    episode that has ended one way cannot end the other, so the side that ends more often the
    other way is charged less often this way.

    :param table: the episode table ``frame`` was computed from, with the :data:`ENDINGS`.
    :param frame: :func:`dominance` output for ``learner``.
    :param learner: the learner's policy label.
    :param criteria: the criteria of ``frame`` (default: :data:`CRITERIA`).
    :param seed: seeds the bootstrap resampling.
    :returns: one row per missed line, with the columns of :func:`dominance`; ``n`` is the
        number of seeds asked (a line with none has verdict ``n/a``, as in :func:`dominance`),
        and ``holm_p`` NaN (lines picked because they were missed are no family to adjust
        over).
    :raises ValueError: if the table has no column of one of the :data:`ENDINGS`.
    """
    if missing := [c for c in ENDINGS if c not in table]:
        raise ValueError(
            f"the episode table has no {missing[0]!r} column to tell finished episodes"
        )
    variant = frame.columns[0]
    by_metric = {c.metric: c for c in criteria}
    done = finished(table)
    rows = []
    for line in frame.itertuples(index=False):
        r = line._asdict()
        if r["meets"] or not r["best_law"]:
            continue
        if r["criterion"] in ENDINGS:  # where neither ended the other way
            (other,) = (e for e in ENDINGS if e != r["criterion"])
            asked = table[other] <= 0.0
        else:
            asked = done
        cell = table[(table[variant] == r[variant]) & asked]
        mine = cell[cell["policy"] == learner].set_index("seed")
        theirs = cell[cell["policy"] == r["best_law"]].set_index("seed")
        c = by_metric[r["criterion"]]
        rows.append(_line(r[variant], c, mine, r["best_law"], theirs, seed, variant, learner))
    # No Holm p here: these lines were chosen after seeing the table (the missed ones), so they
    # are no family to adjust over; the main table's adjusted p is the one to read.
    return pd.DataFrame(rows, columns=[variant, *COLUMNS])


def criterion_summary(frame: pd.DataFrame) -> pd.DataFrame:
    """Each criterion held to its scope.

    :param frame: :func:`dominance` output.
    :returns: one row per criterion, in table order: ``criterion``, ``need``, ``scope``,
        ``met`` (scenarios meeting the requirement), ``scenarios``, ``needed`` (how many must,
        :meth:`Criterion.needed`), ``holds`` (``met >= needed``) and ``missed`` (the scenarios
        that do not meet it, comma-separated).
    """
    variant = frame.columns[0]
    rows = []
    for criterion in dict.fromkeys(frame["criterion"]):
        lines = frame[frame["criterion"] == criterion]
        need, scope = lines["need"].iloc[0], lines["scope"].iloc[0]
        meets = lines["meets"].astype(bool)
        needed = Criterion(str(criterion), True, need, scope).needed(len(lines))
        rows.append(
            {
                "criterion": criterion,
                "need": need,
                "scope": scope,
                "met": int(meets.sum()),
                "scenarios": len(lines),
                "needed": needed,
                "holds": int(meets.sum()) >= needed,
                "missed": ", ".join(map(str, lines.loc[~meets, variant])),
            }
        )
    return pd.DataFrame(rows)


def dominates(frame: pd.DataFrame) -> bool:
    """Whether the learner dominates: every criterion of :func:`dominance`'s table holds on
    its scope (:func:`criterion_summary`)."""
    return bool(criterion_summary(frame)["holds"].all())

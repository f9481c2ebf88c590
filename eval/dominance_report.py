"""The dominance report in markdown: :mod:`eval.dominance`'s table as ``follow-eval dominance``
writes it into ``dominance-<learner>.md``.

:func:`dominance_markdown` opens with the verdict and the counts (requirements met, lines
significantly better and worse, with and without Holm's correction, and the laws' own counts
against each other for scale), says where each criterion is missed, then gives the table at a
glance (:func:`grid_markdown`) and the full table, a line per (scenario, criterion).
:func:`finished_markdown` adds the missed lines asked again on the episodes both finished (a
lost line on those in which neither collided, a collision line on those in which neither lost
the person).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence

import numpy as np
import pandas as pd

from eval.dominance import CRITERIA, RULE, Criterion, criterion_summary, dominates, tally
from eval.metrics import metric_digits, metric_label

__all__ = ["MINUS", "dominance_markdown", "finished_markdown", "grid_markdown"]


def finished_markdown(view: pd.DataFrame, learner: str) -> str:
    """:func:`~eval.dominance.finished_view` in markdown (empty when no line was asked again)."""
    if view.empty:
        return ""
    variant = view.columns[0]
    lines = [
        "",
        "On the episodes both finished (neither lost nor collided) or, for a lost line, on "
        "those in which neither collided and, for a collision line, on those in which neither "
        f"lost the person: the lines `{learner}` misses above, against the same law (an "
        "explanation, not part of the verdict):",
        "",
        f"| {variant} | criterion | episodes | {learner} | the line's law | law | "
        f"{learner} - law [95 % CI] | p | verdict | meets |",
        "|---|---|---:|---:|---|---:|---|---:|---|---|",
    ]
    for row in view.itertuples(index=False):
        lines.append(_markdown_row(row._asdict(), variant, str(row.n), holm=False))
    return "\n".join(lines) + "\n"


def dominance_markdown(
    frame: pd.DataFrame,
    learner: str,
    calibrated: dict[str, dict[str, int]] | None = None,
    criteria: Sequence[Criterion] = CRITERIA,
) -> str:
    """The table in markdown, after one line per criterion saying where it is met and the
    table at a glance (:func:`grid_markdown`).

    :param frame: :func:`~eval.dominance.dominance` output.
    :param learner: the learner's label, for the text.
    :param calibrated: :func:`~eval.dominance.calibration` of the same laws, said after the
        headline.
    :param criteria: the criteria ``frame`` was judged by (their directions mark the grid).
    """
    variant = frame.columns[0]
    summary = criterion_summary(frame)
    lines = []
    held = int(summary["holds"].sum())
    counts = tally(frame)
    lines.append(
        f"`{learner}` {'dominates' if dominates(frame) else 'does not dominate'} the laws: "
        f"{held} of {len(summary)} criteria hold on their scope; "
        f"{counts['met']} of {len(frame)} (scenario, criterion) requirements met."
    )
    worse = frame[frame["verdict"] == "worse"]
    named = ", ".join(f"{w[variant]} {metric_label(w['criterion'])}" for _, w in worse.iterrows())
    lines.append(
        f"Significantly better than the best law on {counts['better']} of {len(frame)} lines, "
        f"significantly worse on {counts['worse']} ({RULE})"
        f"{f': {named}' if named else ''}."
    )
    tested = int(np.isfinite(frame["holm_p"].to_numpy(dtype=np.float64)).sum())
    lines.append(
        f"With Holm's correction for the {tested} lines tested (the chance that any line counted "
        f"here differs by chance alone at most 5 %): better on {counts['better_holm']}, worse "
        f"on {counts['worse_holm']}."
    )
    if calibrated:
        met = {law: t["met"] for law, t in calibrated.items()}
        each = ", ".join(f"{law} {m}" for law, m in met.items())
        lines.append(
            f"For scale, each law against the other {len(calibrated) - 1} (the same test): "
            f"{_span(met.values())} of {len(frame)} ({each}); significantly better on "
            f"{_span(t['better'] for t in calibrated.values())} lines and worse on "
            f"{_span(t['worse'] for t in calibrated.values())}."
        )
    lines.append("")
    for s in summary.itertuples(index=False):
        what = "at least as good as" if s.need == "at_least" else "significantly better than"
        scope = "every scenario" if s.scope == "every" else f"most: {s.needed}"
        where = f"; not in {s.missed}" if s.missed else ""
        lines.append(
            f"- {metric_label(s.criterion)}: {what} the best law in "
            f"{s.met} of {s.scenarios} scenarios (needed: {scope}; "
            f"{'holds' if s.holds else '**does not hold**'}){where}"
        )
    lines.append("")
    lines.append(grid_markdown(frame, learner, criteria))
    lines.append(
        f"| {variant} | criterion | need | {learner} | best law | law | "
        f"{learner} - law [95 % CI] | p | verdict | meets |"
    )
    lines.append("|---|---|---|---:|---|---:|---|---:|---|---|")
    for row in frame.itertuples(index=False):
        lines.append(_markdown_row(row._asdict(), variant, str(row.need)))
    return "\n".join(lines) + "\n"


MINUS = "\N{MINUS SIGN}"
"""The grid's mark against the learner (the typographic minus the docs' tables use)."""


def grid_markdown(
    frame: pd.DataFrame, learner: str, criteria: Sequence[Criterion] = CRITERIA
) -> str:
    """:func:`~eval.dominance.dominance`'s table at a glance, in markdown: one row per
    scenario, one column per criterion, each cell ``learner / best law`` (the two means, with
    the digits of the full table), after a line of legend; the text ends in a newline.

    A cell is bold where the requirement is missed. ``+`` / ``−`` mark a line that is
    significantly better / worse by :data:`~eval.dominance.RULE` (the line's ``verdict``);
    ``(+)`` / ``(−)`` one whose 95 % CI alone excludes zero in the learner's favour / against
    it while the verdict is a tie (the permutation test does not confirm it), so a reader of a
    table marked by the CI alone finds the same lines. A line with no paired seed reads
    ``**n/a**``.

    :param frame: :func:`~eval.dominance.dominance` output.
    :param learner: the learner's label, for the legend.
    :param criteria: the criteria ``frame`` was judged by, where each one's direction is looked
        up for the ``(+)`` / ``(−)`` marks (a metric not among them gets the verdict's only).
    """
    variant = frame.columns[0]
    higher = {c.metric: c.higher_is_better for c in criteria}
    names = list(dict.fromkeys(frame["criterion"]))
    head = " | ".join(metric_label(str(n)) for n in names)
    lines = [
        f"Each cell `{learner} / best law`; bold: the requirement is missed; `+` / `{MINUS}`: "
        f"significantly better / worse (the verdict below); `(+)` / `({MINUS})`: the 95 % CI alone "
        "excludes zero in the learner's favour / against it, the permutation test does not "
        "confirm it; n/a: no seed paired:",
        "",
        f"| {variant} | {head} |",
        "|---|" + "---:|" * len(names),
    ]
    by_line: dict[tuple[object, object], pd.Series] = {}
    for _, row in frame.iterrows():  # the first row of each (scenario, criterion)
        by_line.setdefault((row[variant], row["criterion"]), row)
    for scenario in dict.fromkeys(frame[variant]):
        cells = [
            _grid_cell(by_line[scenario, name], higher.get(str(name)))
            if (scenario, name) in by_line
            else ""
            for name in names
        ]
        lines.append(f"| {scenario} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def _grid_cell(r: pd.Series, higher_is_better: bool | None) -> str:
    """One cell of :func:`grid_markdown`: ``learner / law``, bold when missed, and its mark."""
    if r["verdict"] == "n/a":
        return "**n/a**"
    d = metric_digits(str(r["criterion"]))
    text = f"{r['learner_mean']:.{d}f} / {r['law_mean']:.{d}f}"
    if not r["meets"]:
        text = f"**{text}**"
    if r["verdict"] == "better":
        return f"{text} +"
    if r["verdict"] == "worse":
        return f"{text} {MINUS}"
    if higher_is_better is None:
        return text
    low, high = float(r["diff_ci_low"]), float(r["diff_ci_high"])
    # the learner's side of zero: above it where higher is better, below it where lower is
    favour, against = (low > 0.0, high < 0.0) if higher_is_better else (high < 0.0, low > 0.0)
    return f"{text} (+)" if favour else f"{text} ({MINUS})" if against else text


def _span(values: Iterable[int]) -> str:
    """``"lo-hi"`` of some counts, or the one count when they are all equal."""
    got = list(values)
    lo, hi = min(got), max(got)
    return str(lo) if lo == hi else f"{lo}-{hi}"


def _markdown_row(r: dict[str, object], variant: str, middle: str, *, holm: bool = True) -> str:
    """One line of a table in markdown; ``middle`` goes after the criterion (the need, or the
    number of episodes compared); ``holm``: with the Holm p column."""
    label = metric_label(str(r["criterion"]))
    ps = [_p(r[k]) for k in ("perm_p", "holm_p")[: 2 if holm else 1]]
    if r["verdict"] == "n/a":
        blank = " |" * len(ps)
        return f"| {r[variant]} | {label} | {middle} | | {r['best_law']} | | |{blank} n/a | no |"
    d = metric_digits(str(r["criterion"]))
    return (
        f"| {r[variant]} | {label} | {middle} | "
        f"{r['learner_mean']:.{d}f} | {r['best_law']} | {r['law_mean']:.{d}f} | "
        f"{r['diff']:+.{d}f} [{r['diff_ci_low']:+.{d}f}, {r['diff_ci_high']:+.{d}f}] | "
        f"{' | '.join(ps)} | {r['verdict']} | {'yes' if r['meets'] else '**no**'} |"
    )


def _p(value: object) -> str:
    """A p-value for the table: two significant digits, ``n/a`` when it was not tested."""
    p = float(value)  # type: ignore[arg-type]
    return "n/a" if not math.isfinite(p) else f"{p:.2g}"

"""Reports: the summary table as CSV, Markdown, JSON and LaTeX; plots; videos.

Every file is written atomically (:mod:`follow_env.sim.atomic`). The thesis's metrics appear
in the thesis's units (px, mm/s², %); everything else is SI, as its column name says.

The tables are PersonFollow's unless ``tables=`` says otherwise: a :class:`Tables` names a
task's metrics, its headline ones and the headline table's title (LineTrace's is
:data:`eval.line_metrics.LINE_TABLES`).
"""

from __future__ import annotations

import json
import math
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from eval.metrics import (
    HEADLINE_METRICS,
    METRICS,
    THESIS_METRICS,
    Metric,
    metric_digits,
    metric_label,
)
from eval.rollout import Episode
from eval.stats import (
    ALPHA,
    SMALL_CELL,
    PairedTest,
    error_bars,
    pairing_notes,
    smallest_p,
    variant_column,
)
from follow_env.sim.atomic import atomic_path, atomic_write_text

__all__ = [
    "PERSON_FOLLOW_TABLES",
    "Tables",
    "comparison_markdown",
    "holm_note",
    "markdown_report",
    "plot_metric_bars",
    "plot_offsets",
    "plot_thesis_metrics",
    "plot_trajectories",
    "safe_name",
    "summary_latex",
    "summary_markdown",
    "write_tables",
    "write_video",
]

#: The leading columns of summary.csv, fixed by the evaluation issue (thesis metrics first).
SUMMARY_LEADING = ("policy", "scenario", "episodes", *THESIS_METRICS)
#: Marks a significant paired difference in the Markdown comparisons.
SIGNIFICANT_MARK = "*"
#: How the Markdown comparisons read, said under them.
COMPARISON_NOTE = (
    f"n: seeds both ran. p: two-sided paired sign-flip permutation test of the mean difference "
    f"(comparisons.csv also has the Wilcoxon p). {SIGNIFICANT_MARK}: significant, the 95 % CI "
    f"excludes zero and p < {ALPHA:g}."
)


@dataclass(frozen=True)
class Tables:
    """What a task's tables show.

    :param metrics: every metric by name, in column order.
    :param headline: the headline table's metrics (the rest are "further metrics").
    :param title: the headline table's title in the Markdown report.
    """

    metrics: Mapping[str, Metric]
    headline: tuple[str, ...]
    title: str


PERSON_FOLLOW_TABLES = Tables(
    METRICS,
    HEADLINE_METRICS,
    "Thesis metrics (reference §1.6) with collisions, losses and distance error",
)
"""PersonFollow's tables: the thesis's five metrics and the outcomes first."""


def safe_name(name: str) -> str:
    """A policy or scenario name as a file name part: ``"pn:tuned"`` -> ``"pn_tuned"``."""
    return re.sub(r"[^A-Za-z0-9._-]+", "_", name).strip("_") or "_"


def _fmt(value: float, digits: int) -> str:
    return "n/a" if not np.isfinite(value) else f"{value:.{digits}f}"


#: Marks an interval from fewer than :data:`eval.stats.SMALL_CELL` values (footnoted).
SMALL_MARK = "†"


def _small_note(what: str) -> str:
    """The footnote of :data:`SMALL_MARK` in a table of ``what``."""
    return (
        f"{SMALL_MARK} n<{SMALL_CELL}: {what} from fewer than {SMALL_CELL} episodes, and rough: "
        "a bootstrap interval of so few covers less than 95 % (about 80 % at 5)."
    )


def _with_ci(summary: pd.DataFrame, name: str) -> tuple[pd.Series, bool]:
    """``mean [low, high]`` per row; ``(n=k)`` after it where the metric has a value on fewer
    episodes than the cell holds (``<name>_n``), and :data:`SMALL_MARK` after an interval of
    fewer than :data:`eval.stats.SMALL_CELL` values; and whether some interval is so marked
    (decided here only, so the footnote goes with the marks)."""
    d = metric_digits(name)
    episodes = summary["episodes"].to_numpy()
    counts = summary[f"{name}_n"].to_numpy() if f"{name}_n" in summary else episodes
    cells = []
    marked = False
    for m, lo, hi, n, total in zip(
        summary[name],
        summary[f"{name}_ci_low"],
        summary[f"{name}_ci_high"],
        counts,
        episodes,
        strict=True,
    ):
        text = f"{_fmt(m, d)} [{_fmt(lo, d)}, {_fmt(hi, d)}]" if np.isfinite(lo) else _fmt(m, d)
        if np.isfinite(lo) and n < SMALL_CELL:
            text += SMALL_MARK
            marked = True
        if 0 < n < total:
            text += f" (n={int(n)})"
        cells.append(text)
    return pd.Series(cells, index=summary.index), marked


def _metric_table(
    summary: pd.DataFrame, names: Sequence[str], tables: Tables
) -> tuple[pd.DataFrame, bool]:
    """The columns ``policy, scenario, episodes`` and a ``mean [95 % CI]`` column per metric;
    and whether some interval is marked :data:`SMALL_MARK`."""
    table = summary[["policy", variant_column(summary), "episodes"]].copy()
    marked = False
    for name in names:
        table[metric_label(name, tables.metrics)], small = _with_ci(summary, name)
        marked |= small
    return table, marked


def summary_markdown(
    summary: pd.DataFrame, *, extras: bool = False, tables: Tables = PERSON_FOLLOW_TABLES
) -> str:
    """The summary as a Markdown table: mean [95 % CI] per cell, ``(n=k)`` where a metric has
    a value on k of the cell's episodes only, and a footnoted :data:`SMALL_MARK` on intervals
    of fewer than :data:`eval.stats.SMALL_CELL` values.

    :param summary: from :func:`eval.stats.summarize`.
    :param extras: the further metrics instead of the headline ones (the thesis's five, then
        :data:`eval.metrics.OUTCOME_METRICS`: collisions, losses, distance error).
    :param tables: the task's metrics (default PersonFollow's).
    """
    wanted = [m for m in tables.metrics if m not in tables.headline] if extras else tables.headline
    table, marked = _metric_table(summary, [m for m in wanted if m in summary], tables)
    text = table.to_markdown(index=False, disable_numparse=True)
    return text + ("\n\n" + _small_note("the interval is") if marked else "")


def comparison_markdown(
    comparisons: pd.DataFrame,
    metrics: Sequence[str] | None = None,
    *,
    tables: Tables = PERSON_FOLLOW_TABLES,
) -> str:
    """Paired differences A - B on the same seeds, a row per scenario and pair: ``n`` (the
    seeds both ran), then per metric ``diff [95 % CI] p=<sign-flip permutation p>``, with
    :data:`SIGNIFICANT_MARK` where the difference is significant (:class:`eval.stats.PairedTest`)
    and ``(n=k)`` where the metric has a value on both sides for k of those seeds only; the
    headline metrics unless ``metrics`` names others."""
    metrics = tables.headline if metrics is None else metrics
    variant = variant_column(comparisons)
    rows = []
    for (scenario, a, b), group in comparisons.groupby(
        [variant, "policy_a", "policy_b"], sort=False
    ):
        by_metric = group.set_index("metric")
        paired = int(group["seeds_both"].iloc[0]) if "seeds_both" in group else None
        row = {variant: scenario, "A - B": f"{a} - {b}", "n": "" if paired is None else paired}
        for name in metrics:
            if name not in by_metric.index:
                continue
            r = by_metric.loc[name]
            d = metric_digits(name)
            p = r["perm_p"] if "perm_p" in r else r["wilcoxon_p"]
            test = PairedTest(r["mean_diff"], r["diff_ci_low"], r["diff_ci_high"], p)
            ci = (
                f" [{_fmt(r['diff_ci_low'], d)}, {_fmt(r['diff_ci_high'], d)}]"
                if np.isfinite(r["diff_ci_low"])
                else ""
            )
            mark = SIGNIFICANT_MARK if "perm_p" in r and test.direction else ""
            fewer = f" (n={int(r['n'])})" if paired is not None and 0 < r["n"] < paired else ""
            p_text = "n/a" if not np.isfinite(p) else f"{p:.2g}"
            row[metric_label(name, tables.metrics)] = (
                f"{_fmt(r['mean_diff'], d)}{ci}{mark} p={p_text}{fewer}"
            )
        rows.append(row)
    return pd.DataFrame(rows).to_markdown(index=False, disable_numparse=True) if rows else ""


def holm_note(
    comparisons: pd.DataFrame,
    metrics: Sequence[str] | None = None,
    *,
    tables: Tables = PERSON_FOLLOW_TABLES,
) -> str:
    """How many of the starred differences of each metric shown (the headline metrics unless
    ``metrics`` names others) stand under Holm's correction over the metric's comparisons
    (``holm_p``, :func:`eval.stats.with_holm`): a sentence after a blank line, or ``""`` for a
    table without ``holm_p`` (written before it had one) or with no starred difference."""
    metrics = tables.headline if metrics is None else metrics
    if "holm_p" not in comparisons:
        return ""
    counts, unreachable = [], []
    for name in metrics:
        rows = comparisons[comparisons["metric"] == name]
        if rows.empty:
            continue
        starred = stand = 0
        for r in rows.to_dict("records"):
            ends = (r["mean_diff"], r["diff_ci_low"], r["diff_ci_high"])
            starred += bool(PairedTest(*ends, r["perm_p"]).direction)
            stand += bool(PairedTest(*ends, r["holm_p"]).direction)
        if not starred:
            continue
        label = metric_label(name, tables.metrics)
        counts.append(f"{label} {stand} of {starred}")
        # the permutation p has a floor: past ALPHA / floor lines, none can stand
        tested = rows[np.isfinite(rows["perm_p"].to_numpy(dtype=np.float64))]
        floor = min(smallest_p(int(n)) for n in tested["n"])
        if len(tested) * floor >= ALPHA:
            unreachable.append((label, len(tested), floor))
    if not counts:
        return ""
    text = (
        "\n\nStarred differences that stand under Holm's correction over each metric's "
        "comparisons in the table (holm_p, in comparisons.csv when the tables are written), per "
        f"metric: {'; '.join(counts)}."
    )
    for label, m, floor in unreachable:
        text += (
            f" {label}: none can stand, whatever the data: with {m} comparisons a line needs "
            f"p < {ALPHA / m:.2g}, and the permutation test's p is at least {floor:.2g} here "
            "(compare fewer policies at once)."
        )
    return text


def _ci_note(tables: Tables) -> str:
    """What the summary's intervals are, said under its tables."""
    rates = [m.label for m in tables.metrics.values() if m.binary]
    wilson = (
        f"; for the rates of episodes ({', '.join(rates)}) the Wilson score interval"
        if rates
        else ""
    )
    return (
        f"Intervals: BCa bootstrap of the mean{wilson}. (n=k): the metric has a value on k of "
        "the episodes."
    )


def markdown_report(
    summary: pd.DataFrame,
    comparisons: pd.DataFrame | None = None,
    *,
    tables: Tables = PERSON_FOLLOW_TABLES,
) -> str:
    """The headline table, the further metrics and (if given) the paired comparisons, with a
    note for each pair of policies that ran different seeds (:func:`eval.stats.pairing_notes`).
    """
    parts = [
        f"## {tables.title}: mean [95 % CI] over episodes\n",
        summary_markdown(summary, tables=tables),
    ]
    if any(m in summary and m not in tables.headline for m in tables.metrics):
        parts += ["\n\n## Further metrics\n", summary_markdown(summary, extras=True, tables=tables)]
    parts.append("\n\n" + _ci_note(tables))
    if comparisons is not None and not comparisons.empty:
        parts += [
            "\n\n## Paired differences on the seeds both ran: A - B [95 % CI], permutation p\n",
            comparison_markdown(comparisons, tables=tables),
            "\n\n" + COMPARISON_NOTE,
            holm_note(comparisons, tables=tables),
        ]
        notes = pairing_notes(comparisons)
        if notes:
            parts.append(
                "\n\n**Different seeds.** Each comparison pairs only the seeds both policies "
                "ran:\n\n" + "\n".join(f"- {note}" for note in notes)
            )
    return "".join(parts) + "\n"


def summary_latex(summary: pd.DataFrame, *, tables: Tables = PERSON_FOLLOW_TABLES) -> str:
    """The headline table as a LaTeX ``tabular`` (booktabs): mean [95 % CI] per cell, marked as
    in :func:`summary_markdown`."""
    table, _ = _metric_table(summary, [m for m in tables.headline if m in summary], tables)
    return table.to_latex(index=False, escape=True, column_format="ll" + "r" * (table.shape[1] - 2))


def _json_value(value: Any) -> Any:
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, np.generic):
        return _json_value(value.item())
    return value


def _records(frame: pd.DataFrame) -> list[dict[str, Any]]:
    return [{k: _json_value(v) for k, v in row.items()} for row in frame.to_dict("records")]


def write_tables(
    out: Path,
    summary: pd.DataFrame,
    episodes: pd.DataFrame,
    comparisons: pd.DataFrame,
    meta: Mapping[str, Any],
    *,
    tables: Tables = PERSON_FOLLOW_TABLES,
) -> dict[str, Path]:
    """Write summary.{csv,md,json,tex}, episodes.csv and comparisons.csv into ``out``.

    :param tables: the task's metrics (default PersonFollow's).
    :returns: the written files by kind.
    """
    float_format = "%.6g"
    files: dict[str, Path] = {}
    for name, frame in (
        ("summary.csv", summary),
        ("episodes.csv", episodes),
        ("comparisons.csv", comparisons),
    ):
        with atomic_path(out / name) as tmp:
            frame.to_csv(tmp, index=False, float_format=float_format, lineterminator="\n")
        files[name] = out / name
    files["summary.md"] = atomic_write_text(
        out / "summary.md", markdown_report(summary, comparisons, tables=tables)
    )
    files["summary.tex"] = atomic_write_text(
        out / "summary.tex", summary_latex(summary, tables=tables)
    )
    document = {
        "meta": {k: _json_value(v) for k, v in meta.items()},
        "metrics": {
            name: {"unit": m.unit, "label": m.label, "thesis": m.thesis}
            for name, m in tables.metrics.items()
        },
        "summary": _records(summary),
        "comparisons": _records(comparisons),
    }
    files["summary.json"] = atomic_write_text(
        out / "summary.json", json.dumps(document, indent=2, allow_nan=False) + "\n"
    )
    return files


# -- plots ----------------------------------------------------------------------------------------


def _pyplot() -> Any:
    import matplotlib

    matplotlib.use("Agg")  # no display: files only
    import matplotlib.pyplot as plt

    return plt


def _save(fig: Any, path: Path) -> Path:
    plt = _pyplot()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=110, bbox_inches="tight")
    plt.close(fig)
    return path


def plot_thesis_metrics(summary: pd.DataFrame, path: Path) -> Path:
    """Bar charts of the thesis's five metrics: scenarios on x, a bar per policy, 95 % CIs."""
    return plot_metric_bars(
        summary, path, THESIS_METRICS, "Thesis metrics, mean over episodes with 95 % bootstrap CI"
    )


def plot_metric_bars(
    summary: pd.DataFrame,
    path: Path,
    metrics: Sequence[str],
    title: str,
    labels: Mapping[str, Metric] = METRICS,
) -> Path:
    """Bar charts of ``metrics``, a panel each: scenarios (tracks) on x, a bar per policy,
    95 % CIs; panels titled by the metrics' labels in ``labels``."""
    plt = _pyplot()
    variant = variant_column(summary)
    policies = list(dict.fromkeys(summary["policy"]))
    scenarios = list(dict.fromkeys(summary[variant]))
    fig, axes = plt.subplots(1, len(metrics), figsize=(4.0 * len(metrics), 3.8))
    width = 0.8 / len(policies)
    x = np.arange(len(scenarios))
    for ax, name in zip(np.atleast_1d(axes), metrics, strict=True):
        for i, policy in enumerate(policies):
            rows = summary[summary["policy"] == policy].set_index(variant).reindex(scenarios)
            mean = rows[name].to_numpy(dtype=float)
            low = rows[f"{name}_ci_low"].to_numpy(dtype=float)
            high = rows[f"{name}_ci_high"].to_numpy(dtype=float)
            err = error_bars(mean, low, high)
            ax.bar(
                x + (i - (len(policies) - 1) / 2) * width,
                mean,
                width,
                yerr=err,
                capsize=3,
                label=policy,
            )
        ax.set_xticks(x, scenarios, rotation=30 if len(scenarios) > 3 else 0)
        ax.set_title(metric_label(name, labels))
        ax.grid(axis="y", alpha=0.3)
    np.atleast_1d(axes)[0].legend(fontsize="small")
    fig.suptitle(title)
    fig.tight_layout()
    return _save(fig, path)


def _one_seed(episodes: Sequence[Episode], seed: int) -> dict[str, list[Episode]]:
    by_scenario: dict[str, list[Episode]] = {}
    for ep in episodes:
        if ep.seed == seed:
            by_scenario.setdefault(ep.scenario, []).append(ep)
    return by_scenario


def plot_offsets(episodes: Sequence[Episode], seed: int, path: Path) -> Path:
    """Observed offset over time for every policy on one seed, a panel per scenario."""
    plt = _pyplot()
    by_scenario = _one_seed(episodes, seed)
    if not by_scenario:
        raise ValueError(f"no episode with seed {seed} to plot")
    fig, axes = plt.subplots(
        len(by_scenario), 1, figsize=(9, 3.0 * len(by_scenario)), squeeze=False
    )
    for ax, (scenario, eps) in zip(axes[:, 0], by_scenario.items(), strict=True):
        for ep in eps:
            log = ep.log
            ax.plot(log["time_s"], log["obs_offset_px"], label=ep.policy, lw=1.2)
        ax.axhline(0.0, color="k", lw=0.6)
        ax.set_title(f"{scenario}, seed {seed}: observed offset")
        ax.set_ylabel("offset (px, > 0 right)")
        ax.grid(alpha=0.3)
        ax.legend(fontsize="small")
    axes[-1, 0].set_xlabel("time (s)")
    fig.tight_layout()
    return _save(fig, path)


def plot_trajectories(episodes: Sequence[Episode], seed: int, path: Path) -> Path:
    """Top-down paths of the person and of every policy's robot on one seed, per scenario."""
    plt = _pyplot()
    by_scenario = _one_seed(episodes, seed)
    if not by_scenario:
        raise ValueError(f"no episode with seed {seed} to plot")
    n = len(by_scenario)
    fig, axes = plt.subplots(1, n, figsize=(5.5 * n, 5.0), squeeze=False)
    for ax, (scenario, eps) in zip(axes[0], by_scenario.items(), strict=True):
        person = eps[0].log
        ax.plot(person["person_x_m"], person["person_y_m"], "k--", lw=2, label="person")
        for ep in eps:
            (line,) = ax.plot(ep.log["robot_x_m"], ep.log["robot_y_m"], lw=1.2, label=ep.policy)
            end = ep.log.iloc[-1]
            ax.plot(end["robot_x_m"], end["robot_y_m"], "o", ms=4, color=line.get_color())
        ax.set_aspect("equal", adjustable="datalim")
        ax.set_title(f"{scenario}, seed {seed}")
        ax.set_xlabel("x (m)")
        ax.set_ylabel("y (m)")
        ax.grid(alpha=0.3)
        ax.legend(fontsize="small")
    fig.tight_layout()
    return _save(fig, path)


def write_video(
    policy: str,
    scenario: str,
    seed: int,
    path: Path,
    *,
    config: Any = "thesis",
    fps: int = 10,
    task: str = "person_follow",
) -> Path:
    """Render one episode (identical to the evaluated one) to an mp4 (OpenCV, mp4v).

    :param fps: frames per second; 10 plays the 0.1 s control steps in real time.
    :param task: the task (``"line_trace"``: ``scenario`` is a track).
    """
    import cv2

    from eval.rollout import run_episode

    writer: Any = None
    with atomic_path(path) as tmp:
        try:

            def on_frame(frame: np.ndarray) -> None:
                nonlocal writer
                if writer is None:
                    h, w = frame.shape[:2]
                    writer = cv2.VideoWriter(str(tmp), cv2.VideoWriter_fourcc(*"mp4v"), fps, (w, h))
                    if not writer.isOpened():
                        raise OSError(f"cannot open a video writer for {path}")
                writer.write(cv2.cvtColor(frame, cv2.COLOR_RGB2BGR))  # OpenCV wants BGR

            run_episode(policy, scenario, seed, config=config, on_frame=on_frame, task=task)
        finally:
            if writer is not None:
                writer.release()
    return path

"""What ``follow-eval run`` needs to know of each task, in one place per task.

The rollout, the statistics and the tables are the same machinery for every task
(:mod:`eval.rollout`, :mod:`eval.stats`, :mod:`eval.report`); an :class:`EvalTask` says what
differs: the name of the grid's variant (PersonFollow's scenarios, LineTrace's tracks), the
default policies and variants, the metrics and tables, how a ``--config`` text is read, the
video's frame rate and the plots. :func:`eval_task` gives one by name; a new task adds one entry
to :data:`EVAL_TASKS`.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pandas as pd

from eval.metrics import METRICS, Metric
from eval.report import PERSON_FOLLOW_TABLES, Tables
from eval.rollout import Episode

__all__ = ["EVAL_TASKS", "EvalTask", "eval_task"]

#: ``plots(summary, episodes, seed, folder, config)`` writes the task's plots into ``folder``.
PlotsFn = Callable[[pd.DataFrame, Sequence[Episode], int, Path, Any], None]


@dataclass(frozen=True)
class EvalTask:
    """One task as the evaluation sees it.

    :param name: the task (``follow_env.tasks.<name>``).
    :param variant: the grid's variant, singular (``scenario``, ``track``): the tables' column.
    :param default_policies: ``--policies`` when not given.
    :param default_variants: ``--scenarios`` / ``--tracks`` when not given.
    :param default_config: the preset ``--config`` means when not given.
    :param metrics: the metrics by name, in table order.
    :param tables: what the tables show (:class:`eval.report.Tables`).
    :param config_from_text: reads a ``--config`` text (``ValueError`` when bad).
    :param presets: the preset names, for the help text.
    :param fps: the video's frames per second (one frame per control step: real time).
    :param plots: writes the task's plots.
    :param summary_plot: writes the chart of the summary alone into a folder (what
        ``follow-eval metrics`` draws from logs, without the run's world).
    :param perfect_sensing: the run's ``--config`` (as :attr:`config_from_text` returns it)
        made perfectly sensed: the task's ``ideal`` preset's sensing fields over it, nothing
        else changed (``--ideal-baseline``).
    """

    name: str
    variant: str
    default_policies: str
    default_variants: str
    default_config: str
    metrics: Mapping[str, Metric]
    tables: Tables
    config_from_text: Callable[[str], Any]
    presets: Sequence[str]
    fps: int
    plots: PlotsFn
    summary_plot: Callable[[pd.DataFrame, Path], None]
    perfect_sensing: Callable[[Any], Any]

    @property
    def variants_option(self) -> str:
        """The command line's option naming the variants: ``scenarios`` or ``tracks``."""
        return f"{self.variant}s"


def _with_sensing_of(
    ideal: Any, sections: Sequence[str], randomized: Sequence[str] = ()
) -> Callable[..., Any]:
    """``(config, presets) -> config`` with ``ideal``'s fields of ``sections`` wherever
    ``ideal`` differs from the default preset (its sensing changes), and the ``randomized``
    fields of the ``randomization`` section (per-episode draws of sensing errors) off, as in
    the default preset; everything else as given. ``config`` is a preset name (looked up in
    ``presets``) or section overrides."""
    from dataclasses import fields

    base = type(ideal)()
    off = {name: getattr(base.randomization, name) for name in randomized}

    def perfect(config: Any, presets: Mapping[str, Any]) -> Any:
        given = presets[config] if isinstance(config, str) else base.replace(**config)
        changes: dict[str, dict[str, Any]] = {"randomization": off} if off else {}
        for section in sections:
            mine, theirs = getattr(base, section), getattr(ideal, section)
            changed = {
                f.name: getattr(theirs, f.name)
                for f in fields(theirs)
                if getattr(theirs, f.name) != getattr(mine, f.name)
            }
            if changed:
                changes[section] = changed
        return given.replace(**changes)

    return perfect


def _person_follow() -> EvalTask:
    from functools import partial

    from eval.report import plot_offsets, plot_thesis_metrics, plot_trajectories
    from follow_env.tasks.person_follow.config import IDEAL, PRESETS, config_from_text

    def summary_plot(summary: pd.DataFrame, folder: Path) -> None:
        plot_thesis_metrics(summary, folder / "thesis_metrics.png")

    def plots(summary: pd.DataFrame, episodes: Any, seed: int, folder: Path, config: Any) -> None:
        summary_plot(summary, folder)
        plot_offsets(episodes, seed, folder / f"offsets_seed{seed}.png")
        plot_trajectories(episodes, seed, folder / f"trajectories_seed{seed}.png")

    return EvalTask(
        "person_follow",
        "scenario",
        "pn,mpn,gsmpn",
        "straight,curve",
        "thesis",
        METRICS,
        PERSON_FOLLOW_TABLES,
        config_from_text,
        sorted(PRESETS),
        10,
        plots,
        summary_plot,
        # the detector's noise and latency, the depth's: the camera and perception sections,
        # and the randomisation's draws of them (the randomized preset's latency up to 3 frames)
        partial(
            _with_sensing_of(
                IDEAL,
                ("camera", "perception"),
                randomized=(
                    "camera_tilt_deg",
                    "detector_level_spread",
                    "latency_frames_max",
                    "depth_noise_scale_max",
                ),
            ),
            presets=PRESETS,
        ),
    )


def _line_trace() -> EvalTask:
    from functools import partial

    from eval.line_metrics import LINE_METRICS, LINE_TABLES
    from eval.line_report import plot_cross_track, plot_line_metrics, plot_line_paths
    from follow_env.tasks.line_trace.config import IDEAL, PRESETS, config_from_text

    def summary_plot(summary: pd.DataFrame, folder: Path) -> None:
        plot_line_metrics(summary, folder / "line_metrics.png")

    def plots(summary: pd.DataFrame, episodes: Any, seed: int, folder: Path, config: Any) -> None:
        summary_plot(summary, folder)
        plot_cross_track(episodes, seed, folder / f"cross_track_seed{seed}.png")
        plot_line_paths(episodes, seed, folder / f"paths_seed{seed}.png", config=config)

    return EvalTask(
        "line_trace",
        "track",
        "coordinate,pid",
        "straight,corners,curves,zigzag,gaps,course,random",
        "paper",
        LINE_METRICS,
        LINE_TABLES,
        config_from_text,
        sorted(PRESETS),
        50,
        plots,
        summary_plot,
        partial(_with_sensing_of(IDEAL, ("sensor",)), presets=PRESETS),  # the light grid's noise
    )


EVAL_TASKS: dict[str, Callable[[], EvalTask]] = {
    "person_follow": _person_follow,
    "line_trace": _line_trace,
}
"""Every task the evaluation runs, by name (built on first use: imports stay light)."""


def eval_task(name: str) -> EvalTask:
    """The task called ``name``; ``ValueError`` listing the known ones."""
    if name not in EVAL_TASKS:
        raise ValueError(
            f"task {name!r} is out of range: must be one of " + ", ".join(sorted(EVAL_TASKS))
        )
    return EVAL_TASKS[name]()

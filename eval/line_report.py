"""LineTrace's plots: what the robots did on one seed, beside the tables of :mod:`eval.report`.

- :func:`plot_line_metrics`: the headline line metrics as bars, a bar per policy per track, with
  95 % CIs (:func:`eval.report.plot_metric_bars`).
- :func:`plot_cross_track`: the cross-track error along the line, every policy on one seed, a
  panel per track.
- :func:`plot_line_paths`: the line (gaps dashed) and every policy's path on one seed, a panel
  per track; the line is the one the env laid for that seed (a ``random`` track differs per
  seed).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from eval.line_metrics import LINE_METRICS, LINE_TASK_METRICS
from eval.report import _one_seed, _pyplot, _save, plot_metric_bars
from eval.rollout import Episode

__all__ = ["LINE_PLOTTED_METRICS", "plot_cross_track", "plot_line_metrics", "plot_line_paths"]

#: The metrics of the bar chart (the task's six, in its order).
LINE_PLOTTED_METRICS: tuple[str, ...] = LINE_TASK_METRICS


def plot_line_metrics(summary: pd.DataFrame, path: Path) -> Path:
    """Bar charts of :data:`LINE_PLOTTED_METRICS`: tracks on x, a bar per policy, 95 % CIs."""
    return plot_metric_bars(
        summary,
        path,
        LINE_PLOTTED_METRICS,
        "Line tracing, mean over episodes with 95 % bootstrap CI",
        LINE_METRICS,
    )


def plot_cross_track(episodes: Sequence[Episode], seed: int, path: Path) -> Path:
    """Cross-track error (mm, > 0 robot left of the line) against progress along the line for
    every policy on one seed, a panel per track."""
    plt = _pyplot()
    by_track = _one_seed(episodes, seed)
    if not by_track:
        raise ValueError(f"no episode with seed {seed} to plot")
    fig, axes = plt.subplots(len(by_track), 1, figsize=(9, 2.8 * len(by_track)), squeeze=False)
    for ax, (track, eps) in zip(axes[:, 0], by_track.items(), strict=True):
        for ep in eps:
            log = ep.log
            label = f"{ep.policy} ({ep.termination})"
            ax.plot(log["progress_m"], 1000.0 * log["cross_track_m"], label=label, lw=1.0)
        ax.axhline(0.0, color="k", lw=0.6)
        ax.set_title(f"{track}, seed {seed}: cross-track error")
        ax.set_ylabel("error (mm, > 0 left)")
        ax.grid(alpha=0.3)
        ax.legend(fontsize="small")
    axes[-1, 0].set_xlabel("progress along the line (m)")
    fig.tight_layout()
    return _save(fig, path)


def _line_of(track: str, seed: int, config: Any) -> np.ndarray:
    """The line segments (float array, :data:`follow_env.world.floor_line.SEG` columns) the env
    lays for ``track`` and ``seed`` under ``config``."""
    import gymnasium as gym

    import follow_env  # noqa: F401  (registers the envs)

    env = gym.make("LineTrace-v0", track=track, config=config)
    try:
        env.reset(seed=int(seed))
        sim = env.unwrapped.sim
        (segs,) = sim.world
        n = int(sim.state["task"]["n_seg"][0])
        return segs[0].view(np.float64).reshape(segs.shape[1], -1)[:n].copy()
    finally:
        env.close()


def plot_line_paths(
    episodes: Sequence[Episode], seed: int, path: Path, *, config: Any = None
) -> Path:
    """The line (ink solid, gaps dashed) and every policy's path on one seed, per track."""
    from follow_env.world.floor_line import SEG

    plt = _pyplot()
    by_track = _one_seed(episodes, seed)
    if not by_track:
        raise ValueError(f"no episode with seed {seed} to plot")
    n = len(by_track)
    cols = min(n, 4)
    rows = -(-n // cols)
    fig, axes = plt.subplots(rows, cols, figsize=(4.5 * cols, 4.3 * rows), squeeze=False)
    for ax, (track, eps) in zip(axes.flat, by_track.items(), strict=False):
        segs = _line_of(track, seed, config)
        for ink, style in ((1.0, "-"), (0.0, ":")):
            pieces = segs[segs[:, SEG.ink] == ink]
            xs = np.stack([pieces[:, SEG.x1], pieces[:, SEG.x2], np.full(len(pieces), np.nan)])
            ys = np.stack([pieces[:, SEG.y1], pieces[:, SEG.y2], np.full(len(pieces), np.nan)])
            ax.plot(xs.T.ravel(), ys.T.ravel(), style, color="k", lw=3.0 if ink else 1.5)
        for ep in eps:
            (line,) = ax.plot(ep.log["robot_x_m"], ep.log["robot_y_m"], lw=1.0, label=ep.policy)
            end = ep.log.iloc[-1]
            ax.plot(end["robot_x_m"], end["robot_y_m"], "o", ms=4, color=line.get_color())
        ax.set_aspect("equal", adjustable="datalim")
        ax.set_title(f"{track}, seed {seed}")
        ax.set_xlabel("x (m)")
        ax.set_ylabel("y (m)")
        ax.grid(alpha=0.3)
        ax.legend(fontsize="small")
    for ax in list(axes.flat)[n:]:
        ax.set_visible(False)
    fig.tight_layout()
    return _save(fig, path)

"""Identical-rollout evaluation: run controllers on the same grid, score them, report.

- :func:`rollout` runs policies (by name, as everywhere) on a scenario x seed grid, so every
  policy meets the same person and the same sensor noise (:mod:`eval.rollout`); each policy is
  built and checked first, by the same check as ``follow-eval run`` (:mod:`eval.grid`).
- Step logs (:mod:`eval.steplog`) are CSV, one row per control step, in a layout a real robot's
  log can be written in; :func:`read_step_log` validates one.
- :data:`METRICS` are functions over a step log: the thesis's five (reference §1.6) and more
  (:mod:`eval.metrics`); :func:`episode_metrics` computes them all.
- :func:`summarize` and :func:`compare` give bootstrap CIs and paired tests (:mod:`eval.stats`);
  :func:`eval.scoring.score` computes them with the step logs, scenario by scenario on a backend;
  :mod:`eval.report` writes tables, plots and videos; ``follow-eval`` (:mod:`eval.cli`) fronts it.
- ``follow-tune`` (:mod:`eval.tuning`) searches a registered law's parameters with Optuna on the
  same rollouts and checks the best on held-out seeds: the search behind the ``tuned`` presets.

Example::

    from eval import rollout, episode_table, summarize
    episodes = rollout(["pn", "gsmpn"], ["straight"], range(5))
    print(summarize(episode_table(episodes))[["policy", "mean_offset_px", "std_accel_mm_s2"]])
"""

from eval.metrics import METRICS, THESIS_METRICS, Metric, episode_metrics, metric
from eval.rollout import Episode, rollout, run_episode
from eval.stats import compare, episode_table, summarize
from eval.steplog import COLUMNS, StepLogError, read_step_log, write_step_log

__all__ = [
    "COLUMNS",
    "METRICS",
    "THESIS_METRICS",
    "Episode",
    "Metric",
    "StepLogError",
    "compare",
    "episode_metrics",
    "episode_table",
    "metric",
    "read_step_log",
    "rollout",
    "run_episode",
    "summarize",
    "write_step_log",
]

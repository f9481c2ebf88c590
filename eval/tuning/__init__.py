"""Tuning: a registered law's parameters searched with Optuna, checked on held-out seeds.

``follow-tune LAW`` (:mod:`eval.tuning.cli`) tunes any law registered with a search space
(``SEARCH_SPACE`` beside its ``PRESETS``, :mod:`policies.space`): ``pn``, ``mpn``, ``gsmpn`` on
PersonFollow, ``coordinate`` and ``pid`` on LineTrace. It replaces the grids of the former
``eval.tune`` and ``eval.line_tune`` (now thin wrappers onto it).

1. **Objective** (:mod:`eval.tuning.objective`): the env's own reward summed per episode,
   averaged over the task's tuning variants x tuning seeds 1000 + k (the evaluation's seeds
   are 0..19).
2. **Search** (:mod:`eval.tuning.driver`): a seeded TPE sampler; trials asked in batches of the
   backend's slots, each batch's episodes placed as work units on the execution layer
   (:func:`eval.rollout.rollout` on a :class:`execution.Backend`: this process, a pool, Ray);
   every trial scored on a quarter, a half, then all of its seeds, reported after each rung,
   and pruned by a median pruner when it trails. The current preset is the first trial.
3. **Storage**: a journal file (``JournalStorage(JournalFileBackend(path))``, default
   ``OUT/study.journal``), or an RDB URL for several machines. The same command on the same
   storage resumes the study and runs only the trials still missing, if the study was made
   with the same settings and scored by the same code; running trials whose machine is gone
   (no heartbeat for 10 min) are failed, so they stop counting towards the budget.
4. **Held-out check** (:mod:`eval.tuning.holdout`): the top trials and the current preset
   re-scored on held-out seeds 2000 + k, with bootstrap CIs and paired permutation tests,
   and one chosen by the one-standard-error rule, replacing the preset only on evidence (a
   difference significant by the evaluation's rule, or as good and smoother).
5. **Output** (:mod:`eval.tuning.report`): ``OUT/result.json`` and ``OUT/preset.txt`` (written
   atomically), and the table on stdout.
"""

from eval.tuning.driver import SearchConfig, open_study, run_search, rungs
from eval.tuning.holdout import Candidate, choose, holdout_candidates, reevaluate, verdict
from eval.tuning.objective import HOLDOUT_SEED0, TUNE_SEED0, LawObjective, episode_score

__all__ = [
    "HOLDOUT_SEED0",
    "TUNE_SEED0",
    "Candidate",
    "LawObjective",
    "SearchConfig",
    "choose",
    "episode_score",
    "holdout_candidates",
    "open_study",
    "reevaluate",
    "run_search",
    "rungs",
    "verdict",
]

"""After the search: the best trials and the current preset re-scored on held-out seeds.

The search's best score is biased upwards (the best of many noisy means), so it never decides
alone. The top trials (distinct parameters, by search score) and the law's current preset run
again on held-out seeds (2000 + k: neither tuning nor evaluation seeds), all on the same
episodes, and each gets its mean reward per episode with a 95 % bootstrap CI and its paired
difference from the current preset with a CI and a sign-flip permutation p-value
(:func:`eval.stats.paired_test`).

The choice (:func:`choose`) is the one-standard-error rule, as the grid search before it made
it, with one addition: every candidate whose paired shortfall against the held-out top scorer is
within one standard error of that shortfall, and that failed (lost the person or the line,
collided) in no more episodes than the top scorer, is "as good" (``within_1se``); of those the
one that turns most smoothly (lowest mean turn accel RMS) is ``chosen``. (Without the failure
clause a candidate could pass *because* of a failure: its one very bad episode widens the very
standard error it is measured against.) The current preset is a candidate,
and a trial replaces it only with evidence: a held-out mean significantly above the preset's
by the evaluation's rule (:data:`eval.dominance.RULE`: the paired difference's 95 % CI above 0
*and* its permutation p < 0.05, :attr:`eval.stats.PairedTest.direction`), or within one
standard error of the best and a smoother turn than the preset's. So the preset stays unless a
trial scored better, or as well and more smoothly, on episodes none of them was tuned on;
:func:`verdict` says which.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
import optuna
from optuna.trial import TrialState

from eval.stats import ALPHA, PairedTest, mean_ci, paired_test
from eval.tuning.objective import LawObjective

__all__ = ["Candidate", "choose", "holdout_candidates", "reevaluate", "rounded", "verdict"]

#: The bootstrap seed of every held-out interval.
BOOTSTRAP_SEED = 0
#: Significant digits of the re-scored values (and of the preset lines written).
DIGITS = 3


@dataclass(frozen=True)
class Candidate:
    """A parameter set re-scored on the held-out seeds.

    :param label: its name in tables (``trial 12``, ``pn:tuned``).
    :param values: the searched fields' values (the rest are the law's default preset's).
    :param trial: its trial number, or None for the current preset.
    :param search_score: its mean score in the search (None if it never ran there).
    """

    label: str
    values: Mapping[str, float]
    trial: int | None = None
    search_score: float | None = None


def rounded(values: Mapping[str, float], digits: int = DIGITS) -> dict[str, float]:
    """``values`` to ``digits`` significant digits (what a preset line holds)."""
    return {k: float(f"{float(v):.{digits}g}") for k, v in values.items()}


def holdout_candidates(
    study: optuna.Study, current: Candidate, top: int, digits: int = DIGITS
) -> list[Candidate]:
    """The ``top`` best complete trials, best first, their values rounded to ``digits``
    significant digits (so the values re-scored are the ones a preset line would hold) and
    distinct after rounding, then ``current`` (a trial equal to it is left out)."""
    done = list(study.get_trials(deepcopy=False, states=(TrialState.COMPLETE,)))
    done.sort(key=lambda t: (-float(t.value), t.number))  # type: ignore[arg-type]
    seen = [rounded(current.values, digits)]
    out: list[Candidate] = []
    for t in done:
        if len(out) >= top:
            break
        values = rounded(t.params, digits)
        if values in seen:
            continue
        seen.append(values)
        out.append(Candidate(f"trial {t.number}", values, t.number, float(t.value)))  # type: ignore[arg-type]
    if current.search_score is None:  # the preset ran in the search too (the first trial)
        same = (t for t in done if rounded(t.params, digits) == seen[0])
        first = next(same, None)
        if first is not None:
            current = replace(current, search_score=float(first.value))  # type: ignore[arg-type]
    return [*out, current]


def reevaluate(
    objective: LawObjective, candidates: Sequence[Candidate], seeds: Sequence[int]
) -> list[dict[str, Any]]:
    """Score every candidate on ``seeds`` x the objective's variants (identical rollouts) and
    choose one (:func:`choose`); one row per candidate, in the given order (the current
    preset, the last candidate, is the reference of the paired differences)."""
    law = objective.law
    names = [f"{law.law}#{c.trial}" if c.trial is not None else c.label for c in candidates]
    policies = [law.policy(c.values, n) for c, n in zip(candidates, names, strict=True)]
    results = objective.score(policies, seeds)
    return choose(candidates, [{k: v.ravel() for k, v in r.items()} for r in results])


def choose(
    candidates: Sequence[Candidate], episodes: Sequence[Mapping[str, np.ndarray]]
) -> list[dict[str, Any]]:
    """The held-out table and the one-standard-error choice (module docstring).

    :param candidates: the candidates, the current preset last.
    :param episodes: per candidate, per-episode arrays on the same episodes in the same order:
        ``score`` (summed reward), ``turn_accel_rms_rad_s2`` and ``failed`` (0/1).
    :returns: per candidate: ``label, trial, search_score, holdout_mean, ci_low, ci_high,
        diff_vs_current, diff_ci_low, diff_ci_high, diff_perm_p, se_gap, within_1se,
        turn_accel_rms_rad_s2, failed, chosen, values`` (the current preset's difference is
        the point 0 with p = 1).
    """
    if not candidates or len(candidates) != len(episodes):
        raise ValueError("give one set of episodes per candidate, at least one candidate")
    scores = np.stack([np.asarray(e["score"], dtype=np.float64) for e in episodes])
    n = scores.shape[1]
    means = scores.mean(axis=1)
    top = int(np.argmax(means))
    gaps = scores[top] - scores  # paired shortfall per episode
    se = gaps.std(axis=1, ddof=1) / np.sqrt(n) if n > 1 else np.zeros(len(candidates))
    failed = np.stack([np.asarray(e["failed"], dtype=np.float64) for e in episodes]).sum(axis=1)
    # A failure costs more than neighbouring gains do, and inflates the candidate's own standard
    # error: one that failed more often than the top scorer is not "as good", however wide its SE.
    within = (gaps.mean(axis=1) <= se + 1e-12) & (failed <= failed[top])
    current = scores[-1]
    rows = []
    for i, (c, e) in enumerate(zip(candidates, episodes, strict=True)):
        low, high = mean_ci(scores[i], BOOTSTRAP_SEED, c.label, "holdout")
        diff = scores[i] - current
        # paired_test draws its CI from the stream mean_ci drew it from: the intervals as before
        test = (
            PairedTest(0.0, 0.0, 0.0, 1.0)
            if i == len(candidates) - 1
            else paired_test(diff, BOOTSTRAP_SEED, c.label, candidates[-1].label, "diff")
        )
        rows.append(
            {
                "label": c.label,
                "trial": c.trial,
                "search_score": c.search_score,
                "holdout_mean": float(means[i]),
                "ci_low": low,
                "ci_high": high,
                "diff_vs_current": float(diff.mean()),
                "diff_ci_low": test.low,
                "diff_ci_high": test.high,
                "diff_perm_p": test.p,
                "se_gap": float(se[i]),
                "within_1se": bool(within[i]),
                "turn_accel_rms_rad_s2": float(np.nanmean(e["turn_accel_rms_rad_s2"])),
                "failed": int(np.sum(e["failed"])),
                "chosen": False,
                "values": {k: float(v) for k, v in c.values.items()},
            }
        )
    pool = [r for r in rows if r["within_1se"]]
    # Ties in smoothness go to the current preset (last), then to the better held-out mean.
    best = min(
        pool, key=lambda r: (r["turn_accel_rms_rad_s2"], r["trial"] is not None, -r["holdout_mean"])
    )
    # Only evidence replaces the current preset: a held-out score significantly better than
    # the preset's by the evaluation's rule (CI above 0 and permutation p < ALPHA: the CI
    # alone calls too many differences significant on paired seeds, eval.stats), or one as
    # good and a smoother turn.
    now = rows[-1]
    if not (_better(best) or best["turn_accel_rms_rad_s2"] < now["turn_accel_rms_rad_s2"]):
        best = now
    best["chosen"] = True
    return rows


def _better(row: Mapping[str, Any]) -> bool:
    """Whether a held-out row's paired difference from the current preset is significantly
    above 0 by the evaluation's rule (:attr:`eval.stats.PairedTest.direction`)."""
    test = PairedTest(
        row["diff_vs_current"], row["diff_ci_low"], row["diff_ci_high"], row["diff_perm_p"]
    )
    return test.direction > 0


def verdict(rows: Sequence[Mapping[str, Any]]) -> str:
    """One sentence on what the held-out check says about the current preset (the last row)."""
    chosen = next(r for r in rows if r["chosen"])
    current = rows[-1]
    if chosen is current:
        return f"keep {current['label']}: no trial is better on the held-out seeds by the rule"
    low, high = chosen["diff_ci_low"], chosen["diff_ci_high"]
    if _better(chosen):
        how = (
            "better than the current preset (its paired difference's 95 % CI is above 0 and "
            f"the permutation test's p < {ALPHA:g})"
        )
    else:
        where = "also within it" if current["within_1se"] else "below it"
        how = (
            "within one standard error of the best held-out score and the most smoothly "
            f"turning of those (the current preset: {where})"
        )
    return (
        f"replace {current['label']} by {chosen['label']}: {how}; paired difference "
        f"{chosen['diff_vs_current']:+.2f} [{low:+.2f}, {high:+.2f}] per episode, "
        f"p {chosen['diff_perm_p']:.2g}"
    )

"""After the search: the best trials and the current preset re-scored on held-out seeds.

The search's best score is biased upwards (the best of many noisy means), so it never decides
alone. The top trials (distinct parameters, by search score) and the law's current preset run
again on held-out seeds (2000 + k: neither tuning nor evaluation seeds), all on the same
episodes, and each gets its mean reward per episode with a 95 % bootstrap CI and its paired
difference from the current preset with a CI and a sign-flip permutation p-value
(:func:`eval.stats.paired_test`).

The choice (:func:`choose`) is the one-standard-error rule, as the grid search before it made
it, with evidence required: every candidate whose paired shortfall against the held-out top
scorer is within one standard error of that shortfall, and that failed (lost the person or the
line, collided) in no more episodes than the top scorer, is "as good" (``within_1se``). (Without
the failure clause a candidate could pass *because* of a failure: its one very bad episode
widens the very standard error it is measured against.) Of those, a trial may replace the
current preset (the last candidate) only with evidence against it, by the evaluation's rule
(:data:`eval.dominance.RULE`: the paired difference's 95 % CI on one side of 0 *and* its
permutation p < 0.05, :attr:`eval.stats.PairedTest.direction`), the p adjusted by Holm's method
over the trials re-scored (the best of ``--top`` would otherwise pass by chance more often than
the level says):

- a held-out score significantly above the preset's, by at least :data:`MIN_GAIN` of it; or
- a score not significantly below the preset's and a turn significantly smoother (the same rule
  on the paired per-episode turn accel RMS), by at least :data:`MIN_SMOOTHER` of the preset's.

Of the trials that may, the one that turns most smoothly is ``chosen``; if none may, the preset
stays. :func:`verdict` says which, and why. (Until 2026-12-06 the smoothest "as good" candidate
was picked first and only then asked for evidence, so a trial better by the rule could be
passed over for a smoother one that had none; smoothness was compared by its means alone, and
the trials' p-values were not adjusted.)
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
import optuna
from optuna.trial import TrialState

from eval.stats import ALPHA, PairedTest, holm, mean_ci, paired_test
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
        diff_vs_current, diff_ci_low, diff_ci_high, diff_perm_p, diff_holm_p, se_gap,
        within_1se, turn_accel_rms_rad_s2, smoother_diff, smoother_ci_low, smoother_ci_high,
        smoother_perm_p, smoother_holm_p, failed, chosen, values`` (``smoother_*``: the paired
        turn accel RMS the preset's minus the candidate's; the current preset's differences
        are the point 0 with p = 1).
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
    # Evidence against the preset, each kind over the family of trials re-scored (Holm): the
    # best of --top trials tested on the episodes it was picked on would pass by chance more
    # often than the level says.
    trial_rows = rows[:-1]
    turns = [np.asarray(e["turn_accel_rms_rad_s2"], dtype=np.float64) for e in episodes]
    smoother = [
        paired_test(turns[-1] - turns[i], BOOTSTRAP_SEED, c.label, "turn")
        for i, c in enumerate(candidates[:-1])
    ]
    diff_holm = holm([r["diff_perm_p"] for r in trial_rows])
    turn_holm = holm([t.p for t in smoother])
    for r, dh, t, th in zip(trial_rows, diff_holm, smoother, turn_holm, strict=True):
        r.update(diff_holm_p=float(dh), smoother_diff=t.mean, smoother_ci_low=t.low)
        r.update(smoother_ci_high=t.high, smoother_perm_p=t.p, smoother_holm_p=float(th))
    rows[-1].update(diff_holm_p=1.0, smoother_diff=0.0, smoother_ci_low=0.0, smoother_ci_high=0.0)
    rows[-1].update(smoother_perm_p=1.0, smoother_holm_p=1.0)  # the preset against itself
    # Only evidence replaces the current preset: among the candidates as good as the held-out
    # top (within_1se), one whose score is significantly above the preset's by the evaluation's
    # rule (CI above 0 and permutation p < ALPHA, Holm-adjusted) by at least MIN_GAIN of it, or
    # one whose score is not significantly below it and whose turn is significantly smoother
    # (the same rule on the paired turn accel RMS) by at least MIN_SMOOTHER. Of those, the most
    # smoothly turning; none: the preset stays.
    now = rows[-1]
    eligible = [
        r
        for r in trial_rows
        if r["within_1se"] and (_better(r, now) or (_not_worse(r) and _smoother(r, now)))
    ]
    smoothest = min(
        eligible, key=lambda r: (r["turn_accel_rms_rad_s2"], -r["holdout_mean"]), default=now
    )
    smoothest["chosen"] = True
    return rows


#: The least held-out gain [share of the preset's mean score per episode] that replaces a preset
#: on score: paired, nearly identical rollouts make a gain of 0.1 % significant, and a preset
#: rewritten for it changes every result computed with it for nothing anyone would notice.
MIN_GAIN = 0.01
#: The least reduction of the turn accel RMS [share of the preset's] that replaces a preset on
#: smoothness, for the same reason.
MIN_SMOOTHER = 0.05


def _better(row: Mapping[str, Any], now: Mapping[str, Any]) -> bool:
    """Whether a held-out row's paired difference from the current preset is significantly
    above 0 by the evaluation's rule (:attr:`eval.stats.PairedTest.direction`, its p adjusted
    by Holm over the trials) and at least :data:`MIN_GAIN` of the preset's mean."""
    test = PairedTest(
        row["diff_vs_current"], row["diff_ci_low"], row["diff_ci_high"], row["diff_holm_p"]
    )
    return test.direction > 0 and row["diff_vs_current"] >= MIN_GAIN * abs(now["holdout_mean"])


def _not_worse(row: Mapping[str, Any]) -> bool:
    """Whether a held-out row's score is not significantly below the preset's (unadjusted:
    the stricter reading for the candidate)."""
    test = PairedTest(
        row["diff_vs_current"], row["diff_ci_low"], row["diff_ci_high"], row["diff_perm_p"]
    )
    return test.direction >= 0


def _smoother(row: Mapping[str, Any], now: Mapping[str, Any]) -> bool:
    """Whether a held-out row turns significantly more smoothly than the preset (Holm over the
    trials) and by at least :data:`MIN_SMOOTHER` of the preset's turn accel RMS."""
    keys = ("smoother_diff", "smoother_ci_low", "smoother_ci_high", "smoother_holm_p")
    test = PairedTest(*(row[k] for k in keys))
    gain = now["turn_accel_rms_rad_s2"] - row["turn_accel_rms_rad_s2"]
    return test.direction > 0 and gain >= MIN_SMOOTHER * now["turn_accel_rms_rad_s2"]


def verdict(rows: Sequence[Mapping[str, Any]]) -> str:
    """One sentence on what the held-out check says about the current preset (the last row)."""
    chosen = next(r for r in rows if r["chosen"])
    current = rows[-1]
    if chosen is current:
        return f"keep {current['label']}: no trial is better on the held-out seeds by the rule"
    low, high = chosen["diff_ci_low"], chosen["diff_ci_high"]
    if _better(chosen, current):
        how = (
            "better than the current preset (its paired difference's 95 % CI is above 0, the "
            f"permutation test's p < {ALPHA:g} with Holm's correction over the trials, and the "
            f"gain at least {MIN_GAIN * 100:g} % of the preset's score)"
        )
    else:
        how = (
            "within one standard error of the best held-out score, not significantly below the "
            "current preset, and turning significantly more smoothly than it (Holm over the "
            f"trials; at least {MIN_SMOOTHER * 100:g} % less turn accel RMS): the smoothest "
            "such trial"
        )
    return (
        f"replace {current['label']} by {chosen['label']}: {how}; paired difference "
        f"{chosen['diff_vs_current']:+.2f} [{low:+.2f}, {high:+.2f}] per episode, "
        f"p {chosen['diff_perm_p']:.2g} (Holm {chosen['diff_holm_p']:.2g})"
    )

"""Tune the guidance laws' gains in simulation: the search behind the ``tuned`` presets.

    python -m eval.tune                # the search whose result is committed (about a minute)
    python -m eval.tune --seeds 4      # quicker, coarser

A grid search, per law, over the gains that shape its behaviour, scoring every candidate by the
**environment's own reward** (``PersonFollowEnv`` docstring, ``RewardConfig``: distance error,
true offset, acceleration, frame loss, collisions), summed over episodes of the default robot
(``config="thesis"``) on ``straight``, ``curve`` and ``random``. The reward is the task's
declared objective, the same one a learned controller (PPO) is trained on, so a tuned law and a
trained agent are judged against the same target. Episodes end early on a loss or a collision,
so the summed reward also punishes those.

The tuning seeds (1000 + k) are disjoint from the evaluation seeds (``make eval`` uses 0..19):
the presets are not fitted to the episodes they are judged on. Every law keeps the thesis's
navigation constant N = 0.1 and d_ref = 1 m (only the product N kw matters, so kw carries the
proportional gain), the thesis's dt = 0.1 s and, for GS-MPN, the default variant.

The grid is deterministic and the episodes are identical rollouts, so the search is exactly
reproducible; it prints the best candidates per law and the preset lines to paste into
``policies/<law>.py``.
"""

from __future__ import annotations

import argparse
import itertools
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
import pandas as pd

from eval.metrics import METRICS
from eval.rollout import Episode, rollout
from policies import GSMPN, GSMPN_THESIS, MPN, MPN_THESIS, PN, PN_THESIS, Policy

__all__ = ["SCENARIOS", "TUNE_SEED0", "Candidate", "candidates", "main", "search"]

#: Scenarios the gains are tuned on: the thesis's two conditions and the richer random walk.
SCENARIOS: tuple[str, ...] = ("straight", "curve", "random")
#: First tuning seed; far from the evaluation seeds 0..19 so the two never overlap.
TUNE_SEED0 = 1000

# The grid (SI; module docstring). kv [1/s]; kw [rad/s/px] with N = 0.1, so N kw spans
# 3 .. 14 mrad/s/px around the thesis's 5; derivative gains [rad/px] from "off" to 100 x the
# thesis's 1e-4; the schedule's steepness a [s/px] from a gain that ramps over ~2000 px/s to one
# saturated at ~20 px/s (the detector's jitter alone moves the offset by ~300 px/s at 1 m).
KV_PER_S = (3.0, 5.0, 8.0)
KW_RAD_PER_S_PX = (0.03, 0.05, 0.07, 0.1)
MPN_LAMBDA = (0.0, 1e-4, 3e-4, 1e-3, 3e-3)
GSMPN_LAMBDA_D = (1e-4, 3e-4, 1e-3, 3e-3, 1e-2)
GSMPN_A = (0.001, 0.01, 0.1)


@dataclass(frozen=True)
class Candidate:
    """One point of the grid: a law with its gains, named by them."""

    law: str
    policy: Policy


def candidates() -> list[Candidate]:
    """Every grid point of every law, PN then MPN then GS-MPN."""
    out: list[Candidate] = []
    for kv, kw in itertools.product(KV_PER_S, KW_RAD_PER_S_PX):
        params = replace(PN_THESIS, kv_per_s=kv, kw_rad_per_s_px=kw)
        out.append(Candidate("pn", PN(params, name=f"pn kv={kv:g} kw={kw:g}")))
    for kv, kw, lam in itertools.product(KV_PER_S, KW_RAD_PER_S_PX, MPN_LAMBDA):
        params = replace(MPN_THESIS, kv_per_s=kv, kw_rad_per_s_px=kw, lambda_rad_per_px=lam)
        out.append(Candidate("mpn", MPN(params, name=f"mpn kv={kv:g} kw={kw:g} lambda={lam:g}")))
    for kv, kw, lam, a in itertools.product(KV_PER_S, KW_RAD_PER_S_PX, GSMPN_LAMBDA_D, GSMPN_A):
        params = replace(GSMPN_THESIS, kv_per_s=kv, kw_rad_per_s_px=kw, lambda_d=lam, a=a)
        name = f"gsmpn kv={kv:g} kw={kw:g} lambda_d={lam:g} a={a:g}"
        out.append(Candidate("gsmpn", GSMPN(params, name=name)))
    return out


def search(
    grid: Sequence[Candidate], seeds: int, *, workers: int | None = None, progress: bool = True
) -> pd.DataFrame:
    """Score every candidate and pick one per law by the one-standard-error rule.

    ``score`` is the env's summed reward per episode, averaged over ``SCENARIOS`` x ``seeds``
    tuning seeds. Rare events (an occlusion burst while the person brakes, a loss in a sharp
    turn) move it by more than neighbouring gains do, so the top scores are often statistically
    indistinguishable. Per law, every candidate whose paired shortfall against the top scorer
    (same scenario and seed) is within one standard error of that shortfall is "as good"
    (``within_1se``); of those, the one with the smoothest turning (lowest mean
    ``turn_accel_rms_rad_s2``) is ``chosen``: the one-standard-error rule of model selection
    (Breiman et al., 1984), with smoothness, the thesis's other aim, as the tie-break.

    :returns: one row per candidate: ``law, policy, score, se_gap`` (the standard error of its
        shortfall), ``within_1se, chosen, turn_accel_rms_rad_s2, lost, collisions`` (episode
        counts), ``params``; per law the chosen row first, then by score.
    """
    results = rollout(
        [c.policy for c in grid],
        list(SCENARIOS),
        list(range(TUNE_SEED0, TUNE_SEED0 + seeds)),
        workers=workers,
        progress=progress,
        reduce=_episode_score,
    )
    columns = ["policy", "scenario", "seed", "score", "turn", "lost", "collisions"]
    episodes = pd.DataFrame(results, columns=columns)
    by_name = {c.policy.name: c for c in grid}
    episodes["law"] = [by_name[p].law for p in episodes["policy"]]
    rows = []
    for law, in_law in episodes.groupby("law", sort=False):
        scores = in_law.pivot(index=["scenario", "seed"], columns="policy", values="score")
        means = scores.mean()
        top = means.idxmax()
        gaps = scores[[top]].to_numpy() - scores.to_numpy()  # paired shortfall per episode
        n = gaps.shape[0]
        se = gaps.std(axis=0, ddof=1) / np.sqrt(n) if n > 1 else np.zeros(gaps.shape[1])
        gap = gaps.mean(axis=0)
        per_policy = in_law.groupby("policy", sort=False)
        for j, policy in enumerate(scores.columns):
            group = per_policy.get_group(policy)
            rows.append(
                {
                    "law": law,
                    "policy": policy,
                    "score": float(means[policy]),
                    "se_gap": float(se[j]),
                    "within_1se": bool(gap[j] <= se[j]),
                    "turn_accel_rms_rad_s2": float(group["turn"].mean()),
                    "lost": int(group["lost"].sum()),
                    "collisions": int(group["collisions"].sum()),
                    "params": repr(getattr(by_name[policy].policy, "params", None)),
                }
            )
    table = pd.DataFrame(rows)
    table["chosen"] = False
    for _, in_law in table.groupby("law", sort=False):
        pool = in_law[in_law["within_1se"]]
        table.loc[pool["turn_accel_rms_rad_s2"].idxmin(), "chosen"] = True
    return table.sort_values(
        ["law", "chosen", "score"], ascending=[True, False, False], ignore_index=True
    )


def _episode_score(episode: Episode) -> tuple[str, str, int, float, float, int, int]:
    """(policy, scenario, seed, summed reward, turn accel RMS, lost?, collision?); in the worker."""
    ending = episode.termination
    reward = float(episode.log["reward"].sum())  # the reset row's NaN is skipped
    turn = METRICS["turn_accel_rms_rad_s2"].fn(episode.log)
    return (
        episode.policy,
        episode.scenario,
        episode.seed,
        reward,
        turn,
        int(ending == "lost"),
        int(ending.startswith("collision")),
    )


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m eval.tune``: run the search and print the best gains per law."""
    parser = argparse.ArgumentParser(prog="python -m eval.tune", description=__doc__.split("\n")[0])
    parser.add_argument(
        "--seeds", type=int, default=20, help="tuning seeds per scenario (default: %(default)s)"
    )
    parser.add_argument(
        "--workers", type=int, default=None, help="processes (default: chosen by eval.rollout)"
    )
    parser.add_argument("--top", type=int, default=3, help="candidates shown per law")
    args = parser.parse_args(argv)
    if args.seeds < 1 or (args.workers is not None and args.workers < 1) or args.top < 1:
        print(
            "python -m eval.tune: error: --seeds, --workers and --top must be >= 1", file=sys.stderr
        )
        return 2
    grid = candidates()
    started = time.perf_counter()
    table = search(grid, args.seeds, workers=args.workers)
    elapsed = time.perf_counter() - started
    n_eps = len(grid) * len(SCENARIOS) * args.seeds
    print(
        f"{len(grid)} candidates x {len(SCENARIOS)} scenarios x {args.seeds} seeds "
        f"({TUNE_SEED0}..{TUNE_SEED0 + args.seeds - 1}) = {n_eps} episodes in {elapsed:.0f} s"
    )
    pd.set_option("display.width", 200)
    pd.set_option("display.max_colwidth", 60)
    shown = ["policy", "score", "se_gap", "within_1se", "chosen", "turn_accel_rms_rad_s2"]
    shown += ["lost", "collisions"]
    for law, group in table.groupby("law", sort=False):
        print(
            f"\n{law}: {group['within_1se'].sum()} of {len(group)} candidates within one standard "
            f"error of the top score; the chosen one, then the top {args.top} by score"
        )
        top = group[~group["chosen"]].head(args.top)
        print(pd.concat([group[group["chosen"]], top])[shown].to_string(index=False))
    print("\nPreset lines (policies/<law>.py):")
    for law in ("pn", "mpn", "gsmpn"):
        chosen = table[(table["law"] == law) & table["chosen"]].iloc[0]
        print(f"{law.upper()}_TUNED = {chosen['params']}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""Tune the line followers in simulation: the search behind their ``tuned`` presets.

    python -m eval.line_tune              # the search whose result is committed (a few minutes)
    python -m eval.line_tune --seeds 2    # quicker, coarser

The same search for both controllers, so that neither is compared untuned against a tuned
other: a grid over the parameters that shape each one's behaviour (coordinate control: its
speed and turn gain, the paper's circle of 3 cells kept; the PID: its speed and its
proportional and derivative gains), every candidate scored by the **environment's own reward**
(``LineTraceEnv`` docstring: progress along the line, cross-track error, smoothness, losing
the line), summed per episode and averaged over the tuning tracks x seeds on the default robot
(``config="paper"``, the mecanum base). The candidate with the highest mean is chosen. The
search knows nothing of the evaluation's metrics.

The tuning seeds (1000 + k) are disjoint from the evaluation's (0..19), and the tuning tracks
leave out ``course`` and ``random``, the evaluation's mixed courses, so the presets are not
fitted to the episodes that judge them.
"""

from __future__ import annotations

import argparse
import itertools
import sys
import time
from collections.abc import Sequence
from dataclasses import replace

import pandas as pd

from eval.rollout import Episode, rollout
from policies.base import Policy
from policies.coordinate import PRESETS as COORDINATE_PRESETS
from policies.coordinate import Coordinate
from policies.pid_line import PRESETS as PID_PRESETS
from policies.pid_line import PIDLine

__all__ = ["TRACKS", "TUNE_SEED0", "candidates", "main", "search"]

#: Tracks the controllers are tuned on: one of each kind of tile.
TRACKS: tuple[str, ...] = ("straight", "corners", "curves", "zigzag", "gaps")
#: First tuning seed; far from the evaluation seeds 0..19.
TUNE_SEED0 = 1000

SPEED_MPS = (0.15, 0.2, 0.3, 0.4, 0.5)
COORDINATE_TURN_GAIN = (2.0, 4.0, 8.0, 16.0)  # rad/s per rad of theta1 (the signed reading)
PID_KP = (2.0, 6.0, 10.0, 20.0, 40.0)  # rad/s per unit of e
PID_KD = (0.0, 0.15, 0.4, 1.0)  # rad per unit of e per s


def candidates() -> list[tuple[str, Policy]]:
    """Every grid point, ``(controller, policy)``, coordinate control then the PID."""
    out: list[tuple[str, Policy]] = []
    base = COORDINATE_PRESETS["signed"]
    for speed, gain in itertools.product(SPEED_MPS, COORDINATE_TURN_GAIN):
        params = replace(base, speed_mps=speed, turn_gain=gain)
        out.append(("coordinate", Coordinate(params, f"coordinate v={speed:g} gain={gain:g}")))
    pid = PID_PRESETS["hand"]
    for speed, kp, kd in itertools.product(SPEED_MPS, PID_KP, PID_KD):
        params = replace(pid, speed_mps=speed, kp=kp, kd=kd)
        out.append(("pid", PIDLine(params, f"pid v={speed:g} kp={kp:g} kd={kd:g}")))
    return out


def _episode_score(episode: Episode) -> tuple[str, str, int, float, int]:
    """(policy, track, seed, summed reward, finished?); runs in the worker."""
    reward = float(episode.log["reward"].sum())  # the reset row's NaN is skipped
    return (
        episode.policy,
        episode.scenario,
        episode.seed,
        reward,
        int(episode.termination == "track_end"),
    )


def search(
    grid: Sequence[tuple[str, Policy]], seeds: int, *, workers: int | None = None
) -> pd.DataFrame:
    """Score every candidate: one row each, ``controller, policy, score, finished`` (the share
    of episodes that reached the track's end) and ``params``, best first per controller."""
    results = rollout(
        [p for _, p in grid],
        list(TRACKS),
        list(range(TUNE_SEED0, TUNE_SEED0 + seeds)),
        workers=workers,
        progress=True,
        reduce=_episode_score,
        task="line_trace",
    )
    episodes = pd.DataFrame(results, columns=["policy", "track", "seed", "score", "finished"])
    by_name = {p.name: (c, p) for c, p in grid}
    table = episodes.groupby("policy", sort=False)[["score", "finished"]].mean().reset_index()
    table.insert(0, "controller", [by_name[p][0] for p in table["policy"]])
    table["params"] = [repr(by_name[p][1].params) for p in table["policy"]]  # type: ignore[attr-defined]
    return table.sort_values(["controller", "score"], ascending=[True, False], ignore_index=True)


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m eval.line_tune``: run the search and print the best of each controller."""
    parser = argparse.ArgumentParser(
        prog="python -m eval.line_tune", description=__doc__.split("\n")[0]
    )
    parser.add_argument("--seeds", type=int, default=4, help="seeds per track (default: 4)")
    parser.add_argument("--top", type=int, default=5, help="candidates shown per controller")
    args = parser.parse_args(argv)
    if args.seeds < 1 or args.top < 1:
        print("python -m eval.line_tune: error: --seeds and --top must be >= 1", file=sys.stderr)
        return 2
    grid = candidates()
    started = time.perf_counter()
    table = search(grid, args.seeds)
    n = len(grid) * len(TRACKS) * args.seeds
    print(f"{len(grid)} candidates x {len(TRACKS)} tracks x {args.seeds} seeds = {n} episodes "
          f"in {time.perf_counter() - started:.0f} s")  # fmt: skip
    pd.set_option("display.width", 200)
    for controller, group in table.groupby("controller", sort=False):
        print(f"\n{controller}: the top {args.top} by score")
        print(group.head(args.top)[["policy", "score", "finished"]].to_string(index=False))
    print("\nPreset lines:")
    for controller, group in table.groupby("controller", sort=False):
        print(f"{controller} tuned = {group.iloc[0]['params']}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

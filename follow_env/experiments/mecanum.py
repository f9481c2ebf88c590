"""The mecanum paper's three experiments, reproduced on the simulated base (reference §2).

``python -m follow_env.experiments.mecanum [--out DIR] [--trials 10]`` prints a table and
writes ``mecanum_experiments.md``, ``.json`` and three plots. Each trial is one episode of the
platform's own randomisation (motor speed ratios, static friction, floor), seeded ``0 ..
trials - 1``; the robot drives open loop on duty as the paper's did, with the default
:class:`~follow_env.platforms.mecanum.MecanumConfig` and a 1 ms physics tick. Nothing here is
fitted to the paper's results.

"Duty d" (the paper's ``Pd`` with a unit command) reads as: a move at angle ``theta`` gives
wheel ``i`` the duty ``d (cos theta - +sin theta)`` (the rows of M), a spin gives every wheel
``+-d``. The protocols, where the paper does not say, are choices stated with each experiment:

1. **Diagonal travel**: duty 50, 5000 ms, every 10 deg from 0 to 90; the error is the direction
   of the displacement minus the commanded one.
2. **Spins** at duty 50 and 100, 10 to 90 deg, two stop rules: ``gyro`` (the motors stop when the
   true heading has turned the target; an ideal gyro) and ``timed`` (the motors stop after the
   time the ideal kinematics gives for that duty: open loop). The robot then coasts for 1.5 s;
   the error is the heading at rest minus the target.
3. **Travel 4000 mm at 45 deg while turning 45 deg left**, duty 100: ``together`` (one
   body-frame command for the travel's time, the travel direction fixed in the body), and
   ``sliced`` at 100 ms and 1 ms (translation and rotation slices alternate, the rotation's until
   its time is used up; each translation slice points ``45 deg - heading turned so far``, the
   heading as the commands imply it, or with ``gyro`` the true heading). Reported: the end
   point's distance from the target, the largest distance from the straight path, the progress
   along it, and the heading turned.
"""

from __future__ import annotations

import argparse
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from follow_env.platforms.mecanum import PLATFORM, MecanumConfig, command, drive_ticks
from follow_env.sim.atomic import atomic_path, atomic_write_text, check_writable, file_on_path
from follow_env.sim.body import BODY
from follow_env.sim.jit import njit
from follow_env.sim.rng import LaneSeeds
from follow_env.tasks.person_follow.config import THESIS

__all__ = ["Rig", "diagonal_travel", "main", "spins", "travel_while_turning"]

TICK_S = 0.001
COAST_S = 1.5
SCHEDULES = ("together", "sliced 100 ms", "sliced 1 ms", "sliced 100 ms, gyro", "sliced 1 ms, gyro")


@njit
def _run(params, state, bodies, keys, actions, ticks, stop_turn, world):
    """Every lane through the schedule: segment ``k`` commands ``actions[k]`` (body frame, or a
    world-frame translation turned into the body frame at the segment's start when
    ``world[k]``) for ``ticks[k]`` ticks, or until the heading has turned ``stop_turn[k]``
    (rad, when > 0). Returns the pose after every segment, ``(lanes, segments, 3)``."""
    n, m = params.shape[0], actions.shape[0]
    out = np.zeros((n, m, 3))
    act = np.zeros(3)
    for i in range(n):
        prm, st, body = params[i], state[i], bodies[i]
        unwrapped = body.th
        for k in range(m):
            act[:] = actions[k]
            if world[k]:
                c, s = np.cos(body.th), np.sin(body.th)
                act[0] = c * actions[k, 0] + s * actions[k, 1]
                act[1] = -s * actions[k, 0] + c * actions[k, 1]
            command(prm, st, act)
            start = unwrapped
            for _ in range(ticks[k]):
                before = body.th
                drive_ticks(prm, st, body, keys[i], 1, 1)
                d = body.th - before
                unwrapped += d - 2.0 * np.pi * np.round(d / (2.0 * np.pi))
                if stop_turn[k] > 0.0 and abs(unwrapped - start) >= stop_turn[k]:
                    break
            out[i, k, 0], out[i, k, 1], out[i, k, 2] = body.x, body.y, unwrapped
    return out


@dataclass
class Rig:
    """``trials`` simulated bases at the origin, facing +x, each with its own per-episode
    randomisation (seeds ``0 .. trials - 1``).

    :param trials: bases. :param platform: their configuration (the tick is set to 1 ms).
    """

    trials: int = 10
    platform: MecanumConfig | None = None

    def __post_init__(self) -> None:
        base = self.platform or MecanumConfig()
        self.platform = base.replace(drive={"tick_s": TICK_S})
        self.cfg = THESIS.replace(platform=self.platform)
        p = self.platform
        self.pd = p.duty_per_radps
        self.r = p.body.wheel_radius_m
        self.ab = p.body.half_wheelbase_m + p.body.half_track_m

    def speed(self, duty: float) -> float:
        """The body speed (m/s) the ideal kinematics gives a unit move at ``duty``."""
        return duty * self.r / self.pd

    def run(self, segments: list[tuple[Any, ...]]) -> np.ndarray:
        """Run ``(action [3], seconds, stop_turn_rad, world)`` segments on fresh bases; returns
        the pose ``(x, y, unwrapped heading)`` after each, ``(trials, segments, 3)``."""
        n = self.trials
        params = np.zeros(n, PLATFORM.params.dtype)
        PLATFORM.params.fill(params, self.cfg)
        lanes = np.arange(n)
        seeds = LaneSeeds(n)
        seeds.seed(lanes, list(range(n)))
        keys = seeds.next_keys(lanes)
        PLATFORM.randomize(params, params[0].copy(), lanes, self.cfg, keys)
        state = np.zeros(n, PLATFORM.state.dtype)
        bodies = np.zeros(n, BODY.dtype)
        actions = np.array([s[0] for s in segments], dtype=np.float64).reshape(-1, 3)
        ticks = np.array([round(s[1] / TICK_S) for s in segments], dtype=np.int64)
        stop = np.array([s[2] for s in segments], dtype=np.float64)
        world = np.array([s[3] for s in segments], dtype=np.bool_)
        return _run(params, state, bodies, keys, actions, ticks, stop, world)


def diagonal_travel(rig: Rig, duty: float = 50.0, seconds: float = 5.0) -> dict[str, Any]:
    """Experiment 1: error of the travel direction (deg) per commanded angle, per trial."""
    angles = np.arange(0, 91, 10)
    rows = {}
    for deg in angles:
        th = np.radians(deg)
        v = rig.speed(duty)
        pose = rig.run([((v * np.cos(th), v * np.sin(th), 0.0), seconds, 0.0, False)])[:, -1]
        direction = np.degrees(np.arctan2(pose[:, 1], pose[:, 0]))
        rows[int(deg)] = {
            "error_deg": (direction - deg).tolist(),
            "distance_m": np.hypot(pose[:, 0], pose[:, 1]).tolist(),
            "yaw_deg": np.degrees(pose[:, 2]).tolist(),
        }
    return {"duty": duty, "seconds": seconds, "angles": rows}


def spins(rig: Rig, duties: tuple[float, ...] = (50.0, 100.0)) -> dict[str, Any]:
    """Experiment 2: heading error at rest (deg) per target and duty, both stop rules."""
    out: dict[str, Any] = {}
    for duty in duties:
        rate = rig.speed(duty) / rig.ab  # the ideal kinematics' spin rate (rad/s)
        for rule in ("gyro", "timed"):
            rows = {}
            for deg in range(10, 91, 10):
                target = np.radians(deg)
                spin = (0.0, 0.0, rate)
                seg = (spin, 10.0, target, False) if rule == "gyro" else (
                    spin, target / rate, 0.0, False
                )  # fmt: skip
                pose = rig.run([seg, ((0.0, 0.0, 0.0), COAST_S, 0.0, False)])
                rows[deg] = {
                    "error_deg": (np.degrees(pose[:, -1, 2]) - deg).tolist(),
                    "coast_deg": np.degrees(pose[:, -1, 2] - pose[:, 0, 2]).tolist(),
                }
            out[f"duty {duty:g}, {rule}"] = rows
    return out


def travel_while_turning(
    rig: Rig, duty: float = 100.0, distance_m: float = 4.0, turn_deg: float = 45.0
) -> dict[str, Any]:
    """Experiment 3: end-point error and largest distance from the path (m) per schedule."""
    v = rig.speed(duty)
    w = v / rig.ab
    turn = np.radians(turn_deg)
    t_move, t_turn = distance_m / v, turn / w
    ang = np.radians(45.0)
    target = distance_m * np.array([np.cos(ang), np.sin(ang)])
    schedules: dict[str, list[tuple[Any, ...]]] = {
        "together": [((v * np.cos(ang), v * np.sin(ang), turn / t_move), t_move, 0.0, False)]
    }
    for gyro in (False, True):
        for slice_s in (0.1, 0.001):
            segs: list[tuple[Any, ...]] = []
            moved = turned = 0.0
            while moved < t_move - 1e-9:
                d = min(slice_s, t_move - moved)
                if (
                    gyro
                ):  # the world-frame direction, turned into the body frame by the true heading
                    segs.append(((v * np.cos(ang), v * np.sin(ang), 0.0), d, 0.0, True))
                else:  # the heading as the commands imply it
                    h = turned * w
                    segs.append(((v * np.cos(ang - h), v * np.sin(ang - h), 0.0), d, 0.0, False))
                moved += d
                if turned < t_turn - 1e-9:
                    r = min(slice_s, t_turn - turned)
                    segs.append(((0.0, 0.0, w), r, 0.0, False))
                    turned += r
            schedules[f"sliced {slice_s * 1000:g} ms{', gyro' if gyro else ''}"] = segs
    out: dict[str, Any] = {"duty": duty, "target_m": target.tolist()}
    for name, segs in schedules.items():
        segs = [*segs, ((0.0, 0.0, 0.0), COAST_S, 0.0, False)]
        pose = rig.run(segs)
        path = pose[:, :, :2]
        along = path @ (target / distance_m)
        across = np.abs(path[:, :, 0] * target[1] - path[:, :, 1] * target[0]) / distance_m
        out[name] = {
            "end_error_m": np.hypot(*(path[:, -1] - target).T).tolist(),
            "max_off_path_m": across.max(axis=1).tolist(),
            "progress_m": along[:, -1].tolist(),
            "turn_deg": np.degrees(pose[:, -1, 2]).tolist(),
            "path": path[0, :: max(1, len(segs) // 400)].tolist(),
        }
    return out


def _stats(values: list[float], digits: int = 1) -> str:
    a = np.asarray(values)
    return f"{a.mean():+.{digits}f} ({a.min():+.{digits}f} .. {a.max():+.{digits}f})"


def report(results: dict[str, Any]) -> str:
    """The three experiments as Markdown tables (mean and range over the trials)."""
    lines = ["### 1. Diagonal travel, duty 50, 5000 ms", ""]
    lines += [
        "| angle (deg) | direction error (deg) | distance (m) | yaw (deg) |",
        "|---:|---|---|---|",
    ]
    for deg, row in results["diagonal"]["angles"].items():
        lines.append(
            f"| {deg} | {_stats(row['error_deg'])} | {np.mean(row['distance_m']):.2f} | "
            f"{_stats(row['yaw_deg'])} |"
        )
    lines += ["", "### 2. Spins (heading error at rest, deg)", ""]
    keys = list(results["spins"])
    lines += ["| target (deg) | " + " | ".join(keys) + " |", "|---:|" + "---|" * len(keys)]
    for deg in results["spins"][keys[0]]:
        cells = [_stats(results["spins"][k][deg]["error_deg"]) for k in keys]
        lines.append(f"| {deg} | " + " | ".join(cells) + " |")
    t = results["travel"]
    lines += ["", f"### 3. 4000 mm at 45 deg while turning 45 deg left, duty {t['duty']:g}", ""]
    head = "| schedule | end error (m) | largest distance from the path (m) | along it (m) |"
    lines += [head + " turn (deg) |", "|---|---|---|---|---|"]
    for name in SCHEDULES:
        row = t[name]
        lines.append(
            f"| {name} | {_stats(row['end_error_m'], 2)} | {_stats(row['max_off_path_m'], 2)} | "
            f"{_stats(row['progress_m'], 2)} | {_stats(row['turn_deg'])} |"
        )
    return "\n".join(lines) + "\n"


def plot(results: dict[str, Any], out: Path) -> list[Path]:
    """Three PNG figures (one per experiment) in ``out``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    files = []
    fig, ax = plt.subplots(figsize=(6, 4))
    rows = results["diagonal"]["angles"]
    for deg, row in rows.items():
        ax.scatter([int(deg)] * len(row["error_deg"]), row["error_deg"], s=12, color="C0")
    ax.plot([int(d) for d in rows], [np.mean(r["error_deg"]) for r in rows.values()], "C0-")
    ax.set(xlabel="commanded direction (deg)", ylabel="direction error (deg)")
    ax.set_title("1. diagonal travel, duty 50, 5 s (dots: trials)")
    ax.axhline(0, color="grey", lw=0.5)
    files.append(out / "mecanum_diagonal.png")
    _save(fig, files[-1])
    fig, ax = plt.subplots(figsize=(6, 4))
    for k, (name, rows) in enumerate(results["spins"].items()):
        degs = [int(d) for d in rows]
        ax.plot(degs, [np.mean(r["error_deg"]) for r in rows.values()], f"C{k}o-", label=name)
    ax.axhline(0, color="grey", lw=0.5)
    ax.set(xlabel="target spin (deg)", ylabel="heading error at rest (deg)")
    ax.set_title("2. spins in place")
    ax.legend(fontsize=8)
    files.append(out / "mecanum_spins.png")
    _save(fig, files[-1])
    fig, ax = plt.subplots(figsize=(5, 5))
    t = results["travel"]
    ax.plot([0, t["target_m"][0]], [0, t["target_m"][1]], "k--", label="target path")
    for k, name in enumerate(SCHEDULES):
        path = np.asarray(t[name]["path"])
        ax.plot(path[:, 0], path[:, 1], f"C{k}-", label=name)
    ax.set(xlabel="x (m)", ylabel="y (m)", aspect="equal")
    ax.set_title("3. travel 4 m at 45 deg while turning 45 deg")
    ax.legend(fontsize=8)
    files.append(out / "mecanum_travel.png")
    _save(fig, files[-1])
    plt.close("all")
    return files


def _save(fig: Any, path: Path) -> None:
    """``fig`` as a PNG at ``path``, written whole or not at all."""
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=120, bbox_inches="tight", format="png")


#: The most trials ``--trials`` takes: each is one robot of the batch in every experiment.
MAX_TRIALS = 10_000


def main(argv: list[str] | None = None) -> int:
    """Entry point of ``python -m follow_env.experiments.mecanum``."""
    parser = argparse.ArgumentParser(prog="python -m follow_env.experiments.mecanum")
    parser.add_argument("--out", type=Path, default=Path("runs/mecanum-experiments"))
    parser.add_argument("--trials", type=int, default=10)
    args = parser.parse_args(argv)
    if not 1 <= args.trials <= MAX_TRIALS:
        parser.error(f"--trials {args.trials} is out of range: must be 1 to {MAX_TRIALS:,}")
    blocker = file_on_path(args.out)
    if blocker is not None:  # before the experiments run, not after
        parser.error(f"--out {args.out}: {blocker} is a file, not a folder")
    try:
        check_writable(args.out)
    except OSError as e:
        parser.error(f"--out {args.out}: {e}")
    rig = Rig(args.trials)
    results = {
        "trials": args.trials,
        "diagonal": diagonal_travel(rig),
        "spins": spins(rig),
        "travel": travel_while_turning(rig),
    }
    try:
        args.out.mkdir(parents=True, exist_ok=True)
        text = report(results)
        atomic_write_text(args.out / "mecanum_experiments.md", text)
        atomic_write_text(args.out / "mecanum_experiments.json", json.dumps(results) + "\n")
        files = plot(results, args.out)
    except OSError as e:  # the folder changed while the experiments ran
        parser.error(f"--out {args.out}: {e}")
    print(text)
    print(f"wrote {args.out}/: mecanum_experiments.md, .json, " + ", ".join(f.name for f in files))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

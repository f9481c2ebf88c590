"""The compiled as-built chain against the byte-level emulator: the same statistics?

    python -m bench.thesis_crosscheck [--seeds 5] [--law pn:thesis] [--walk straight]

For each seed, ``follow-robot emulate --firmware reference --framing reference --config
as_built`` runs in its own process (the thesis's main.c on the simulator's wheel models, real
bytes over a socket, this machine's real timing), and the runner drives it in real time with
the PC's PID as the ``as_built`` preset sets it (timer period, no anti-windup, every frame
fed to the PID), the camera being the emulator's world on the same seed. The same law, walk
and seeds then run in the compiled ``as_built`` chain, whose PC timing is a fitted model. Both
are scored by the evaluation; the table gives each mean with its 95 % bootstrap CI. The
compiled chain is given this machine's timer lateness (measured on the runner's wheel loop),
not the fitted lateness of the thesis's PC, so that the model is checked, not the fit.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np
import pandas as pd
from scipy import stats

from eval import episode_metrics, rollout, thesis
from eval.steplog import read_step_log

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests" / "bridge"))  # the emulator-process helper of the tests

METRICS = (*thesis.METRICS, "mean_abs_accel_mm_s2")


def _ci(values: np.ndarray) -> tuple[float, float, float]:
    values = values[np.isfinite(values)]
    if len(values) < 2 or np.ptp(values) == 0:  # one value, or all equal: the CI is the value
        return float(values.mean()), float(values.mean()), float(values.mean())
    res = stats.bootstrap((values,), np.mean, n_resamples=2000, random_state=0)
    return float(values.mean()), res.confidence_interval.low, res.confidence_interval.high


def crosscheck(seeds: int, law: str, walk: str) -> pd.DataFrame:
    """One row per metric: the emulated and the compiled mean [CI], and whether the CIs meet."""
    from conftest import EmulatorProcess

    from bridge import SerialLink
    from bridge.runner import Runner
    from bridge.sources import open_source
    from follow_env.tasks.person_follow.config import AS_BUILT
    from policies import make_policy

    emulated = []
    lateness_ms: list[float] = []
    rates: list[float] = []
    with tempfile.TemporaryDirectory() as tmp:
        for seed in range(seeds):
            emu = EmulatorProcess(
                "--framing",
                "reference",
                "--firmware",
                "reference",
                "--config",
                "as_built",
                "--scenario",
                walk,
                "--seed",
                str(seed),
            )
            try:
                log = Path(tmp) / f"seed_{seed}.csv"
                with SerialLink(emu.url, "reference") as link:
                    runner = Runner(
                        link,
                        make_policy(law),
                        open_source("sim", emu.url, seed=seed),
                        AS_BUILT.platform,
                        log=log,
                    )
                    result = runner.run()
                rates.append(result.feedback_frames / max(result.steps * 0.1, 0.1))
                print(f"seed {seed}: {result.summary()}", file=sys.stderr)
                lateness_ms += result.wheel_lateness_ms
                emulated.append(episode_metrics(read_step_log(log)))
            finally:
                emu.stop()
    # The firmware answers a command at most every 10 ms, and a timer tick late by a little more
    # than the last was early gets none: about 50-100 frames/s at a 10 ms PID. Fewer means the
    # emulator process fell behind (a busy machine), which the comparison would blame on the model.
    slowest = 0.5 / AS_BUILT.platform.chain.pc_pid_period_s
    if min(rates) < slowest:
        print(
            f"warning: the emulator answered as few as {min(rates):.0f} frames/s (expected at "
            f"least {slowest:.0f}): the machine is too busy for this cross-check; run it idle",
            file=sys.stderr,
        )
    # The compiled chain with this machine's timer lateness (measured on the runner's wheel loop)
    # instead of the fitted robot PC's: the cross-check is of the model, not of the fit.
    late_s = float(np.mean(lateness_ms)) / 1000.0
    print(
        f"wheel loop lateness: mean {late_s * 1000:.2f} ms (the compiled chain's)", file=sys.stderr
    )
    here = AS_BUILT.replace(chain={"pc_lateness_s": late_s})
    compiled = [episode_metrics(e.log) for e in rollout([law], [walk], range(seeds), config=here)]
    rows = []
    for metric in METRICS:
        e = _ci(np.array([m[metric] for m in emulated]))
        c = _ci(np.array([m[metric] for m in compiled]))
        rows.append(
            {
                "metric": metric,
                "emulated": f"{e[0]:,.1f} [{e[1]:,.1f}, {e[2]:,.1f}]",
                "compiled": f"{c[0]:,.1f} [{c[1]:,.1f}, {c[2]:,.1f}]",
                "intervals_meet": bool(e[1] <= c[2] and c[1] <= e[2]),
            }
        )
    return pd.DataFrame(rows)


def main() -> None:
    parser = argparse.ArgumentParser(prog="python -m bench.thesis_crosscheck")
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--law", default="pn:thesis")
    parser.add_argument("--walk", default="straight")
    args = parser.parse_args()
    print(crosscheck(args.seeds, args.law, args.walk).to_markdown(index=False))


if __name__ == "__main__":
    main()

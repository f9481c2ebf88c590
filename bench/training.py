"""PPO training speed (env-steps/s) of PersonFollow-v0, per choice of lanes, minibatch, epochs
and threads, beside SB3's PPO on CartPole-v1 with the same choices (the baseline: the same
learner on an env that costs almost nothing, measured in this process).

Each row but the last two trains ``train/configs/ppo.yaml`` (the agent's wrappers, the mirror
policy, the training reward) through ``follow-train``'s own ``train()`` for a fixed number of
steps, no held-out evaluation, no checkpoint, no comparison, with one setting changed; the last
two train the shipped agent's file, ``ppo_fast.yaml``, as it is (its reward, and its history
stacked by ``VecStackFrames`` rather than ``frame_stack``) with two torch threads and with one,
the second given as a ratio to the first (a study's ``--threads 1 --workers 2`` runs two such
one-thread runs at once). The rate is the run's own
``sessions.json`` figure (env steps over the learning loop's wall time). The run folders go to
a temporary folder and are removed.

Two more rows train ``ppo_ensemble``'s file (``ppo_ahead_law_wide.yaml``, networks of 128 x 128)
on one thread as ``follow-train`` commands of their own, without and with ``--mkl-intel-paths``
(:mod:`train.mkl_paths`), the second given as a ratio to the first: on a CPU that is not Intel's,
what MKL's Intel code paths gain there (1.59-1.61x on a 2-core AMD EPYC, 2026-12-07); on an
Intel CPU it should be about 1x (not measured on one).
"""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import yaml

from train.ppo import DEFAULT_HYPERPARAMS

#: The shipped agent's hyperparameters.
SHIPPED_HYPERPARAMS = DEFAULT_HYPERPARAMS.with_name("ppo_fast.yaml")

#: ``ppo_ensemble``'s hyperparameters (its members' networks are 128 x 128).
WIDE_HYPERPARAMS = DEFAULT_HYPERPARAMS.with_name("ppo_ahead_law_wide.yaml")

#: (label, hyperparameter file, changes to it, torch threads).
CHOICES: list[tuple[str, Path, dict[str, Any], int]] = [
    ("ppo.yaml: 48 lanes, mb 256, 10 ep", DEFAULT_HYPERPARAMS, {}, 1),
    ("48 lanes, mb 1536, 4 epochs", DEFAULT_HYPERPARAMS, {"batch_size": 1536, "n_epochs": 4}, 1),
    (
        "192 lanes, mb 4096, 4 epochs",
        DEFAULT_HYPERPARAMS,
        {"n_envs": 192, "batch_size": 4096, "n_epochs": 4},
        1,
    ),
    (
        "192 lanes, mb 6144, 3 ep, 2 thr",
        DEFAULT_HYPERPARAMS,
        {"n_envs": 192, "batch_size": 6144, "n_epochs": 3},
        2,
    ),
    (
        "384 lanes, mb 4096, 4 ep, 2 thr",
        DEFAULT_HYPERPARAMS,
        {"n_envs": 384, "batch_size": 4096, "n_epochs": 4},
        2,
    ),
    ("ppo_fast.yaml as shipped, 2 thr", SHIPPED_HYPERPARAMS, {}, 2),
    ("ppo_fast.yaml as shipped, 1 thr", SHIPPED_HYPERPARAMS, {}, 1),
]


def _follow_train_rate(
    hyperparams: Path, changes: dict[str, Any], threads: int, steps: int, folder: Path
) -> float:
    """follow-train's env-steps/s on ``hyperparams`` with ``changes`` for ``steps`` steps."""
    from train.ppo import Args, train

    document = yaml.safe_load(hyperparams.read_text(encoding="utf-8"))
    document["PersonFollow-v0"].update(changes)
    name = f"{len(list(folder.iterdir()))}"
    copy = folder / f"{name}.yaml"
    copy.write_text(yaml.safe_dump(document), encoding="utf-8")
    never = 10**9
    args = Args(
        hyperparams=copy,
        n_timesteps=steps,
        eval_freq=never,
        checkpoint_freq=never,
        final_episodes=0,
        threads=threads,
        out=folder / f"run-{name}",
        progress=False,
    )
    run = train(args)
    sessions = json.loads((run / "sessions.json").read_text(encoding="utf-8"))
    return float(sessions[-1]["env_steps_per_s"])


def _command_rate(hyperparams: Path, steps: int, folder: Path, *options: str) -> float:
    """env-steps/s of ``follow-train`` run as a command of its own (one torch thread, plus
    ``options``) on ``hyperparams`` for ``steps`` steps, with no preload inherited."""
    out = folder / f"command-{len(list(folder.glob('command-*')))}"
    never = str(10**9)
    argv = ["--hyperparams", str(hyperparams), "--threads", "1", "--n-timesteps", str(steps)]
    argv += ["--eval-freq", never, "--checkpoint-freq", never, "--final-episodes", "0"]
    argv += ["--no-progress", "--out", str(out), *options]
    from train.mkl_paths import plain_env

    done = subprocess.run(
        [sys.executable, "-m", "train", *argv], env=plain_env(), capture_output=True, text=True
    )
    if done.returncode != 0:
        raise RuntimeError(f"follow-train {' '.join(argv)}: {done.stderr.strip()}")
    sessions = json.loads((out / "sessions.json").read_text(encoding="utf-8"))
    return float(sessions[-1]["env_steps_per_s"])


def _cartpole_rate(changes: dict[str, Any], steps: int) -> float:
    """SB3 PPO (MlpPolicy 64 x 64) on CartPole-v1 with the same lanes, minibatch and epochs."""
    import torch
    from stable_baselines3 import PPO
    from stable_baselines3.common.env_util import make_vec_env

    torch.set_num_threads(1)
    venv = make_vec_env("CartPole-v1", n_envs=changes.get("n_envs", 48), seed=0)
    model = PPO(
        "MlpPolicy",
        venv,
        n_steps=64,
        batch_size=changes.get("batch_size", 256),
        n_epochs=changes.get("n_epochs", 10),
        policy_kwargs={"net_arch": [64, 64]},
        device="cpu",
        seed=0,
    )
    t0 = time.perf_counter()
    model.learn(steps)
    return model.num_timesteps / (time.perf_counter() - t0)


def bench_training(quick: bool) -> list[tuple[str, float, str]]:
    """Rows ``(what, env-steps/s, ratio to CartPole-v1 with the same PPO settings)``."""
    steps = 40_000 if quick else 200_000
    rows = []
    with tempfile.TemporaryDirectory(prefix="bench-training-") as tmp:
        folder = Path(tmp)
        shipped: dict[int, float] = {}  # the shipped file's rate, per torch threads
        for label, hyperparams, changes, threads in CHOICES:
            rate = _follow_train_rate(hyperparams, changes, threads, steps, folder)
            if hyperparams == SHIPPED_HYPERPARAMS:
                shipped[threads] = rate
                if threads == 1:
                    # The shipped file on one thread is compared with itself on two: threads
                    # are the one choice its command makes (its lanes, minibatch and epochs
                    # are the 384-lane row's), so no CartPole row.
                    rows.append((label, rate, f"{rate / shipped[2]:.2f}x the 2-thread row's rate"))
                    continue
            cartpole = _cartpole_rate(changes, steps) if threads == 1 else float("nan")
            ratio = f"{cartpole / rate:.2f}x CartPole's time" if threads == 1 else "(2 threads)"
            rows.append((label, rate, ratio))
            if threads == 1:
                rows.append(("  CartPole-v1, same PPO settings", cartpole, "1.00x (baseline)"))
        generic = _command_rate(WIDE_HYPERPARAMS, steps, folder)
        intel = _command_rate(WIDE_HYPERPARAMS, steps, folder, "--mkl-intel-paths")
        rows.append(("ppo_ahead_law_wide.yaml, 1 thr", generic, "(baseline of the next row)"))
        rows.append(("  the same, --mkl-intel-paths", intel, f"{intel / generic:.2f}x its rate"))
    return rows

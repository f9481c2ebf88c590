"""PPO training speed (env-steps/s) of PersonFollow-v0, per choice of lanes, minibatch, epochs
and threads, beside SB3's PPO on CartPole-v1 with the same choices (the baseline: the same
learner on an env that costs almost nothing, measured in this process).

Each row trains ``train/configs/ppo.yaml`` (the agent's wrappers, the mirror policy, the
training reward) through ``follow-train``'s own ``train()`` for a fixed number of steps, no
held-out evaluation, no checkpoint, no comparison, with one setting changed; the rate is the
run's own ``sessions.json`` figure (env steps over the learning loop's wall time). The run
folders go to a temporary folder and are removed.
"""

from __future__ import annotations

import json
import tempfile
import time
from pathlib import Path
from typing import Any

import yaml

#: (label, hyperparameter changes, torch threads).
CHOICES: list[tuple[str, dict[str, Any], int]] = [
    ("ppo.yaml: 48 lanes, mb 256, 10 ep", {}, 1),
    ("48 lanes, mb 1536, 4 epochs", {"batch_size": 1536, "n_epochs": 4}, 1),
    ("192 lanes, mb 4096, 4 epochs", {"n_envs": 192, "batch_size": 4096, "n_epochs": 4}, 1),
    ("192 lanes, mb 6144, 3 ep, 2 thr", {"n_envs": 192, "batch_size": 6144, "n_epochs": 3}, 2),
    (
        "384 lanes, mb 4096, 4 ep, 2 thr (shipped)",
        {"n_envs": 384, "batch_size": 4096, "n_epochs": 4},
        2,
    ),
]


def _follow_train_rate(changes: dict[str, Any], threads: int, steps: int, folder: Path) -> float:
    from train.ppo import DEFAULT_HYPERPARAMS, Args, train

    document = yaml.safe_load(DEFAULT_HYPERPARAMS.read_text(encoding="utf-8"))
    document["PersonFollow-v0"].update(changes)
    name = f"{len(list(folder.iterdir()))}"
    hyperparams = folder / f"{name}.yaml"
    hyperparams.write_text(yaml.safe_dump(document), encoding="utf-8")
    never = 10**9
    args = Args(
        hyperparams=hyperparams,
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
        for label, changes, threads in CHOICES:
            rate = _follow_train_rate(changes, threads, steps, folder)
            cartpole = _cartpole_rate(changes, steps) if threads == 1 else float("nan")
            ratio = f"{cartpole / rate:.2f}x CartPole's time" if threads == 1 else "(2 threads)"
            rows.append((label, rate, ratio))
            if threads == 1:
                rows.append(("  CartPole-v1, same PPO settings", cartpole, "1.00x (baseline)"))
    return rows

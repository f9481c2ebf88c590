"""What a run reports: the learning curve, a held-out comparison with a law, the model card.

The comparison uses the project's evaluation (:mod:`eval`): identical rollouts of the agent and
a guidance law on held-out seeds, the thesis metrics, paired differences with bootstrap CIs.
"""

from __future__ import annotations

import platform
from collections.abc import Sequence
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from eval.atomic import atomic_path

__all__ = [
    "TARGET_METRICS",
    "compare_with_law",
    "comparison_markdown",
    "package_versions",
    "plot_learning_curve",
]

#: The issue's targets: lower MeanOffset and StdAccel than the law, InFrameRate no lower.
TARGET_METRICS = ("mean_offset_px", "std_accel_mm_s2", "in_frame_rate_pct")
_LABELS = {
    "mean_offset_px": "MeanOffset (px)",
    "std_accel_mm_s2": "StdAccel (mm/s²)",
    "in_frame_rate_pct": "InFrameRate (%)",
}


def package_versions() -> dict[str, str]:
    """Versions of Python and the packages training depends on."""
    out = {"python": platform.python_version()}
    for package in ("personfollow", "stable-baselines3", "torch", "gymnasium", "numpy", "numba"):
        try:
            out[package] = version(package)
        except PackageNotFoundError:
            out[package] = "not installed"
    return out


def plot_learning_curve(run: Path, path: Path) -> Path:
    """Plot the held-out evaluation return (mean and range) and the training return over steps.

    Reads ``evaluations.npz`` and ``logs/progress-*.csv`` of ``run``; writes a PNG atomically.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7.0, 4.0), dpi=100)
    frames = [pd.read_csv(p) for p in sorted((run / "logs").glob("progress-*.csv"))]
    frames = [f for f in frames if {"time/total_timesteps", "rollout/ep_rew_mean"} <= set(f)]
    if frames:
        train = pd.concat(frames).dropna(subset=["rollout/ep_rew_mean"])
        train = train.sort_values("time/total_timesteps")
        ax.plot(
            train["time/total_timesteps"],
            train["rollout/ep_rew_mean"],
            color="0.6",
            lw=1,
            label="training episodes (env return, last 100)",
        )
    evaluations = run / "evaluations.npz"
    if evaluations.exists():
        with np.load(evaluations) as log:
            steps, results = log["timesteps"], log["results"]
        if len(steps):
            ax.fill_between(
                steps, results.min(axis=1), results.max(axis=1), color="C0", alpha=0.2, lw=0
            )
            ax.plot(steps, results.mean(axis=1), "o-", color="C0", ms=3, label="held-out seeds")
    ax.set_xlabel("env steps")
    ax.set_ylabel("episode return (env reward)")
    ax.set_title("PPO on PersonFollow-v0")
    ax.grid(alpha=0.3)
    ax.legend(loc="lower right", fontsize=8)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp)
    plt.close(fig)
    return path


def compare_with_law(
    agent: str, law: str, scenarios: Sequence[str], seeds: Sequence[int], config: Any
) -> pd.DataFrame:
    """Paired comparison ``agent - law`` per scenario on the target metrics.

    :param agent: a policy name (e.g. a run folder path).
    :param law: a policy name, e.g. ``"gsmpn:tuned"``.
    :returns: :func:`eval.stats.compare` rows for :data:`TARGET_METRICS`, agent as ``policy_a``.
    """
    from eval.rollout import rollout
    from eval.stats import compare, episode_table

    episodes = rollout([agent, law], list(scenarios), list(seeds), config=config, workers=1)
    table = episode_table(episodes)
    return compare(table, metrics=list(TARGET_METRICS))


def comparison_markdown(comparison: pd.DataFrame) -> str:
    """A Markdown table: per scenario and target metric, agent, law, difference [95 % CI]."""
    header = "| scenario | metric | agent | law | agent - law [95 % CI] |\n|---|---|---:|---:|---|"
    lines = [header]
    for row in comparison.itertuples():
        lines.append(
            f"| {row.scenario} | {_LABELS.get(row.metric, row.metric)} | {row.mean_a:.1f} | "
            f"{row.mean_b:.1f} | {row.mean_diff:+.1f} [{row.diff_ci_low:+.1f}, "
            f"{row.diff_ci_high:+.1f}] |"
        )
    return "\n".join(lines)


def model_card(
    *,
    run: Path,
    args: Any,
    hp: dict[str, Any],
    sessions: list[dict[str, Any]],
    comparison: pd.DataFrame | None,
    seeds: range,
    versions: dict[str, str],
) -> str:
    """The run's ``MODEL_CARD.md``: how it was made, what it saw, how it scores.

    :param run: the run folder (its ``evaluations.npz`` is read if present).
    :param args: the run's :class:`train.ppo.Args`.
    :param hp: the hyperparameters used.
    :param sessions: the training sessions (``sessions.json``).
    :param comparison: :func:`compare_with_law` output, or None if skipped.
    :param seeds: the seeds of that comparison.
    :param versions: :func:`package_versions`.
    """
    import yaml

    steps = sessions[-1]["last_step"] if sessions else 0
    wall_s = sum(s["wall_s"] for s in sessions)
    rates = [s["env_steps_per_s"] for s in sessions if s.get("env_steps_per_s")]
    lines = [
        "# PPO agent for PersonFollow-v0",
        "",
        "A learned person-following controller: stable-baselines3 PPO (MlpPolicy), trained by",
        "the project's own command on the batched simulation. Load it with",
        f'`make_policy({str(run)!r})` (or `make_policy("ppo")` for the shipped copy); the',
        "policy applies the saved normalisation and the agent's wrappers itself.",
        "",
        "## How it was trained",
        "",
        *(
            f"- `{s['command']}` ({s['first_step']:,} -> {s['last_step']:,} steps, "
            f"{s['wall_s']:.0f} s, {s['env_steps_per_s'] or 0:,} env-steps/s, "
            f"{s['threads']} torch thread(s), finished {s['finished_utc']})"
            for s in sessions
        ),
        f"- total: {steps:,} env steps in {wall_s / 60:.1f} min of training"
        + (f" ({min(rates):,}-{max(rates):,} env-steps/s)" if rates else ""),
        f"- scenarios: {', '.join(args.scenarios)}; env preset `{args.env_config}`;"
        f" {hp['n_envs']} lanes ({hp['n_envs'] // len(args.scenarios)} per scenario)",
        f"- seeds: training lane j starts from {args.seed} + j (a resumed session from"
        f" {args.seed} + steps + j); held-out evaluation lanes {args.eval_seed} + j; the",
        "  evaluation harness uses seeds 0 .. N, so no evaluated episode was trained on",
        "",
        "Hyperparameters (rl-zoo3 format, `config.yaml` has the whole resolved configuration):",
        "",
        "```yaml",
        yaml.safe_dump({args.env_id: hp}, sort_keys=False, default_flow_style=None).strip(),
        "```",
        "",
        "## Scores",
        "",
    ]
    evaluations = run / "evaluations.npz"
    if evaluations.exists():
        with np.load(evaluations) as log:
            if len(log["timesteps"]):
                last = log["results"][-1]
                lines += [
                    f"Held-out evaluation at {int(log['timesteps'][-1]):,} steps (EvalCallback,"
                    f" {len(last)} episodes, deterministic): env return {last.mean():.1f}"
                    f" +- {last.std():.1f}; learning curve in `learning_curve.png`.",
                    "",
                ]
    if comparison is not None and len(comparison):
        law = comparison["policy_b"].iloc[0]
        lines += [
            f"Against `{law}` on held-out seeds {seeds.start}..{seeds.stop - 1} per scenario",
            "(identical rollouts, `follow-eval`'s metrics; mean over episodes, paired",
            "difference with 95 % bootstrap CI; lower is better for MeanOffset and StdAccel,",
            "higher for InFrameRate):",
            "",
            comparison_markdown(comparison),
            "",
        ]
    lines += ["## Versions", "", *(f"- {name} {value}" for name, value in versions.items()), ""]
    return "\n".join(lines)

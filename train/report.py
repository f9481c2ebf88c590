"""What a run reports: the learning curve, a held-out comparison with a law, the model card.

The comparison uses the project's evaluation (:mod:`eval`): identical rollouts of the agent and
a guidance law on held-out seeds, paired differences with bootstrap CIs, on the issue's target
metrics and on how often episodes failed (collisions, lost person) and the distance kept
(:data:`CARD_METRICS`). Centring and smoothness alone would rank an agent that backs into a wall
in every episode above the law, so the card says first, in words, whether the agent collides
or loses the person more often than the law does (:func:`outcome_summary`).
"""

from __future__ import annotations

import platform
from collections.abc import Mapping, Sequence
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path
from typing import Any

import pandas as pd

from eval.metrics import OUTCOME_METRICS, metric_digits, metric_label
from follow_env.sim.atomic import atomic_path
from policies.learned.feature import IN_TRAINING
from policies.learned.ppo import shipped_name
from policies.registry import DEFAULT_TASK
from train.algos import ALGOS, DEFAULT_ALGO
from train.config import platform_label, wrapper_specs
from train.run import CONFIG, read_config, read_evaluations
from train.trained_agent import shown_path

__all__ = [
    "CARD_METRICS",
    "TARGET_METRICS",
    "compare_with_law",
    "comparison_markdown",
    "outcome_summary",
    "package_versions",
    "plot_learning_curve",
]

#: The issue's targets: lower MeanOffset and StdAccel than the law, InFrameRate no lower.
TARGET_METRICS = ("mean_offset_px", "std_accel_mm_s2", "in_frame_rate_pct")
#: The card's comparison: the targets, then collision and lost rates and distance error.
CARD_METRICS = (*TARGET_METRICS, *OUTCOME_METRICS)
# Episode endings the card states in words, with the verb for "does it more often".
_FAILURES = (("collision_rate_pct", "collides"), ("lost_rate_pct", "loses the person"))


def package_versions() -> dict[str, str]:
    """Versions of Python and the packages training depends on."""
    out = {"python": platform.python_version()}
    packages = ("personfollow", "stable-baselines3", "sb3-contrib", "torch", "gymnasium", "numpy")
    for package in (*packages, "numba"):
        try:
            out[package] = version(package)
        except PackageNotFoundError:
            out[package] = "not installed"
    return out


def plot_learning_curve(run: Path, path: Path, title: str = "PPO on PersonFollow-v0") -> Path:
    """Plot the held-out evaluation return (mean and range) and the training return over steps.

    Reads ``evaluations.npz`` and ``logs/progress-*.csv`` of ``run``; writes a PNG atomically.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7.0, 4.0), dpi=100)
    # A session that trained no rollout (a resume that only writes the report) left an empty
    # progress file: nothing to plot from it.
    logs = sorted((run / "logs").glob("progress-*.csv"))
    frames = [pd.read_csv(p) for p in logs if p.stat().st_size > 0]
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
    log = read_evaluations(run)
    if log is not None and len(log.timesteps):
        steps, results = log.timesteps, log.results
        ax.fill_between(
            steps, results.min(axis=1), results.max(axis=1), color="C0", alpha=0.2, lw=0
        )
        ax.plot(steps, results.mean(axis=1), "o-", color="C0", ms=3, label="held-out seeds")
    ax.set_xlabel("env steps")
    ax.set_ylabel("episode return (env reward)")
    ax.set_title(title)
    ax.grid(alpha=0.3)
    if ax.get_legend_handles_labels()[0]:  # a run too short to end an episode has no line
        ax.legend(loc="lower right", fontsize=8)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp)
    plt.close(fig)
    return path


def compare_with_law(
    agent: Any,
    law: str,
    scenarios: Sequence[str],
    seeds: Sequence[int],
    config: Any,
    platform: str | Mapping[str, Any] | None = None,
) -> pd.DataFrame:
    """Paired comparison ``agent - law`` per scenario on :data:`CARD_METRICS`.

    :param agent: a policy name (e.g. a run folder path) or a :class:`~policies.Policy`.
    :param law: a policy name, e.g. ``"gsmpn:tuned"``.
    :param platform: run both on this platform (``eval``'s ``policy@platform``), or on a
        platform with section overrides (``{"name": "mecanum", "drive": {...}}``, put into
        ``config``); None: the configuration's.
    :returns: :func:`eval.stats.compare` rows for :data:`CARD_METRICS`, agent as ``policy_a``.
    """
    from eval.rollout import rollout
    from eval.stats import compare, episode_table

    if isinstance(platform, Mapping):
        from follow_env.tasks import get_task

        config = get_task("person_follow").resolve_config(config=config, platform=platform)
        platform = None
    policies = [agent, law] if platform is None else [f"{agent}@{platform}", f"{law}@{platform}"]
    episodes = rollout(policies, list(scenarios), list(seeds), config=config, workers=1)
    table = episode_table(episodes)
    return compare(table, metrics=list(CARD_METRICS))


def comparison_markdown(comparison: pd.DataFrame) -> str:
    """A Markdown table: per scenario and metric, agent, law, difference [95 % CI]."""
    header = "| scenario | metric | agent | law | agent - law [95 % CI] |\n|---|---|---:|---:|---|"
    lines = [header]
    for row in comparison.itertuples():
        d, label = metric_digits(row.metric), metric_label(row.metric)
        lines.append(
            f"| {row.scenario} | {label} | {row.mean_a:.{d}f} | {row.mean_b:.{d}f} | "
            f"{row.mean_diff:+.{d}f} [{row.diff_ci_low:+.{d}f}, {row.diff_ci_high:+.{d}f}] |"
        )
    return "\n".join(lines)


def outcome_summary(comparison: pd.DataFrame) -> str:
    """One plain sentence: does the agent collide or lose the person more often than the law?

    Counted per scenario on the same seeds (identical rollouts): "more often" is a higher rate
    than the law's in that scenario, however small. Rates over all scenarios are pooled by the
    number of episodes.

    :param comparison: :func:`compare_with_law` output (agent as ``policy_a``).
    """
    law = comparison["policy_b"].iloc[0]
    worse, overall = [], []
    for metric, verb in _FAILURES:
        rows = comparison[(comparison["metric"] == metric) & (comparison["n"] > 0)]
        if rows.empty:
            continue
        n = rows["n"].to_numpy(dtype=float)
        agent_pct = float((rows["mean_a"] * n).sum() / n.sum())
        law_pct = float((rows["mean_b"] * n).sum() / n.sum())
        noun = "collisions" if metric == "collision_rate_pct" else "lost person"
        overall.append(f"{noun} in {agent_pct:.1f} % of episodes against {law_pct:.1f} %")
        bad = rows[rows["mean_a"] > rows["mean_b"]]
        if len(bad):
            where = ", ".join(
                f"{r.scenario} {r.mean_a:.0f} % against {r.mean_b:.0f} %" for r in bad.itertuples()
            )
            than = f" than `{law}`" if not worse else ""
            worse.append(
                f"{verb} more often{than} in {len(bad)} of {len(rows)} scenarios ({where})"
            )
    if not overall:
        return f"Collision and lost-person rates are not available for `{law}`'s comparison."
    totals = "; ".join(overall)
    if worse:
        return (
            f"**Warning: the agent {', and '.join(worse)}.** Over all scenarios: {totals}. "
            "Better centring or smoothness below does not make up for that."
        )
    return (
        f"The agent collides and loses the person no more often than `{law}` in any scenario "
        f"(over all scenarios: {totals})."
    )


def _started_from_lines(run: Path) -> list[str]:
    """The card's line on the trained agent the run started from (``--trained-agent``), if
    its ``config.yaml`` records one (:func:`train.trained_agent.record`)."""
    if not (run / CONFIG).is_file():
        return []
    start = read_config(run).get("trained_agent")
    if not isinstance(start, dict):
        return []
    digests = start.get("sha256") or {}
    files = ", ".join(f"{name} {str(digest)[:12]}" for name, digest in digests.items())
    return [
        f"- started from the weights and normalisation of `{shown_path(start.get('path', ''))}` "
        f"({start.get('algo')}, {int(start.get('steps') or 0):,} env steps; SHA-256 {files}),",
        "  not from scratch; the steps above are this run's own",
    ]


def _deploy_only_lines(hp: dict[str, Any]) -> list[str]:
    """The card's words on the steps of the agent's view left out of its training env
    (``in_training: false``): they act in evaluation and on the robot, not in training."""
    names = [
        name.rsplit(".", 1)[-1]
        for name, kwargs in wrapper_specs(hp.get("vec_env_wrapper") or [])
        if kwargs.get(IN_TRAINING) is False
    ]
    if not names:
        return []
    return [
        "",
        f"Not trained with: {', '.join(f'`{n}`' for n in names)} (`{IN_TRAINING}: false`) acts "
        "in the exported agent's view (evaluation, the robot) but passed observations through "
        "in training, so the held-out return below is the agent's without it.",
    ]


def _load_line(run: Path, export: Path | str | None) -> str:
    """How the card's reader loads the agent: the exported copy (by its registered name when
    it is a shipped agent's folder, :data:`policies.learned.ppo.SHIPPED`), and the run folder.

    A shipped agent's card travels with the project, so it names its run folder without the
    path, which is only good on the machine that trained it."""
    at_run = f"`make_policy({str(run)!r})`"
    if export is None:
        return at_run
    shipped = shipped_name(export)
    if shipped is None:
        return (
            f"`make_policy({str(export)!r})` (the copy in `{export}`) or {at_run} (the run folder)"
        )
    name, task = shipped
    call = f'make_policy("{name}"' + ("" if task == DEFAULT_TASK else f', task="{task}"') + ")"
    copy = f"policies/agents/{Path(export).name}"
    return f"`{call}` (the copy in `{copy}`, exported from the run folder `{Path(run).name}`)"


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
    wall_s = sum(s["wall_s"] for s in sessions)  # killed sessions too, to their checkpoint
    rates = [s["env_steps_per_s"] for s in sessions if s.get("env_steps_per_s")]
    platform = platform_label((hp.get("env_kwargs") or {}).get("platform"))
    on = f", platform `{platform}`" if platform else ""
    env_id = getattr(args, "env_id", None) or "PersonFollow-v0"
    learner = ALGOS[getattr(args, "algo", None) or DEFAULT_ALGO]
    lines = [
        f"# {learner.label} agent for {env_id}",
        "",
        f"A learned controller for {env_id}: {learner.library} {learner.label} "
        f"({hp.get('policy', learner.policies[0])}), trained by",
        "the project's own command on the batched simulation. Load it with",
        f"{_load_line(run, getattr(args, 'export', None))}; the",
        "policy applies the saved normalisation and the agent's wrappers itself.",
        *_deploy_only_lines(hp),
        "",
        "## How it was trained",
        "",
        *(_session_line(s) for s in sessions),
        f"- total: {steps:,} env steps in {wall_s / 60:.1f} min of training"
        + (f" ({min(rates):,}-{max(rates):,} env-steps/s)" if rates else ""),
        *_started_from_lines(run),
        f"- scenarios: {', '.join(args.scenarios)}; env preset `{args.env_config}`{on};"
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
    log = read_evaluations(run)
    if log is not None and len(log.timesteps):
        last = log.results[-1]
        lines += [
            f"Held-out evaluation at {int(log.timesteps[-1]):,} steps (EvalCallback,"
            f" {len(last)} episodes, deterministic): env return {last.mean():.1f}"
            f" +- {last.std():.1f}; learning curve in `learning_curve.png`.",
            "",
        ]
    if comparison is not None and len(comparison):
        law = comparison["policy_b"].iloc[0]
        lines += [
            f"Against `{law}` on held-out seeds {seeds.start}..{seeds.stop - 1} per scenario.",
            "",
            outcome_summary(comparison),
            "",
            "Identical rollouts, `follow-eval`'s metrics; mean over episodes, paired difference",
            "with 95 % bootstrap CI. Lower is better for MeanOffset, StdAccel, the collision and",
            "lost-person rates (% of episodes) and the RMS distance error; higher for",
            "InFrameRate; the mean distance error is signed (> 0: the robot trails behind the",
            "1 m reference).",
            "",
            comparison_markdown(comparison),
            "",
        ]
    lines += ["## Versions", "", *(f"- {name} {value}" for name, value in versions.items()), ""]
    return "\n".join(lines)


_ENDINGS = {
    "finished": "finished {end}",
    "interrupted": "interrupted {end}; steps after its last checkpoint were not kept",
    "failed": "failed {end}; steps after its last checkpoint were not kept",
    "killed": "killed; counted up to its last checkpoint",
    "running": "running, or killed; counted up to its last checkpoint",
}


def _session_line(session: dict[str, Any]) -> str:
    """One session of ``sessions.json`` (older runs' entries have no ``status``)."""
    status = session.get("status", "finished")
    ending = _ENDINGS.get(status, status).format(end=session.get("finished_utc"))
    return (
        f"- `{session['command']}` ({session['first_step']:,} -> {session['last_step']:,} steps, "
        f"{session['wall_s']:.0f} s, {session.get('env_steps_per_s') or 0:,} env-steps/s, "
        f"{session.get('threads', 1)} torch thread(s), {ending})"
    )

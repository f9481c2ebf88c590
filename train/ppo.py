"""``follow-train``: PPO (stable-baselines3) on PersonFollow-v0, one run folder per run.

::

    follow-train                                  # train/configs/ppo.yaml, all scenarios
    follow-train --n-timesteps 20000 --out runs/ppo-smoke
    follow-train --resume runs/ppo-<timestamp>    # continue from the newest checkpoint
    follow-train --export policies/agents/ppo     # also copy the agent there (the shipped one)

(also ``python -m train``). Read top-down: :class:`Args` holds every option; :func:`train`
sets up the envs and the model, learns, and saves. SB3 does the algorithm; the agent's view of
the env (action scaling, the observation's extra features, the training reward) is the
``vec_env_wrapper`` list of the hyperparameter file (:mod:`train.wrappers`), assembled by
:func:`train.envs.agent_env`. The run folder's layout is in :mod:`train.run`.

Seeds: training lane ``j`` starts from seed ``seed + j`` (10 000 + j by default) and a resumed
session from ``seed + steps + j``; the held-out evaluation uses ``eval_seed + j`` (5 000 + j);
the evaluation harness (``follow-eval``, ``make eval``) uses seeds 0 .. N. None overlap.
"""

from __future__ import annotations

import argparse
import dataclasses
import shutil
import sys
import tempfile
import time
from collections.abc import Sequence
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any, NoReturn

from eval.atomic import atomic_write_text
from follow_env.tasks import task_for_env
from train.config import (
    ConfigError,
    Hyperparams,
    load_hyperparams,
    parse_hyperparams,
    policy_class,
    schedule,
    sole_section,
)

__all__ = ["Args", "main", "train"]

PROG = "follow-train"
USAGE_ERROR = 2
DEFAULT_HYPERPARAMS = Path(__file__).parent / "configs" / "ppo.yaml"
# The files that make an agent (what --export copies and policies.ppo loads).
AGENT_FILES = ("model.zip", "vecnormalize.pkl", "config.yaml", "MODEL_CARD.md")
EXPORT_EXTRAS = ("learning_curve.png",)


@dataclass(frozen=True)
class Args:
    """Every option of a run (``follow-train --help`` has the same list)."""

    hyperparams: Path = DEFAULT_HYPERPARAMS  # rl-zoo3-style YAML, keyed by env id
    env_id: str | None = None  # the YAML section, and the task; default: the file's only section
    scenarios: tuple[str, ...] = ()  # the task's variants (scenarios) to train on; () = all
    env_config: str = "thesis"  # the env preset the agent trains and is evaluated on
    seed: int = 10_000  # training lanes start from seed + j
    eval_seed: int = 5_000  # held-out lanes start from eval_seed + j
    eval_episodes: int = 2  # per scenario, at each held-out evaluation
    eval_freq: int = 100_000  # env steps between held-out evaluations
    checkpoint_freq: int = 200_000  # env steps between checkpoints
    final_episodes: int = 10  # per scenario, in the model card's comparison with the law
    compare_with: str = "gsmpn:tuned"
    n_timesteps: int | None = None  # overrides the hyperparameter file's
    n_envs: int | None = None  # overrides the hyperparameter file's
    threads: int = 1  # torch threads (the env steps in this thread too)
    runs: Path = Path("runs")
    out: Path | None = None  # the run folder (default: runs/ppo-<timestamp>)
    resume: Path | None = None  # continue this run from its newest checkpoint
    export: Path | None = None  # also copy the finished agent into this folder
    progress: bool = True


def train(args: Args, command: str = PROG) -> Path:
    """Train (or resume) a run as ``args`` say; returns the run folder.

    :raises ValueError: for bad options or inputs (the message names them).
    """
    import torch
    from stable_baselines3 import PPO
    from stable_baselines3.common.logger import CSVOutputFormat, Logger, TensorBoardOutputFormat

    from train import report
    from train import run as runs
    from train.envs import agent_env, base_env

    # -- Set-up: the run folder, the hyperparameters, the envs, the model -------------------
    torch.set_num_threads(args.threads)
    if args.resume is not None:
        run = args.resume
        saved = runs.read_config(run)
        hp = parse_hyperparams(saved["hyperparams"], where=f"{run / runs.CONFIG} [hyperparams]")
        if args.n_timesteps is not None:  # a longer run: the saved total follows
            hp["n_timesteps"] = saved["hyperparams"]["n_timesteps"] = args.n_timesteps
            runs.write_config(run, saved)
        args = dataclasses.replace(
            _args_from_dict(saved["args"]),
            n_timesteps=args.n_timesteps,
            threads=args.threads,
            progress=args.progress,
            export=args.export,
            resume=run,
        )
        checkpoint = runs.newest_checkpoint(run)
        if checkpoint is None:
            raise ValueError(f"{run / runs.CHECKPOINTS}: no checkpoint to resume from")
        start_step, model_path, stats_path = checkpoint
    else:
        args = _with_defaults(args)
        hp = load_hyperparams(args.hyperparams, args.env_id)
        hp |= {k: v for k in ("n_timesteps", "n_envs") if (v := getattr(args, k)) is not None}
        _check_args(args, hp)
        run = args.out if args.out is not None else runs.new_run_dir(args.runs)
        run.mkdir(parents=True, exist_ok=True)
        if any(run.iterdir()):
            raise ValueError(f"{run} already exists and is not empty; use --resume to continue it")
        start_step, model_path, stats_path = 0, None, None
    lanes = hp["n_envs"] // len(args.scenarios)
    venv = agent_env(base_env(args.scenarios, lanes, args.env_config, args.env_id), hp, "train",
                     normalization=stats_path if hp["normalize"] else None)  # fmt: skip
    eval_env = agent_env(
        base_env(args.scenarios, args.eval_episodes, args.env_config, args.env_id), hp, "eval"
    )
    if model_path is not None:
        model = PPO.load(model_path, env=venv, device="cpu")
        model.set_random_seed(args.seed + start_step)  # new episodes, still >= args.seed
    else:
        ppo_kwargs = {k: v for k, v in hp.items() if k not in _ZOO_ONLY}
        for key in ("learning_rate", "clip_range"):
            if key in ppo_kwargs:
                ppo_kwargs[key] = schedule(ppo_kwargs[key])
        policy = policy_class(hp["policy"])
        model = PPO(policy, venv, seed=args.seed, device="cpu", verbose=0, **ppo_kwargs)
        runs.write_config(run, _resolved_config(args, hp, venv, command))
    (run / runs.LOGS).mkdir(exist_ok=True)
    formats = [CSVOutputFormat(str(run / runs.LOGS / f"progress-{start_step}.csv"))]
    formats.append(TensorBoardOutputFormat(str(run / runs.LOGS / "tb")))
    model.set_logger(Logger(str(run / runs.LOGS), formats))
    callbacks = [
        runs.AtomicCheckpointCallback(args.checkpoint_freq, run, venv.num_envs),
        runs.HeldOutEvalCallback(eval_env, run, args.eval_seed, args.eval_freq, venv.num_envs),
    ]

    # -- Learn ------------------------------------------------------------------------------
    remaining = hp["n_timesteps"] - model.num_timesteps
    started = time.perf_counter()
    if remaining > 0:
        model.learn(
            remaining, callback=callbacks, progress_bar=args.progress, reset_num_timesteps=False
        )
    wall_s = time.perf_counter() - started
    steps = model.num_timesteps - start_step

    # -- Save: the agent, the session, the curve, the comparison, the model card --------------
    runs.save_normalization(model.get_vec_normalize_env(), run / runs.NORMALIZATION)
    runs.save_model(model, run / runs.MODEL)
    venv.close()
    eval_env.close()
    sessions = runs.read_sessions(run)
    sessions.append(
        {
            "command": command,
            "finished_utc": datetime.now(UTC).isoformat(timespec="seconds"),
            "first_step": start_step,
            "last_step": model.num_timesteps,
            "wall_s": round(wall_s, 1),
            "env_steps_per_s": round(steps / wall_s) if steps and wall_s > 0 else None,
            "threads": args.threads,
        }
    )
    runs.write_sessions(run, sessions)
    report.plot_learning_curve(run, run / runs.CURVE)
    seeds = range(args.eval_seed, args.eval_seed + args.final_episodes)
    comparison = None
    if args.final_episodes > 0:
        comparison = report.compare_with_law(
            str(run), args.compare_with, args.scenarios, seeds, args.env_config
        )
    card = report.model_card(
        run=run,
        args=args,
        hp=hp,
        sessions=sessions,
        comparison=comparison,
        seeds=seeds,
        versions=report.package_versions(),
    )
    atomic_write_text(run / runs.CARD, card)
    if args.export is not None:
        export_agent(run, args.export)
    return run


# -- Helpers ---------------------------------------------------------------------------------

# Keys the trainer consumes itself; the rest of a hyperparameter section goes to PPO().
_ZOO_ONLY = ("n_envs", "n_timesteps", "normalize", "frame_stack", "vec_env_wrapper", "policy")


def _with_defaults(args: Args) -> Args:
    """``args`` with the env id (the hyperparameter file's only section) and the scenarios (all
    of the task's) filled in where they were left to their defaults."""
    env_id = args.env_id or sole_section(args.hyperparams)
    scenarios = args.scenarios or tuple(task_for_env(env_id).variants())
    return dataclasses.replace(args, env_id=env_id, scenarios=scenarios)


def _check_args(args: Args, hp: Hyperparams) -> None:
    task = task_for_env(args.env_id)
    known = task.variants()
    for name in args.scenarios:
        if name not in known:
            raise ValueError(f"--scenarios: unknown scenario {name!r}; known: {', '.join(known)}")
    if len(set(args.scenarios)) != len(args.scenarios) or not args.scenarios:
        raise ValueError("--scenarios must name each scenario once, at least one")
    if args.env_config not in task.presets:
        raise ValueError(
            f"--env-config {args.env_config!r} is not a preset: {', '.join(task.presets)}"
        )
    if hp["n_envs"] % len(args.scenarios):
        raise ValueError(
            f"n_envs={hp['n_envs']} must be a multiple of the {len(args.scenarios)} scenarios "
            "(each scenario gets the same number of lanes)"
        )
    for name in ("eval_freq", "checkpoint_freq", "eval_episodes", "threads"):
        if getattr(args, name) < 1:
            raise ValueError(f"--{name.replace('_', '-')} must be >= 1")
    if args.final_episodes < 0:
        raise ValueError("--final-episodes must be >= 0")


def _resolved_config(args: Args, hp: Hyperparams, venv: Any, command: str) -> dict[str, Any]:
    """What ``config.yaml`` holds: enough to rebuild the agent's env and to resume."""
    base = venv
    while hasattr(base, "venv"):
        base = base.venv
    return {
        "command": command,
        "env_id": args.env_id,
        "args": _args_to_dict(args),
        "hyperparams": hp,
        # The env's spaces, so that a policy can rebuild the agent's view without an env.
        "env_spaces": {
            "observation": {
                "low": base.observation_space.low.tolist(),
                "high": base.observation_space.high.tolist(),
            },
            "action": {
                "low": base.action_space.low.tolist(),
                "high": base.action_space.high.tolist(),
            },
        },
        "agent_observation_shape": list(venv.observation_space.shape),
    }


def _args_to_dict(args: Args) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for f in dataclasses.fields(args):
        if f.name in ("resume", "export", "out"):
            continue  # where this session writes, not how the run trains
        value = getattr(args, f.name)
        if isinstance(value, Path):
            value = str(value)
        elif isinstance(value, tuple):
            value = list(value)
        out[f.name] = value
    return out


def _args_from_dict(saved: dict[str, Any]) -> Args:
    fields = {f.name: f for f in dataclasses.fields(Args)}
    values: dict[str, Any] = {}
    for name, value in saved.items():
        if name not in fields:
            continue
        if name in ("hyperparams", "runs"):
            value = Path(value)
        elif name == "scenarios":
            value = tuple(value)
        values[name] = value
    return Args(**values)


def export_agent(run: Path, dest: Path) -> Path:
    """Copy the agent's files (:data:`AGENT_FILES` and the learning curve) into ``dest``.

    The folder is replaced as a whole: the new copy is assembled beside it and renamed into
    place, so ``dest`` always holds one complete agent.
    """
    dest = Path(dest)
    dest.parent.mkdir(parents=True, exist_ok=True)
    staging = Path(tempfile.mkdtemp(prefix=f".{dest.name}.", suffix=".tmp", dir=dest.parent))
    try:
        staging.chmod(0o755)  # mkdtemp makes 0700; an exported agent is for everyone to read
        for name in AGENT_FILES + EXPORT_EXTRAS:
            source = run / name
            if source.exists():
                shutil.copy2(source, staging / name)
            elif name != "vecnormalize.pkl":
                raise FileNotFoundError(f"{source}: missing; is the run finished?")
        old = None
        if dest.exists():
            old = dest.with_name(f".{dest.name}.old")
            shutil.rmtree(old, ignore_errors=True)
            dest.rename(old)
        staging.rename(dest)
        if old is not None:
            shutil.rmtree(old, ignore_errors=True)
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise
    return dest


# -- Command line ----------------------------------------------------------------------------


class UsageError(Exception):
    """Bad arguments: reported as one line, exit status 2."""


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> NoReturn:
        raise UsageError(message)


def build_parser() -> argparse.ArgumentParser:
    """The ``follow-train`` argument parser; defaults are :class:`Args`'s."""
    d = Args()
    p = _Parser(prog=PROG, description="Train PPO on PersonFollow-v0 (stable-baselines3).")
    p.add_argument("--hyperparams", type=Path, help=f"YAML file (default: {d.hyperparams})")
    p.add_argument("--env-id", help="section of the YAML file (default: its only one)")
    p.add_argument("--scenarios", help="comma-separated scenarios (default: all registered)")
    p.add_argument("--env-config", help=f"env preset (default: {d.env_config})")
    p.add_argument("--seed", type=int, help=f"training lanes start from seed + j ({d.seed})")
    p.add_argument("--eval-seed", type=int, help=f"held-out lanes: eval_seed + j ({d.eval_seed})")
    p.add_argument("--eval-episodes", type=int, help=f"per scenario ({d.eval_episodes})")
    p.add_argument("--eval-freq", type=int, help=f"env steps ({d.eval_freq})")
    p.add_argument("--checkpoint-freq", type=int, help=f"env steps ({d.checkpoint_freq})")
    p.add_argument("--final-episodes", type=int, help=f"per scenario, 0 skips ({d.final_episodes})")
    p.add_argument("--compare-with", help=f"law in the model card ({d.compare_with})")
    p.add_argument("--n-timesteps", type=int, help="total env steps (default: the YAML's)")
    p.add_argument("--n-envs", type=int, help="lanes (default: the YAML's)")
    p.add_argument("--threads", type=int, help=f"torch threads ({d.threads})")
    p.add_argument("--runs", type=Path, help=f"where run folders go ({d.runs})")
    p.add_argument("--out", type=Path, help="run folder (default: runs/ppo-<timestamp>)")
    p.add_argument("--resume", type=Path, metavar="RUN_DIR", help="continue this run")
    p.add_argument("--export", type=Path, metavar="DIR", help="also copy the agent into DIR")
    p.add_argument("--no-progress", dest="progress", action="store_false", default=None)
    return p


# Options that may accompany --resume (the rest come from the run's config.yaml).
_RESUME_OPTIONS = {"resume", "n_timesteps", "threads", "progress", "export"}


def parse_args(argv: Sequence[str] | None = None) -> Args:
    """Parse the command line into :class:`Args`.

    :raises UsageError: for unknown or conflicting options.
    """
    ns = build_parser().parse_args(argv)
    given = {k: v for k, v in vars(ns).items() if v is not None}
    if "resume" in given and set(given) - _RESUME_OPTIONS:
        extra = ", ".join("--" + k.replace("_", "-") for k in sorted(set(given) - _RESUME_OPTIONS))
        raise UsageError(
            f"{extra}: a resumed run keeps its own settings; with --resume only "
            "--n-timesteps, --threads, --no-progress and --export may be given"
        )
    if "scenarios" in given:
        given["scenarios"] = tuple(s.strip() for s in given["scenarios"].split(",") if s.strip())
    for name in ("n_timesteps", "n_envs"):
        if name in given and given[name] < 1:
            raise UsageError(f"--{name.replace('_', '-')} must be >= 1")
    return Args(**given)


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``follow-train`` and ``python -m train``; returns the exit status."""
    argv = sys.argv[1:] if argv is None else list(argv)
    try:
        args = parse_args(argv)
        run = train(args, command=" ".join([PROG, *argv]))
    except (UsageError, ConfigError, ValueError, FileNotFoundError) as e:
        print(f"{PROG}: error: {e}", file=sys.stderr)
        return USAGE_ERROR
    except KeyboardInterrupt:
        print(f"{PROG}: interrupted; resume with --resume RUN_DIR", file=sys.stderr)
        return 130
    from train.run import read_sessions

    last = read_sessions(run)[-1]
    print(
        f"Trained {last['first_step']:,} -> {last['last_step']:,} env steps in "
        f"{last['wall_s']:.0f} s ({last['env_steps_per_s'] or 0:,} env-steps/s). Wrote {run}/: "
        "model.zip, vecnormalize.pkl, config.yaml, MODEL_CARD.md, learning_curve.png, "
        "evaluations.npz, checkpoints/, logs/"
        + (f"; exported the agent to {args.export}/" if args.export else "")
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""The options of a ``follow-train`` run: :class:`Args`, their checks, their record.

:func:`check_new_run` and :func:`check_resume` check every option and hyperparameter of a new
run or a resume without building or writing anything, so that :func:`train.ppo.train` and
``--seeds`` (every seed before any trains) refuse bad input before a folder exists;
:func:`args_to_dict` and :func:`args_from_dict` are the options' record in ``config.yaml``.
"""

from __future__ import annotations

import copy
import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from follow_env.sim.atomic import check_writable, file_on_path
from follow_env.tasks import task_for_env
from train.algos import DEFAULT_ALGO, algo
from train.config import ConfigError, Hyperparams, load_hyperparams, parse_hyperparams, sole_section
from train.export import FORCE_ALONE_ERROR, check_export
from train.trained_agent import (
    TrainedAgent,
    check_fits,
    check_task,
    defaults_from,
    read_trained_agent,
)

__all__ = [
    "DEFAULT_ENV_CONFIG",
    "DEFAULT_SEED",
    "MAX_SEED",
    "MAX_THREADS",
    "Args",
    "absolute_compare_with",
    "args_from_dict",
    "args_to_dict",
    "base_seed",
    "check_folder_option",
    "check_new_run",
    "check_resume",
    "hyperparams_place",
    "run_hyperparams",
]

#: The largest seed any lane may get: SB3 passes the seed to ``numpy.random.seed``.
MAX_SEED = 2**32 - 1
#: The most torch threads a run may ask for (more only slow a 0.1-ms policy step down).
MAX_THREADS = 256
#: The env preset a run trains on unless told (a run from a trained agent: the agent's).
DEFAULT_ENV_CONFIG = "thesis"
#: Training lane j starts from seed + j, this seed unless told (a run from a trained agent:
#: the agent's seed + its steps, where a resume of it would go on: train.trained_agent).
DEFAULT_SEED = 10_000


@dataclass(frozen=True)
class Args:
    """Every option of a run (``follow-train --help`` has the same list)."""

    algo: str | None = None  # ppo, recurrent_ppo or sac; None: ppo (a resume: the run's)
    hyperparams: Path | None = None  # rl-zoo3-style YAML, keyed by env id; None: the algo's
    env_id: str | None = None  # the YAML section, and the task; default: the file's only section
    scenarios: tuple[str, ...] | None = None  # the task's variants to train on; None = all
    env_config: str | None = None  # the env preset it trains and is evaluated on; None: thesis
    seed: int | None = None  # training lanes start from seed + j; None: DEFAULT_SEED
    eval_seed: int = 5_000  # held-out lanes start from eval_seed + j
    eval_episodes: int = 2  # per scenario, at each held-out evaluation
    eval_freq: int = 100_000  # env steps between held-out evaluations
    checkpoint_freq: int = 200_000  # env steps between checkpoints
    final_episodes: int = 10  # per scenario, in the model card's comparison with the law
    compare_with: str = "gsmpn:tuned"
    n_timesteps: int | None = None  # overrides the hyperparameter file's
    n_envs: int | None = None  # overrides the hyperparameter file's
    threads: int = 1  # torch threads (the env steps in this thread too)
    mkl_intel_paths: bool = False  # MKL's Intel code paths on any x86-64 CPU (train.mkl_paths)
    runs: Path = Path("runs")
    out: Path | None = None  # the run folder (default: runs/<algo>-<timestamp>)
    resume: Path | None = None  # continue this run from its newest checkpoint
    trained_agent: Path | None = None  # start from this agent's weights (train.trained_agent)
    export: Path | None = None  # also copy the finished agent into this folder
    force: bool = False  # --export may write into a folder it did not make (train.export)
    progress: bool = True


def check_new_run(args: Args, *, clearing: bool = False) -> tuple[Args, Hyperparams]:
    """Check a new run's options and hyperparameters without building or writing anything.

    :param clearing: ``--out`` holds what a run killed before its first checkpoint wrote, and
        the caller clears it before this run starts (:mod:`train.seeds`): that it is not empty
        is not refused.
    :returns: the options with their defaults filled in (a ``--compare-with`` agent's path
        absolute, :func:`absolute_compare_with`: the run's ``config.yaml`` records it, and a
        ``--resume`` from another folder must compare with the same agent), and the
        hyperparameters.
    :raises ValueError: naming the option or YAML key, its value and what it may be.
    """
    agent, derived = None, False
    if args.trained_agent is not None:  # its algorithm, preset, scenarios, seeds (and task)
        agent = read_trained_agent(args.trained_agent)
        given = defaults_from(agent, args)
        derived = "seed" in given
        args = dataclasses.replace(args, **given, trained_agent=agent.folder)
    args = _with_defaults(args)
    if agent is not None:  # before the scenarios it gave are checked against another task's
        check_task(agent, args.env_id)
    args = dataclasses.replace(args, compare_with=absolute_compare_with(args.compare_with))
    try:
        _check_options(args, run=None, clearing=clearing)
        if args.n_envs is not None:  # before the file: its batch size may not fit either
            _check_lanes(args.n_envs, args.scenarios)
        hp = run_hyperparams(args, agent)
        if agent is not None:
            check_fits(agent, hp, hyperparams_place(args))
        _check_against_hyperparams(args, hp)
    except ValueError as e:
        if derived and str(e).startswith("--seed "):  # a seed the command line did not give
            raise ValueError(
                f"{e} (the agent's seed + its steps, where its training stopped: give --seed)"
            ) from None
        raise
    return args, hp


def run_hyperparams(args: Args, agent: TrainedAgent | None = None) -> Hyperparams:
    """The hyperparameters a new run with ``args`` trains with: its file's section (a run from
    a trained agent without ``--hyperparams``: the agent's own, ``agent`` read already or read
    here) with the command line's ``--n-timesteps`` and ``--n-envs``, checked.

    :raises ValueError: naming the file or the key.
    """
    args = _with_defaults(args)
    given = {k: v for k in ("n_timesteps", "n_envs") if (v := getattr(args, k)) is not None}
    if args.hyperparams is None:  # only a run from a trained agent leaves it to the agent
        agent = agent or read_trained_agent(args.trained_agent)
        saved = copy.deepcopy(agent.hyperparams)
        return parse_hyperparams(saved, where=agent.where, overrides=given, algo=args.algo)
    return load_hyperparams(args.hyperparams, args.env_id, overrides=given, algo=args.algo)


def hyperparams_place(args: Args) -> str:
    """Where a new run's hyperparameters come from, as error messages name it."""
    if args.hyperparams is None and args.trained_agent is not None:
        return f"{args.trained_agent} (config.yaml [hyperparams])"
    return f"{args.hyperparams} [{args.env_id}]"


def check_resume(args: Args) -> tuple[Args, Hyperparams, dict[str, Any], str, tuple]:
    """Check a resume (``args.resume``) without building or writing anything: the run's
    configuration, logs and checkpoint, and the options a resume may change.

    :returns: ``(args, hyperparameters, saved config, where, (steps, model, statistics))``:
        the run's saved options with those given now.
    :raises ValueError: if the folder is no run, a log is damaged, there is no checkpoint, or
        nothing is left to train, naming the file or option.
    """
    from train import run as runs

    run = Path(args.resume)
    if not run.is_dir():
        what = "is a file, not a run folder" if run.exists() else "no such run folder"
        raise ValueError(f"--resume {run}: {what}")
    saved = runs.read_config(run)
    where = f"{run / runs.CONFIG} [hyperparams]"
    if not isinstance(saved.get("args"), dict):
        raise ValueError(f"{run / runs.CONFIG}: no 'args' mapping; not a follow-train run")
    # Runs saved before there was a choice of algorithm are PPO's.
    learner = algo(saved.get("algo", DEFAULT_ALGO), option=f"{run / runs.CONFIG}: algo")
    if args.algo is not None and args.algo != learner.name:
        raise ValueError(
            f"--algo {args.algo}: {run} is a {learner.name} run (its config.yaml says so); a "
            "resume continues with its own algorithm: leave --algo out"
        )
    given = {"n_timesteps": args.n_timesteps} if args.n_timesteps is not None else {}
    hp = parse_hyperparams(saved["hyperparams"], where=where, overrides=given, algo=learner.name)
    resumed = dataclasses.replace(
        args_from_dict(saved["args"], where=str(run / runs.CONFIG)),
        algo=learner.name,
        n_timesteps=args.n_timesteps,
        threads=args.threads,
        mkl_intel_paths=args.mkl_intel_paths,
        progress=args.progress,
        export=args.export,
        force=args.force,
        resume=run,
    )
    # The logs the session goes on writing, read now: once it has started it has written its
    # config.yaml, progress CSV and TensorBoard file.
    runs.read_sessions(run)
    runs.read_evaluations(run)
    checkpoint = runs.newest_checkpoint(run, learner.name)
    if checkpoint is None:
        raise ValueError(f"{run / runs.CHECKPOINTS}: no checkpoint to resume from")
    steps = checkpoint[0]
    # A run whose training ended but whose report did not (its model card missing: a Ctrl-C
    # while it was written) resumes with nothing to train: the session writes the report.
    report_only = not given and hp["n_timesteps"] <= steps and not (run / runs.CARD).is_file()
    if hp["n_timesteps"] <= steps and not report_only:
        option = "--n-timesteps" if given else f"n_timesteps in {run / runs.CONFIG}"
        raise ValueError(
            f"{option}={hp['n_timesteps']:,} is out of range: the newest checkpoint is at "
            f"{steps:,} env steps, so a resume needs --n-timesteps > {steps:,}"
        )
    _check_options(resumed, run=run)
    _check_against_hyperparams(resumed, hp)
    return resumed, hp, saved, where, checkpoint


def _option(name: str) -> str:
    return "--" + name.replace("_", "-")


def _check_int(name: str, value: Any, low: int, high: int | None = None) -> None:
    """``--name`` must be an integer in ``[low, high]``."""
    is_int = isinstance(value, int) and not isinstance(value, bool)
    if not is_int or value < low or (high is not None and value > high):
        rule = f"an integer >= {low}" if high is None else f"an integer in [{low}, {high:,}]"
        raise ValueError(f"{_option(name)} {value!r} is out of range: must be {rule}")


def _with_defaults(args: Args) -> Args:
    """``args`` with the algorithm (PPO), its hyperparameter file, the env id (the file's only
    section) and the scenarios (all of the task's) filled in where they were left to their
    defaults."""
    learner = algo(DEFAULT_ALGO if args.algo is None else args.algo)
    hyperparams = args.hyperparams
    if hyperparams is None and args.trained_agent is None:  # a trained agent's: its own
        hyperparams = learner.hyperparams
    env_id = args.env_id
    if env_id is None and hyperparams is not None:
        try:
            env_id = sole_section(hyperparams)
        except ConfigError as e:
            raise ValueError(str(e)) from None
    scenarios = args.scenarios
    if scenarios is None:
        try:
            scenarios = tuple(task_for_env(env_id).variants())
        except ValueError as e:
            raise ValueError(f"--env-id: {e}") from None
    return dataclasses.replace(
        args,
        algo=learner.name,
        hyperparams=hyperparams,
        env_id=env_id,
        scenarios=scenarios,
        env_config=DEFAULT_ENV_CONFIG if args.env_config is None else args.env_config,
        seed=base_seed(args),
    )


def base_seed(args: Args) -> int:
    """The seed training lane j starts from ``+ j``: ``--seed``, else :data:`DEFAULT_SEED`."""
    return DEFAULT_SEED if args.seed is None else args.seed


def _check_options(args: Args, *, run: Path | None, clearing: bool = False) -> None:
    """Check every option that does not depend on the hyperparameters.

    :param run: the folder being resumed, None for a new run.
    :param clearing: as :func:`check_new_run`'s.
    :raises ValueError: naming the option, its value and its allowed range.
    """
    from policies import make_policy

    try:
        task = task_for_env(args.env_id)
    except ValueError as e:
        raise ValueError(f"--env-id: {e}") from None
    known = task.variants()
    scenarios = args.scenarios
    if not isinstance(scenarios, tuple | list) or not all(isinstance(s, str) for s in scenarios):
        raise ValueError(f"--scenarios {scenarios!r} must be a list of scenario names")
    for name in scenarios:
        if name not in known:
            raise ValueError(f"--scenarios: unknown scenario {name!r}; known: {', '.join(known)}")
    if len(set(scenarios)) != len(scenarios) or not scenarios:
        raise ValueError("--scenarios must name each scenario once, at least one")
    if args.env_config not in task.presets:
        raise ValueError(
            f"--env-config {args.env_config!r} is not a preset: {', '.join(task.presets)}"
        )
    for name in ("eval_episodes", "eval_freq", "checkpoint_freq"):
        _check_int(name, getattr(args, name), 1)
    _check_int("final_episodes", args.final_episodes, 0)
    if args.final_episodes and task.name != "person_follow":
        raise ValueError(
            f"--final-episodes {args.final_episodes}: the model card's comparison with a law is "
            f"PersonFollow's only so far; give --final-episodes 0 and compare with "
            f"follow-eval run --task {task.name}"
        )
    _check_int("threads", args.threads, 1, MAX_THREADS)
    _check_int("seed", args.seed, 0, MAX_SEED)
    _check_int("eval_seed", args.eval_seed, 0, MAX_SEED)
    if not isinstance(args.progress, bool) or not isinstance(args.force, bool):
        raise ValueError("progress and force must be true or false")
    try:
        make_policy(args.compare_with)
    except (ValueError, TypeError) as e:
        raise ValueError(f"--compare-with {args.compare_with!r}: {e}") from None
    if run is None:
        _check_run_folder(args, clearing=clearing)
    if args.export is not None:
        location = run or args.out or args.runs / f"{args.algo}-<timestamp>"
        check_export(args.export, force=args.force, run=location)
    elif args.force:
        raise ValueError(FORCE_ALONE_ERROR)


def absolute_compare_with(name: str, *, missing: bool = False) -> str:
    """``--compare-with`` as a process in another folder reads it as this one does: a path to
    an agent (a run or export folder, a ``.zip``, an ensemble) made absolute, a registered
    name (``gsmpn:tuned``, ``ppo``) as it is. The registry's rule (:func:`policies.make_policy`):
    a registered name is that policy even if a folder of that name is here too, and any other
    name that exists is a path. A path that does not exist is left for the check to name,
    unless ``missing`` (a study's record: the agent may have moved since its seeds trained)."""
    from policies import available_policies

    if not isinstance(name, str) or not name.strip() or name in available_policies():
        return name  # an empty name is not the current folder: make_policy refuses it
    if not missing and not Path(name).exists():
        return name
    return str(Path(name).absolute())


def _check_lanes(n_envs: int, scenarios: Sequence[str]) -> None:
    if n_envs % len(scenarios):
        raise ValueError(
            f"n_envs={n_envs} is out of range: must be a multiple of the {len(scenarios)} "
            "scenarios (each scenario gets the same number of lanes)"
        )


def _check_against_hyperparams(args: Args, hp: Hyperparams) -> None:
    """The options whose range depends on the hyperparameters: lanes and seeds."""
    _check_lanes(hp["n_envs"], args.scenarios)
    # SB3 seeds numpy with seed + steps at a resume, and lane j with that + j.
    _check_int("n_timesteps", hp["n_timesteps"], 1, MAX_SEED - hp["n_envs"])
    _check_int("seed", args.seed, 0, MAX_SEED - hp["n_timesteps"] - hp["n_envs"])
    eval_lanes = max(args.eval_episodes * len(args.scenarios), args.final_episodes)
    _check_int("eval_seed", args.eval_seed, 0, MAX_SEED - eval_lanes)


def check_folder_option(option: str, path: Path) -> None:
    """``option``'s ``path`` is a folder, or one that can be made, and takes a new file.

    :raises ValueError: naming the option, the path and what is in the way.
    """
    blocker = file_on_path(path)
    if blocker is not None:
        where = "is a file" if blocker == path else f"runs through the file {blocker}"
        raise ValueError(f"{option} {path}: {where}, not a folder")
    try:  # before training: a folder that takes no file would lose the run at the end
        check_writable(path / "config.yaml")
    except OSError as e:
        raise ValueError(f"{option} {path}: {e}") from None


def _check_run_folder(args: Args, *, clearing: bool = False) -> None:
    """``--out`` must be new or an empty folder (or one the caller clears first:
    ``clearing``), and ``--runs`` a folder or creatable."""
    for option, path in (("--out", args.out), ("--runs", args.runs)):
        if path is None or (option == "--runs" and args.out is not None):
            continue
        check_folder_option(option, path)
    if args.out is not None and not clearing and args.out.exists() and any(args.out.iterdir()):
        raise ValueError(
            f"--out {args.out} already exists and is not empty; use --resume to continue it"
        )


def args_to_dict(args: Args) -> dict[str, Any]:
    """The options ``config.yaml`` records: how the run trains, not where this session writes."""
    out: dict[str, Any] = {}
    for f in dataclasses.fields(args):
        if f.name in ("resume", "export", "out", "force"):
            continue  # where this session writes, not how the run trains
        value = getattr(args, f.name)
        if isinstance(value, Path):
            value = str(value)
        elif isinstance(value, tuple):
            value = list(value)
        out[f.name] = value
    return out


def args_from_dict(saved: dict[str, Any], *, where: str = "config.yaml") -> Args:
    """:class:`Args` from a saved ``config.yaml`` (values are checked by :func:`check_resume`).

    :raises ValueError: naming the file for a value of the wrong kind.
    """
    fields = {f.name: f for f in dataclasses.fields(Args)}
    values: dict[str, Any] = {}
    for name, value in saved.items():
        if name not in fields:
            continue
        try:
            if name in ("hyperparams", "runs", "trained_agent") and value is not None:
                value = Path(value)
            elif name == "scenarios":
                value = tuple(value)
        except TypeError:
            raise ValueError(f"{where}: args.{name}={value!r} is not valid") from None
        values[name] = value
    return Args(**values)

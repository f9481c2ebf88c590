"""``follow-train``: PPO, RecurrentPPO or SAC on PersonFollow-v0, one run folder per run.

::

    follow-train                                  # PPO, train/configs/ppo.yaml, all scenarios
    follow-train --algo sac                       # SAC, train/configs/sac.yaml
    follow-train --algo recurrent_ppo             # sb3-contrib's RecurrentPPO (LSTM policy)
    follow-train --n-timesteps 20000 --out runs/ppo-smoke
    follow-train --resume runs/ppo-<timestamp>    # continue from the newest checkpoint
    follow-train --export agents/mine             # also copy the agent there (train.export)

(also ``python -m train``). Read top-down: :class:`Args` holds every option; :func:`train`
sets up the envs and the model, learns, and saves, the same way for every algorithm
(:mod:`train.algos` has what differs: the class, the rules of its hyperparameters, the shipped
file). The run's ``config.yaml`` records the algorithm, and a resume continues with it. SB3
(and sb3-contrib) do the algorithm; the agent's view of
the env (action scaling, the observation's extra features, the training reward) is the
``vec_env_wrapper`` list of the hyperparameter file (:mod:`train.wrappers`), assembled by
:func:`train.envs.agent_env`. The run folder's layout is in :mod:`train.run`.

Seeds: training lane ``j`` starts from seed ``seed + j`` (10 000 + j by default) and a resumed
session from ``seed + steps + j``; the held-out evaluation uses ``eval_seed + j`` (5 000 + j);
the evaluation harness (``follow-eval``, ``make eval``) uses seeds 0 .. N. None overlap. Every
seed stays below 2**32 (:data:`MAX_SEED`): SB3 seeds numpy's global generator, which takes no
larger one.

Every option and every hyperparameter is checked, and the envs and the model are built in
memory, before anything is written: a bad input gives one line ``follow-train: error: ...``
naming the option or YAML key, its value and what it may be, exit status 2, and no folder.
"""

from __future__ import annotations

import dataclasses
import shutil
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from follow_env.sim.atomic import atomic_write_text, check_writable, file_on_path
from follow_env.tasks import task_for_env
from train.algos import ALGOS, DEFAULT_ALGO, algo, load_model, new_model
from train.config import (
    ConfigError,
    Hyperparams,
    check_action_fit,
    load_hyperparams,
    parse_hyperparams,
    policy_class,
    sole_section,
)
from train.export import AGENT_FILES, EXPORT_EXTRAS, FORCE_ALONE_ERROR, check_export, export_agent

__all__ = [
    "AGENT_FILES",
    "EXPORT_EXTRAS",
    "Args",
    "Interrupted",
    "check_new_run",
    "check_resume",
    "train",
]

PROG = "follow-train"
USAGE_ERROR = 2
DEFAULT_HYPERPARAMS = ALGOS[DEFAULT_ALGO].hyperparams  # train/configs/ppo.yaml
#: The largest seed any lane may get: SB3 passes the seed to ``numpy.random.seed``.
MAX_SEED = 2**32 - 1
#: The most torch threads a run may ask for (more only slow a 0.1-ms policy step down).
MAX_THREADS = 256


@dataclass(frozen=True)
class Args:
    """Every option of a run (``follow-train --help`` has the same list)."""

    algo: str | None = None  # ppo, recurrent_ppo or sac; None: ppo (a resume: the run's)
    hyperparams: Path | None = None  # rl-zoo3-style YAML, keyed by env id; None: the algo's
    env_id: str | None = None  # the YAML section, and the task; default: the file's only section
    scenarios: tuple[str, ...] | None = None  # the task's variants to train on; None = all
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
    out: Path | None = None  # the run folder (default: runs/<algo>-<timestamp>)
    resume: Path | None = None  # continue this run from its newest checkpoint
    export: Path | None = None  # also copy the finished agent into this folder
    force: bool = False  # --export may write into a folder it did not make (train.export)
    progress: bool = True


class Interrupted(KeyboardInterrupt):
    """Ctrl-C during a run; the message says what was kept and how to go on."""


class TrainingError(RuntimeError):
    """Training diverged; the message says where and what the run folder keeps."""


def train(args: Args, command: str = PROG) -> Path:
    """Train (or resume) a run as ``args`` say; returns the run folder.

    :raises ValueError: for bad options or inputs (the message names them), before anything
        is written.
    :raises Interrupted: on Ctrl-C once the run folder exists.
    :raises TrainingError: if the policy's outputs became NaN.
    """
    import torch
    from stable_baselines3.common.logger import CSVOutputFormat, Logger, TensorBoardOutputFormat

    from train import report
    from train import run as runs

    # -- Check every option and hyperparameter; build the envs and the model in memory -------
    if args.resume is not None:
        run: Path | None = args.resume
        args, hp, saved, where, checkpoint = _resume_settings(args)
        start_step, model_path, stats_path = checkpoint
        _check_options(args, run=run)
    else:
        run, saved, model_path, stats_path, start_step = None, None, None, None, 0
        args, hp = check_new_run(args)
        where = f"{args.hyperparams} [{args.env_id}]"
    _check_against_hyperparams(args, hp)
    torch.set_num_threads(args.threads)
    venv, eval_env, model = _build(args, hp, where, model_path, stats_path, start_step)

    # -- The run folder, now that everything checked out -------------------------------------
    made = run is None and (args.out is None or not args.out.exists())
    if run is None:
        run = args.out if args.out is not None else runs.new_run_dir(args.runs, args.algo)
        run.mkdir(parents=True, exist_ok=True)
    try:
        if saved is None:
            runs.write_config(run, _resolved_config(args, hp, venv, command))
        else:
            runs.remove_stale_scratch(run)
            if args.n_timesteps is not None:  # a longer run: the saved total follows
                saved["hyperparams"]["n_timesteps"] = hp["n_timesteps"]
                runs.write_config(run, saved)
        (run / runs.LOGS).mkdir(exist_ok=True)
        formats = [CSVOutputFormat(str(run / runs.LOGS / f"progress-{start_step}.csv"))]
        formats.append(TensorBoardOutputFormat(str(run / runs.LOGS / "tb")))
        model.set_logger(Logger(str(run / runs.LOGS), formats))
        session = runs.SessionLog(run, command, start_step, args.threads)
    except BaseException:
        if saved is None:
            _remove_new_run(run, made)
        raise
    callbacks = [
        runs.AtomicCheckpointCallback(
            args.checkpoint_freq, run, venv.num_envs, session, prefix=args.algo
        ),
        runs.HeldOutEvalCallback(eval_env, run, args.eval_seed, args.eval_freq, venv.num_envs),
    ]

    # -- Learn ------------------------------------------------------------------------------
    try:
        model.learn(
            hp["n_timesteps"] - model.num_timesteps,
            callback=callbacks,
            progress_bar=args.progress,
            reset_num_timesteps=False,
        )
    except KeyboardInterrupt:
        kept = runs.newest_checkpoint(run, args.algo)
        trained = model.num_timesteps - start_step
        session.close("interrupted", kept[0] if kept else start_step, trained)
        if kept is None and saved is None:
            _remove_new_run(run, made)
            raise Interrupted(
                f"interrupted before the first checkpoint (every {args.checkpoint_freq:,} env "
                f"steps): nothing to resume, removed {run}"
            ) from None
        raise Interrupted(
            f"interrupted; resume with --resume {run} (continues from the checkpoint at "
            f"{kept[0] if kept else start_step:,} env steps)"
        ) from None
    except ValueError as e:
        kept = runs.newest_checkpoint(run, args.algo)
        trained = model.num_timesteps - start_step
        session.close("failed", kept[0] if kept else start_step, trained)
        if "invalid values" not in str(e):
            raise
        raise TrainingError(
            f"training diverged at {model.num_timesteps:,} env steps: the policy's outputs became "
            f"NaN (lower learning_rate or clip_range in {where}); {run} keeps its checkpoints"
        ) from None
    steps = model.num_timesteps - start_step

    # -- Save: the agent, the session, the curve, the comparison, the model card --------------
    try:
        runs.save_normalization(model.get_vec_normalize_env(), run / runs.NORMALIZATION)
        runs.save_model(model, run / runs.MODEL)
        session.close("finished", model.num_timesteps, steps)
        venv.close()
        eval_env.close()
        title = f"{ALGOS[args.algo].label} on {args.env_id}"
        report.plot_learning_curve(run, run / runs.CURVE, title)
        seeds = range(args.eval_seed, args.eval_seed + args.final_episodes)
        comparison = None
        if args.final_episodes > 0:
            comparison = report.compare_with_law(
                str(run),
                args.compare_with,
                args.scenarios,
                seeds,
                args.env_config,
                platform=(hp.get("env_kwargs") or {}).get("platform"),
            )
        card = report.model_card(
            run=run,
            args=args,
            hp=hp,
            sessions=session.sessions,
            comparison=comparison,
            seeds=seeds,
            versions=report.package_versions(),
        )
        atomic_write_text(run / runs.CARD, card)
    except KeyboardInterrupt:
        raise Interrupted(
            f"interrupted after training, while writing the report: the agent is in {run}, "
            f"{runs.CARD} may be missing"
        ) from None
    if args.export is not None:
        try:
            export_agent(run, args.export, force=args.force)
        except ValueError as e:  # the folder changed during training: the run stays whole
            raise ValueError(f"{e} (training finished: the run is complete in {run})") from None
    return run


def check_new_run(args: Args) -> tuple[Args, Hyperparams]:
    """Check a new run's options and hyperparameters without building or writing anything.

    :returns: the options with their defaults filled in, and the hyperparameters.
    :raises ValueError: naming the option or YAML key, its value and what it may be.
    """
    args = _with_defaults(args)
    _check_options(args, run=None)
    if args.n_envs is not None:  # before the file: its batch size may not fit either
        _check_lanes(args.n_envs, args.scenarios)
    given = {k: v for k in ("n_timesteps", "n_envs") if (v := getattr(args, k)) is not None}
    hp = load_hyperparams(args.hyperparams, args.env_id, overrides=given, algo=args.algo)
    _check_against_hyperparams(args, hp)
    return args, hp


def check_resume(args: Args) -> None:
    """Check a resume (``args.resume``) as :func:`train` would, without building or writing
    anything: the run's configuration, logs and checkpoint, and the options given with it.

    :raises ValueError: naming the file or option and what is wrong.
    """
    resumed, hp, *_ = _resume_settings(args)
    _check_options(resumed, run=resumed.resume)
    _check_against_hyperparams(resumed, hp)


# -- Helpers ---------------------------------------------------------------------------------


def _resume_settings(args: Args) -> tuple[Args, Hyperparams, dict[str, Any], str, tuple]:
    """The saved settings of the run ``args.resume``, with the options a resume may change.

    :returns: ``(args, hyperparameters, saved config, where, (steps, model, statistics))``.
    :raises ValueError: if the folder is no run, has no checkpoint, or nothing is left to train.
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
        _args_from_dict(saved["args"], where=str(run / runs.CONFIG)),
        algo=learner.name,
        n_timesteps=args.n_timesteps,
        threads=args.threads,
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
    if hp["n_timesteps"] <= steps:
        option = "--n-timesteps" if given else f"n_timesteps in {run / runs.CONFIG}"
        raise ValueError(
            f"{option}={hp['n_timesteps']:,} is out of range: the newest checkpoint is at "
            f"{steps:,} env steps, so a resume needs --n-timesteps > {steps:,}"
        )
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
    hyperparams = learner.hyperparams if args.hyperparams is None else args.hyperparams
    env_id = args.env_id
    if env_id is None:
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
        args, algo=learner.name, hyperparams=hyperparams, env_id=env_id, scenarios=scenarios
    )


def _check_options(args: Args, *, run: Path | None) -> None:
    """Check every option that does not depend on the hyperparameters.

    :param run: the folder being resumed, None for a new run.
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
        _check_run_folder(args)
    if args.export is not None:
        location = run or args.out or args.runs / f"{args.algo}-<timestamp>"
        check_export(args.export, force=args.force, run=location)
    elif args.force:
        raise ValueError(FORCE_ALONE_ERROR)


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


def _check_run_folder(args: Args) -> None:
    """``--out`` must be new or an empty folder, and ``--runs`` a folder or creatable."""
    for option, path in (("--out", args.out), ("--runs", args.runs)):
        if path is None or (option == "--runs" and args.out is not None):
            continue
        blocker = file_on_path(path)
        if blocker is not None:
            where = "is a file" if blocker == path else f"runs through the file {blocker}"
            raise ValueError(f"{option} {path}: {where}, not a folder")
        try:  # before training: a folder that takes no file would lose the run at the end
            check_writable(path / "config.yaml")
        except OSError as e:
            raise ValueError(f"{option} {path}: {e}") from None
    if args.out is not None and args.out.exists() and any(args.out.iterdir()):
        raise ValueError(
            f"--out {args.out} already exists and is not empty; use --resume to continue it"
        )


def _build(
    args: Args,
    hp: Hyperparams,
    where: str,
    model_path: Path | None,
    stats_path: Path | None,
    start_step: int,
) -> tuple[Any, Any, Any]:
    """The training env, the held-out env and the model (``args.algo``'s), in memory (nothing
    is written).

    The wrappers and SB3 check their own arguments here, so a value they refuse is reported
    as a bad hyperparameter before the run folder exists.
    """
    from train import run as runs
    from train.envs import agent_env, base_env
    from train.wrappers import env_action_names

    lanes = hp["n_envs"] // len(args.scenarios)
    normalization = stats_path if hp["normalize"] and stats_path is not None else None
    try:
        env_kwargs = hp.get("env_kwargs")
        train_base = base_env(args.scenarios, lanes, args.env_config, args.env_id, env_kwargs)
        check_action_fit(hp, env_action_names(train_base), where=where)
        venv = agent_env(train_base, hp, "train", normalization=normalization)
        eval_env = agent_env(
            base_env(args.scenarios, args.eval_episodes, args.env_config, args.env_id, env_kwargs),
            hp,
            "eval",
        )
    except ConfigError:
        raise
    except (ValueError, TypeError) as e:
        raise ConfigError(f"{where}: the agent's env cannot be built: {e}") from None
    except Exception as e:  # a resume's statistics file: pickle and SB3 raise their own
        if normalization is None:
            raise
        problem = f"{type(e).__name__}: {e}"
        raise ValueError(f"{normalization}: cannot resume from it ({problem})") from None
    learner = ALGOS[args.algo]
    if model_path is not None:
        model = load_model(learner, model_path, venv)
        replay = runs.replay_buffer_file(model_path)
        try:  # an off-policy run goes on learning from its transitions
            if replay.is_file():
                model.load_replay_buffer(replay)
        except Exception as e:  # pickle and SB3 raise their own
            raise ValueError(f"{replay}: cannot resume from it ({type(e).__name__}: {e})") from None
        model.set_random_seed(args.seed + start_step)  # new episodes, still >= args.seed
        return venv, eval_env, model
    policy = policy_class(hp["policy"], algo=learner.name)
    return venv, eval_env, new_model(learner, policy, hp, venv, args.seed, where=where)


def _remove_new_run(run: Path, made: bool) -> None:
    """Remove what this session wrote into a new run folder (the folder too if it made it)."""
    if made:
        shutil.rmtree(run, ignore_errors=True)
    else:  # --out was an empty folder: everything in it is this session's
        for child in run.iterdir():
            if child.is_dir() and not child.is_symlink():
                shutil.rmtree(child, ignore_errors=True)
            else:
                child.unlink(missing_ok=True)


def _resolved_config(args: Args, hp: Hyperparams, venv: Any, command: str) -> dict[str, Any]:
    """What ``config.yaml`` holds: enough to rebuild the agent's env and to resume."""
    from train.wrappers import env_action_names, env_platform

    base = venv
    while hasattr(base, "venv"):
        base = base.venv
    names = env_action_names(base)
    return {
        "command": command,
        # The learner; policies.learned reads it to rebuild the network (and its memory).
        "algo": args.algo,
        "env_id": args.env_id,
        "args": _args_to_dict(args),
        "hyperparams": hp,
        # The platform the agent drives; policies.learned.ppo refuses any other.
        "platform": env_platform(base),
        # The env's spaces, so that a policy can rebuild the agent's view without an env.
        "env_spaces": {
            "observation": {
                "low": base.observation_space.low.tolist(),
                "high": base.observation_space.high.tolist(),
            },
            "action": {
                "low": base.action_space.low.tolist(),
                "high": base.action_space.high.tolist(),
                **({"names": list(names)} if names is not None else {}),
            },
        },
        "agent_observation_shape": list(venv.observation_space.shape),
    }


def _args_to_dict(args: Args) -> dict[str, Any]:
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


def _args_from_dict(saved: dict[str, Any], *, where: str = "config.yaml") -> Args:
    """:class:`Args` from a saved ``config.yaml`` (values are checked by :func:`_check_args`).

    :raises ValueError: naming the file for a value of the wrong kind.
    """
    fields = {f.name: f for f in dataclasses.fields(Args)}
    values: dict[str, Any] = {}
    for name, value in saved.items():
        if name not in fields:
            continue
        try:
            if name in ("hyperparams", "runs"):
                value = Path(value)
            elif name == "scenarios":
                value = tuple(value)
        except TypeError:
            raise ValueError(f"{where}: args.{name}={value!r} is not valid") from None
        values[name] = value
    return Args(**values)

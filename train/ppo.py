"""``follow-train``: PPO, RecurrentPPO or SAC on PersonFollow-v0, one run folder per run.

::

    follow-train                                  # PPO, train/configs/ppo.yaml, all scenarios
    follow-train --algo sac                       # SAC, train/configs/sac.yaml
    follow-train --algo recurrent_ppo             # sb3-contrib's RecurrentPPO (LSTM policy)
    follow-train --n-timesteps 20000 --out runs/ppo-smoke
    follow-train --resume runs/ppo-<timestamp>    # continue from the newest checkpoint
    follow-train --trained-agent agents/mine      # a new run from an agent's weights
    follow-train --export agents/mine             # also copy the agent there (train.export)

(also ``python -m train``). Read top-down: :class:`~train.options.Args` holds every option
(checked in :mod:`train.options`); :func:`train` sets up the envs and the model, learns, and
saves, the same way for every algorithm (:mod:`train.algos` has what differs: the class, the
rules of its hyperparameters, the shipped file). The run's ``config.yaml`` records the
algorithm, and a resume continues with it. SB3 (and sb3-contrib) do the algorithm; the agent's
view of the env (action scaling, the observation's extra features, the training reward) is the
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

import contextlib
import shutil
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from follow_env.sim.atomic import atomic_write_text, missing_folders, remove_empty_folders
from follow_env.sim.checks import one_line
from train.algos import ALGOS, DEFAULT_ALGO, load_model, new_model
from train.config import ConfigError, Hyperparams, check_action_fit, policy_class
from train.export import AGENT_FILES, EXPORT_EXTRAS, export_agent
from train.options import (
    MAX_SEED,
    MAX_THREADS,
    Args,
    args_to_dict,
    check_new_run,
    check_resume,
    hyperparams_place,
)
from train.study_lock import StudyLock
from train.trained_agent import (
    TrainedAgent,
    check_base,
    check_spaces,
    load_statistics,
    read_trained_agent,
    record,
    start_from,
    statistics_digest,
)

__all__ = [
    "AGENT_FILES",
    "EXPORT_EXTRAS",
    "MAX_SEED",
    "MAX_THREADS",
    "Args",
    "Interrupted",
    "check_new_run",
    "check_resume",
    "train",
]

PROG = "follow-train"
USAGE_ERROR = 2
DEFAULT_HYPERPARAMS = ALGOS[DEFAULT_ALGO].hyperparams  # train/configs/ppo.yaml


class Interrupted(KeyboardInterrupt):
    """Ctrl-C during a run; the message says what was kept and how to go on."""


class TrainingError(RuntimeError):
    """Training diverged; the message says where and what the run folder keeps."""


def train(args: Args, command: str = PROG) -> Path:
    """Train (or resume) a run as ``args`` say; returns the run folder.

    The run folder is held while it trains (:class:`train.study_lock.StudyLock`): a second
    training of the same run meanwhile (``--resume RUN`` twice, or beside the ``--seeds``
    command training it) is refused before it writes anything.

    :raises ValueError: for bad options or inputs (the message names them), before anything
        is written.
    :raises Interrupted: on Ctrl-C once the run folder exists.
    :raises TrainingError: if the policy's outputs became NaN.
    """
    option = "--resume" if args.resume is not None else "--out"
    with StudyLock(option=option, what="run") as lock:
        return _train(args, command, lock)


def _train(args: Args, command: str, lock: StudyLock) -> Path:
    """:func:`train`, its run folder held by ``lock`` from when it exists."""
    import torch
    from stable_baselines3.common.logger import CSVOutputFormat, Logger, TensorBoardOutputFormat

    from train import report
    from train import run as runs
    from train.mkl_paths import mkl_code_path, require_active

    # -- Check every option and hyperparameter; build the envs and the model in memory -------
    if args.resume is not None:
        run: Path | None = args.resume
        args, hp, saved, where, checkpoint = check_resume(args)
        start_step, model_path, stats_path = checkpoint
    else:
        run, saved, model_path, stats_path, start_step = None, None, None, None, 0
        args, hp = check_new_run(args)
        where = hyperparams_place(args)
    if args.mkl_intel_paths:  # never the generic paths for a run that asked for Intel's
        require_active()
    torch.set_num_threads(args.threads)
    agent = None
    if saved is None and args.trained_agent is not None:
        agent = read_trained_agent(args.trained_agent)
        digests = statistics_digest(agent, bool(hp["normalize"]))
    venv, eval_env, model = _build(args, hp, where, model_path, stats_path, start_step, agent)
    started_from = None
    if agent is not None:
        start_from(model, agent)
        if statistics_digest(agent, bool(hp["normalize"])) != digests:
            raise ValueError(
                f"--trained-agent {agent.folder}: its files changed while this run read them; "
                "run the command again once they are whole"
            )
        started_from = record(agent, digests)

    # -- The run folder, now that everything checked out -------------------------------------
    # The folders this run makes (its own, and the missing parents of --out or --runs),
    # deepest first: removed again if it ends before its first checkpoint.
    made: list[Path] = []
    if run is None:
        made = missing_folders(args.out if args.out is not None else args.runs)
        run = args.out if args.out is not None else runs.new_run_dir(args.runs, args.algo)
        if args.out is None:
            made.insert(0, run)
        run.mkdir(parents=True, exist_ok=True)
    lock.take(run)  # before anything is written (a refusal removes nothing: it is another's)
    try:
        if saved is None:
            runs.write_config(run, _resolved_config(args, hp, venv, command, started_from))
        else:
            runs.remove_stale_scratch(run)
            if args.n_timesteps is not None:  # a longer run: the saved total follows
                saved["hyperparams"]["n_timesteps"] = hp["n_timesteps"]
                runs.write_config(run, saved)
        (run / runs.LOGS).mkdir(exist_ok=True)
        formats = [CSVOutputFormat(str(run / runs.LOGS / f"progress-{start_step}.csv"))]
        formats.append(TensorBoardOutputFormat(str(run / runs.LOGS / "tb")))
        model.set_logger(Logger(str(run / runs.LOGS), formats))
        session = runs.SessionLog(
            run, command, start_step, args.threads, args.mkl_intel_paths, mkl_code_path()
        )
    except BaseException:
        if saved is None:
            _remove_new_run(run, made)
        raise
    checkpoints = runs.AtomicCheckpointCallback(
        args.checkpoint_freq, run, venv.num_envs, session, prefix=args.algo
    )
    evaluations = runs.HeldOutEvalCallback(
        eval_env, run, args.eval_seed, args.eval_freq, venv.num_envs, start_step=start_step
    )

    # -- Learn ------------------------------------------------------------------------------
    try:
        model.learn(
            max(hp["n_timesteps"] - model.num_timesteps, 0),  # 0: a resume to write the report
            callback=[checkpoints, evaluations],
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
    except Exception as e:  # SB3, torch or a wrapper failing mid-training: one line, no trace
        kept = runs.newest_checkpoint(run, args.algo)
        trained = model.num_timesteps - start_step
        session.close("failed", kept[0] if kept else start_step, trained)
        if isinstance(e, ValueError) and "invalid values" in str(e):
            raise TrainingError(
                f"training diverged at {model.num_timesteps:,} env steps: the policy's outputs "
                f"became NaN (lower learning_rate or clip_range in {where}); {run} keeps its "
                "checkpoints"
            ) from None
        if kept is None and saved is None:
            _remove_new_run(run, made)
            left = f"nothing to resume, removed {run}"
        else:
            left = f"{run} keeps its checkpoints"
        problem = one_line(e) or "no message"
        raise TrainingError(
            f"training failed at {model.num_timesteps:,} env steps ({type(e).__name__}: "
            f"{problem}; check the hyperparameters in {where}); {left}"
        ) from None
    steps = model.num_timesteps - start_step

    # -- Save: the agent, the session, the curve, the comparison, the model card --------------
    try:
        checkpoints.save()  # the newest checkpoint is the final state: a resume goes on there
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
            f"interrupted after training, while writing the report: the agent is in {run}; "
            f"--resume {run} writes the report"
        ) from None
    if args.export is not None:
        try:
            export_agent(run, args.export, force=args.force)
        except ValueError as e:  # the folder changed during training: the run stays whole
            raise ValueError(f"{e} (training finished: the run is complete in {run})") from None
    return run


# -- Helpers ---------------------------------------------------------------------------------


def _build(
    args: Args,
    hp: Hyperparams,
    where: str,
    model_path: Path | None,
    stats_path: Path | None,
    start_step: int,
    agent: TrainedAgent | None = None,
) -> tuple[Any, Any, Any]:
    """The training env, the held-out env and the model (``args.algo``'s), in memory (nothing
    is written). A run from a trained ``agent`` has its env and view checked to fit the agent's
    and starts from its statistics; its weights are the caller's to load.

    The wrappers and SB3 check their own arguments here, so a value they refuse is reported
    as a bad hyperparameter before the run folder exists.
    """
    from train import run as runs
    from train.envs import agent_env, base_env
    from train.wrappers import env_action_names

    lanes = hp["n_envs"] // len(args.scenarios)
    normalization = stats_path if hp["normalize"] and stats_path is not None else None
    env_kwargs = hp.get("env_kwargs")
    with _building(where, normalization):
        train_base = base_env(args.scenarios, lanes, args.env_config, args.env_id, env_kwargs)
    if agent is not None:  # its env before its view: another platform is named as such
        check_base(agent, train_base)
    with _building(where, normalization):
        check_action_fit(hp, env_action_names(train_base), where=where)
        venv = agent_env(train_base, hp, "train", normalization=normalization)
        eval_env = agent_env(
            base_env(args.scenarios, args.eval_episodes, args.env_config, args.env_id, env_kwargs),
            hp,
            "eval",
        )
    if agent is not None:
        check_spaces(agent, venv)
        load_statistics(venv, agent)  # into a VecNormalize of this run's settings (its gamma)
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


@contextlib.contextmanager
def _building(where: str, normalization: Path | None) -> Iterator[None]:
    """Errors of building the envs as one line: a value a wrapper or the env refuses is a bad
    hyperparameter of ``where``; a resume's statistics file that cannot be read is named."""
    try:
        yield
    except ConfigError:
        raise
    except (ValueError, TypeError, OverflowError, MemoryError) as e:  # e.g. frame_stack 10**9
        problem = one_line(e)
        raise ConfigError(f"{where}: the agent's env cannot be built: {problem}") from None
    except Exception as e:  # a resume's statistics file: pickle and SB3 raise their own
        if normalization is None:
            raise
        problem = f"{type(e).__name__}: {e}"
        raise ValueError(f"{normalization}: cannot resume from it ({problem})") from None


def _remove_new_run(run: Path, made: list[Path]) -> None:
    """Remove what this session wrote into a new run folder, and the folders it made (``run``
    and the missing parents of ``--out`` or ``--runs``, deepest first) once they are empty."""
    for child in run.iterdir():  # everything in it is this session's: it was new or empty
        if child.is_dir() and not child.is_symlink():
            shutil.rmtree(child, ignore_errors=True)
        else:
            child.unlink(missing_ok=True)
    remove_empty_folders(made)


def _resolved_config(
    args: Args, hp: Hyperparams, venv: Any, command: str, started_from: dict[str, Any] | None
) -> dict[str, Any]:
    """What ``config.yaml`` holds: enough to rebuild the agent's env and to resume, and the
    trained agent the run started from (:func:`train.trained_agent.record`), if any."""
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
        "args": args_to_dict(args),
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
        **({"trained_agent": started_from} if started_from is not None else {}),
    }

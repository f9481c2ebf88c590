"""``follow-train``'s command line: options into :class:`~train.ppo.Args`, one-line errors.

Bad arguments or input give one line on stderr (``follow-train: error: ...``) and exit status 2,
before anything is written; Ctrl-C names the run to resume. A ``--seeds`` study whose workers
kept dying (:class:`execution.WorkerLostError`) exits with status :data:`WORKERS_LOST` (3, as
``follow-eval``), saying that the same command resumes it.
"""

from __future__ import annotations

import argparse
import shlex
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import NoReturn

from eval.cli_base import _positive, path_option
from execution import (
    BACKENDS,
    WORKERS_LOST,
    Backend,
    BackendUnavailableError,
    WorkerLostError,
    backend_from_args,
    error_line,
)
from train.algos import ALGOS, CONFIGS, DEFAULT_ALGO
from train.config import ConfigError
from train.export import FORCE_ALONE_ERROR
from train.options import DEFAULT_ENV_CONFIG, DEFAULT_SEED, MAX_THREADS, Args
from train.ppo import PROG, USAGE_ERROR, Interrupted, TrainingError, train
from train.seeds import parse_seeds, train_seeds

__all__ = ["WORKERS_LOST", "build_parser", "main", "parse_args"]


# -- Command line ----------------------------------------------------------------------------


class UsageError(Exception):
    """Bad arguments: reported as one line, exit status 2."""


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> NoReturn:
        raise UsageError(message)


def build_parser() -> argparse.ArgumentParser:
    """The ``follow-train`` argument parser; defaults are :class:`Args`'s."""
    d = Args()
    p = _Parser(
        prog=PROG,
        description="Train PPO, RecurrentPPO or SAC on PersonFollow-v0 (stable-baselines3, "
        "sb3-contrib).",
    )
    p.add_argument(
        "--algo",
        choices=tuple(ALGOS),
        help=f"the learner (default: {DEFAULT_ALGO}; with --resume: the run's own)",
    )
    p.add_argument(
        "--hyperparams",
        type=path_option,
        help=f"YAML file (default: the algorithm's, {CONFIGS}/<algo>.yaml)",
    )
    p.add_argument(
        "--env-id", help="section of the YAML file, naming the task (default: its only one)"
    )
    p.add_argument("--scenarios", help="comma-separated scenarios (default: all registered)")
    p.add_argument(
        "--env-config",
        help=f"env preset (default: {DEFAULT_ENV_CONFIG}; with --trained-agent: the agent's)",
    )
    p.add_argument(
        "--seed",
        type=int,
        help=f"training lanes start from seed + j ({DEFAULT_SEED}; with --trained-agent: the "
        "agent's seed + its steps, where its own training would go on); seed + n_timesteps + "
        "n_envs must stay below 2**32",
    )
    p.add_argument("--eval-seed", type=int, help=f"held-out lanes: eval_seed + j ({d.eval_seed})")
    p.add_argument("--eval-episodes", type=int, help=f"per scenario ({d.eval_episodes})")
    p.add_argument("--eval-freq", type=int, help=f"env steps ({d.eval_freq})")
    p.add_argument("--checkpoint-freq", type=int, help=f"env steps ({d.checkpoint_freq})")
    p.add_argument("--final-episodes", type=int, help=f"per scenario, 0 skips ({d.final_episodes})")
    p.add_argument("--compare-with", help=f"law in the model card ({d.compare_with})")
    p.add_argument("--n-timesteps", type=int, help="total env steps (default: the YAML's)")
    p.add_argument("--n-envs", type=int, help="lanes (default: the YAML's)")
    p.add_argument("--threads", type=int, help=f"torch threads, 1..{MAX_THREADS} ({d.threads})")
    p.add_argument(
        "--mkl-intel-paths",
        action="store_true",
        default=None,
        help="on a CPU that is not Intel's, let torch's MKL take the kernels it gives an Intel "
        "CPU with the same instruction set (Linux x86-64; the command runs again with a "
        "one-line library preloaded, built once with cc): on the AMD EPYC measured, training "
        "ran 1.6x faster and gave the Intel Xeon's weights; on an Intel CPU it should change "
        "nothing (train.mkl_paths)",
    )
    p.add_argument("--runs", type=path_option, help=f"where run folders go ({d.runs})")
    p.add_argument("--out", type=path_option, help="run folder (default: runs/<algo>-<timestamp>)")
    p.add_argument("--resume", type=path_option, metavar="RUN_DIR", help="continue this run")
    p.add_argument(
        "--trained-agent",
        type=path_option,
        metavar="AGENT",
        help="a new run that starts from this agent's weights and normalisation (a run or "
        "export folder, a .zip; an ensemble with --seeds: seed k from its member seed-<k>): "
        "without --hyperparams, with the agent's own hyperparameters, scenarios and algorithm "
        "(train.trained_agent)",
    )
    p.add_argument(
        "--export",
        type=path_option,
        metavar="DIR",
        help="also copy the agent into DIR: a new or empty folder, or one an earlier export "
        "wrote (its files are replaced, nothing else); with --seeds, the study as one agent "
        "(DIR/seed-<k> and DIR/ensemble.yaml)",
    )
    p.add_argument(
        "--force",
        action="store_true",
        default=None,
        help="let --export write into a folder it did not make, or over exported files that "
        "were changed: only files named like the agent's are replaced, none is deleted (with "
        "--seeds: an earlier export's members of this study's other seeds are removed, if "
        "unchanged); let --add-step edit files changed since the folder's export",
    )
    p.add_argument("--no-progress", dest="progress", action="store_false", default=None)
    edit = p.add_argument_group(
        "a step added to a trained agent's view, or one changed, without training (train.edit)"
    )
    edit.add_argument(
        "--add-step",
        type=path_option,
        metavar="DIR",
        help="the agent's folder (a run, an export or an ensemble); with --step, and --force "
        "for files changed since its export",
    )
    edit.add_argument(
        "--change-step",
        type=path_option,
        metavar="DIR",
        help="as --add-step, for a step already in the view: --step's arguments replace its",
    )
    edit.add_argument(
        "--step",
        help="YAML: '{train.wrappers.VecJumpGate: {max_jump_m: 0.5}}' (--add-step adds "
        "in_training: false)",
    )
    edit.add_argument("--before", metavar="NAME", help="the entry it goes before (default: first)")
    study = p.add_argument_group(
        "several training seeds (train.seeds): one run per seed in OUT/seed-<k>, and a summary"
    )
    study.add_argument(
        "--seeds",
        help="training seeds, e.g. 0-4 or 0,3,7: seed k trains from --seed + k * 10**8; the "
        "same command again resumes the study",
    )
    study.add_argument(
        "--backend",
        choices=BACKENDS,
        help="with --seeds: where the runs train, local or ray (default: local)",
    )
    study.add_argument(
        "--workers",
        type=_positive,
        help="with --seeds: runs at once (local default 1: one after another; ray default: the "
        "cluster's CPUs / --threads)",
    )
    study.add_argument("--address", help="with --backend ray: the cluster (default: RAY_ADDRESS)")
    return p


# Options that may accompany --resume (the rest come from the run's config.yaml).
_RESUME_OPTIONS = {
    "resume", "algo", "n_timesteps", "threads", "mkl_intel_paths", "progress", "export", "force"
}  # fmt: skip


# Options of a study (--seeds), not of one run.
_STUDY_OPTIONS = ("seeds", "backend", "workers", "address")
# Options of --add-step and --change-step (train.edit), which train nothing.
_EDIT_OPTIONS = ("add_step", "change_step", "step", "before")


def parse_study(argv: Sequence[str] | None = None) -> tuple[Args, tuple[int, ...], Backend] | None:
    """The study a command line asks for (``--seeds``), or None for a single run.

    :raises UsageError: for a study option without --seeds, or one a study cannot take.
    """
    return _study(build_parser().parse_args(argv))


def _study(ns: argparse.Namespace) -> tuple[Args, tuple[int, ...], Backend] | None:
    given = {k: getattr(ns, k) for k in _STUDY_OPTIONS if getattr(ns, k) is not None}
    if "seeds" not in given:
        if given:
            raise UsageError(", ".join(f"--{k}" for k in given) + " applies to --seeds only")
        return None
    if ns.resume is not None:
        raise UsageError(
            "--resume takes one run, not a study: run the same --seeds command again to "
            "resume it; a seed's agent is the run folder OUT/seed-K (make_policy and "
            "follow-eval load it by that path)"
        )
    if ns.force is not None and ns.export is None:
        raise UsageError(FORCE_ALONE_ERROR)
    try:
        seeds = parse_seeds(given["seeds"])
    except ValueError as e:
        raise UsageError(str(e)) from None
    args = _args(ns)  # the study options are not the runs' (_args leaves them out)
    kind = given.get("backend", "local")
    workers = given.get("workers", 1 if kind == "local" else None)
    try:
        backend = backend_from_args(
            kind, workers=workers, address=given.get("address"), cpus_per_task=args.threads
        )
    except ValueError as e:
        raise UsageError(str(e)) from None
    return args, seeds, backend


def parse_args(argv: Sequence[str] | None = None) -> Args:
    """Parse the command line into :class:`Args`.

    :raises UsageError: for unknown or conflicting options.
    """
    return _args(build_parser().parse_args(argv))


def _edit(ns: argparse.Namespace) -> tuple[str, Path, str, str | None, bool] | None:
    """``(option, folder, step, before, force)`` of an ``--add-step`` or ``--change-step``
    command line (``option`` is ``add_step`` or ``change_step``), or None.

    :raises UsageError: for --step or --before alone, both options, one without --step,
        --before with --change-step, or a training option beside either.
    """
    given = {k for k, v in vars(ns).items() if v is not None}
    options = sorted(given & {"add_step", "change_step"})
    if not options:
        if given & {"step", "before"}:
            raise UsageError("--step and --before apply to --add-step or --change-step only")
        return None
    if len(options) == 2:
        raise UsageError("--add-step and --change-step: give one of them")
    (option,) = options
    flag = "--" + option.replace("_", "-")
    if "step" not in given:
        raise UsageError(f"{flag} needs --step (the step's YAML)")
    if option == "change_step" and "before" in given:
        raise UsageError("--before: --change-step changes a step where it is")
    extra = sorted(given - {*_EDIT_OPTIONS, "force"})
    if extra:
        takes = "--step, --before and --force" if option == "add_step" else "--step and --force"
        raise UsageError(
            ", ".join(_flag(k) for k in extra) + f": {flag} trains nothing; it takes {takes} only"
        )
    return option, getattr(ns, option), ns.step, ns.before, bool(ns.force)


def _flag(dest: str) -> str:
    """The option as the user typed it: ``progress`` is only ever given as ``--no-progress``."""
    return "--no-progress" if dest == "progress" else "--" + dest.replace("_", "-")


def _args(ns: argparse.Namespace) -> Args:
    skip = (*_STUDY_OPTIONS, *_EDIT_OPTIONS)
    given = {k: v for k, v in vars(ns).items() if v is not None and k not in skip}
    if "resume" in given and set(given) - _RESUME_OPTIONS:
        extra = ", ".join(_flag(k) for k in sorted(set(given) - _RESUME_OPTIONS))
        raise UsageError(
            f"{extra}: a resumed run keeps its own settings; with --resume only "
            "--algo (the run's own), --n-timesteps, --threads, --mkl-intel-paths, --no-progress, "
            "--export and --force may be given"
        )
    if "scenarios" in given:
        given["scenarios"] = tuple(s.strip() for s in given["scenarios"].split(",") if s.strip())
    for name in ("n_timesteps", "n_envs"):
        if name in given and given[name] < 1:
            raise UsageError(
                f"--{name.replace('_', '-')} {given[name]} is out of range: must be an integer >= 1"
            )
    return Args(**given)


def _written(run: Path) -> str:
    """The run folder's files, as they are (a short run may have no checkpoint yet)."""
    from train import run as runs

    names = [runs.MODEL, runs.NORMALIZATION, runs.CONFIG, runs.CARD, runs.CURVE]
    names += [runs.EVALUATIONS, runs.SESSIONS]
    found = [name for name in names if (run / name).is_file()]
    prefix = runs.read_config(run).get("algo", runs.CHECKPOINT_PREFIX)
    checkpoints = len(list((run / runs.CHECKPOINTS).glob(f"{prefix}_*_steps.zip")))
    if checkpoints:
        found.append(f"{runs.CHECKPOINTS}/ ({checkpoints} checkpoint{'s' * (checkpoints > 1)})")
    if (run / runs.LOGS).is_dir():
        found.append(f"{runs.LOGS}/")
    return ", ".join(found)


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``follow-train`` and ``python -m train``; returns the exit status."""
    argv = sys.argv[1:] if argv is None else list(argv)
    try:
        ns = build_parser().parse_args(argv)
        edit = _edit(ns)
        if edit is not None:
            return _main_edit(*edit, command=shlex.join([PROG, *argv]))
        study = _study(ns)
        args = _args(ns) if study is None else study[0]
        _preload(ns, argv)  # after the options' own checks
        if study is not None:
            return _main_study(*study, command=" ".join([PROG, *argv]))
        run = train(args, command=" ".join([PROG, *argv]))
    except Interrupted as e:
        print(f"{PROG}: {e}", file=sys.stderr)
        return 130
    except KeyboardInterrupt:
        print(f"{PROG}: interrupted before training started; nothing was written", file=sys.stderr)
        return 130
    except TrainingError as e:
        print(f"{PROG}: error: {e}", file=sys.stderr)
        return 1
    except WorkerLostError as e:  # a seed's worker killed again and again (out of memory, often)
        print(
            f"{PROG}: error: {e}; the finished seeds are kept and the others resume from their "
            "checkpoints: run the same command again (with fewer --workers if memory is short)",
            file=sys.stderr,
        )
        return WORKERS_LOST
    except (UsageError, ConfigError, ValueError, FileNotFoundError, BackendUnavailableError) as e:
        print(f"{PROG}: error: {error_line(e)}", file=sys.stderr)  # a seed's worker: which, where
        return USAGE_ERROR
    from train.run import read_sessions

    last = read_sessions(run)[-1]
    print(
        f"Trained {last['first_step']:,} -> {last['last_step']:,} env steps in "
        f"{last['wall_s']:.0f} s ({last['env_steps_per_s'] or 0:,} env-steps/s). Wrote {run}/: "
        + _written(run)
        + (f"; exported the agent to {args.export}/" if args.export else "")
        + _no_held_out([run])
    )
    return 0


def _preload(ns: argparse.Namespace, argv: Sequence[str]) -> None:
    """With ``--mkl-intel-paths``, the same command again in place of this one with MKL's
    Intel code paths preloaded (:mod:`train.mkl_paths`), unless they are already: ``main``
    called from Python with other arguments than its process's is refused, not replaced."""
    if ns.mkl_intel_paths:
        from train.mkl_paths import ensure_preloaded

        ensure_preloaded(argv)


def _no_held_out(runs_: Sequence[Path]) -> str:
    """A sentence for runs that wrote no held-out evaluation (a run shorter than its
    ``--eval-freq``: SB3's EvalCallback never came due), else ``""``."""
    from train.run import EVALUATIONS

    missing = [run for run in runs_ if not (run / EVALUATIONS).is_file()]
    if not missing:
        return ""
    which = "the run" if len(runs_) == 1 else f"{len(missing)} of the {len(runs_)} runs"
    return (
        f". No periodic held-out evaluation ran in {which} (trained fewer env steps than "
        f"--eval-freq): no {EVALUATIONS}, so the learning curve has no held-out points and a "
        "study's summary no held-out return"
    )


def _main_edit(
    option: str, folder: Path, step: str, before: str | None, force: bool, command: str
) -> int:
    """``follow-train --add-step`` or ``--change-step``: see :mod:`train.edit`."""
    from train.edit import add_step, change_step
    from train.export import MANIFEST

    if option == "change_step":
        changed = change_step(folder, step, force=force, command=command)
        what = f"Changed {changed.name} to {changed.new} in"
        members = changed.members
    else:
        added = add_step(folder, step, before, force=force, command=command)
        ((name, kwargs),) = added.entry.items()
        where = f"before {before}" if before else "first"
        what = f"Added {name} {kwargs} to"
        members = added.members
    if members:  # an ensemble: every member that lacked it
        listed = ", ".join(f"{m}/" for m in members)
        print(
            f"{what} the view of the ensemble in {folder}/ (its weights unchanged): "
            f"config.yaml and MODEL_CARD.md of {listed}"
        )
        return 0
    place = "" if option == "change_step" else f" ({where}; left out of training)"
    print(
        f"{what} the view of the agent in {folder}/{place}: config.yaml, MODEL_CARD.md"
        + (f", {MANIFEST}" if (folder / MANIFEST).exists() else "")
    )
    return 0


def _main_study(args: Args, seeds: tuple[int, ...], backend: Backend, command: str) -> int:
    """``follow-train --seeds``: see :mod:`train.seeds`."""
    from train.study_summary import SEEDS_CSV, SUMMARY_MD

    try:
        study = train_seeds(args, seeds, backend, command=command)
    except KeyboardInterrupt:
        print(
            f"{PROG}: interrupted; the finished seeds are kept and the interrupted ones resume "
            "from their checkpoints: run the same command again",
            file=sys.stderr,
        )
        return 130
    print((study / SUMMARY_MD).read_text(encoding="utf-8"))
    print(
        f"Trained {len(seeds)} seeds. Wrote {study}/: seed-<k>/ (runs), {SEEDS_CSV}, {SUMMARY_MD}"
        + (f"; exported the study to {args.export}/" if args.export else "")
        + _no_held_out([study / f"seed-{k}" for k in seeds])
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())

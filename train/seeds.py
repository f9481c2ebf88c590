"""``follow-train --seeds 0-4``: one training run per seed on a backend, and a summary.

::

    follow-train --seeds 0-4 --out runs/ppo-study            # one seed after another
    follow-train --seeds 0-4 --out runs/ppo-study --workers 2 --threads 1
    follow-train --seeds 0-4 --out runs/ppo-study --backend ray [--address HOST:PORT]
    follow-train --seeds 0-4 --algo sac --out runs/sac-study  # any algorithm (train.algos)

Training seed ``k`` is an ordinary run (:func:`train.ppo.train`) in ``<out>/seed-<k>/`` whose
training lanes and network start from ``seed + k * SEED_STRIDE`` (so no two seeds share an
episode, and no seed meets the held-out or evaluation episodes); every seed is judged on the
same held-out seeds (``eval_seed + j``). The runs are work units of :mod:`execution`: in this
process, ``--workers`` at once in a process pool, or Ray tasks, each given ``--threads`` CPUs.

When every seed has finished, ``<out>/seeds.csv`` (one row per seed: its folder, env steps,
wall time, env-steps/s, final held-out return) and ``<out>/summary.md`` / ``summary.json``
(mean, standard deviation, median and interquartile mean of the final held-out return over the
seeds, with a bootstrap 95 % CI of the mean) are written, atomically, and ``<out>/ensemble.yaml``,
which makes the study one agent: ``make_policy("runs/ppo-study")`` (or ``follow-eval run
--policies runs/ppo-study``) acts with the mean of every seed's action
(:mod:`policies.learned.ensemble`), an agent no one picked from the seeds. ``<out>/study.json``
records the command's settings: the same command run again skips the finished seeds, resumes
an interrupted one from its newest checkpoint (:mod:`train.run`) and starts the missing ones
(so ``--seeds 0-9`` after ``--seeds 0-4`` trains five more); other settings pointed at the same
folder are refused.

A seed's folder that holds no checkpoint, only what a run writes before its first one (its
run was killed early: :func:`_early_files`), has nothing to resume from: the same command
clears it and trains the seed again, saying so on stderr; a folder holding anything else (a
hidden file that is no atomic write's temporary file, a hidden folder) is refused, naming it.

A command holds its study while it runs (:class:`train.study_lock.StudyLock`, which says why): a
second command on the same folder meanwhile is refused before it changes anything.

``--export DIR`` exports the study as one agent once every seed is trained
(:func:`train.study_export.export_study`): each seed's run into ``DIR/seed-<k>`` as one run's export
(:mod:`train.export`) and ``DIR/ensemble.yaml`` listing them, checked before any seed trains; an
earlier one of other seeds in ``DIR`` is refused (``--force`` replaces it). ``ppo_ensemble`` is one.

On a cluster the run folders are written by the nodes that train them: give ``--runs`` / ``--out``
on a file system every node shares. A seed's unit names its folder (and a ``--hyperparams`` file,
and a ``--compare-with`` agent given by its path) by absolute path, whatever folder a node started
in, and carries the driver's sources digest and hyperparameters, which the node checks before it
trains (:func:`eval.provenance.check_worker_code`). Its worker decides whether the folder is a new
run or one to resume, as the same command run again does: a unit whose worker died is run again (by
the execution layer) from the seed's newest checkpoint. ``study.json`` records the digest
(``code``), and a seed is trained on a study only by the code that started it (a study made before
it was recorded is refused when a seed would train; the message says how to go on).
"""

from __future__ import annotations

import dataclasses
import json
import re
import shutil
import socket
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from eval.provenance import check_worker_code, running_sources_sha256
from execution import Backend, execute
from follow_env.sim.atomic import missing_folders, remove_empty_folders
from train import run as runs
from train.algos import DEFAULT_ALGO
from train.options import (
    MAX_SEED,
    Args,
    absolute_compare_with,
    base_seed,
    check_folder_option,
    check_new_run,
    check_resume,
    run_hyperparams,
)
from train.ppo import PROG, train
from train.study_export import check_study_export, export_study, write_ensemble
from train.study_lock import StudyLock
from train.study_record import TRAINING_PACKAGES, claim, read_study, study_settings
from train.study_summary import write_summary
from train.trained_agent import (
    defaults_from,
    member_for_seed,
    read_trained_agent,
    statistics_digest,
)

__all__ = [
    "MAX_SEEDS",
    "SEED_STRIDE",
    "check_study_export",
    "export_study",
    "parse_seeds",
    "seed_args",
    "train_seeds",
    "write_ensemble",
]

#: Training seed k's lanes start this many seeds after seed k - 1's: more than any run's
#: env steps plus lanes (a run of n_timesteps steps uses seed .. seed + n_timesteps + n_envs).
SEED_STRIDE = 100_000_000
#: The largest training seed: seed + k * SEED_STRIDE + n_timesteps must stay below 2**32.
MAX_SEEDS = 40


def parse_seeds(text: str) -> tuple[int, ...]:
    """Training seeds from ``"0-4"``, ``"0,2,7"``, ``"3"`` or a mix (``"0-2,5"``).

    :raises ValueError: for anything else, a seed beyond :data:`MAX_SEEDS` or a repeat.
    """
    out_of_range = f"--seeds {text!r} is out of range: training seeds are 0..{MAX_SEEDS}"
    seeds: list[int] = []
    for part in str(text).split(","):
        part = part.strip()
        # [0-9], not \d or isdigit(): those take other scripts' digits ("٣") and "²"
        if m := re.fullmatch(r"([0-9]+)-([0-9]+)", part):
            low, high = int(m[1]), int(m[2])
            if high < low:
                raise ValueError(f"--seeds {text!r}: the range {part} counts down")
            if high > MAX_SEEDS:  # before the range is built: 0-1000000000 is 8 GB of ints
                raise ValueError(out_of_range)
            seeds += range(low, high + 1)
        elif re.fullmatch(r"[0-9]+", part):
            seeds.append(int(part))
        else:
            raise ValueError(f"--seeds {text!r}: {part!r} is not a seed or a range like 0-4")
    if len(set(seeds)) != len(seeds):
        raise ValueError(f"--seeds {text!r} names a seed twice")
    if max(seeds) > MAX_SEEDS:
        raise ValueError(out_of_range)
    return tuple(seeds)


def seed_args(args: Args, k: int, study: Path) -> Args:
    """The options of training seed ``k``'s run in ``study`` (see the module docstring); its
    folder, hyperparameter file and a ``--compare-with`` agent's path absolute, as any node of
    a cluster finds them (a Ray worker reads a relative path from the folder it started in),
    and a ``--trained-agent`` ensemble narrowed to its member ``seed-<k>``."""
    hyperparams = args.hyperparams.absolute() if args.hyperparams is not None else None
    agent = None if args.trained_agent is None else member_for_seed(args.trained_agent, k)
    return dataclasses.replace(
        args,
        seed=_seed_of(args, k, agent),
        out=Path(study).absolute() / f"seed-{k}",
        hyperparams=hyperparams,
        compare_with=absolute_compare_with(args.compare_with),
        trained_agent=agent,  # an ensemble's member seed-<k>
        progress=False,
        export=None,  # the study exports its seeds together, once all are trained
        force=False,
    )


def _seed_of(args: Args, k: int, agent: Path | None) -> int | None:
    """Seed ``k``'s first lane seed: ``--seed`` (default 10000) + k * 10**8; or without
    ``--seed`` in a study from an agent, the seed where a resume of its agent's own training
    would go on: an ensemble's member ``seed-<k>``'s own (a study's member k already carries
    its k * 10**8), one agent's + k * 10**8. So whichever seeds a command lists, seed k's is
    the same. None if that agent cannot be read: a seed that resumes needs none, and a new
    seed's check names the agent."""
    if args.seed is not None or agent is None:
        return base_seed(args) + k * SEED_STRIDE
    try:
        trained = read_trained_agent(agent)
    except ValueError:
        return None
    start = trained.next_seed
    if start is None:
        return base_seed(args) + k * SEED_STRIDE
    member = agent != Path(args.trained_agent or "").absolute()  # seed-<k> of an ensemble
    return start if member else start + k * SEED_STRIDE


def _same_training(k: int, folder: Path, hp: dict[str, Any]) -> int | None:
    """Check that seed ``k``'s run in ``folder`` trains with ``hp`` (the command's), so that
    the study's seeds differ in their seed only; returns the longer ``n_timesteps`` it must be
    resumed to, or None if its own is the command's.

    :raises ValueError: naming the seed and the first hyperparameter that differs (a file
        edited since, another --n-envs, a step added with --add-step), or a shorter budget.
    """
    saved = json.loads(json.dumps(runs.read_config(folder)["hyperparams"]))
    now = json.loads(json.dumps(hp))
    keys = sorted((saved.keys() | now.keys()) - {"n_timesteps"})
    changed = [key for key in keys if saved.get(key) != now.get(key)]
    if changed:
        raise ValueError(
            f"{folder}: seed {k} trained with {changed[0]}={saved.get(changed[0])!r}, this "
            f"command with {now.get(changed[0])!r}; a study's seeds differ in their seed only: "
            "give the same hyperparameters, or another --out"
        )
    had, want = int(saved["n_timesteps"]), int(now["n_timesteps"])
    if want < had:
        raise ValueError(
            f"--n-timesteps={want:,} is out of range: seed {k} in {folder} trains to {had:,} "
            f"env steps, so the study needs --n-timesteps >= {had:,}"
        )
    return want if want > had else None


def _same_start(
    k: int, one: Args, own: dict[str, Any], seen: dict[str, Any], study: Path, filled: set[str]
) -> None:
    """Check that new seed ``k`` starts as the study's seeds do: with the study's
    hyperparameters, and the preset and scenarios the study took from its first seed's agent
    (``filled``; an ensemble's members may differ), and from the agent the other seeds that
    started from the same path started from (its files unchanged since).

    :raises ValueError: naming the first differing key or option, or the changed file.
    """
    agent = one.trained_agent
    assert agent is not None  # a study from an agent only
    agent_now = read_trained_agent(agent)  # its files as they are now
    saved = agent_now.args
    for name in sorted(filled & {"env_config", "scenarios"}):
        theirs, ours = saved.get(name), getattr(one, name)
        if isinstance(theirs, list):  # config.yaml's list; Args holds a tuple
            theirs = tuple(theirs)
        if theirs is not None and theirs != ours:
            option = "--" + name.replace("_", "-")
            raise ValueError(
                f"--trained-agent: seed {k} would start from {agent}, trained with {option} "
                f"{theirs!r}, where the study takes {ours!r} from its first seed's agent: give "
                f"{option} for the study"
            )
    changed = [key for key in sorted(own.keys() | seen.keys()) if own.get(key) != seen.get(key)]
    if changed:
        key = changed[0]
        option = "--n-timesteps" if key == "n_timesteps" else "--hyperparams"
        raise ValueError(
            f"--trained-agent: seed {k} would start from {agent}, whose {key}={own.get(key)!r} "
            f"is not the study's {seen.get(key)!r}; a study's seeds differ in their seed only: "
            f"give {option} for the study"
        )
    for folder in sorted(study.glob("seed-*")):
        config = folder / runs.CONFIG
        if folder.name == f"seed-{k}" or not config.is_file():
            continue
        started = runs.read_config(config).get("trained_agent")
        if not isinstance(started, dict) or started.get("path") != str(agent):
            continue
        then = started.get("sha256") or {}
        now = statistics_digest(agent_now, agent_now.normalization.name in then)
        for name, digest in then.items():
            if now.get(name) != digest:
                raise ValueError(
                    f"--trained-agent: {Path(agent) / name} changed since {folder.name} "
                    f"started from it (SHA-256 {digest[:12]}, now "
                    f"{str(now.get(name))[:12]}); a study's seeds start from the same agent: "
                    "put its files back, or give another --out"
                )


def _finished(folder: Path) -> bool:
    """The seed's run trained to the end and wrote its report (a run without its model card
    is resumed, which writes the report)."""
    if not ((folder / runs.MODEL).is_file() and (folder / runs.CARD).is_file()):
        return False
    sessions = runs.read_sessions(folder)
    return bool(sessions) and sessions[-1].get("status") == "finished"


def _row(k: int, folder: Path) -> dict[str, Any]:
    """Seed ``k``'s line of ``seeds.csv``, read from its finished run folder."""
    sessions = runs.read_sessions(folder)
    wall = sum(float(s.get("wall_s") or 0.0) for s in sessions)
    steps = int(sessions[-1]["last_step"])
    heldout = float("nan")
    log = runs.read_evaluations(folder)
    if log is not None and len(log.results):
        heldout = float(np.mean(log.results[-1]))
    return {
        "seed": k,
        "run": folder.name,
        "env_steps": steps,
        "wall_s": round(wall, 1),
        "env_steps_per_s": round(steps / wall) if wall > 0 else None,
        "heldout_return": heldout,
    }


class _Seed(NamedTuple):
    """One seed's work unit: the seed ``k``, its options as a new run (:func:`seed_args`), the
    study's command line, the budget [env steps] a resume must reach if longer than the run's
    own, whether its folder was new or empty when the command started, the driver's sources
    digest of :data:`TRAINING_PACKAGES`, and the hyperparameters a new run trains with (JSON)."""

    k: int
    args: Args
    command: str
    longer: int | None
    new: bool
    code: str
    hp: dict[str, Any]


def _train_unit(unit: _Seed) -> dict[str, Any]:
    """One seed's run (a work unit: in this process, a pool worker or a Ray task): trained
    anew or resumed as its folder is now, not as it was when the command started, so that a
    unit run again after its worker died resumes what that worker left."""
    check_worker_code(unit.code, TRAINING_PACKAGES)
    k, folder = unit.k, unit.args.out
    assert folder is not None  # seed_args names it
    if _finished(folder) and (unit.longer is None or _budget(folder) >= unit.longer):
        return _row(k, folder)  # its worker died after the run had finished
    if unit.new and _no_checkpoint(folder):
        # What a lost worker wrote before its first checkpoint (the folder was empty when
        # the command started): nothing to resume from, so the seed starts again.
        _clear(folder)
    if folder.is_dir() and any(folder.iterdir()):
        # Its own budget once a lost worker's resume has written the longer one (a resume
        # whose training is done then writes the report only).
        longer = unit.longer if unit.longer is not None and _budget(folder) < unit.longer else None
        resume = Args(
            resume=folder,
            n_timesteps=longer,
            threads=unit.args.threads,
            mkl_intel_paths=unit.args.mkl_intel_paths,
            progress=False,
        )
        return _row(k, train(resume, command=f"{unit.command} [seed {k}, resumed]"))
    if json.loads(json.dumps(run_hyperparams(unit.args))) != unit.hp:
        raise ValueError(
            f"seed {k}: this worker ({socket.gethostname()}) reads other hyperparameters than "
            f"the driver from {_source(unit.args)}: give a --hyperparams file (or an agent) "
            "every node shares, or install the same version on every node"
        )
    return _row(k, train(unit.args, command=f"{unit.command} [seed {k}]"))


def _source(args: Args) -> str:
    """Where a seed's hyperparameters are read from, as a worker's message names it."""
    if args.hyperparams is not None:
        return str(args.hyperparams)
    if args.trained_agent is not None:
        return f"the agent's config.yaml in {args.trained_agent}"
    return "its installed defaults"


def _budget(folder: Path) -> int:
    """The env steps the run in ``folder`` trains to (its ``config.yaml``'s)."""
    return int(runs.read_config(folder)["hyperparams"]["n_timesteps"])


def _no_checkpoint(folder: Path) -> bool:
    """``folder`` holds something but no checkpoint: a seed's run killed before its first
    checkpoint (if it holds only what such a run writes: :func:`_early_files`)."""
    return (
        folder.is_dir()
        and any(folder.iterdir())
        and not any(folder.glob(f"{runs.CHECKPOINTS}/*_steps.zip"))
    )


def _early_files(folder: Path) -> list[str]:
    """The names in ``folder`` (a run folder without a checkpoint), checked to be only what a
    run writes before its first checkpoint (:func:`train.run.not_written_early`).

    :raises ValueError: naming the folder and the first file no run writes before then.
    """
    other = runs.not_written_early(folder)
    if other is not None:
        raise ValueError(
            f"{folder}: its run ended before its first checkpoint, but the folder holds "
            f"{other}, which no run writes before then: move it away to train the seed again"
        )
    return sorted(c.name for c in folder.iterdir() if not c.name.startswith("."))


def _clear(folder: Path) -> list[str]:
    """Empty ``folder``, a new seed's run that ended before its first checkpoint, if it holds
    only what such a run writes (:func:`_early_files`): nothing else is deleted. Returns the
    names it held (hidden ones left out).

    :raises ValueError: naming a file no run writes before its first checkpoint.
    """
    names = [f"{n}/" if (folder / n).is_dir() else n for n in _early_files(folder)]
    for child in folder.iterdir():
        if child.is_dir() and not child.is_symlink():
            shutil.rmtree(child)
        else:
            child.unlink()
    return names


def train_seeds(
    args: Args, seeds: Sequence[int], backend: Backend | None = None, command: str = ""
) -> Path:
    """Train every seed (skipping finished ones, resuming interrupted ones); returns the study
    folder, with its summary written.

    :raises ValueError: for bad options (every seed's are checked before any trains), a
        study folder that holds another study, or a study another command is training now.
    """
    backend = backend or Backend("local", workers=1, cpus_per_task=args.threads)
    made: list[Path] = []  # the folders this command makes before any check: taken back below
    if args.out is not None:
        study = args.out
    else:  # the study's folder is made now, in --runs (a file in the way named first)
        check_folder_option("--runs", args.runs)
        made = missing_folders(args.runs)
        study = _new_study_path(args.runs, args.algo)
        made.insert(0, study)
    try:
        with StudyLock(study) as lock:
            return _train_study(args, seeds, backend, command, study, lock)
    except BaseException:  # a new study is still empty if a check refused it: taken back
        remove_empty_folders(made)
        raise


def _train_study(
    args: Args, seeds: Sequence[int], backend: Backend, command: str, study: Path, lock: StudyLock
) -> Path:
    """:func:`train_seeds` in ``study``, held by ``lock`` from when it exists."""
    lock.take()  # before anything is read: a command refused here has changed nothing
    agent, filled = None, set()
    if args.trained_agent is not None:  # its algorithm, preset and lanes: the first seed's
        first = member_for_seed(args.trained_agent, seeds[0])
        had = read_study(study)
        gone = not first.exists() and had is not None
        if gone and had.get("trained_agent") == str(args.trained_agent.absolute()):
            raise ValueError(
                f"--trained-agent {first}: no such agent; the study in {study} started from it, "
                "and the command reads it again (its algorithm, preset, scenarios and "
                "hyperparameters) even where every seed resumes from its own checkpoint: put it "
                "back where it was"
            )
        agent = read_trained_agent(first)
        given = defaults_from(agent, args)
        given.pop("seed", None)  # each seed's own, from its agent (seed_args)
        filled = set(given)
        args = dataclasses.replace(args, **given, trained_agent=args.trained_agent.absolute())
    if agent is not None and args.hyperparams is None and args.n_timesteps is None:
        # The agent's own budget may have grown since (a resume of it): the study keeps its.
        budgets = [_budget(f) for f in study.glob("seed-*") if (f / runs.CONFIG).is_file()]
        if budgets:
            args = dataclasses.replace(args, n_timesteps=max(budgets))
    settings = study_settings(args, seeds)
    hp = run_hyperparams(args, agent)  # what every seed trains with, the earlier seeds too
    code = running_sources_sha256(TRAINING_PACKAGES)  # the code every seed's worker must run
    seen = json.loads(json.dumps(hp))
    had = read_study(study)
    # The study's other seeds, not in this command: they must have trained as these will, and
    # the summary and the ensemble are of every finished seed.
    others = sorted(set(had["seeds"] if had else ()) - set(seeds))
    for k in others:
        folder = study / f"seed-{k}"
        if (folder / runs.CONFIG).is_file() and _same_training(k, folder, hp) is not None:
            raise ValueError(
                f"--seeds {','.join(map(str, seeds))}: seed {k} of the study in {study} trains "
                f"to fewer env steps than {hp['n_timesteps']:,}; give it in --seeds too, to "
                "resume it to them"
            )
    units: list[_Seed] = []
    done: dict[int, dict[str, Any]] = {}
    restart: list[tuple[int, Path]] = []  # seeds killed before their first checkpoint
    for i, k in enumerate(seeds):
        folder = study / f"seed-{k}"
        one = seed_args(args, k, study)
        # Nothing to resume from: the seed starts again, in its folder cleared below once every
        # check has passed (refused now, naming it, if the folder holds another file).
        early = _no_checkpoint(folder) and not _finished(folder)
        if early:
            _early_files(folder)
            restart.append((k, folder))
        saved = (folder / runs.CONFIG).is_file() and not early
        longer = _same_training(k, folder, hp) if saved else None
        if _finished(folder) and longer is None:
            done[i] = _row(k, folder)  # its unit below is a placeholder
        elif folder.is_dir() and any(folder.iterdir()) and not early:
            resume = Args(
                resume=folder,
                n_timesteps=longer,
                threads=args.threads,
                mkl_intel_paths=args.mkl_intel_paths,
                progress=False,
            )
            check_resume(resume)  # before any seed trains, as a new seed's options are
        else:
            if one.seed is not None and one.seed > MAX_SEED:
                source = (
                    f"--seed {base_seed(args)}"
                    if args.seed is not None or args.trained_agent is None
                    else "its seed from where its agent's training stopped (give --seed)"
                )
                raise ValueError(f"--seeds: seed {k} is out of range with {source}")
            try:
                _, own = check_new_run(one, clearing=early)  # every option, before any trains
            except ValueError as e:
                if (
                    args.seed is None
                    and one.trained_agent is not None
                    and str(e).startswith("--seed ")
                ):  # a seed the command line did not give
                    raise ValueError(
                        f"{e} (seed {k}'s, from where its agent's training stopped: give --seed)"
                    ) from None
                raise
            if one.trained_agent is not None:
                _same_start(k, one, json.loads(json.dumps(own)), seen, study, filled)
        new = early or not (folder.is_dir() and any(folder.iterdir()))
        units.append(_Seed(k, one, command, longer, new, code, seen))
    if args.export is not None:  # before any seed trains, as for one run's export
        check_study_export(args.export, seeds, study, force=args.force)
    backend.check_reachable()  # before study.json is written
    claim(study, settings, code, lock, training=len(done) < len(units))
    for k, folder in restart:
        held = ", ".join(_clear(folder)) or "hidden temporary files"
        print(
            f"{PROG}: {folder} held no checkpoint, only what its run wrote before the first "
            f"({held}): cleared it; seed {k} starts again",
            file=sys.stderr,
        )
    rows = execute(_train_unit, units, backend, done=done, describe=lambda u: f"seed {u.k}")
    rows += [_row(k, study / f"seed-{k}") for k in others if _finished(study / f"seed-{k}")]
    rows.sort(key=lambda row: row["seed"])
    write_summary(study, rows)
    if len(rows) > 1:
        write_ensemble(study, [f"seed-{row['seed']}" for row in rows])
    if args.export is not None:
        try:
            export_study(study, seeds, args.export, force=args.force)
        except ValueError as e:  # the folder changed during training: the study stays whole
            raise ValueError(f"{e} (training finished: the study is complete in {study})") from None
    return study


def _new_study_path(root: Path, learner: str | None) -> Path:
    """A new study folder, made now, exclusively (:func:`train.run.new_run_dir`)."""
    return runs.new_run_dir(root, f"{learner or DEFAULT_ALGO}-seeds")

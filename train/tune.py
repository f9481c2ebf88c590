"""PPO hyperparameters searched with ``follow-tune``'s driver: ``python -m train.tune``.

    python -m train.tune --trials 20 --n-timesteps 200000 --seeds 4 --out runs/tune-ppo

The same search as ``follow-tune`` (:mod:`eval.tuning.driver`: a seeded TPE sampler, trials
asked in batches, a journal file or RDB URL to resume from, a median pruner on partial seed
sets; a study resumed only with the settings it was run with), with a training run as each
trial: the hyperparameters of :data:`PPO_SPACE` put into the hyperparameter file's section
(``train/configs/ppo.yaml`` unless told), a ``follow-train`` run of ``--n-timesteps`` env steps
(as a work unit on the execution backend, one per trial of a batch), then the trained agent
scored by the env's own reward summed per episode on the tuning variants x seeds 1000 + k
(:class:`eval.tuning.objective.LawObjective`'s numbers). The pruner spares evaluation episodes
only: a trial is trained once, at its first rung.

Left out: the held-out check and the one-standard-error choice that ``follow-tune`` makes for
a law (a trained agent is judged by ``follow-eval`` on held-out seeds instead), and pruning on
partial *training* budgets, which is where most of a PPO trial's time goes.
"""

from __future__ import annotations

import argparse
import dataclasses
import hashlib
import json
import math
import re
import shutil
import sys
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from types import MappingProxyType
from typing import Any

import numpy as np
import yaml

from eval.cli_base import (
    UsageError,
    _names,
    _Parser,
    _positive,
    path_option,
    sigterm_as_interrupt,
    stopped,
)
from eval.provenance import running_code_sha256, running_sources_sha256
from eval.rollout import rollout
from eval.tuning.cli import run_reporting, stale_reporter
from eval.tuning.driver import SearchConfig, run_search
from eval.tuning.folders import (
    check_journal_owner,
    check_out_folder,
    check_storage,
    journal_check,
    open_search,
    refuse_empty,
    refuse_repeats,
    text_check,
)
from eval.tuning.objective import DEFAULT_VARIANTS, SCORE_KEYS, TUNE_SEED0, episode_score
from execution import Backend, backend_from_args, execute
from follow_env.sim.atomic import atomic_write_text
from policies.space import ParamRange
from train.config import read_document
from train.options import check_new_run
from train.ppo import DEFAULT_HYPERPARAMS, Args
from train.study_record import TRAINING_PACKAGES

__all__ = ["INTEGER_KEYS", "PPO_SPACE", "PPOObjective", "hyperparams_for", "main"]

PROG = "python -m train.tune"


PPO_SPACE = MappingProxyType(
    {
        "learning_rate": ParamRange(1e-5, 1e-3, log=True),
        "n_steps": ParamRange(16.0, 512.0, log=True),
        "batch_size": ParamRange(64.0, 2048.0, log=True),
        "gamma": ParamRange(0.95, 0.999),
        "ent_coef": ParamRange(0.0, 0.01),
    }
)
"""What is searched: the learning rate (log), the rollout length per lane ``n_steps`` and the
minibatch ``batch_size`` (log, rounded to integers), the discount ``gamma`` and the entropy
coefficient ``ent_coef``; every other key keeps the hyperparameter file's value."""
#: Keys of :data:`PPO_SPACE` that PPO takes as integers.
INTEGER_KEYS = ("n_steps", "batch_size")
#: The temporary name of an interrupted atomic write of ``result.json``: a search's folder may
#: hold one (its other files and the folder ``trials`` are listed in :func:`_check_out`).
_OWN_TEMPORARY = re.compile(r"\.result\..+\.tmp\.json")


def hyperparams_for(values: Mapping[str, float], n_envs: int) -> dict[str, Any]:
    """The PPO keys a trial's ``values`` set: integers rounded, and the minibatch the divisor of
    one rollout (``n_steps x n_envs``, SB3's buffer) nearest to it on a log scale, so that no
    epoch ends in a truncated minibatch (SB3 warns of those)."""
    out: dict[str, Any] = {k: float(v) for k, v in values.items()}
    for key in INTEGER_KEYS:
        if key in out:
            out[key] = max(1, round(out[key]))
    if "batch_size" in out and "n_steps" in out:
        buffer = out["n_steps"] * n_envs
        divisors = [d for d in range(2, buffer + 1) if buffer % d == 0] or [buffer]
        out["batch_size"] = min(divisors, key=lambda d: abs(math.log(d / out["batch_size"])))
    return out


def _train_unit(unit: tuple[Args, str]) -> str:
    """Train one trial's run (a work unit); returns its folder. Skips a run already finished."""
    from train.ppo import train

    args, _ = unit
    out = Path(str(args.out))
    if not (out / "model.zip").exists():
        if out.exists():  # a run that did not finish (interrupted): train it afresh
            shutil.rmtree(out)
        train(args, command=PROG)
    return str(out)


@dataclass(frozen=True)
class PPOObjective:
    """Trains and scores batches of PPO hyperparameters (an :data:`eval.tuning.driver.Evaluate`).

    :param base: the training options every trial shares (``n_timesteps``, ``n_envs``, the
        hyperparameter file and its section); ``out`` and ``hyperparams`` are set per trial.
    :param folder: where the trials' runs go (``<folder>/trial-<hash>/``).
    :param variants: the scenarios the trained agents are scored on.
    :param backend: where the training runs and the episodes run.
    """

    base: Args
    folder: Path
    variants: tuple[str, ...]
    backend: Backend

    def section(self) -> dict[str, Any]:
        """The hyperparameter file's section the trials start from."""
        env_id = self.base.env_id or "PersonFollow-v0"
        document = read_document(self.base.hyperparams)
        if not isinstance(document, dict) or env_id not in document:
            raise ValueError(f"{self.base.hyperparams}: no section {env_id!r}")
        return dict(document[env_id])

    def n_envs(self) -> int:
        """Lanes of every trial's training."""
        return self.base.n_envs or int(self.section()["n_envs"])

    def _unit(self, values: Mapping[str, float]) -> tuple[Args, str]:
        env_id = self.base.env_id or "PersonFollow-v0"
        section = self.section()
        section.update(hyperparams_for(values, self.n_envs()))
        text = yaml.safe_dump({env_id: section}, sort_keys=False)
        # The budget, the lanes and the code are in the key too: a trial's run trained for
        # another --n-timesteps or --n-envs, or by other code (the study refuses to resume
        # across a code change, and a new study must not reuse the old code's agents), is
        # another trial's, never reused for this one.
        budget = (
            f"n_timesteps={self.base.n_timesteps} n_envs={self.base.n_envs} "
            f"code={running_code_sha256(TRAINING_PACKAGES)}\n"
        )
        key = hashlib.sha256((text + budget).encode()).hexdigest()[:12]
        trial = self.folder / f"trial-{key}"
        trial.mkdir(parents=True, exist_ok=True)
        if not (trial / "hyperparams.yaml").exists():
            atomic_write_text(trial / "hyperparams.yaml", text)
        args = dataclasses.replace(
            self.base, hyperparams=trial / "hyperparams.yaml", env_id=env_id, out=trial / "run"
        )
        return args, text

    def __call__(
        self, params: Sequence[Mapping[str, float]], seeds: Sequence[int]
    ) -> list[dict[str, np.ndarray]]:
        """Per trial, the per-episode :data:`~eval.tuning.objective.SCORE_KEYS` of its
        trained agent, each shaped (variants, seeds)."""
        units = [self._unit(p) for p in params]
        unique = list(dict.fromkeys(units))  # the same hyperparameters train once
        trained = dict(zip(unique, execute(_train_unit, unique, self.backend), strict=True))
        runs = [trained[u] for u in units]
        results = rollout(
            runs,
            list(self.variants),
            [int(s) for s in seeds],
            reduce=episode_score,
            backend=self.backend,
        )
        shape = (len(runs), len(self.variants), len(seeds), len(SCORE_KEYS))
        table = np.asarray(results, dtype=np.float64).reshape(shape)
        return [{k: table[i, :, :, j] for j, k in enumerate(SCORE_KEYS)} for i in range(shape[0])]


def build_parser() -> argparse.ArgumentParser:
    """The command line (errors raise :class:`UsageError`)."""
    p = _Parser(prog=PROG, description="Search PPO hyperparameters with follow-tune's driver.")
    p.add_argument("--trials", type=_positive, default=20, help="finished trials (default 20)")
    p.add_argument("--n-timesteps", type=_positive, default=200_000, help="env steps per trial")
    p.add_argument("--n-envs", type=_positive, default=None, help="lanes (default: the file's)")
    p.add_argument("--hyperparams", type=path_option, default=DEFAULT_HYPERPARAMS, help="base YAML")
    p.add_argument("--seeds", type=_positive, default=4, help="scoring seeds 1000.. per scenario")
    p.add_argument("--scenarios", default=None, help="scored on (default straight,curve,random)")
    p.add_argument("--storage", default=None, help="journal file or RDB URL (OUT/study.journal)")
    p.add_argument("--study", default="ppo", help="the study's name (default ppo)")
    p.add_argument("--backend", choices=("local", "ray"), default="local")
    p.add_argument("--address", default=None, help="--backend ray: the cluster")
    p.add_argument("--workers", type=_positive, default=None, help="processes or Ray slots")
    p.add_argument("--seed", type=int, default=0, help="the TPE sampler's seed (default 0)")
    p.add_argument(
        "--out", type=path_option, default=Path("runs") / "tune-ppo", help="output folder"
    )
    p.add_argument(
        "--mkl-intel-paths",
        action="store_true",
        help="train each trial with torch's MKL on an Intel CPU's code paths, as follow-train's "
        "option (train.mkl_paths); the command runs again with them preloaded",
    )
    return p


def run(args: argparse.Namespace, argv: Sequence[str] | None = None) -> int:
    """Search, then write ``OUT/result.json`` and print the best trial's hyperparameters.

    :param argv: the command line, which ``--mkl-intel-paths`` runs again with MKL's Intel
        code paths preloaded (default: this process's).
    """
    from follow_env.tasks import get_task

    refuse_empty(args, ("storage", "study", "address"))
    # an empty --scenarios '' is a mistake to name, not a request for the defaults
    given = args.scenarios
    variants = (
        _names(given, "scenarios") if given is not None else DEFAULT_VARIANTS["person_follow"]
    )
    refuse_repeats(given, "scenarios")
    for name in variants:
        if name not in get_task("person_follow").variants():
            raise UsageError(f"--scenarios: unknown scenario {name!r}")
    if not Path(args.hyperparams).is_file():
        raise UsageError(f"--hyperparams {args.hyperparams}: no such file")
    if args.address is not None and args.backend != "ray":
        raise UsageError("--address is for --backend ray")
    workers = args.workers if args.backend == "ray" else args.workers or 1
    backend = backend_from_args(args.backend, workers=workers, address=args.address)
    base = Args(
        hyperparams=args.hyperparams,
        n_timesteps=args.n_timesteps,
        n_envs=args.n_envs,
        final_episodes=0,
        eval_episodes=1,
        eval_freq=max(args.n_timesteps, 1),
        checkpoint_freq=max(args.n_timesteps, 1),
        progress=False,
        mkl_intel_paths=args.mkl_intel_paths,
    )
    _check_training(base, args.out)
    seeds = tuple(range(TUNE_SEED0, TUNE_SEED0 + args.seeds))
    config = SearchConfig(args.trials, seeds, 1, args.seed)  # checks --seed too
    _check_out(args.out)  # before the folder is made, not after a trial
    storage, _ = check_storage(args.storage, args.out)
    _check_out_owner(args.out, args.study)
    if args.mkl_intel_paths:  # after the options' own checks, before anything is written
        from train.mkl_paths import ensure_preloaded

        ensure_preloaded(sys.argv[1:] if argv is None else argv)
    objective = PPOObjective(base, args.out / "trials", tuple(variants), backend)
    n_envs = objective.n_envs()
    identity = {
        "trainer": "ppo",
        "env_id": base.env_id or "PersonFollow-v0",
        "section": json.loads(json.dumps(objective.section(), default=str)),
        "n_timesteps": args.n_timesteps,
        "n_envs": n_envs,
        "variants": list(variants),
        "seeds": args.seeds,
        "space": {k: [r.low, r.high, r.log] for k, r in PPO_SPACE.items()},
    }
    backend.check_reachable()  # before anything is written: no journal left behind
    config = dataclasses.replace(config, batch=backend.slots())
    try:
        study = open_search(
            args.out,
            storage,
            args.study,
            config,
            identity,
            running_code_sha256(TRAINING_PACKAGES),
            running_sources_sha256(TRAINING_PACKAGES),
        )
    except KeyboardInterrupt as e:  # open_search removed what it made: the folder, a new journal
        what, status = stopped(e)  # Ctrl-C, or SIGTERM (sigterm_as_interrupt, in main)
        print(
            f"{PROG}: {what} while opening the study {args.study} in {storage}; no trial "
            "ran: run the same command again",
            file=sys.stderr,
        )
        return status
    try:
        ran = run_search(study, PPO_SPACE, config, objective, on_stale=stale_reporter(PROG))
        return _report(args, storage, study, ran, n_envs)
    except KeyboardInterrupt as e:  # anywhere after the study opened: the search or its report
        what, status = stopped(e)
        print(
            f"{PROG}: {what}; the study {args.study} in {storage} keeps its finished "
            f"trials, and {args.out / 'trials'} their runs: run the same command again to "
            "resume",
            file=sys.stderr,
        )
        return status


def _report(args: argparse.Namespace, storage: str, study: Any, ran: int, n_envs: int) -> int:
    """Write ``OUT/result.json`` (atomically) and print it: the best trial and its values."""
    best = study.best_trial
    summary = {
        "study": args.study,
        "storage": storage,
        "code": running_sources_sha256(TRAINING_PACKAGES),
        "ran_now": ran,
        "trials": len(study.trials),
        "n_timesteps": args.n_timesteps,
        "best_trial": best.number,
        "best_score": best.value,
        "best_hyperparams": hyperparams_for(best.params, n_envs),
    }
    atomic_write_text(args.out / "result.json", json.dumps(summary, indent=2) + "\n")
    print(json.dumps(summary, indent=2))
    return 0


def _check_training(base: Args, out: Path) -> None:
    """The training options and the hyperparameter file every trial shares, checked as
    ``follow-train`` checks a new run, before ``--out`` is made: a trial's training would
    otherwise refuse them only after the journal and the trial's folder were written.

    :raises ValueError: naming the option or the file's key, its value and what is allowed.
    """
    env_id = base.env_id or "PersonFollow-v0"
    # A trial's run folder that does not exist yet (its writability is checked by a file made
    # and removed in the nearest existing folder, which --out's own check tries too).
    run = out / "trials" / "trial-check" / "run"
    check_new_run(dataclasses.replace(base, env_id=env_id, out=run))


def _check_out(out: Path) -> None:
    """``--out``: a folder that can be made, an empty one, or a search's (to resume it); never
    a folder of other files, among which the results and trials would be written.

    :raises UsageError: naming the folder and what it holds.
    """

    def is_result(text: str) -> bool:
        try:
            summary = json.loads(text)
        except ValueError:
            return False
        return isinstance(summary, dict) and {"study", "best_hyperparams"} <= summary.keys()

    check_out_folder(
        out,
        prog=PROG,
        own={
            "study.journal": journal_check,
            "study.journal.lock": None,
            "result.json": text_check(PROG, is_result),
        },
        temporary=_OWN_TEMPORARY,
        folders=("trials",),
    )


def _check_out_owner(out: Path, study: str) -> None:
    """``--out`` is resumed only by its own study: a folder whose ``result.json`` or journal
    belongs to another ``--study`` would have its results overwritten."""
    result = out / "result.json"
    if result.is_file():  # _check_out found it this command's (readable, with "study")
        held = json.loads(result.read_text(encoding="utf-8"))["study"]
        if held != study:
            raise UsageError(
                f"--out {out}: it holds the results of the study {held}, not {study}; give "
                "another --out, or that --study to resume it"
            )
    check_journal_owner(out, study)


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point; returns the exit status (2 with one line on stderr for bad arguments; 130
    on Ctrl-C, 143 on SIGTERM, which takes Ctrl-C's path as follow-tune's does)."""
    with sigterm_as_interrupt():  # `timeout`, Slurm and Kubernetes stop a study as Ctrl-C does
        return run_reporting(
            PROG,
            "the study keeps its finished trials and their runs",
            lambda: run(build_parser().parse_args(argv), argv),
        )


if __name__ == "__main__":
    sys.exit(main())

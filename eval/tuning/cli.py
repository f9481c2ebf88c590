"""``follow-tune``: tune a registered law's parameters with Optuna (see :mod:`eval.tuning`).

    follow-tune pn --trials 100 --seeds 12 --workers 2 --out runs/tune-pn
    follow-tune pid --task line_trace --trials 60 --seeds 4
    follow-tune gsmpn --storage postgresql://user@db/tune --backend ray --address auto

Bad arguments give one line on stderr (``follow-tune: error: ...``) and exit status 2 before
any episode runs or any file is written. A file or folder follow-tune did not write is never
changed: ``--storage`` must be a new or empty file or an Optuna journal, ``--out`` a new or
empty folder or one that holds only a follow-tune study (:data:`OWN_FILES`), to resume it.
"""

from __future__ import annotations

import argparse
import json
import math
import re
import shlex
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import replace
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

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
from execution import (
    BACKENDS,
    WORKERS_LOST,
    BackendUnavailableError,
    WorkerLostError,
    backend_from_args,
    error_line,
)
from follow_env.sim.atomic import atomic_write_text

__all__ = ["PROG", "build_parser", "main", "run_reporting"]

PROG = "follow-tune"
#: Most tuning or held-out seeds: 1000 + k and 2000 + k must never meet.
MAX_SEEDS = 1000
#: The largest ``--seed``: the TPE sampler's (:data:`eval.tuning.driver.MAX_SAMPLER_SEED`,
#: repeated here so that parsing the command line does not import Optuna).
MAX_SAMPLER_SEED = 2**32 - 1
#: What follow-tune writes into ``--out``: the default journal, the results, Optuna's lock
#: beside the journal. A folder holding only these (and the temporary files of an interrupted
#: atomic write, :data:`_OWN_TEMPORARY`) is a follow-tune study's, and may be resumed into.
OWN_FILES = ("study.journal", "study.journal.lock", "result.json", "preset.txt")
_OWN_TEMPORARY = re.compile(r"\.(preset|result)\..+\.tmp\.(txt|json)")


def _sampler_seed(text: str) -> int:
    """``--seed``: an integer the TPE sampler takes, 0..2**32-1."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not an integer") from None
    if not 0 <= value <= MAX_SAMPLER_SEED:
        raise argparse.ArgumentTypeError(
            f"{value} is out of range: 0..2**32-1 (the TPE sampler's seeds)"
        )
    return value


def build_parser() -> argparse.ArgumentParser:
    """The ``follow-tune`` argument parser (errors raise :class:`UsageError`)."""
    p = _Parser(
        prog=PROG,
        description="Tune a registered law's parameters with Optuna (TPE, pruning on partial "
        "seed sets), then check the best on held-out seeds.",
    )
    p.add_argument("law", help="a registered law with a search space (pn, mpn, gsmpn, ...)")
    p.add_argument("--task", default=None, help="person_follow or line_trace (default: the law's)")
    p.add_argument("--trials", type=_positive, default=100, help="finished trials (default 100)")
    p.add_argument(
        "--seeds", type=_positive, default=12, help="tuning seeds 1000.. per variant (default 12)"
    )
    p.add_argument(
        "--scenarios", default=None, help="comma-separated scenarios (tracks for line_trace)"
    )
    p.add_argument("--config", default=None, help="env config: a preset, JSON or a YAML file")
    p.add_argument(
        "--storage",
        default=None,
        help="a journal file (default OUT/study.journal) or an RDB URL (sqlite:///x.db, "
        "postgresql://...) shared by several machines",
    )
    p.add_argument("--study", default=None, help="the study's name (default LAW-TASK)")
    p.add_argument("--backend", choices=BACKENDS, default="local", help="where episodes run")
    p.add_argument("--address", default=None, help="--backend ray: the cluster (auto, host:port)")
    p.add_argument("--workers", type=_positive, default=None, help="processes or Ray slots")
    p.add_argument(
        "--batch", type=_positive, default=None, help="trials evaluated together (default: slots)"
    )
    p.add_argument(
        "--seed", type=_sampler_seed, default=0, help="the TPE sampler's seed (default 0)"
    )
    p.add_argument(
        "--holdout-seeds", type=_positive, default=20, help="held-out seeds 2000.. (default 20)"
    )
    p.add_argument(
        "--holdout-scenarios",
        default=None,
        help="variants of the held-out check (default: the tuned ones); e.g. a line task's "
        "mixed courses, to check that a trial generalises beyond the tracks it was tuned on",
    )
    p.add_argument("--top", type=_positive, default=3, help="trials re-evaluated (default 3)")
    p.add_argument(
        "--write-preset",
        type=path_option,
        default=None,
        help="also write the preset here (a new file, or a preset follow-tune wrote)",
    )
    p.add_argument(
        "--out", type=path_option, default=None, help="output folder (default runs/tune-LAW)"
    )
    return p


def _check(args: argparse.Namespace) -> dict[str, Any]:
    """Everything checked before anything runs or is written; returns the search's identity."""
    from eval.tuning.objective import DEFAULT_VARIANTS
    from follow_env.tasks import get_task
    from policies import tunable_law

    try:
        law = tunable_law(args.law)
    except ValueError as e:
        raise UsageError(str(e)) from None
    # (The list options are refused by `_names`, which they reach when given.)
    refuse_empty(args, ("task", "config", "storage", "study", "address"))
    task = args.task or law.task
    if task != law.task:
        raise UsageError(f"--task {task}: {args.law!r} is a law of the {law.task} task")
    given = args.scenarios
    variants = _names(given, "scenarios") if given is not None else DEFAULT_VARIANTS[task]
    given = args.holdout_scenarios
    args.holdout_variants = (
        _names(given, "holdout-scenarios") if given is not None else list(variants)
    )
    for option in ("scenarios", "holdout_scenarios"):
        refuse_repeats(getattr(args, option), option.replace("_", "-"))
    known = get_task(task).variants()
    for option, names in (("scenarios", variants), ("holdout-scenarios", args.holdout_variants)):
        for name in names:
            if name not in known:
                raise UsageError(
                    f"--{option}: unknown {task} variant {name!r}; known: "
                    + ", ".join(sorted(known))
                )
    for option in ("seeds", "holdout_seeds"):
        if getattr(args, option) > MAX_SEEDS:
            raise UsageError(
                f"--{option.replace('_', '-')} {getattr(args, option)} is out of range: at most "
                f"{MAX_SEEDS} (tuning and held-out seeds stay apart)"
            )
    if args.address is not None and args.backend != "ray":
        raise UsageError("--address is for --backend ray")
    config = None
    if args.config is not None:
        from eval.cli_base import _config
        from eval.tasks import eval_task

        try:
            config = _config(args.config, eval_task(task).config_from_text)
        except argparse.ArgumentTypeError as e:
            raise UsageError(f"argument --config: {e}") from None
    args.out = args.out or Path("runs") / f"tune-{args.law}"
    _check_out(args.out)
    args.storage, database = check_storage(args.storage, args.out)
    args.study = args.study or f"{args.law}-{task}"
    _check_out_owner(args.out, args.law, args.study)
    if args.write_preset is not None:
        parent = args.write_preset.parent
        if args.write_preset.is_dir() or not parent.is_dir():
            raise UsageError(
                f"--write-preset {args.write_preset}: not a file in an existing folder"
            )
        _check_preset_target(args, database)
        _check_preset_file(args.write_preset)
    space = {k: [r.low, r.high, r.log] for k, r in law.space.items()}
    return {
        "law": args.law,
        "task": task,
        "variants": list(variants),
        "seeds": args.seeds,
        "config": config,
        "space": space,
    }


def _check_preset_target(args: argparse.Namespace, database: Path | None) -> None:
    """``--write-preset`` must not name a file the study keeps or follow-tune writes: writing
    the preset over the journal (or database) would lose the study's trials."""
    from eval.tuning.driver import is_url

    kept = {name: args.out / name for name in OWN_FILES}
    if not is_url(args.storage):
        kept["--storage"] = Path(args.storage)
        kept["--storage's lock"] = Path(f"{args.storage}.lock")
    if database is not None:
        kept["--storage"] = database
    target = args.write_preset.resolve()
    for what, path in kept.items():
        if path.resolve() == target:
            name = what if what.startswith("--") else f"--out's {what}"
            raise UsageError(
                f"--write-preset {args.write_preset}: that is {name}, which the study keeps "
                "or follow-tune writes itself; give another file"
            )


#: How a preset follow-tune writes begins (:func:`eval.tuning.report.preset_text`).
_PRESET_HEAD = f"# {PROG} ".encode()


def _check_preset_file(path: Path) -> None:
    """``--write-preset`` replaces only a preset follow-tune wrote (its text begins with
    ``# follow-tune ``), never another file: ``--write-preset policies/pn.py`` would otherwise
    replace the law's module with four lines."""
    if not path.exists():
        return
    try:
        with path.open("rb") as f:
            head = f.read(len(_PRESET_HEAD))
    except OSError as e:
        raise UsageError(f"--write-preset {path}: cannot be read: {e.strerror or e}") from None
    if head != _PRESET_HEAD:
        raise UsageError(
            f"--write-preset {path}: the file exists and is not a preset follow-tune wrote (its "
            f"text begins with {_PRESET_HEAD.decode()!r}); give a new file, or move that one"
        )


def _check_out_owner(out: Path, law: str, study: str) -> None:
    """``--out`` is resumed only by its own study: a folder whose ``result.json`` or journal
    belongs to another law or ``--study`` would have its results overwritten."""
    result = out / "result.json"
    if result.is_file():  # _check_out found it follow-tune's (readable, with "search")
        summary = json.loads(result.read_text(encoding="utf-8"))
        search = summary.get("search")
        held_law = search.get("law") if isinstance(search, dict) else None
        held_study = summary.get("study")
        if (held_law, held_study) != (law, study):
            raise UsageError(
                f"--out {out}: it holds the results of the study {held_study} of the law "
                f"{held_law}, not {study} of {law}; give another --out, or that law and "
                "--study to resume it"
            )
    check_journal_owner(out, study)


def _check_out(out: Path) -> None:
    """``--out``: a folder that can be made, an empty one, or a follow-tune study's (to resume
    it); never a folder of other files, which the results would be written among."""
    check_out_folder(
        out,
        prog=PROG,
        own={
            "study.journal": journal_check,
            "study.journal.lock": None,
            "result.json": text_check(PROG, _is_own_result),
            "preset.txt": text_check(PROG, lambda text: text.startswith(f"# {PROG} ")),
        },
        temporary=_OWN_TEMPORARY,
    )


def _is_own_result(text: str) -> bool:
    """Whether ``text`` is a ``result.json`` as :func:`run` writes it."""
    try:
        summary = json.loads(text)
    except ValueError:
        return False
    return isinstance(summary, dict) and {"search", "holdout", "verdict"} <= summary.keys()


def _tune_seeds(n: int) -> tuple[int, ...]:
    from eval.tuning.objective import TUNE_SEED0

    return tuple(range(TUNE_SEED0, TUNE_SEED0 + n))


def run(args: argparse.Namespace) -> int:
    """Check, search, re-evaluate, write; see the module docstring."""
    from policies import tunable_law

    identity = _check(args)
    law = tunable_law(args.law)
    workers = args.workers if args.backend == "ray" else args.workers or 1
    backend = backend_from_args(args.backend, workers=workers, address=args.address)
    # The backend is reached (Ray connected) before the study opens, whatever --workers says,
    # so that an unreachable cluster leaves no journal behind and no failed trial in it.
    backend.reach()
    batch = args.batch or backend.slots()
    from eval.tuning.driver import SearchConfig

    config = SearchConfig(args.trials, _tune_seeds(args.seeds), 1, args.seed)
    try:
        study = open_search(
            args.out,
            args.storage,
            args.study,
            config,
            identity,
            running_code_sha256(),
            running_sources_sha256(),
        )
    except KeyboardInterrupt as e:  # open_search removed what it made: the folder, a new journal
        what, status = stopped(e)  # Ctrl-C, or SIGTERM (sigterm_as_interrupt)
        print(
            f"{PROG}: {what} while opening the study {args.study} in {args.storage}; "
            "no trial ran: run the same command again",
            file=sys.stderr,
        )
        return status
    try:
        return _search_and_check(args, identity, law, backend, study, batch)
    except KeyboardInterrupt as e:  # anywhere after the study opened: the search or held-out check
        what, status = stopped(e)
        print(
            f"{PROG}: {what}; the study {args.study} in {args.storage} keeps its finished "
            f"trials (this run's held-out check is not in {args.out}): run the same command "
            "again to resume",
            file=sys.stderr,
        )
        return status


def _search_and_check(
    args: argparse.Namespace,
    identity: dict[str, Any],
    law: Any,
    backend: Any,
    study: Any,
    batch: int,
) -> int:
    """Search the opened study, re-evaluate its best on held-out seeds, write the results."""
    from eval.tuning.driver import SearchConfig, run_search
    from eval.tuning.holdout import Candidate, holdout_candidates, reevaluate, verdict
    from eval.tuning.objective import HOLDOUT_SEED0, LawObjective
    from eval.tuning.report import preset_text, table_text

    config = SearchConfig(args.trials, _tune_seeds(args.seeds), batch, args.seed)
    objective = LawObjective(law, tuple(identity["variants"]), backend, identity["config"])
    started = time.perf_counter()
    base = {k: float(getattr(law.base, k)) for k in law.space}

    def progress(trials: list[Any]) -> None:
        for t in trials:
            value = "" if t.value is None else f" {t.value:.2f}"
            params = ", ".join(f"{k}={v:.3g}" for k, v in t.params.items())
            print(
                f"{PROG}: trial {t.number} {t.state.name.lower()}{value} after "
                f"{t.user_attrs.get('seeds', 0)} seeds: {params}",
                file=sys.stderr,
            )

    ran = run_search(
        study,
        law.space,
        config,
        objective,
        enqueue=base,
        on_batch=progress,
        on_stale=stale_reporter(PROG),
    )
    searched = time.perf_counter() - started
    current = Candidate(f"{law.law}:{law.default_preset}", base)
    candidates = holdout_candidates(study, current, args.top)
    holdout = tuple(range(HOLDOUT_SEED0, HOLDOUT_SEED0 + args.holdout_seeds))
    check = replace(objective, variants=tuple(args.holdout_variants))
    rows = reevaluate(check, candidates, holdout)
    elapsed = time.perf_counter() - started
    states = [t.state.name.lower() for t in study.trials]
    summary = {
        "command": shlex.join([PROG, *args.argv]),
        "finished_utc": datetime.now(UTC).isoformat(timespec="seconds"),
        "study": args.study,
        "storage": str(args.storage),
        "search": identity,
        "code": running_sources_sha256(),  # this run's; the study keeps the code it was scored by
        "trials": {s: states.count(s) for s in sorted(set(states))},
        "ran_now": ran,
        "batch": batch,
        "sampler_seed": args.seed,
        "tuning_seeds": [config.seeds[0], config.seeds[-1]],
        "holdout_seeds": [holdout[0], holdout[-1]],
        "holdout_variants": list(args.holdout_variants),
        "search_s": round(searched, 1),
        "elapsed_s": round(elapsed, 1),
        "backend": {"kind": backend.kind, "workers": backend.workers},
        "holdout": rows,
        "verdict": verdict(rows),
    }
    chosen = next(r for r in rows if r["chosen"])
    text = preset_text(law, chosen["values"], summary)
    atomic_write_text(args.out / "preset.txt", text)
    if args.write_preset is not None:
        atomic_write_text(args.write_preset, text)
    # Strict JSON: an interval undefined on one held-out episode is null, not NaN (which
    # Python writes and reads back but JSON parsers elsewhere refuse).
    result = json.dumps(_finite(summary), indent=2, allow_nan=False)
    atomic_write_text(args.out / "result.json", result + "\n")
    print(table_text(rows, summary))
    also = "" if args.write_preset is None else f" and {args.write_preset}"
    print(
        f"{ran} trials run now ({_counts(summary['trials'])} in the study), search "
        f"{searched:.0f} s, "
        f"held-out check {elapsed - searched:.0f} s. Wrote {args.out}/result.json, "
        f"preset.txt{also}"
    )
    return 0


def _finite(value: Any) -> Any:
    """``value`` (JSON-like: dicts, lists, numbers, text) with every NaN or infinite float
    replaced by None, for ``json.dumps(..., allow_nan=False)``."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: _finite(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_finite(v) for v in value]
    return value


def _counts(trials: dict[str, int]) -> str:
    """``{"complete": 5, "pruned": 1}`` as ``5 complete, 1 pruned``."""
    return ", ".join(f"{n} {state}" for state, n in trials.items())


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``follow-tune``; returns the exit status."""
    argv = sys.argv[1:] if argv is None else list(argv)

    def parsed_and_run() -> int:
        args = build_parser().parse_args(argv)
        args.argv = argv
        return run(args)

    with sigterm_as_interrupt():  # `timeout`, Slurm and Kubernetes stop a study as Ctrl-C does
        return run_reporting(PROG, "the study keeps its finished trials", parsed_and_run)


def stale_reporter(prog: str) -> Callable[[Sequence[Any]], None]:
    """A tuning command's ``on_stale`` (:func:`eval.tuning.driver.run_search`): a line on
    stderr naming each trial a lost process left running that the search marked failed."""
    from eval.tuning.liveness import stale_text

    def say(trials: Sequence[Any]) -> None:
        for trial in trials:
            print(f"{prog}: {stale_text(trial)}", file=sys.stderr)

    return say


def run_reporting(prog: str, kept: str, call: Callable[[], int]) -> int:
    """A tuning command's ``call`` (``follow-tune``'s, ``python -m train.tune``'s), its
    expected errors reported in one line on stderr: its exit status.

    :param prog: the command's name, as its lines begin.
    :param kept: what its study keeps when a trial's workers kept dying (exit status
        :data:`execution.WORKERS_LOST`); the line then says how to resume.
    """
    try:
        return call()
    except WorkerLostError as e:  # a trial's workers killed again and again (out of memory)
        print(
            f"{prog}: error: {e}; {kept}: run the same command again to resume (with fewer "
            "--workers if memory is short)",
            file=sys.stderr,
        )
        return WORKERS_LOST
    except (UsageError, OSError, ValueError, BackendUnavailableError) as e:
        print(f"{prog}: error: {error_line(e)}", file=sys.stderr)  # a worker's: unit, host
        return 2
    except KeyboardInterrupt as e:  # before the search began (its own is caught in run)
        what, status = stopped(e)
        print(f"{prog}: {what} before the search began; nothing was written", file=sys.stderr)
        return status


if __name__ == "__main__":
    sys.exit(main())

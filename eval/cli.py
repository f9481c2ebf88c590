"""``follow-eval``: run the identical-rollout comparison, or score step logs.

::

    follow-eval run --policies pn,mpn,gsmpn --scenarios straight,curve --episodes 20 --seed 0 \\
        --out runs/eval-<timestamp> [--workers auto|N] [--config thesis] [--video] [--no-logs] \\
        [--platforms diff_drive,mecanum] [--backend local|ray [--address HOST:PORT]]
    follow-eval run --task line_trace --policies coordinate,pid --tracks course,random ...
    follow-eval metrics LOG.csv [LOG.csv | FOLDER ...] [--out DIR] [--workers auto|N]
    follow-eval aggregate RUN... [--laws pn,mpn,gsmpn] [--scenarios ...] [--out DIR]
    follow-eval dominance RUN... --learner ppo[,...] [--laws ...] [--out DIR]

(also ``python -m eval ...``). ``run`` writes into its output folder::

    summary.csv summary.md summary.json summary.tex   the table (policy x scenario)
    comparisons.csv                                  paired differences per pair of policies
    episodes.csv                                     every episode's metrics
    logs/<policy>/<scenario>/seed_<k>.csv            step logs (eval.steplog), unless --no-logs
    plots/thesis_metrics.png offsets_seed<k>.png trajectories_seed<k>.png
    videos/<policy>_<scenario>_seed<k>.mp4           with --video
    meta.json                                        command, grid, gains, model digests,
                                                     versions, code revision, timing

With ``--task line_trace`` (LineTrace-v0) the grid's variants are tracks (``--tracks``), the
tables hold the line metrics (:mod:`eval.line_metrics`), the logs sit in
``logs/<policy>/<track>/`` and the plots are ``line_metrics.png``, ``cross_track_seed<k>.png``
and ``paths_seed<k>.png`` (:mod:`eval.line_report`); everything else is the same.

``meta.json``'s ``code`` is the code that made the episodes (:mod:`eval.provenance`):
``sources_sha256`` over the ``.py`` files of ``follow_env``, ``policies`` and ``eval``, ``git``
(the HEAD commit, or null outside a git checkout) and ``git_dirty`` (those packages edited since
it);
``dominance`` notes runs pooled from different or unrecorded code.

The folder appears whole when the run succeeds, or not at all. Each finished work unit is kept
in ``.<out>.units/`` beside it (:mod:`eval.journal`) until then, so a run stopped by Ctrl-C or a
crash resumes when the same command is run again, skipping the finished units. ``--backend ray``
runs the units as Ray tasks (:mod:`execution`) and writes the same files, byte for byte, as
``--backend local``. Bad arguments or input give one line on stderr (``follow-eval: error:
...``) and exit status 2, never a traceback, and are caught before any episode runs. A run is
at most :data:`MAX_EPISODES` episodes (policies x scenarios x episodes), and its seeds stay
within :data:`MAX_SEED`. With ``--no-logs`` each episode is reduced to its table row in the
process that ran it and no step log is written (the plot seed's episodes are kept for the
plots); the tables are the same, byte for byte, and a run takes up to
:data:`MAX_EPISODES_WITHOUT_LOGS` episodes.
"""

from __future__ import annotations

import argparse
import csv
import json
import sys
import time
from collections.abc import Sequence
from datetime import UTC, datetime
from pathlib import Path

import follow_env
from eval.cli_aggregate import cmd_aggregate
from eval.cli_base import (  # noqa: F401  (the limits, read here)
    MAX_EPISODES,
    MAX_EPISODES_WITHOUT_LOGS,
    MAX_SEED,
    PROG,
    USAGE_ERROR,
    UsageError,
    _config,
    _integer,
    _names,
    _non_negative,
    _out_folder,
    _Parser,
    _positive,
    _workers,
    sigterm_as_interrupt,
    stopped,
)
from eval.cli_dominance import cmd_dominance
from eval.cli_errors import KNOWN_ERRORS, report_error
from eval.cli_run import _check_grid, cmd_run, run_backend, run_order
from eval.steplog import step_log_files
from execution import BACKENDS
from follow_env.sim.atomic import atomic_folder, check_new_folder

__all__ = ["MAX_EPISODES", "MAX_EPISODES_WITHOUT_LOGS", "MAX_SEED", "main"]


def _backend_arguments(parser: argparse.ArgumentParser, where: str) -> None:
    """--workers, --backend and --address: where ``where`` (:mod:`execution`)."""
    parser.add_argument(
        "--workers",
        type=_workers,
        default=None,
        help="local: processes, 'auto' (default: a pool only when it pays off) or a number; "
        "ray: work units in flight (default: the cluster's CPUs)",
    )
    parser.add_argument(
        "--backend",
        choices=BACKENDS,
        default="local",
        help=f"where {where}: local (this machine) or ray (a Ray cluster: --address, "
        "RAY_ADDRESS, or a local Ray); the files written are the same (default: %(default)s)",
    )
    parser.add_argument(
        "--address",
        default=None,
        help="with --backend ray: the cluster's address, e.g. 127.0.0.1:6379 (default: "
        "RAY_ADDRESS, else a local Ray)",
    )


def build_parser() -> argparse.ArgumentParser:
    """The ``follow-eval`` argument parser."""
    parser = _Parser(
        prog=PROG, description="Compare person-following controllers on identical rollouts."
    )
    sub = parser.add_subparsers(
        dest="command", required=True, metavar="{run,metrics,thesis,aggregate,dominance}"
    )
    run = sub.add_parser(
        "run",
        help="run policies on a scenario x seed grid and write tables, logs and plots",
        description="Run every policy on every scenario and seed (identical rollouts).",
    )
    run.add_argument(
        "--task",
        default="person_follow",
        help="the task: person_follow (PersonFollow-v0) or line_trace (LineTrace-v0) "
        "(default: %(default)s)",
    )
    run.add_argument(
        "--policies",
        default=None,
        help="comma-separated policy names, e.g. pn,mpn:thesis,gsmpn-listing "
        "(default: pn,mpn,gsmpn; with --task line_trace coordinate,pid)",
    )
    run.add_argument(
        "--platforms",
        default=None,
        help="comma-separated platforms (e.g. diff_drive,mecanum): every policy runs on each, "
        "on the same scenarios and seeds, labelled <policy>@<platform>; a single pair is also "
        "named as pn@mecanum in --policies (default: the config's platform)",
    )
    run.add_argument(
        "--scenarios", default=None, help="comma-separated scenario names (default: straight,curve)"
    )
    run.add_argument(
        "--tracks",
        default=None,
        help="with --task line_trace: comma-separated track names (default: every built-in "
        "track: straight,corners,curves,zigzag,gaps,course,random)",
    )
    run.add_argument(
        "--episodes", type=_positive, default=20, help="seeds per scenario (default: %(default)s)"
    )
    run.add_argument(
        "--seed",
        type=_non_negative,
        default=0,
        help="first seed; episodes use seed .. seed + episodes - 1 (default: %(default)s)",
    )
    run.add_argument(
        "--config",
        default=None,
        help="env preset ("
        + ", ".join(sorted(follow_env.PRESETS))
        + "), a JSON object of config sections applied to 'thesis' (e.g. "
        + """'{"perception": {"association": "tracker"}}'), or a .json/.yaml file of one"""
        + " (default: thesis; with --task line_trace the presets are ideal, noisy and paper,"
        + " the default)",
    )
    run.add_argument(
        "--out",
        type=_out_folder,
        default=None,
        help="output folder (default: runs/eval-<timestamp>)",
    )
    _backend_arguments(run, "the episodes and their scoring run")
    run.add_argument(
        "--plot-seed",
        type=_non_negative,
        default=None,
        help="the seed shown in the offset/trajectory plots and videos (default: --seed)",
    )
    run.add_argument(
        "--video", action="store_true", help="also write an mp4 per policy and scenario"
    )
    run.add_argument(
        "--no-logs",
        action="store_true",
        help="write no step logs: each episode is reduced to its row of episodes.csv where it "
        "ran (the --plot-seed's episodes kept for the plots), so memory stays small and a run "
        f"takes up to {MAX_EPISODES_WITHOUT_LOGS:,} episodes instead of {MAX_EPISODES:,} (at most "
        f"{MAX_EPISODES:,} seeds a scenario); the tables are the same",
    )
    run.add_argument(
        "--ideal-baseline",
        action="store_true",
        help="also run every policy under perfect sensing (the ideal preset's detector and "
        "depth, with no per-episode draws of their errors, or light sensors, on the run's "
        "config), labelled <policy>+ideal: the paired differences say what sensing noise costs "
        "each controller",
    )
    metrics = sub.add_parser(
        "metrics",
        help="compute the same tables from step-log CSVs (simulated or recorded on a robot)",
        description="Score step logs (eval.steplog layout); folders are searched for *.csv.",
    )
    metrics.add_argument("logs", nargs="+", type=Path, help="step-log CSV files or folders")
    metrics.add_argument(
        "--policy",
        default="robot",
        help="policy label for logs without a policy column (default: %(default)s)",
    )
    metrics.add_argument(
        "--scenario",
        default="recorded",
        help="scenario label for logs without a scenario column (default: %(default)s)",
    )
    metrics.add_argument(
        "--out", type=_out_folder, default=None, help="also write the tables into this new folder"
    )
    metrics.add_argument(
        "--task",
        default=None,
        help="the task the logs are of: person_follow or line_trace (default: line_trace for "
        "logs with a track column, else person_follow)",
    )
    _backend_arguments(metrics, "the logs are read and scored")
    thesis = sub.add_parser(
        "thesis",
        help="the reference robot's Table 4.1 against the as-built and corrected chains",
        description="Every law x both walks x --episodes seeds under the as-built chain and the "
        "corrected one, against the thesis's Table 4.1 (eval.thesis).",
    )
    thesis.add_argument(  # the report's spreads and run counts need two episodes a cell
        "--episodes",
        type=lambda text: _integer(text, 2),
        default=20,
        help="seeds per cell, at least 2 (default: %(default)s)",
    )
    thesis.add_argument("--seed", type=_non_negative, default=0, help="first seed (default: 0)")
    thesis.add_argument(
        "--out",
        type=_out_folder,
        default=None,
        help="output folder (default: runs/thesis-<timestamp>)",
    )
    agg = sub.add_parser(
        "aggregate",
        help="learners over their training seeds against the laws: IQM, performance profiles, "
        "probability of improvement (eval.aggregate)",
        description="Score each learner (a follow-train --seeds study or a run folder) and the "
        "laws on the same episodes, with stratified bootstrap CIs (eval.aggregate).",
    )
    agg.add_argument("runs", nargs="+", type=Path, help="study or run folders, one per learner")
    agg.add_argument("--laws", default="pn,mpn,gsmpn", help="laws (default: %(default)s)")
    agg.add_argument(
        "--scenarios", default="straight,curve,random", help="scenarios (default: %(default)s)"
    )
    agg.add_argument(
        "--episodes", type=_positive, default=10, help="seeds per scenario (default: 10)"
    )
    agg.add_argument(
        "--seed", type=_non_negative, default=9001, help="first seed (default: %(default)s)"
    )
    agg.add_argument(
        "--reps",
        type=_positive,
        default=2000,
        help="bootstrap samples (default: %(default)s; the performance profiles' bands draw a "
        "quarter of them, at least one)",
    )
    agg.add_argument(
        "--out",
        type=_out_folder,
        default=None,
        help="output folder (default: runs/aggregate-<time>)",
    )
    dom = sub.add_parser(
        "dominance",
        help="a learner against the best law per scenario and criterion (eval.dominance)",
        description="Read a follow-eval run folder's episodes.csv and compare each learner with "
        "the best of the laws on each scenario and criterion, paired over seeds; writes "
        "dominance-<learner>.md|csv into the folder. Several runs on disjoint seeds, made "
        "alike, are pooled into one table (a run holds at most "
        f"{MAX_EPISODES:,} episodes, {MAX_EPISODES_WITHOUT_LOGS:,} with --no-logs) and "
        "written into --out.",
    )
    dom.add_argument(
        "runs",
        type=Path,
        nargs="+",
        metavar="RUN",
        help="a follow-eval run output folder; several are pooled",
    )
    dom.add_argument(
        "--learner",
        required=True,
        help="the learner's policy label, e.g. ppo; several, comma-separated (a study's seeds), "
        "are each met by the same laws, and a table of all of them follows",
    )
    dom.add_argument(
        "--laws",
        default=None,
        help="the laws' labels (default: every other policy in the run under the learner's "
        "sensing, the learners named left out: with --ideal-baseline, ppo+ideal meets the "
        "+ideal laws)",
    )
    dom.add_argument(
        "--out",
        type=_out_folder,
        default=None,
        help="a new folder for the tables and the pooled episodes (needed with several runs; "
        "default: the run's folder)",
    )
    return parser


def cmd_thesis(args: argparse.Namespace) -> int:
    """``follow-eval thesis``: the Table 4.1 comparison (:mod:`eval.thesis`)."""
    from eval import thesis

    _check_grid(len(thesis.LAWS) * len(thesis.CHAINS), len(thesis.WALKS), args.episodes, args.seed)
    out = args.out or Path("runs") / f"thesis-{datetime.now(UTC):%Y%m%d-%H%M%S}"
    check_new_folder(out)
    start = time.perf_counter()
    tables = {c: thesis.run_chain(c, args.episodes, args.seed) for c in thesis.CHAINS}
    with atomic_folder(out) as tmp:
        report = thesis.write_report(tmp, tables, args.seed)
    print(report["markdown"])
    n = sum(len(t) for t in tables.values())
    took = time.perf_counter() - start
    print(f"{n} episodes in {took:.1f} s. Wrote {out}/: thesis_table.csv|md|json, plots/")
    return 0


def _refuse_run_without_logs(path: Path) -> None:
    """A run folder written with ``--no-logs`` (or its missing ``logs/``) has nothing to score:
    say so, rather than read its tables as step logs or report a missing file. A run folder
    with its logs is sent to them: its own tables are not step logs.

    :raises UsageError: naming the run.
    """
    if path.exists() and not path.is_dir():
        return  # a file: read as a step log
    run = path if path.is_dir() else path.parent
    try:
        meta = json.loads((run / "meta.json").read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return  # not a run folder: the logs are read, or refused, as given
    if not isinstance(meta, dict):
        return
    if path == run and meta.get("step_logs") is not False and (run / "logs").is_dir():
        raise UsageError(
            f"{run} is a follow-eval run folder, whose tables are not step logs: give "
            f"{run / 'logs'}, its step logs"
        )
    if meta.get("step_logs") is False:
        where = f"{run}" if path == run else f"{path}: the run {run}"
        raise UsageError(
            f"{where} holds no step logs to score (follow-eval run --no-logs wrote it); its "
            f"tables are {run / 'episodes.csv'} and summary.*"
        )
    if path == run:  # a run with logs whose logs/ folder is gone
        raise UsageError(
            f"{run} is a follow-eval run folder whose step logs ({run / 'logs'}) are missing: "
            f"nothing to score; its tables are {run / 'episodes.csv'} and summary.*"
        )


def cmd_metrics(args: argparse.Namespace) -> int:
    """``follow-eval metrics``: the same tables from step-log files.

    Episodes are ordered as ``run`` orders them (policy and scenario in the order of the run's
    ``meta.json`` for a run's logs, else in the order first seen; then seed as a number, not as
    text), so the same logs give the same tables, the comparisons' pairs the same way round.

    :raises UsageError: when two logs are the same (policy, scenario, seed) episode.
    """
    from eval.report import markdown_report, write_tables
    from eval.scoring import read_episodes, score
    from eval.tasks import eval_task

    if args.out is not None:
        check_new_folder(args.out)  # before scoring: a bad --out should not cost the work
    for path in args.logs:
        _refuse_run_without_logs(Path(path))
    if args.task is not None:  # named before any log is read
        try:
            eval_task(args.task)
        except ValueError as e:
            raise UsageError(f"--task: {e}") from None
    files = step_log_files(args.logs)
    if not files:
        raise UsageError(f"no *.csv step logs under {', '.join(map(str, args.logs))}")
    # A log without a seed column takes its position as its seed: the same file given twice
    # (or a folder and a file in it) would be two episodes, not one given twice.
    given: dict[Path, Path] = {}
    for path in files:
        if (first := given.setdefault(path.resolve(), path)) is not path:
            same = f"{path}" if first == path else f"{first} and {path}"
            raise UsageError(f"{same}: the same step log given twice; give each log once")
    # the first log's header decides the task, unless --task says
    task = eval_task(args.task or _task_of_log(files[0]))
    backend = run_backend(args, len(files), 0)
    episodes = read_episodes(
        files,
        task=task.name,
        variant=task.variant,
        policy=args.policy,
        label=args.scenario,
        # Ray's workers may be on machines that do not have the files: they only score
        backend=backend if backend.kind == "local" else None,
    )
    seen: dict[tuple[str, str, int], Path] = {}
    for path, ep in zip(files, episodes, strict=True):
        key = (ep.policy, ep.scenario, ep.seed)
        if key in seen:
            raise UsageError(
                f"{seen[key]} and {path} are both policy {ep.policy!r}, {task.variant} "
                f"{ep.scenario!r}, seed {ep.seed}: give each episode once"
            )
        seen[key] = path
    # A run's logs in the run's order (its meta.json's), others as first seen
    ran_policies, ran_variants = run_order(args.logs)
    policies = dict.fromkeys([*ran_policies, *(ep.policy for ep in episodes)])
    variants = dict.fromkeys([*ran_variants, *(ep.scenario for ep in episodes)])
    policy_order = {p: k for k, p in enumerate(policies)}
    scenario_order = {s: k for k, s in enumerate(variants)}
    episodes.sort(key=lambda ep: (policy_order[ep.policy], scenario_order[ep.scenario], ep.seed))
    try:
        scored = score(episodes, metrics=task.metrics, variant=task.variant, backend=backend)
    except KeyError as e:
        raise UsageError(
            f"the logs lack the column {e} that the {task.name} task's metrics need "
            f"(--task {task.name}; the first log: {files[0]})"
        ) from None
    summary, comparisons = scored.summary, scored.comparisons
    if args.out is not None:
        with atomic_folder(args.out) as tmp:
            meta = {
                "command": " ".join([PROG, *sys.argv[1:]]),
                "task": task.name,
                "logs": [str(f) for f in files],
            }
            write_tables(tmp, summary, scored.table, comparisons, meta, tables=task.tables)
            (tmp / "plots").mkdir()
            task.summary_plot(summary, tmp / "plots")
    print(markdown_report(summary, comparisons, tables=task.tables))
    where = f"; wrote {args.out}/" if args.out is not None else ""
    print(f"{len(files)} step log{'s' if len(files) != 1 else ''} scored{where}")
    return 0


def _task_of_log(path: Path) -> str:
    """``line_trace`` for a log whose header has a ``track`` column, else ``person_follow``
    (a file that cannot be read is left for :func:`read_step_log` to report)."""
    try:
        with path.open(newline="", encoding="utf-8") as f:
            header = next(csv.reader(f), [])
    except (OSError, UnicodeDecodeError, csv.Error):
        return "person_follow"
    return "line_trace" if "track" in (cell.strip() for cell in header) else "person_follow"


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``follow-eval`` and ``python -m eval``; returns the exit status: 0, 2 for
    bad arguments or input, 3 when workers kept dying (:mod:`eval.cli_errors`), 130 on Ctrl-C,
    143 on SIGTERM (which takes Ctrl-C's path: :func:`eval.cli_base.sigterm_as_interrupt`)."""
    with sigterm_as_interrupt():
        return _main(argv)


def _main(argv: Sequence[str] | None) -> int:
    """:func:`main` with SIGTERM handled."""
    args: argparse.Namespace | None = None
    try:
        args = build_parser().parse_args(argv)
        if args.command == "run" and args.out is None:  # named now: an error says where to resume
            args.out = Path("runs") / f"eval-{datetime.now():%Y%m%d-%H%M%S}"
        commands = {
            "run": cmd_run,
            "metrics": cmd_metrics,
            "thesis": cmd_thesis,
            "aggregate": cmd_aggregate,
            "dominance": cmd_dominance,
        }
        return commands[args.command](args)
    except KNOWN_ERRORS as e:
        return report_error(e, args)
    except KeyboardInterrupt as e:
        what, status = stopped(e)
        print(f"{PROG}: {what}; nothing was written", file=sys.stderr)
        return status


if __name__ == "__main__":
    sys.exit(main())

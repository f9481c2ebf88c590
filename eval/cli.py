"""``follow-eval``: run the identical-rollout comparison, or score step logs.

::

    follow-eval run --policies pn,mpn,gsmpn --scenarios straight,curve --episodes 20 --seed 0 \\
        --out runs/eval-<timestamp> [--workers auto|N] [--config thesis] [--video] \\
        [--platforms diff_drive,mecanum]
    follow-eval run --task line_trace --policies coordinate,pid --tracks course,random ...
    follow-eval metrics LOG.csv [LOG.csv | FOLDER ...] [--out DIR]

(also ``python -m eval ...``). ``run`` writes into its output folder::

    summary.csv summary.md summary.json summary.tex   the table (policy x scenario)
    comparisons.csv                                  paired differences per pair of policies
    episodes.csv                                     every episode's metrics
    logs/<policy>/<scenario>/seed_<k>.csv            step logs (eval.steplog)
    plots/thesis_metrics.png offsets_seed<k>.png trajectories_seed<k>.png
    videos/<policy>_<scenario>_seed<k>.mp4           with --video
    meta.json                                        command, grid, gains, versions, timing

With ``--task line_trace`` (LineTrace-v0) the grid's variants are tracks (``--tracks``), the
tables hold the line metrics (:mod:`eval.line_metrics`), the logs sit in
``logs/<policy>/<track>/`` and the plots are ``line_metrics.png``, ``cross_track_seed<k>.png``
and ``paths_seed<k>.png`` (:mod:`eval.line_report`); everything else is the same.

The folder appears whole when the run succeeds, or not at all. Bad arguments or input give one
line on stderr (``follow-eval: error: ...``) and exit status 2, never a traceback, and are
caught before any episode runs. A run is at most :data:`MAX_EPISODES` episodes (policies x
scenarios x episodes), and its seeds stay within :data:`MAX_SEED`.
"""

from __future__ import annotations

import argparse
import csv
import json
import platform
import sys
import time
from collections.abc import Sequence
from datetime import UTC, datetime
from pathlib import Path
from typing import Any, NoReturn

import follow_env
from eval.atomic import atomic_folder, atomic_write_text, check_new_folder
from eval.steplog import StepLogError, read_step_log, step_log_files, write_step_log
from follow_env.tasks.person_follow.config import config_from_text

__all__ = ["MAX_EPISODES", "MAX_SEED", "main"]

PROG = "follow-eval"
USAGE_ERROR = 2
#: The most episodes one ``follow-eval run`` takes (policies x scenarios x episodes). A run holds
#: every episode's step log in memory until its tables are written (50-200 kB an episode,
#: measured: 135-450 rows of 41 columns) and writes one CSV of 40-140 kB per episode, so 50,000
#: episodes can take 10 GB of memory and 7 GB of disk. Larger searches use ``eval.rollout``
#: with a ``reduce`` function, as ``eval.tune`` does.
MAX_EPISODES = 50_000
#: The largest seed the env accepts: ``reset(seed=s)`` takes 0 <= s < 2**256 (follow_env seeds
#: numpy's SeedSequence with up to eight 32-bit words; a test pins this).
MAX_SEED = 2**256 - 1


class UsageError(Exception):
    """Bad arguments or input: reported as one line, exit status 2."""


class _Parser(argparse.ArgumentParser):
    """argparse that reports errors as one line (no usage dump), exit status 2."""

    def error(self, message: str) -> NoReturn:
        raise UsageError(message)


def _config(text: str, read: Any = config_from_text) -> str | dict[str, Any]:
    """``--config``: a preset name, a JSON object of section overrides, or a file of one (read
    by the task's ``config_from_text``, PersonFollow's unless told)."""
    try:
        return read(text)  # type: ignore[no-any-return]
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def _names(text: str, what: str) -> list[str]:
    names = [n.strip() for n in text.split(",") if n.strip()]
    if not names:
        raise UsageError(f"--{what} is empty: give a comma-separated list of names")
    return list(dict.fromkeys(names))  # drop repeats, keep order


def _workers(text: str) -> int | None:
    if text == "auto":
        return None
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not 'auto' or an integer >= 1") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"{value} is out of range: must be 'auto' or >= 1")
    return value


def _integer(text: str, low: int) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not an integer") from None
    if value < low:
        raise argparse.ArgumentTypeError(f"{value} is out of range: must be >= {low}")
    return value


def _non_negative(text: str) -> int:
    return _integer(text, 0)


def _positive(text: str) -> int:
    return _integer(text, 1)


def build_parser() -> argparse.ArgumentParser:
    """The ``follow-eval`` argument parser."""
    parser = _Parser(
        prog=PROG, description="Compare person-following controllers on identical rollouts."
    )
    sub = parser.add_subparsers(dest="command", required=True, metavar="{run,metrics,thesis}")
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
        "--out", type=Path, default=None, help="output folder (default: runs/eval-<timestamp>)"
    )
    run.add_argument(
        "--workers",
        type=_workers,
        default=None,
        help="processes: 'auto' (default: a pool only when it pays off) or a number",
    )
    run.add_argument(
        "--plot-seed",
        type=_non_negative,
        default=None,
        help="the seed shown in the offset/trajectory plots and videos (default: --seed)",
    )
    run.add_argument(
        "--video", action="store_true", help="also write an mp4 per policy and scenario"
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
        "--out", type=Path, default=None, help="also write the tables into this new folder"
    )
    metrics.add_argument(
        "--task",
        default=None,
        help="the task the logs are of: person_follow or line_trace (default: line_trace for "
        "logs with a track column, else person_follow)",
    )
    thesis = sub.add_parser(
        "thesis",
        help="the reference robot's Table 4.1 against the as-built and corrected chains",
        description="Every law x both walks x --episodes seeds under the as-built chain and the "
        "corrected one, against the thesis's Table 4.1 (eval.thesis).",
    )
    thesis.add_argument(
        "--episodes", type=_positive, default=20, help="seeds per cell (default: %(default)s)"
    )
    thesis.add_argument("--seed", type=_non_negative, default=0, help="first seed (default: 0)")
    thesis.add_argument(
        "--out", type=Path, default=None, help="output folder (default: runs/thesis-<timestamp>)"
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


def _plural(n: int, one: str, many: str) -> str:
    return one if n == 1 else many


def _check_grid(n_policies: int, n_scenarios: int, episodes: int, seed: int) -> None:
    """Refuse a grid larger than :data:`MAX_EPISODES` or seeds beyond :data:`MAX_SEED`."""
    total = n_policies * n_scenarios * episodes
    if total > MAX_EPISODES:
        raise UsageError(
            f"--episodes {episodes:,}: {n_policies} {_plural(n_policies, 'policy', 'policies')} "
            f"x {n_scenarios} {_plural(n_scenarios, 'scenario', 'scenarios')} x "
            f"{episodes:,} episodes = {total:,} episodes is out of range: a run takes at most "
            f"{MAX_EPISODES:,} episodes (every step log is held in memory and written to disk)"
        )
    if seed + episodes - 1 > MAX_SEED:
        raise UsageError(
            f"--seed {seed} with --episodes {episodes:,} is out of range: the seeds "
            f"seed .. seed + episodes - 1 must stay within 0 .. 2**256 - 1 (the env's seeds)"
        )


def _check_run_args(args: argparse.Namespace) -> tuple[list[str], list[str]]:
    """The run's policies and variants (scenarios, tracks), checked; sets ``args.config`` to
    the task's configuration read from its text and ``args.eval_task`` to the task."""
    from eval.rollout import policy_spec
    from eval.tasks import eval_task
    from follow_env.platforms import get_platform
    from policies import available_policies, for_platform, make_policy

    try:
        task = eval_task(args.task)
    except ValueError as e:
        raise UsageError(f"--task: {e}") from None
    args.eval_task = task
    other = "tracks" if task.variant == "scenario" else "scenarios"
    if getattr(args, other) is not None:
        raise UsageError(
            f"--{other} is not an option of the {task.name} task: give --{task.variants_option}"
        )
    try:
        args.config = _config(
            task.default_config if args.config is None else args.config, task.config_from_text
        )
    except argparse.ArgumentTypeError as e:
        raise UsageError(f"argument --config: {e}") from None
    policies = _names(args.policies or task.default_policies, "policies")
    if args.platforms is not None:
        platforms = _names(args.platforms, "platforms")
        for name in platforms:
            try:
                get_platform(name)
            except ValueError as e:
                raise UsageError(f"--platforms: {e}") from None
        if any("@" in p for p in policies):
            raise UsageError("--policies names a platform (policy@platform): leave out --platforms")
        policies = [f"{p}@{m}" for p in policies for m in platforms]
    given = getattr(args, task.variants_option)
    scenarios = _names(given or task.default_variants, task.variants_option)
    # Size first: it needs only the counts, and loading a policy is already work.
    _check_grid(len(policies), len(scenarios), args.episodes, args.seed)
    registered, for_task = set(available_policies()), set(available_policies(task.name))
    for name in policies:
        try:
            spec, platform = policy_spec(name)
            if spec in registered and spec not in for_task:
                raise ValueError(
                    f"policy {spec!r} is not for the {task.name} task; its policies: "
                    + ", ".join(sorted(for_task))
                )
            law = make_policy(spec)  # type: ignore[arg-type]
            if platform is not None:
                for_platform(law, tuple(a.name for a in get_platform(platform).actions))
        except (ValueError, TypeError) as e:
            raise UsageError(f"--policies: {e}") from None
    from follow_env.tasks import get_task

    known_variants = get_task(task.name).variants()
    for name in scenarios:
        if name not in known_variants:
            known = ", ".join(sorted(known_variants))
            raise UsageError(
                f"--{task.variants_option}: unknown {task.variant} {name!r}; known "
                f"{task.variants_option}: {known}"
            )
    seeds = range(args.seed, args.seed + args.episodes)
    if args.plot_seed is not None and args.plot_seed not in seeds:
        raise UsageError(
            f"--plot-seed {args.plot_seed} is out of range: must be one of the run's seeds "
            f"{seeds.start}..{seeds.stop - 1}"
        )
    return policies, scenarios


def _versions() -> dict[str, str]:
    from importlib.metadata import PackageNotFoundError, version

    out = {"python": platform.python_version()}
    for package in ("personfollow", "gymnasium", "numpy", "numba", "scipy", "pandas"):
        try:
            out[package] = version(package)
        except PackageNotFoundError:
            out[package] = "not installed"
    return out


def cmd_run(args: argparse.Namespace) -> int:
    """``follow-eval run``: see the module docstring."""
    from eval.report import markdown_report, safe_name, write_tables, write_video
    from eval.rollout import auto_workers, rollout
    from eval.stats import compare, episode_table, summarize

    policies, scenarios = _check_run_args(args)
    task = args.eval_task
    seeds = list(range(args.seed, args.seed + args.episodes))
    plot_seed = args.seed if args.plot_seed is None else args.plot_seed
    out: Path = args.out or Path("runs") / f"eval-{datetime.now():%Y%m%d-%H%M%S}"
    n_episodes = len(policies) * len(scenarios) * len(seeds)
    workers = args.workers or auto_workers(n_episodes)
    started = time.perf_counter()
    with atomic_folder(out) as tmp:
        episodes = rollout(
            policies,
            scenarios,
            seeds,
            config=args.config,
            workers=workers,
            progress=True,
            task=task.name,
        )
        for ep in episodes:
            folder = tmp / "logs" / safe_name(ep.policy) / safe_name(ep.scenario)
            folder.mkdir(parents=True, exist_ok=True)
            write_step_log(ep.log, folder / f"seed_{ep.seed}.csv")
        table = episode_table(episodes, metrics=task.metrics, variant=task.variant)
        # The bootstrap's default seed, as in `follow-eval metrics`: the same episodes give the
        # same intervals whichever command scores them.
        summary = summarize(table, metrics=list(task.metrics))
        comparisons = compare(table, metrics=list(task.metrics))
        (tmp / "plots").mkdir()
        task.plots(summary, episodes, plot_seed, tmp / "plots", args.config)
        if args.video:
            (tmp / "videos").mkdir()
            for policy in dict.fromkeys(ep.policy for ep in episodes):
                for scenario in scenarios:
                    name = f"{safe_name(policy)}_{safe_name(scenario)}_seed{plot_seed}.mp4"
                    write_video(
                        policy,
                        scenario,
                        plot_seed,
                        tmp / "videos" / name,
                        config=args.config,
                        fps=task.fps,
                        task=task.name,
                    )
        elapsed = time.perf_counter() - started
        meta: dict[str, Any] = {
            "command": " ".join([PROG, *sys.argv[1:]]),
            "finished_utc": datetime.now(UTC).isoformat(timespec="seconds"),
            "elapsed_s": round(elapsed, 2),
            "policies": {name: repr(getattr(p, "params", p)) for name, p in _built(policies)},
            "task": task.name,
            task.variants_option: scenarios,
            "seeds": seeds,
            "config": args.config,
            "workers": workers,
            "plot_seed": plot_seed,
            "versions": _versions(),
        }
        write_tables(tmp, summary, table, comparisons, meta, tables=task.tables)
        atomic_write_text(tmp / "meta.json", json.dumps(meta, indent=2) + "\n")
    print(markdown_report(summary, comparisons, tables=task.tables))
    plots = ", ".join(sorted(p.name for p in (out / "plots").iterdir()))
    print(
        f"{n_episodes} episodes in {elapsed:.1f} s ({workers} process"
        f"{'es' if workers > 1 else ''}). Wrote {out}/: summary.csv|md|json|tex, "
        f"comparisons.csv, episodes.csv, logs/, plots/ ({plots})"
        + (", videos/" if args.video else "")
    )
    return 0


def _built(policies: list[str]) -> list[tuple[str, Any]]:
    """``(episode label, policy)`` of every policy spec (``pn@mecanum`` included)."""
    from eval.rollout import policy_spec
    from policies import make_policy

    out = []
    for name in policies:
        spec, platform = policy_spec(name)
        law = make_policy(spec)  # type: ignore[arg-type]
        out.append((law.name if platform is None else f"{law.name}@{platform}", law))
    return out


def cmd_metrics(args: argparse.Namespace) -> int:
    """``follow-eval metrics``: the same tables from step-log files.

    Episodes are ordered as ``run`` orders them (policy and scenario in the order first seen,
    then seed as a number, not as text), so the same logs give the same tables and intervals.

    :raises UsageError: when two logs are the same (policy, scenario, seed) episode.
    """
    from eval.report import markdown_report, write_tables
    from eval.rollout import Episode
    from eval.stats import compare, episode_table, summarize
    from eval.tasks import eval_task

    if args.out is not None:
        check_new_folder(args.out)  # before scoring: a bad --out should not cost the work
    files = step_log_files(args.logs)
    if not files:
        raise UsageError(f"no *.csv step logs under {', '.join(map(str, args.logs))}")
    episodes = []
    seen: dict[tuple[str, str, int], Path] = {}
    task = None
    for i, path in enumerate(files):
        if task is None:  # the first log's header decides, unless --task says
            task = eval_task(args.task or _task_of_log(path))
        log = read_step_log(path, task.name)
        policy = _first_text(log, "policy") or args.policy
        variant = _first_text(log, task.variant) or args.scenario
        seed = int(log["seed"].iloc[0]) if "seed" in log and log["seed"].notna().all() else i
        key = (policy, variant, seed)
        if key in seen:
            raise UsageError(
                f"{seen[key]} and {path} are both policy {policy!r}, {task.variant} "
                f"{variant!r}, seed {seed}: give each episode once"
            )
        seen[key] = path
        if "termination" not in log:
            log = log.assign(termination="")
        episodes.append(Episode(policy, variant, seed, log))
    assert task is not None
    policy_order = {p: k for k, p in enumerate(dict.fromkeys(ep.policy for ep in episodes))}
    scenario_order = {s: k for k, s in enumerate(dict.fromkeys(ep.scenario for ep in episodes))}
    episodes.sort(key=lambda ep: (policy_order[ep.policy], scenario_order[ep.scenario], ep.seed))
    try:
        table = episode_table(episodes, metrics=task.metrics, variant=task.variant)
    except KeyError as e:
        raise UsageError(
            f"the logs lack the column {e} that the {task.name} task's metrics need "
            f"(--task {task.name}; the first log: {files[0]})"
        ) from None
    summary = summarize(table, metrics=list(task.metrics))
    comparisons = compare(table, metrics=list(task.metrics))
    if args.out is not None:
        with atomic_folder(args.out) as tmp:
            meta = {
                "command": " ".join([PROG, *sys.argv[1:]]),
                "task": task.name,
                "logs": [str(f) for f in files],
            }
            write_tables(tmp, summary, table, comparisons, meta, tables=task.tables)
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


def _first_text(log: Any, column: str) -> str | None:
    if column not in log:
        return None
    values = [v for v in log[column] if isinstance(v, str) and v]
    return values[0] if values else None


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``follow-eval`` and ``python -m eval``; returns the exit status."""
    try:
        args = build_parser().parse_args(argv)
        commands = {"run": cmd_run, "metrics": cmd_metrics, "thesis": cmd_thesis}
        return commands[args.command](args)
    except (UsageError, StepLogError, FileExistsError, OSError, ValueError) as e:
        print(f"{PROG}: error: {e}", file=sys.stderr)
        return USAGE_ERROR
    except KeyboardInterrupt:
        print(f"{PROG}: interrupted; nothing was written", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())

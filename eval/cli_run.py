"""``follow-eval run``: the identical-rollout comparison on a backend, resumable (see
:mod:`eval.cli`)."""

from __future__ import annotations

import argparse
import dataclasses
import functools
import json
import platform
import sys
import time
from collections.abc import Sequence
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from eval.cli_base import (
    MAX_EPISODES,
    MAX_EPISODES_WITHOUT_LOGS,
    MAX_SEED,
    PROG,
    UsageError,
    _config,
    _names,
    stopped,
)
from execution import Backend, backend_from_args
from follow_env.sim.atomic import atomic_folder, atomic_write_text, check_new_folder

__all__ = ["cmd_run", "policy_label", "refuse_aliases", "run_backend", "run_order"]


def _plural(n: int, one: str, many: str) -> str:
    return one if n == 1 else many


def _check_grid(
    n_policies: int, n_scenarios: int, episodes: int, seed: int, *, logs: bool = True
) -> None:
    """Refuse a grid larger than :data:`MAX_EPISODES` (:data:`MAX_EPISODES_WITHOUT_LOGS` for a
    run without step logs), more than :data:`MAX_EPISODES` seeds a scenario, or seeds beyond
    :data:`MAX_SEED`."""
    total = n_policies * n_scenarios * episodes
    limit = MAX_EPISODES if logs else MAX_EPISODES_WITHOUT_LOGS
    if total > limit:
        why = (
            "every step log is held in memory and written to disk; --no-logs keeps only each "
            f"episode's table row and takes up to {MAX_EPISODES_WITHOUT_LOGS:,}"
            if logs
            else "each episode's table row is held in memory"
        )
        raise UsageError(
            f"--episodes {episodes:,}: {n_policies} {_plural(n_policies, 'policy', 'policies')} "
            f"x {n_scenarios} {_plural(n_scenarios, 'scenario', 'scenarios')} x "
            f"{episodes:,} episodes = {total:,} episodes is out of range: a run takes at most "
            f"{limit:,} episodes ({why})"
        )
    if episodes > MAX_EPISODES:  # only without logs: with them the run's limit is smaller
        raise UsageError(
            f"--episodes {episodes:,} is out of range: a scenario takes at most "
            f"{MAX_EPISODES:,} seeds (each cell's bootstrap intervals cost time with the square "
            "of its episodes, about 11 s an interval at 50,000); run more seeds as several "
            "runs and pool them with follow-eval dominance"
        )
    if seed + episodes - 1 > MAX_SEED:
        raise UsageError(
            f"--seed {seed} with --episodes {episodes:,} is out of range: the seeds "
            f"seed .. seed + episodes - 1 must stay within 0 .. 2**256 - 1 (the env's seeds)"
        )


def _check_run_args(args: argparse.Namespace) -> tuple[list[str], list[str], list[tuple[str, Any]]]:
    """The run's policies and variants (scenarios, tracks), checked, and each policy as built
    for the check, with the label its episodes carry (the run's record of their parameters
    reads these, so no policy is loaded twice); sets ``args.config`` to the task's configuration
    read from its text and ``args.eval_task`` to the task."""
    from eval.grid import checked_policy
    from eval.tasks import eval_task
    from follow_env.platforms import get_platform

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
    if args.config is not None and not args.config.strip():  # "" would be read as the folder .
        raise UsageError(
            f"argument --config: {args.config!r} is empty: give a preset, a JSON object of "
            "config sections or a .json/.yaml file (or leave --config out for the default)"
        )
    try:
        args.config = _config(
            task.default_config if args.config is None else args.config, task.config_from_text
        )
    except argparse.ArgumentTypeError as e:
        raise UsageError(f"argument --config: {e}") from None
    # An empty --policies '' is a mistake to name, not a request for the defaults.
    default = task.default_policies
    policies = _names(default if args.policies is None else args.policies, "policies")
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
    scenarios = _names(task.default_variants if given is None else given, task.variants_option)
    # Size first: it needs only the counts, and loading a policy is already work.
    runs = 2 if getattr(args, "ideal_baseline", False) else 1  # the grid again, perfect sensing
    _check_grid(
        len(policies) * runs, len(scenarios), args.episodes, args.seed, logs=not args.no_logs
    )
    built: list[tuple[str, Any]] = []
    for name in policies:
        try:
            policy, platform = checked_policy(name, task.name)
        except (ValueError, TypeError) as e:
            raise UsageError(f"--policies: {e}") from None
        built.append((_episode_label(policy, platform), policy))
    named = [(name, label) for name, (label, _) in zip(policies, built, strict=True)]
    refuse_aliases(named, "policies")
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
    return policies, scenarios, built


def _versions() -> dict[str, str]:
    from importlib.metadata import PackageNotFoundError, version

    out = {"python": platform.python_version()}
    for package in ("personfollow", "gymnasium", "numpy", "numba", "scipy", "pandas"):
        try:
            out[package] = version(package)
        except PackageNotFoundError:
            out[package] = "not installed"
    return out


def run_backend(args: argparse.Namespace, n_episodes: int, learned_episodes: int) -> Backend:
    """The execution backend from --backend, --workers and --address (``run``, ``metrics``)."""
    from eval.rollout import auto_workers

    if args.address is not None and args.backend != "ray":
        raise UsageError("--address is for --backend ray")
    workers = args.workers
    if args.backend == "local" and workers is None:
        workers = auto_workers(n_episodes, learned_episodes, scored=True)
    return backend_from_args(args.backend, workers=workers, address=args.address)


def cmd_run(args: argparse.Namespace) -> int:
    """``follow-eval run``: see the module docstring."""
    from eval.journal import CODE, MODELS, UnitJournal, journal_folder
    from eval.provenance import agent_path, code_revision, model_sha256
    from eval.report import markdown_report, safe_name, write_tables, write_video
    from eval.rollout import Episode, chunk_size, rollout
    from eval.scoring import score
    from eval.stats import TableRow
    from policies.learned.ensemble import is_learned

    policies, scenarios, built = _check_run_args(args)
    learned = sum(is_learned(policy) for _, policy in built)
    task = args.eval_task
    seeds = list(range(args.seed, args.seed + args.episodes))
    plot_seed = args.seed if args.plot_seed is None else args.plot_seed
    out: Path = args.out or Path("runs") / f"eval-{datetime.now():%Y%m%d-%H%M%S}"
    n_episodes = len(policies) * len(scenarios) * len(seeds) * (2 if args.ideal_baseline else 1)
    learned_episodes = n_episodes // len(policies) * learned
    check_new_folder(out)
    backend = run_backend(args, n_episodes, learned_episodes)
    backend.reach()  # Ray connected (a cluster found answering) before the journal is made
    started = time.perf_counter()
    run = {"task": task.name, "policies": policies, task.variants_option: scenarios}
    run |= {"seeds": [seeds[0], seeds[-1]], "config": args.config}
    # What each learned policy's files held, read once, before any episode: a model replaced
    # between an interrupted run and its resume is another run, not mixed into this one (the
    # journal names the policy and its files), and each unit's worker checks its own files.
    digests = {label: d for label, p in built if (d := model_sha256(p)) is not None}
    agents = {label: str(agent_path(p)) for label, p in built if label in digests}
    run |= {MODELS: digests} if digests else {}
    # The code the episodes run, read once before any of them, as the models are: pooling
    # runs (`follow-eval dominance`) compares it, and a resume by other code is refused (its
    # tables would mix two versions' episodes; eval.journal says so and what to do).
    code = code_revision()
    run |= {CODE: code["sources_sha256"]}
    # Without step logs a unit keeps rows, not episodes: its journal is of another run. It
    # keeps the plot seed's episodes whole, so another --plot-seed is another run too (a run
    # with logs keeps every episode, and its journal stays as it was).
    run |= {"step_logs": False, "plot_seed": plot_seed} if args.no_logs else {}
    # Each episode reduced to its table row where it ran, the plot seed's kept for the plots.
    reduce = TableRow(task.metrics, plot_seed) if args.no_logs else None
    folder = journal_folder(out)
    chunk = _journal_chunk(folder) or chunk_size(
        len(seeds), backend.slots(), len(policies) * len(scenarios)
    )
    # The run's grid, and with --ideal-baseline the same grid again under perfect sensing
    # (its units kept in a journal of their own, inside the run's).
    journal = UnitJournal(folder, run | {"chunk": chunk}, agents)
    grids = [("", args.config, journal)]
    if args.ideal_baseline:
        perfect = task.perfect_sensing(args.config)
        ideal = UnitJournal(
            folder / "ideal", run | {"chunk": chunk, "baseline": IDEAL_SUFFIX}, agents
        )
        grids.append((IDEAL_SUFFIX, perfect, ideal))
    episodes: list[Any] = []
    try:
        for suffix, config, kept_in in grids:
            done = kept_in.load()
            if done:
                print(
                    f"{PROG}: resuming: {len(done)} work units already done in {kept_in.folder}",
                    file=sys.stderr,
                )
            got = rollout(
                policies,
                scenarios,
                seeds,
                config=config,
                backend=backend,
                progress=True,
                task=task.name,
                chunk=chunk,
                done=done,
                on_unit=kept_in.put,
                reduce=reduce,
                models=digests,  # as recorded: files replaced since stop the run
                label_suffix=suffix,  # the ideal grid's units named as its episodes will be
            )
            episodes += [_labelled(ep, suffix) for ep in got] if suffix else got
    except BaseException as e:
        kept = len(list(folder.rglob("unit-*.pkl")))
        if not kept:
            journal.remove()  # nothing to resume (the ideal grid's journal is inside it)
        if not isinstance(e, KeyboardInterrupt):
            raise
        what, status = stopped(e)  # Ctrl-C, or SIGTERM (eval.cli_base.sigterm_as_interrupt)
        print(
            f"{PROG}: {what}; {out} was not written. "
            + (
                f"{kept} finished work units are kept in {folder}: run the same command "
                "again to resume"
                if kept
                else "No work unit had finished; nothing was kept"
            ),
            file=sys.stderr,
        )
        return status
    with atomic_folder(out) as tmp:
        log_path = None if args.no_logs else functools.partial(_log_path, tmp)
        if log_path is not None:
            for ep in episodes:
                log_path(ep).parent.mkdir(parents=True, exist_ok=True)
        # By scenario on the run's backend, with the bootstrap's default seed, as in
        # `follow-eval metrics`: the same episodes give the same intervals whichever command
        # scores them.
        scored = score(
            episodes, metrics=task.metrics, variant=task.variant, log_path=log_path, backend=backend
        )
        table, summary, comparisons = scored.table, scored.summary, scored.comparisons
        (tmp / "plots").mkdir()
        whole = [ep for ep in episodes if isinstance(ep, Episode)]  # all, or the plot seed's
        task.plots(summary, whole, plot_seed, tmp / "plots", args.config)
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
            "policies": {label: repr(getattr(p, "params", p)) for label, p in built},
            # what each learned policy's files held: its repr names only a path
            "model_sha256": digests,
            "task": task.name,
            task.variants_option: scenarios,
            "seeds": seeds,
            "config": args.config,
            "backend": {"kind": backend.kind, "workers": backend.workers, "chunk": chunk},
            "plot_seed": plot_seed,
            "ideal_baseline": bool(args.ideal_baseline),
            "step_logs": not args.no_logs,
            "versions": _versions(),
            "code": code,  # eval.provenance: sources digest, git commit and whether edited
        }
        write_tables(tmp, summary, table, comparisons, meta, tables=task.tables)
        atomic_write_text(tmp / "meta.json", json.dumps(meta, indent=2) + "\n")
    journal.remove()
    print(markdown_report(summary, comparisons, tables=task.tables))
    plots = ", ".join(sorted(p.name for p in (out / "plots").iterdir()))
    print(
        f"{n_episodes} episodes in {elapsed:.1f} s ({_where(backend)}). Wrote {out}/: "
        "summary.csv|md|json|tex, "
        f"comparisons.csv, episodes.csv, {'' if args.no_logs else 'logs/, '}plots/ ({plots})"
        + (", videos/" if args.video else "")
    )
    return 0


#: What ``--ideal-baseline`` appends to a policy's label: the policy under perfect sensing.
IDEAL_SUFFIX = "+ideal"


def run_order(paths: Sequence[str | Path]) -> tuple[list[str], list[str]]:
    """The policy labels and variants (scenarios, tracks) in the order a run gave them, for
    step logs read from a run's ``logs/`` folder (or below it): ``follow-eval metrics``
    orders its tables so, as the run ordered its own (the files are found in alphabetical
    order). Logs of no run give ``([], [])``; logs of several runs their orders in turn.
    """
    policies: list[str] = []
    variants: list[str] = []
    for given in map(Path, paths):
        where = given.resolve()
        logs = next((f for f in (where, *where.parents) if f.name == "logs"), None)
        if logs is None:
            continue
        try:
            meta = json.loads((logs.parent / "meta.json").read_text(encoding="utf-8"))
        except (OSError, ValueError):
            continue  # not a run's logs: the order the logs are read in
        if not isinstance(meta, dict) or not isinstance(meta.get("policies"), dict):
            continue
        labels = [str(label) for label in meta["policies"]]
        # the run's grid, then with --ideal-baseline the same grid under perfect sensing
        ideal = [f"{p}{IDEAL_SUFFIX}" for p in labels] if meta.get("ideal_baseline") is True else []
        policies += labels + ideal
        for key in ("scenarios", "tracks"):
            if isinstance(meta.get(key), list):
                variants += [str(v) for v in meta[key]]
    return list(dict.fromkeys(policies)), list(dict.fromkeys(variants))


def _log_path(folder: Path, episode: Any) -> Path:
    """Where a run written to ``folder`` keeps ``episode``'s step log."""
    from eval.report import safe_name

    logs = folder / "logs" / safe_name(episode.policy) / safe_name(episode.scenario)
    return logs / f"seed_{episode.seed}.csv"


def _labelled(episode: Any, suffix: str) -> Any:
    """The episode (or its table row) under another policy label (its step log's ``policy``
    column too)."""
    from eval.stats import EpisodeRow

    label = episode.policy + suffix
    if isinstance(episode, EpisodeRow):
        return dataclasses.replace(episode, policy=label)
    return dataclasses.replace(episode, policy=label, log=episode.log.assign(policy=label))


def _journal_chunk(folder: Path) -> int | None:
    """The chunking an interrupted run started with (its journal's), so its units still match."""
    try:
        chunk = json.loads((folder / "run.json").read_text(encoding="utf-8")).get("chunk")
    except (OSError, ValueError, AttributeError):
        return None  # no journal, or one UnitJournal will refuse with a message
    return chunk if isinstance(chunk, int) and chunk >= 1 else None


def _where(backend: Backend) -> str:
    if backend.kind == "ray":
        return f"Ray, {backend.slots()} slots"
    n = backend.workers or 1
    return f"{n} process" + ("es" if n > 1 else "")


def _episode_label(policy: Any, platform: str | None) -> str:
    """The label a policy's episodes carry: its name, ``@platform`` when one is named."""
    return policy.name if platform is None else f"{policy.name}@{platform}"


def policy_label(name: str, option: str) -> str:
    """The label the episodes of policy spec ``name`` (``pn:tuned``, ``pn@mecanum``) carry.

    :raises UsageError: naming ``--option``, if no policy has that name.
    """
    from eval.grid import policy_spec
    from policies import make_policy

    try:
        spec, platform = policy_spec(name)
        return _episode_label(make_policy(spec), platform)
    except (ValueError, TypeError) as e:
        raise UsageError(f"--{option}: {e}") from None


def refuse_aliases(named: list[tuple[str, str]], option: str) -> None:
    """Refuse two names of one controller (``pn`` is ``pn:tuned``) in ``[(name, label), ...]``.

    Episodes are told apart by label: in a run the two would pool their episodes into one
    cell; in an aggregate they would be one controller's lines twice.

    :raises UsageError: naming ``--option`` and both names.
    """
    seen: dict[str, str] = {}
    for name, label in named:
        if label in seen:
            raise UsageError(
                f"--{option}: {seen[label]!r} and {name!r} are the same controller "
                f"({label}); give it once"
            )
        seen[label] = name

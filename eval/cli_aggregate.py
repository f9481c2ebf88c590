"""``follow-eval aggregate``: learners over their training seeds against the laws (see
:mod:`eval.cli` and :mod:`eval.aggregate`).

Every input is checked before any episode runs (:mod:`eval.aggregate_inputs`): the learners'
folders and seeds, clashes between their names, agents and the laws, the scenarios and the
grid's size, the output folder, and each agent's files and platform. The output folder appears
whole, with its ``meta.json`` (what ran, on which code), or not at all.
"""

from __future__ import annotations

import argparse
import contextlib
import sys
import time
from collections.abc import Sequence
from datetime import UTC, datetime
from pathlib import Path
from typing import TYPE_CHECKING

from eval.cli_base import PROG, UsageError, _names
from eval.cli_run import _check_grid, _versions, policy_label, refuse_aliases
from follow_env.sim.atomic import atomic_folder, check_new_folder

if TYPE_CHECKING:  # the module imports pandas: only when aggregate runs
    from eval.aggregate import LearnerRuns

__all__ = ["cmd_aggregate"]


def cmd_aggregate(args: argparse.Namespace) -> int:
    """``follow-eval aggregate``: see :mod:`eval.aggregate`."""
    from eval import aggregate as agg
    from eval.aggregate_inputs import PLATFORM, aggregate_record, check_agents
    from eval.provenance import code_revision

    started = time.perf_counter()
    learners = [agg.learner_runs(path) for path in args.runs]
    laws = _names(args.laws, "laws")
    named = [(law, policy_label(law, "laws")) for law in laws]
    refuse_aliases(named, "laws")
    # Each learner is named by its folder and its tables are keyed by that name, each agent
    # by its path: a clash would merge two controllers' lines after every episode had run.
    agg.check_learners(args.runs, learners, named, _law_aliases(learners, named))
    scenarios = _names(args.scenarios, "scenarios")
    _check_scenarios(scenarios)
    n_agents = sum(len(learner.agents) for learner in learners)
    _check_grid(n_agents + len(laws), len(scenarios), args.episodes, args.seed)
    out = args.out or Path("runs") / f"aggregate-{datetime.now(UTC):%Y%m%d-%H%M%S}"
    check_new_folder(out)
    # Loads every agent (the rollout reuses the loads): its files, task and platform checked,
    # and the digest of the files its episodes will be played by, read before any of them.
    digests = check_agents(learners)
    code = code_revision()  # the code the episodes run, read once before any of them
    seeds = range(args.seed, args.seed + args.episodes)
    tables = agg.aggregate(learners, laws, scenarios, seeds, reps=args.reps)
    meta = aggregate_record(
        learners,
        args.runs,
        digests,
        command=" ".join([PROG, *sys.argv[1:]]),
        finished_utc=datetime.now(UTC).isoformat(timespec="seconds"),
        elapsed_s=round(time.perf_counter() - started, 2),
        laws={law: label for law, label in named},  # as given -> the label the tables use
        scenarios=scenarios,
        seeds=list(seeds),
        platform=PLATFORM,
        bootstrap=agg.bootstrap_record(args.reps),
        versions=_versions(),
        code=code,  # eval.provenance: sources digest, git commit and whether edited
    )
    with atomic_folder(out) as tmp:
        report = agg.write(tables, tmp, meta)
    print(report)
    files = "aggregate.csv|md, improvement.csv, learners.csv, splits.csv, profiles.csv, "
    files += "scores.csv, "
    print(f"Wrote {out}/: {files}plots/, meta.json")
    return 0


def _law_aliases(learners: Sequence[LearnerRuns], named: list[tuple[str, str]]) -> list[str | None]:
    """Each learner's folder name read as a law's spelling, by the label its episodes would
    carry (``pn`` -> ``pn:tuned``), where it spells a law in ``--laws``; else None."""

    def base(name: str) -> str:  # "pn:tuned@mecanum" -> "pn"
        return name.partition("@")[0].partition(":")[0]

    bases = {base(law) for law, _ in named}
    aliases: list[str | None] = []
    for learner in learners:
        alias = None
        if base(learner.name) in bases:  # only then is a policy built
            with contextlib.suppress(UsageError):  # raised if it is not a law's spelling at all
                alias = policy_label(learner.name, "laws")
        aliases.append(alias)
    return aliases


def _check_scenarios(scenarios: list[str]) -> None:
    """Refuse a ``--scenarios`` name PersonFollow does not know, naming the option."""
    from follow_env.tasks import get_task

    known = get_task("person_follow").variants()
    for name in scenarios:
        if name not in known:
            raise UsageError(
                f"--scenarios: unknown scenario {name!r}; known scenarios: "
                + ", ".join(sorted(known))
            )

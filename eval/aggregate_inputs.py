"""What ``follow-eval aggregate`` compares, found and checked before any episode runs, and its
record of them (``meta.json``).

A learner is a folder: a ``follow-train --seeds`` study (one run folder ``seed-<k>/`` per
training seed ``k``) or a single run folder (one seed). A study records its seeds in
``study.json`` (:data:`STUDY`, written by ``follow-train --seeds``): its runs are those seeds,
and a listed seed whose ``model.zip`` is missing (its training was cut short or crashed) is
refused, not left out. Leaving it out would score the seeds that happened to finish, the
survivorship bias rliable's protocol exists to avoid. A study without ``study.json`` (made by
hand, or an export) is read from its ``seed-<k>`` folders, named as ``follow-train`` names
them (``seed-1.bak`` or ``seed-01`` is not a seed), each of which must hold its model.

``study.json`` is read here, in the evaluation layer, and by ``follow-train``
(:mod:`train.study_record` imports :func:`read_study`): the evaluation never imports training.
"""

from __future__ import annotations

import json
import re
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from policies.learned.ppo import MODEL  # a run folder holds it once its training finished

__all__ = [
    "PLATFORM",
    "STUDY",
    "LearnerRuns",
    "aggregate_record",
    "check_agents",
    "check_learners",
    "learner_runs",
    "read_study",
]

#: A study's record, written by ``follow-train --seeds`` (:mod:`train.study_record`).
STUDY = "study.json"
#: A training seed's run folder as ``follow-train --seeds`` names it (``seed-<k>``, ``k`` without
#: leading zeros, so that ``seed-01`` cannot stand for seed 1 a second time).
_SEED_FOLDER = re.compile(r"seed-(0|[1-9][0-9]*)")
#: The platform ``aggregate`` runs every controller on: the PersonFollow task's default
#: configuration's (it takes no ``--config`` or ``--platforms``).
PLATFORM = "diff_drive"


class LearnerRuns:
    """A learner's agents: its name, one agent path per run, and each run's training seed
    (``k`` of its ``seed-<k>`` folder; None for a single run folder, not a study's seed)."""

    def __init__(
        self, name: str, agents: Sequence[Path], seeds: Sequence[int | None] | None = None
    ) -> None:
        self.name = name
        self.agents = list(agents)
        self.seeds: list[int | None] = [None] * len(self.agents) if seeds is None else list(seeds)
        if len(self.seeds) != len(self.agents):
            raise ValueError(
                f"learner {name!r}: {len(self.seeds)} training seeds for {len(self.agents)} agents"
            )


def read_study(study: Path) -> dict[str, Any] | None:
    """The folder's ``study.json`` (None if it has none), checked.

    :raises ValueError: naming the file if it is unreadable or not a study description.
    """
    path = study / STUDY
    if not path.exists():
        return None
    try:
        had = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as e:
        raise ValueError(f"{path}: not a readable study description ({e})") from None
    seeds = had.get("seeds") if isinstance(had, dict) else None
    if not (isinstance(seeds, list) and all(type(s) is int and s >= 0 for s in seeds)):
        raise ValueError(
            f"{path}: not a study description (a JSON object with a list of seeds, as "
            "follow-train --seeds writes it)"
        )
    return had


def _seed_list(seeds: Sequence[int]) -> str:
    """Seeds as ``--seeds`` takes them: ``0,1,2``."""
    return ",".join(map(str, seeds))


def learner_runs(path: str | Path) -> LearnerRuns:
    """The learner at ``path`` (module docstring): a study's seeds, from its ``study.json`` if
    it has one, else from its ``seed-<k>`` folders; or one run folder.

    :raises ValueError: naming the path if it holds no agent, and naming the seed folders of a
        study that have no ``model.zip`` (with how to finish them).
    """
    path = Path(path)
    if not path.is_dir():
        raise ValueError(f"{path}: not a folder (a follow-train run or --seeds study)")
    study = read_study(path)
    if study is not None:
        seeds = sorted(set(study["seeds"]))
        if not seeds:
            raise ValueError(f"{path / STUDY}: lists no seeds (its seeds: [])")
        folders = [path / f"seed-{k}" for k in seeds]
        unfinished = [f.name for f in folders if not (f / MODEL).is_file()]
        if unfinished:
            raise ValueError(
                f"{path}: {', '.join(unfinished)} of the study's seeds ({STUDY}: "
                f"{_seed_list(seeds)}) {'has' if len(unfinished) == 1 else 'have'} no {MODEL} "
                "(training did not finish), and scoring only the seeds that finished would "
                f"bias the learner: run the same follow-train --seeds {_seed_list(seeds)} ... "
                f"--out {path} command again, which resumes them"
            )
        return LearnerRuns(path.name, folders, seeds)
    found = sorted(
        (int(match[1]), p)
        for p in path.iterdir()
        if (match := _SEED_FOLDER.fullmatch(p.name)) and p.is_dir()
    )
    if found:
        unfinished = [p.name for _, p in found if not (p / MODEL).is_file()]
        if unfinished:  # no record says which seeds the study has: its folders are the seeds
            raise ValueError(
                f"{path}: {', '.join(unfinished)} {'holds' if len(unfinished) == 1 else 'hold'} "
                f"no {MODEL} (training did not finish), and scoring only the seeds that "
                "finished would bias the learner: finish them (the follow-train command that "
                "trained them, run again, resumes them) or move them out of the study"
            )
        return LearnerRuns(path.name, [p for _, p in found], [k for k, _ in found])
    if (path / MODEL).is_file():
        return LearnerRuns(path.name, [path])
    raise ValueError(f"{path}: holds no trained agent (no {MODEL}, no seed-<k>/{MODEL})")


def _law_folder(law: str) -> Path | None:
    """The agent folder a law names (resolved; a ``model.zip`` stands for its folder), or None
    for a law that names no file (``pn``, ``ppo``)."""
    from eval.grid import policy_spec
    from policies import available_policies

    spec, _ = policy_spec(law)
    where = Path(str(spec))
    if spec in available_policies() or not where.exists():  # a registered name goes first
        return None
    where = where.resolve()
    return where.parent if where.name == MODEL else where


def check_learners(
    paths: Sequence[str | Path],
    learners: Sequence[LearnerRuns],
    laws: Sequence[tuple[str, str]],
    aliases: Sequence[str | None] | None = None,
) -> None:
    """Refuse learners whose lines would merge with another controller's: two learners of one
    name (a folder given twice, or two folders of one name), a learner named as a law (its
    name or its label: ``learners/pn`` against ``--laws pn``), one agent in two learners
    (a study and its own ``seed-0`` folder), which would count that agent for one of them only,
    or a learner's agent given as a law too (``--laws pn,study/seed-0``), whose episodes would
    be filed under the learner.

    :param paths: the learners' folders as given, in the order of ``learners``.
    :param laws: each law's name as given and the label its episodes carry.
    :param aliases: each learner's name read as a law's spelling, by its label (``pn`` ->
        ``pn:tuned``), or None: a learner ``pn`` beside ``--laws pn:tuned`` is that law too.
    :raises ValueError: one line, naming both sides of the clash.
    """
    seen: dict[str, Path] = {}
    aliases = [None] * len(learners) if aliases is None else aliases
    for path, learner, alias in zip(paths, learners, aliases, strict=True):
        if learner.name in seen:
            same = Path(path).resolve() == seen[learner.name].resolve()
            raise ValueError(
                f"{path}: names the learner {learner.name!r} twice; give each folder once"
                if same
                else f"{seen[learner.name]} and {path} are both named {learner.name!r} (a "
                "learner is named by its folder): rename one"
            )
        seen[learner.name] = Path(path)
        for law, label in laws:
            if learner.name in (law, label) or alias == label:
                raise ValueError(
                    f"{path}: the learner is named {learner.name!r} (by its folder), as the law "
                    f"{law!r} in --laws is: rename the folder or leave the law out"
                )
    owners: dict[Path, tuple[Path, Path]] = {}  # agent -> (its learner's folder, as given)
    for path, learner in zip(paths, learners, strict=True):
        for agent in learner.agents:
            where = Path(agent).resolve()
            if where in owners:
                first, given = owners[where]
                raise ValueError(
                    f"the agent {given} is in two learners, {first} and {path}: give each "
                    "agent in one learner only (a study, or one of its seed folders)"
                )
            owners[where] = (Path(path), Path(agent))
    for law, _ in laws:
        where = _law_folder(law)
        if where is not None and where in owners:
            learner, agent = owners[where]
            raise ValueError(
                f"--laws: {law!r} is the agent {agent} of the learner {learner}, one of its "
                "runs, not a law: leave it out of --laws"
            )


def check_agents(learners: Sequence[LearnerRuns]) -> dict[str, str]:
    """Build every learner's agent as the episodes will (a cached load: the rollout's costs
    nothing more), refusing what ``aggregate`` cannot run, and read its files' digest.

    :returns: each agent's absolute path -> :func:`eval.provenance.model_sha256` of its files.
    :raises ValueError: naming the agent, for files that do not load, an agent of another task,
        or one trained on another platform than :data:`PLATFORM` (saying what compares it).
    """
    from eval.grid import checked_policy
    from eval.provenance import model_sha256
    from follow_env.platforms import get_platform
    from policies.adapt import action_names

    acts = tuple(a.name for a in get_platform(PLATFORM).actions)
    digests: dict[str, str] = {}
    for learner in learners:
        for agent in learner.agents:
            policy, _ = checked_policy(str(agent), "person_follow")
            trained_on = getattr(policy, "platform", None)
            if trained_on is not None and action_names(policy) != acts:
                # aggregate takes no platform, and a law's episodes on another platform would
                # not be the agent's scenarios: `follow-eval run` compares it on its own
                raise ValueError(
                    f"{agent}: the agent was trained on the {trained_on} platform, and "
                    "follow-eval aggregate runs PersonFollow on the diff-drive platform "
                    f"({PLATFORM}) only: compare it on its own with follow-eval run --policies "
                    f"{agent}@{trained_on},pn@{trained_on},..."
                )
            digest = model_sha256(policy)
            if digest is not None:  # always, for an agent's folder
                digests[_absolute(agent)] = digest
    return digests


def _absolute(path: str | Path) -> str:
    """A path as the outputs name it: absolute, symlinks as given (as ``follow-eval run``)."""
    return str(Path(path).absolute())


def aggregate_record(
    learners: Sequence[LearnerRuns],
    paths: Sequence[str | Path],
    digests: Mapping[str, str],
    **run: Any,
) -> dict[str, Any]:
    """``meta.json``'s ``learners`` entry and the run's other keys (``run``, in order).

    :param paths: the learners' folders as given, in the order of ``learners``.
    :param digests: :func:`check_agents`' digests.
    :returns: ``{"learners": {name: {"path", "study_json", "agents": [{"path",
        "training_seed", "model_sha256"}]}}, **run}``.
    """
    learned = {
        learner.name: {
            "path": _absolute(path),
            "study_json": (Path(path) / STUDY).is_file(),  # its runs are the seeds it lists
            "agents": [
                {
                    "path": _absolute(agent),
                    "training_seed": seed,
                    "model_sha256": digests.get(_absolute(agent)),
                }
                for agent, seed in zip(learner.agents, learner.seeds, strict=True)
            ],
        }
        for learner, path in zip(learners, paths, strict=True)
    }
    return {"learners": learned, **run}

"""Several trained agents acting as one: the mean of their actions (a seed ensemble).

A study (``follow-train --seeds 0-4 --out runs/ppo-study``) trains one agent per seed; their
spread is wide (``README``: 47 to 58 of 72 dominance requirements for the same file). Acting
with the mean of every seed's action is one agent that no one picked: ``make_policy(
"runs/ppo-study")`` builds it from the study's ``ensemble.yaml``, which lists the members' run
folders relative to itself (the study writes it; any folder with such a file is an ensemble)::

    # runs/ppo-study/ensemble.yaml
    members: [seed-0, seed-1, seed-2, seed-3, seed-4]

Each member is a lone agent, listed once: the ensemble's own folder, another ensemble, or one
agent under two spellings (``seed-0`` and ``./seed-0``, told apart by the model file they load)
is refused.

The members must see the env alike: the same observation and action boxes, platform and
feature steps (``vec_env_wrapper`` without the training-only reward shaping, which may differ,
and ``frame_stack``), so one feature pipeline serves all of them and the command in force (the
incremental action's memory) is the ensemble's, not any member's. Each member then applies its
own observation normalisation (its saved statistics) and frame stack, its network gives its
deterministic action in agent units (within the action box, as a lone agent's), and the
ensemble's action is their mean, mapped back to SI by the shared pipeline. The mean of
mirror-symmetric members is mirror-symmetric.

Batched acting gives each lane the action it gets alone, as :class:`~.ppo.PPOPolicy` does (each
member's network runs one lane at a time).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import yaml

from follow_env.sim.checks import load_yaml, utf8_problem, yaml_problem
from policies.base import lane_flags
from policies.learned.features import Pipeline
from policies.learned.networks import Memory
from policies.learned.ppo import (
    AGENTS,
    AgentLoadError,
    PPOPolicy,
    _Loaded,
    agent_files,
    load_shipped,
)

__all__ = ["ENSEMBLE", "EnsemblePolicy", "is_learned", "member_folders", "resolve_path", "shipped"]

#: The file that makes a folder an ensemble.
ENSEMBLE = "ensemble.yaml"
#: An ensemble's memory for some lanes: the shared pipeline, each member's own steps (its
#: normalisation and frame stack) and each member's network memory (a recurrent one's state).
_Views = tuple[Pipeline, list[Pipeline], list[Memory | None]]


def member_folders(path: Path) -> list[Path]:
    """The member folders listed in ``path`` (an ``ensemble.yaml``), checked: each a lone agent
    (not the ensemble's own folder, nor another ensemble), none the same agent as another under
    another spelling (``seed-0``, ``./seed-0``, ``seed-0/model.zip``)."""
    try:
        data = load_yaml(path.read_text(encoding="utf-8"))
    except OSError as e:
        raise AgentLoadError(f"{path}: not a readable ensemble file: {e}") from None
    except UnicodeDecodeError as e:
        raise AgentLoadError(f"{path}: {utf8_problem(e)}") from None
    except yaml.YAMLError as e:
        raise AgentLoadError(f"{path}: not valid YAML: {yaml_problem(e)}") from None
    members = data.get("members") if isinstance(data, dict) else None
    if not isinstance(members, list) or len(members) < 2:
        raise AgentLoadError(
            f"{path}: 'members' must list at least two run folders, got {members!r}"
        )
    if not all(isinstance(m, str) and m for m in members):
        raise AgentLoadError(f"{path}: every member must be a run folder's path, got {members!r}")
    folders = [path.parent / m for m in members]
    home = path.parent.resolve()
    seen: dict[Path, str] = {}
    for member, folder in zip(members, folders, strict=True):
        if folder.resolve() == home:
            raise AgentLoadError(
                f"{path}: member {member!r} is the ensemble's own folder; list its run folders"
            )
        if (folder / ENSEMBLE).exists() or folder.name == ENSEMBLE:
            raise AgentLoadError(
                f"{path}: member {member!r} is itself an ensemble ({ENSEMBLE}); list its run "
                "folders instead"
            )
        model = _model_of(folder)
        if model in seen:
            raise AgentLoadError(
                f"{path}: a member is listed twice: {seen[model]!r} and {member!r} are the "
                f"same agent ({model})"
            )
        seen[model] = member
    return folders


def _model_of(folder: Path) -> Path:
    """The model file a member loads, resolved: what makes two spellings one member. A member
    whose files cannot be found is left to its loading, which names the missing file."""
    try:
        return agent_files(folder).model.resolve()
    except AgentLoadError:
        return folder.resolve()


class EnsemblePolicy:
    """The mean action of several agents as one :class:`~policies.base.Policy`.

    :param path: a folder holding ``ensemble.yaml``, or that file.
    :param name: the name in tables and logs (default: ``path`` as given).
    :raises AgentLoadError: for a missing or malformed ensemble file, a member that cannot be
        loaded (naming its file), or members that do not see the env alike.
    """

    def __init__(self, path: str | Path, name: str | None = None) -> None:
        self.path = str(path)
        self._absolute = str(Path(path).absolute())  # not resolve(): symlinks as given
        self.name = name if name is not None else self.path.rstrip("/")
        where = Path(path)
        where = where / ENSEMBLE if where.is_dir() else where
        if not where.exists():
            raise AgentLoadError(f"{where}: ensemble file not found")
        self._folders = member_folders(where)
        # Each member is checked as a lone agent is (its files, shapes and statistics).
        self._policies = [PPOPolicy(folder) for folder in self._folders]
        self._agents: list[_Loaded] = [policy._agent for policy in self._policies]
        lead, view = self._policies[0], Pipeline.view_entries
        first = lead._agent
        for folder, policy in zip(self._folders[1:], self._policies[1:], strict=True):
            agent = policy._agent
            for what, mine, theirs in (
                ("platform", agent.platform, first.platform),
                ("reading ahead", policy.reads_ahead, lead.reads_ahead),
                ("action", repr(agent.action_box), repr(first.action_box)),
                ("observation", repr(agent.observation_box), repr(first.observation_box)),
                ("feature steps", view(agent.wrappers), view(first.wrappers)),
                ("frame_stack", agent.frame_stack, first.frame_stack),
            ):
                if mine != theirs:
                    raise AgentLoadError(
                        f"{where}: member {folder} does not see the env as {self._folders[0]} "
                        f"does ({what}: {mine!r} against {theirs!r})"
                    )
        self.platform: str = first.platform
        self.action_names: tuple[str, ...] = first.action_names
        #: The reading ahead the members read (they read the same), and what an env needs for
        #: it: evaluation applies it, a robot's perception must publish it (as for one agent).
        self.reads_ahead: dict[str, Any] | None = lead.reads_ahead
        self.env_overrides: dict[str, Any] = lead.env_overrides
        self._rows = lead._rows
        self._single: _Views | None = None
        self._batch: _Views | None = None
        self._batch_n: int | None = None

    @property
    def members(self) -> tuple[str, ...]:
        """The members' run folders."""
        return tuple(str(f) for f in self._folders)

    def _views(self, n: int) -> _Views:
        """A fresh memory (:data:`_Views`) for ``n`` lanes."""
        first = self._agents[0]
        shared = Pipeline(
            Pipeline.from_wrappers(first.wrappers), first.observation_box, first.action_box, n
        )
        tails = [
            Pipeline(agent.own_steps(), shared.observation_box, shared.action_box, n)
            for agent in self._agents
        ]
        return shared, tails, [agent.model.memory(n) for agent in self._agents]

    def _act(
        self, views: _Views, obs: np.ndarray, start: bool, done: np.ndarray | None = None
    ) -> np.ndarray:
        """The ensemble's SI actions for ``obs`` (``start``: the lanes' first step; ``done``:
        the lanes whose episodes start again now, :meth:`reset_lanes`)."""
        shared, tails, memories = views
        seen = shared.start(obs) if start else shared.observe(obs, done)
        total = sum(
            agent.model.act(tail.start(seen) if start else tail.observe(seen, done), memory)
            for agent, tail, memory in zip(self._agents, tails, memories, strict=True)
        )
        return shared.act(total / len(self._agents)).astype(np.float32)

    def reset(self) -> None:
        """Start a new episode (every member's memory and the shared pipeline afresh)."""
        self._single = None

    def act(self, obs: np.ndarray) -> np.ndarray:
        """The mean of the members' actions for one observation, in SI (the platform's
        :attr:`action_names`).

        :raises ValueError: if ``obs`` is not a finite array of real numbers
            (:func:`policies.base.real_obs`) of the agents' observation shape.
        """
        row = self._rows(obs, batch=False)
        start = self._single is None
        if start:
            self._single = self._views(1)
        return self._act(self._single, row, start)[0]

    def reset_batch(self, n: int) -> None:
        """Start ``n`` lanes' episodes."""
        self._batch = None
        self._batch_n = n
        self._restart = np.zeros(n, dtype=bool)

    def reset_lanes(self, lanes: np.ndarray) -> None:
        """Start new episodes in the lanes flagged in ``lanes`` (bool, one per lane), every
        member's memory of them too; the others' kept (:meth:`PPOPolicy.reset_lanes`)."""
        self._restart = lane_flags(lanes, self._batch_n, getattr(self, "_restart", None))
        if self._batch is not None:
            for memory in self._batch[2]:
                if memory is not None:
                    memory.restart(self._restart)

    def act_batch(self, obs: np.ndarray) -> np.ndarray:
        """Actions ``(n, m)`` for observations ``(n, k)``, each lane as :meth:`act` gives it."""
        rows = self._rows(obs, batch=True)
        if self._batch_n != len(rows):
            raise ValueError(
                f"act_batch got {len(rows)} observations: call reset_batch({len(rows)}) first"
            )
        start = self._batch is None
        if start:
            self._batch = self._views(len(rows))
        actions = self._act(self._batch, rows, start, self._restart)
        self._restart = np.zeros(len(rows), dtype=bool)
        return actions

    def __reduce__(self) -> tuple[Any, ...]:
        # Rebuilt from its files in a worker process, as a lone agent is: by the absolute path
        # taken when built (a worker's current folder need not be this one's).
        return (EnsemblePolicy, (self._absolute, self.name))

    def __repr__(self) -> str:
        return f"EnsemblePolicy(name={self.name!r}, members={len(self._folders)})"


def resolve_path(name: str) -> EnsemblePolicy | None:
    """Registry resolver: a folder holding ``ensemble.yaml`` (or the file itself) -> ensemble;
    anything else is left to the other resolvers (None)."""
    path = Path(name)
    if path.name == ENSEMBLE or (path.is_dir() and (path / ENSEMBLE).exists()):
        return EnsemblePolicy(path, name)
    return None


def shipped(folder: str, name: str | None = None) -> EnsemblePolicy | PPOPolicy:
    """The shipped agent ``policies/agents/<folder>`` named ``name`` (default: ``folder``): the
    mean of its members when the folder holds an ``ensemble.yaml`` (``ppo_ensemble``), else one
    agent (:func:`policies.learned.ppo.load_shipped`)."""
    if (AGENTS / folder / ENSEMBLE).is_file():
        return EnsemblePolicy(AGENTS / folder, name or folder)
    return load_shipped(folder, name)


def is_learned(policy: object) -> bool:
    """Whether ``policy`` is a learned agent (one, or an ensemble of them): its episodes cost a
    network's work a step, which is what a pool of workers shares
    (:func:`eval.rollout.auto_workers`)."""
    return isinstance(policy, PPOPolicy | EnsemblePolicy)

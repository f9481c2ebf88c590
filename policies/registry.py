"""Policies by name, so that every tool (rollout, eval, train) takes a name.

## Names
``<law>[:<preset>]``:

- law: ``pn``, ``mpn``, ``gsmpn``, ``gsmpn-listing``, ``gsmpn-equation``. A GS-MPN variant is a
  different equation, so it is part of the law's name (:mod:`policies.gsmpn` describes them).
  ``holonomic`` (:mod:`policies.holonomic`) also strafes, for a platform that can.
- line tracing (``LineTrace-v0``): ``coordinate`` (the mecanum paper's coordinate control,
  presets ``signed``, ``literal`` and ``tuned``; :mod:`policies.coordinate`) and ``pid`` (the
  three-sensor PID line follower, presets ``hand`` and ``tuned``; :mod:`policies.pid_line`);
  a bare name means ``tuned``, as for the guidance laws.
- preset: ``thesis`` (the thesis's values in SI) or ``tuned``. A bare law name means ``tuned``
  (``holonomic`` has one preset, ``default``, which a bare name means).

So ``"gsmpn"`` is ``"gsmpn:tuned"``, and ``"gsmpn-listing:thesis"`` is the thesis's code listing
with the thesis's values. A built policy's ``name`` is always the full ``<law>:<preset>``.
Each :func:`make_policy` call builds a fresh policy, so laws never share memory.

Learned agents: ``ppo`` is each task's shipped PPO agent (PersonFollow's
``policies/agents/ppo``; with ``task="line_trace"``, ``policies/agents/ppo_line``),
``ppo_mecanum`` PersonFollow's on the mecanum base (``policies/agents/ppo_mecanum``),
``ppo_ahead`` PersonFollow's that also reads the reading ahead (``policies/agents/ppo_ahead``;
its observation has ``ahead_m``, ``PerceptionConfig.ahead_rays``; its view gates the detection's
jumps), ``ppo_law`` PersonFollow's that reads ahead and starts from ``pn:thesis``'s command
(``policies/agents/ppo_law``; its view holds the law's command, :mod:`policies.learned.hint`),
``ppo_ensemble`` the mean of two such agents' actions (``policies/agents/ppo_ensemble``, whose
``ensemble.yaml`` lists them: :mod:`policies.learned.ensemble`), and a path
(a run folder of ``follow-train``, its ``model.zip``, or a checkpoint ``.zip``) loads that
agent under the path as its name (:mod:`policies.learned.ppo`).

## Extending
- A new law: one module with a :class:`~policies.base.GuidanceLaw` subclass and its ``PRESETS``,
  plus one ``register_law(...)`` line at the bottom of this file. Give it a ``SEARCH_SPACE``
  (:mod:`policies.space`) and pass ``search_space=`` there, and ``follow-tune <law>`` tunes it.
- A learned agent: ``register_policy("ppo", factory)``, where the factory imports
  torch/stable-baselines3 and loads the model only when called (:mod:`policies.learned.ppo`).
- A filesystem path (``runs/x/model.zip`` or a run folder): ``register_resolver(resolver)``;
  :func:`policies.learned.ppo.resolve_path` is registered and loads PPO agents;
  :func:`policies.learned.ensemble.resolve_path`, before it, loads a folder with an
  ``ensemble.yaml`` as the mean of its members.
  Names not registered exactly are offered to each resolver in turn; a resolver returns a policy
  for names it understands and None for the rest.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, replace
from functools import partial
from typing import Any, Generic, TypeVar

from policies import coordinate, gsmpn, holonomic, mpn, pid_line, pn
from policies.base import Policy
from policies.learned import ensemble, hint, ppo
from policies.space import SearchSpace, check_space

PolicyFactory = Callable[[], Policy]
PolicyResolver = Callable[[str], Policy | None]
P = TypeVar("P")

DEFAULT_PRESET = "tuned"
DEFAULT_TASK = "person_follow"


@dataclass(frozen=True)
class TunableLaw(Generic[P]):
    """A registered law with a search space: what a tuner needs to build its candidates.

    :param law: the law's name (``"pn"``).
    :param build: ``build(params, name)`` makes a policy.
    :param base: the parameters of the default preset; fields outside the space keep these.
    :param space: field -> range (:mod:`policies.space`).
    :param task: the task whose observation the law reads.
    :param default_preset: the preset the tuner's result would replace (``"tuned"``).
    """

    law: str
    build: Callable[[P, str], Policy]
    base: P
    space: SearchSpace
    task: str
    default_preset: str

    def params(self, values: Mapping[str, Any]) -> P:
        """The base parameters with ``values`` (field -> value) put in (validated by them)."""
        return replace(self.base, **dict(values))  # type: ignore[type-var]

    def policy(self, values: Mapping[str, Any], name: str) -> Policy:
        """A policy with the base parameters and ``values`` put in, called ``name``."""
        return self.build(self.params(values), name)


class PolicyRegistry:
    """A mapping from names to policy factories, plus resolvers for open-ended names."""

    def __init__(self) -> None:
        # name -> task -> factory: a name may mean one policy per task (``ppo`` is each task's
        # shipped agent); a law's name is one task's only.
        self._factories: dict[str, dict[str, PolicyFactory]] = {}
        self._resolvers: list[PolicyResolver] = []
        self._tunable: dict[str, TunableLaw[Any]] = {}

    def register(self, name: str, factory: PolicyFactory, task: str = DEFAULT_TASK) -> None:
        """Make ``name`` build a policy with ``factory()``, for ``task`` (whose observation
        it reads: ``"person_follow"`` unless told).

        :raises ValueError: if the name is empty, contains whitespace or ``@`` (which names
            a platform: ``pn@mecanum``), is already taken for ``task`` (re-registering would
            silently change what a name means in earlier results), or ``task`` is not a task.
        :raises TypeError: if the name is not text or the factory cannot be called.
        """
        if not isinstance(name, str):
            raise TypeError(f"a policy name is text, such as 'my_law'; got {name!r}")
        if not name or name != "".join(name.split()) or "@" in name:
            raise ValueError(
                f"policy name {name!r} must be non-empty, without whitespace and without '@' "
                "(NAME@PLATFORM runs NAME on that platform)"
            )
        if not callable(factory):
            raise TypeError(f"the factory for {name!r} must be callable, got {factory!r}")
        self._check_task(task)
        if task in self._factories.get(name, {}):
            raise ValueError(f"policy name {name!r} is already registered for {task}")
        self._factories.setdefault(name, {})[task] = factory

    def register_law(
        self,
        law: str,
        build: Callable[[P, str], Policy],
        presets: Mapping[str, P],
        default_preset: str = DEFAULT_PRESET,
        task: str = DEFAULT_TASK,
        search_space: SearchSpace | None = None,
    ) -> None:
        """Register ``law:<preset>`` for every preset, and ``law`` for the default preset.

        :param law: the law's name, e.g. ``"pn"``.
        :param build: called as ``build(params, name)``; a law class fits.
        :param presets: preset name -> parameters.
        :param default_preset: the preset a bare ``law`` name stands for.
        :param task: the task whose observation the law reads.
        :param search_space: the ranges a tuner may search (:mod:`policies.space`), around
            the default preset; a law without one cannot be tuned by ``follow-tune``.
        :raises ValueError: for a missing default preset, or a space that does not fit the
            parameters (a field they lack, a range whose ends they refuse).
        """
        if default_preset not in presets:
            raise ValueError(
                f"law {law!r} has no preset {default_preset!r}; presets: {sorted(presets)}"
            )
        if search_space is not None:
            check_space(search_space, presets[default_preset])
        for preset, params in presets.items():
            self.register(f"{law}:{preset}", partial(build, params, f"{law}:{preset}"), task)
        default_name = f"{law}:{default_preset}"
        self.register(law, partial(build, presets[default_preset], default_name), task)
        if search_space is not None:
            base = presets[default_preset]
            self._tunable[law] = TunableLaw(law, build, base, search_space, task, default_preset)

    def tunable(self, law: str) -> TunableLaw[Any]:
        """The law called ``law`` with its search space.

        :raises ValueError: for an unknown law, or one registered without a search space
            (the message lists the tunable ones).
        """
        found = self._tunable.get(law)
        if found is None:
            known = ", ".join(sorted(self._tunable))
            why = "has no search space" if law in self._factories else "is not a registered law"
            raise ValueError(f"{law!r} {why}; laws that can be tuned: {known}")
        return found

    def tunable_laws(self, task: str | None = None) -> list[str]:
        """The laws registered with a search space, sorted; with ``task``, those for it."""
        return sorted(n for n, t in self._tunable.items() if task is None or t.task == task)

    def register_resolver(self, resolver: PolicyResolver) -> None:
        """Offer names that are not registered exactly (e.g. model paths) to ``resolver``."""
        self._resolvers.append(resolver)

    def make(self, name: str, task: str | None = None) -> Policy:
        """Build a fresh policy by name: ``task``'s when the name is registered for several
        tasks (``ppo``), else PersonFollow's; a name of one task only is that task's.

        :raises ValueError: for an unknown or empty name (the message lists the known names),
            or a task no policy is registered for.
        :raises TypeError: if ``name`` is not text.
        """
        if not isinstance(name, str):
            raise TypeError(f"a policy name is text, such as 'pn:thesis'; got {name!r}")
        if not name.strip():  # else a path resolver would look for a model in the current folder
            raise ValueError(f"the policy name is empty; known names: {', '.join(self.names())}")
        if task is not None and task not in self.tasks():
            raise ValueError(f"task={task!r} is out of range: must be one of {self.tasks()}")
        by_task = self._factories.get(name, {})
        factory = by_task.get(task or DEFAULT_TASK) or (
            next(iter(by_task.values())) if len(by_task) == 1 else None
        )
        if factory is not None:
            policy = factory()
        else:
            policy = next((p for r in self._resolvers if (p := r(name)) is not None), None)
            if policy is None:
                hint = ", or a name a registered resolver accepts" if self._resolvers else ""
                raise ValueError(
                    f"unknown policy {name!r}; known names: {', '.join(self.names())}{hint}"
                )
        if not isinstance(policy, Policy):
            raise TypeError(f"the factory for {name!r} returned {policy!r}, which is no Policy")
        return policy

    def names(self, task: str | None = None) -> list[str]:
        """All exactly registered names, sorted (names only resolvers accept are not listed);
        with ``task``, only those for that task.

        :raises ValueError: if ``task`` is not a task.
        """
        if task is not None:
            self._check_task(task)
        return sorted(n for n, tasks in self._factories.items() if task is None or task in tasks)

    def tasks(self) -> list[str]:
        """The tasks policies are registered for (PersonFollow's always), sorted."""
        return sorted({DEFAULT_TASK, *(t for by in self._factories.values() for t in by)})

    def _check_task(self, task: str) -> None:
        """Refuse a ``task`` that is not a task package's name (``person_follow``,
        ``line_trace``): one with a spec, ``follow_env.tasks.<task>.spec``, which is all a
        policy reads of a task.

        :raises ValueError: naming the value and the tasks policies are registered for.
        """
        import importlib.util

        try:
            found = importlib.util.find_spec(f"follow_env.tasks.{task}.spec") is not None
        except (ImportError, ValueError):  # "a.b" past the package, or an empty name
            found = False
        if not isinstance(task, str) or not task.isidentifier() or not found:
            raise ValueError(f"task={task!r} is out of range: must be one of {self.tasks()}")

    def task_of(self, name: str) -> str:
        """The task a registered name's policy is for: PersonFollow's for a name several tasks
        have, and for a resolved name (a model path)."""
        tasks = self._factories.get(name, {})
        return next(iter(tasks)) if len(tasks) == 1 else DEFAULT_TASK


REGISTRY = PolicyRegistry()


def make_policy(name: str, task: str | None = None) -> Policy:
    """Build a fresh policy by name (module docstring lists the scheme), e.g. ``"pn:thesis"``;
    ``task`` picks among the policies of a name several tasks have (``ppo``: each task's
    shipped agent; default PersonFollow's).

    :raises ValueError: for an unknown name; the message lists the known names.
    """
    return REGISTRY.make(name, task)


def available_policies(task: str | None = None) -> list[str]:
    """All registered policy names, sorted; with ``task`` (``"line_trace"``), those for it."""
    return REGISTRY.names(task)


def policy_task(name: str) -> str:
    """The task whose observation the policy called ``name`` reads."""
    return REGISTRY.task_of(name)


def register_policy(name: str, factory: PolicyFactory, task: str = DEFAULT_TASK) -> None:
    """Make ``name`` build a policy with ``factory()`` for ``task``; see
    :meth:`PolicyRegistry.register`."""
    REGISTRY.register(name, factory, task)


def register_law(
    law: str,
    build: Callable[[P, str], Policy],
    presets: Mapping[str, P],
    default_preset: str = DEFAULT_PRESET,
    task: str = "person_follow",
    search_space: SearchSpace | None = None,
) -> None:
    """Register ``law`` and ``law:<preset>``; see :meth:`PolicyRegistry.register_law`."""
    REGISTRY.register_law(law, build, presets, default_preset, task, search_space)


def tunable_law(law: str) -> TunableLaw[Any]:
    """The registered law ``law`` with its search space; see :meth:`PolicyRegistry.tunable`."""
    return REGISTRY.tunable(law)


def tunable_laws(task: str | None = None) -> list[str]:
    """The laws ``follow-tune`` can tune; see :meth:`PolicyRegistry.tunable_laws`."""
    return REGISTRY.tunable_laws(task)


def register_resolver(resolver: PolicyResolver) -> None:
    """Hook for open-ended names (model paths); see :meth:`PolicyRegistry.register_resolver`."""
    REGISTRY.register_resolver(resolver)


# The built-in laws: one line per law.
register_law("pn", pn.PN, pn.PRESETS, search_space=pn.SEARCH_SPACE)
register_law("mpn", mpn.MPN, mpn.PRESETS, search_space=mpn.SEARCH_SPACE)
for _variant in gsmpn.GSMPN_VARIANTS:
    # The space is in the default variant's units; the other readings are not tuned.
    register_law(
        "gsmpn" if _variant == "default" else f"gsmpn-{_variant}",
        gsmpn.GSMPN,
        {preset: replace(p, variant=_variant) for preset, p in gsmpn.PRESETS.items()},
        search_space=gsmpn.SEARCH_SPACE if _variant == "default" else None,
    )
# A base that strafes (the mecanum platform); no tuned preset yet.
register_law("holonomic", holonomic.Holonomic, holonomic.PRESETS, default_preset="default")
# Line tracing (LineTrace-v0, reference §2): the paper's coordinate control and the PID line
# follower it is compared with.
register_law(
    "coordinate",
    coordinate.Coordinate,
    coordinate.PRESETS,
    task="line_trace",
    search_space=coordinate.SEARCH_SPACE,
)
register_law(
    "pid", pid_line.PIDLine, pid_line.PRESETS, task="line_trace", search_space=pid_line.SEARCH_SPACE
)
# Learned agents: the shipped ones by name (policies.learned.ppo.SHIPPED says which folder is
# which; a folder with an ensemble.yaml is the mean of its members), any other by its path (a
# run folder or a .zip). policies.learned.ppo loads torch and stable-baselines3 only when an
# agent is built.
for _folder, (_name, _task) in ppo.SHIPPED.items():
    register_policy(_name, partial(ensemble.shipped, _folder, name=_name), task=_task)
# A folder with an ensemble.yaml (a seed study's) is the mean of its members' actions.
register_resolver(ensemble.resolve_path)
register_resolver(ppo.resolve_path)


# A learned agent's view may hold a law's command (policies.learned.hint), built by name here.
def _guidance_laws() -> list[str]:
    """PersonFollow's registered policies that are guidance laws: every one but the learned
    agents (a learned policy registered by a user under another name is refused when built,
    as no :class:`~policies.base.LaneActing`)."""
    learned = {name for name, _ in ppo.SHIPPED.values()}
    return [n for n in REGISTRY.names("person_follow") if n not in learned]


hint.use_laws(make_policy, _guidance_laws)

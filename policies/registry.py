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

Learned agents: ``ppo`` is the shipped PPO agent (``policies/agents/ppo``), and a path (a run
folder of ``follow-train``, its ``model.zip``, or a checkpoint ``.zip``) loads that agent under
the path as its name (:mod:`policies.learned.ppo`).

## Extending
- A new law: one module with a :class:`~policies.base.GuidanceLaw` subclass and its ``PRESETS``,
  plus one ``register_law(...)`` line at the bottom of this file.
- A learned agent: ``register_policy("ppo", factory)``, where the factory imports
  torch/stable-baselines3 and loads the model only when called (:mod:`policies.learned.ppo`).
- A filesystem path (``runs/x/model.zip`` or a run folder): ``register_resolver(resolver)``;
  :func:`policies.learned.ppo.resolve_path` is registered and loads PPO agents.
  Names not registered exactly are offered to each resolver in turn; a resolver returns a policy
  for names it understands and None for the rest.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import replace
from functools import partial
from typing import TypeVar

from policies import coordinate, gsmpn, holonomic, mpn, pid_line, pn
from policies.base import Policy
from policies.learned import ppo

PolicyFactory = Callable[[], Policy]
PolicyResolver = Callable[[str], Policy | None]
P = TypeVar("P")

DEFAULT_PRESET = "tuned"
DEFAULT_TASK = "person_follow"


class PolicyRegistry:
    """A mapping from names to policy factories, plus resolvers for open-ended names."""

    def __init__(self) -> None:
        self._factories: dict[str, PolicyFactory] = {}
        self._tasks: dict[str, str] = {}
        self._resolvers: list[PolicyResolver] = []

    def register(self, name: str, factory: PolicyFactory, task: str = DEFAULT_TASK) -> None:
        """Make ``name`` build a policy with ``factory()``, for ``task`` (whose observation
        it reads: ``"person_follow"`` unless told).

        :raises ValueError: if the name is empty, contains whitespace or is already taken
            (re-registering would silently change what a name means in earlier results).
        """
        if not name or name != "".join(name.split()):
            raise ValueError(f"policy name {name!r} must be non-empty and without whitespace")
        if name in self._factories:
            raise ValueError(f"policy name {name!r} is already registered")
        self._factories[name] = factory
        self._tasks[name] = task

    def register_law(
        self,
        law: str,
        build: Callable[[P, str], Policy],
        presets: Mapping[str, P],
        default_preset: str = DEFAULT_PRESET,
        task: str = DEFAULT_TASK,
    ) -> None:
        """Register ``law:<preset>`` for every preset, and ``law`` for the default preset.

        :param law: the law's name, e.g. ``"pn"``.
        :param build: called as ``build(params, name)``; a law class fits.
        :param presets: preset name -> parameters.
        :param default_preset: the preset a bare ``law`` name stands for.
        :param task: the task whose observation the law reads.
        """
        if default_preset not in presets:
            raise ValueError(
                f"law {law!r} has no preset {default_preset!r}; presets: {sorted(presets)}"
            )
        for preset, params in presets.items():
            self.register(f"{law}:{preset}", partial(build, params, f"{law}:{preset}"), task)
        default_name = f"{law}:{default_preset}"
        self.register(law, partial(build, presets[default_preset], default_name), task)

    def register_resolver(self, resolver: PolicyResolver) -> None:
        """Offer names that are not registered exactly (e.g. model paths) to ``resolver``."""
        self._resolvers.append(resolver)

    def make(self, name: str) -> Policy:
        """Build a fresh policy by name.

        :raises ValueError: for an unknown name; the message lists the known names.
        """
        factory = self._factories.get(name)
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
        with ``task``, only those for that task."""
        return sorted(n for n in self._factories if task is None or self._tasks[n] == task)

    def task_of(self, name: str) -> str:
        """The task a registered name's policy is for (a resolved name, a model path, is
        PersonFollow's)."""
        return self._tasks.get(name, DEFAULT_TASK)


REGISTRY = PolicyRegistry()


def make_policy(name: str) -> Policy:
    """Build a fresh policy by name (module docstring lists the scheme), e.g. ``"pn:thesis"``.

    :raises ValueError: for an unknown name; the message lists the known names.
    """
    return REGISTRY.make(name)


def available_policies(task: str | None = None) -> list[str]:
    """All registered policy names, sorted; with ``task`` (``"line_trace"``), those for it."""
    return REGISTRY.names(task)


def policy_task(name: str) -> str:
    """The task whose observation the policy called ``name`` reads."""
    return REGISTRY.task_of(name)


def register_policy(name: str, factory: PolicyFactory) -> None:
    """Make ``name`` build a policy with ``factory()``; see :meth:`PolicyRegistry.register`."""
    REGISTRY.register(name, factory)


def register_law(
    law: str,
    build: Callable[[P, str], Policy],
    presets: Mapping[str, P],
    default_preset: str = DEFAULT_PRESET,
    task: str = "person_follow",
) -> None:
    """Register ``law`` and ``law:<preset>``; see :meth:`PolicyRegistry.register_law`."""
    REGISTRY.register_law(law, build, presets, default_preset, task)


def register_resolver(resolver: PolicyResolver) -> None:
    """Hook for open-ended names (model paths); see :meth:`PolicyRegistry.register_resolver`."""
    REGISTRY.register_resolver(resolver)


# The built-in laws: one line per law.
register_law("pn", pn.PN, pn.PRESETS)
register_law("mpn", mpn.MPN, mpn.PRESETS)
for _variant in gsmpn.GSMPN_VARIANTS:
    register_law(
        "gsmpn" if _variant == "default" else f"gsmpn-{_variant}",
        gsmpn.GSMPN,
        {preset: replace(p, variant=_variant) for preset, p in gsmpn.PRESETS.items()},
    )
# A base that strafes (the mecanum platform); no tuned preset yet.
register_law("holonomic", holonomic.Holonomic, holonomic.PRESETS, default_preset="default")
# Line tracing (LineTrace-v0, reference §2): the paper's coordinate control and the PID line
# follower it is compared with.
register_law("coordinate", coordinate.Coordinate, coordinate.PRESETS, task="line_trace")
register_law("pid", pid_line.PIDLine, pid_line.PRESETS, task="line_trace")
# Learned agents: the shipped PPO agent by name, any other by its path (a run folder or a .zip).
# policies.learned.ppo loads torch and stable-baselines3 only when an agent is built.
register_policy("ppo", ppo.load_default)
register_resolver(ppo.resolve_path)

"""The work units of an identical rollout (:func:`eval.rollout.rollout`): what each carries from
the driver to its worker, and how messages name it.

A unit is one policy on one scenario for a chunk of seeds (:func:`chunk_size`). It names an
agent given by a relative path by its absolute path (:func:`sent`: a Ray worker's folder is not
the driver's) and carries what the driver read before any episode ran: the SHA-256 of its
sources (:func:`eval.provenance.check_worker_code`) and, for a learned policy, of the agent's
files (:func:`eval.provenance.check_worker_model`), which the worker checks against its own. A
message about a unit (its worker died, it raised) names it by :func:`unit_label`, e.g.
``pn:tuned on straight, seeds 0-19``, as the run's tables name its cell.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any, NamedTuple

from eval.grid import PolicySpec, policy_spec
from eval.provenance import model_sha256, running_sources_sha256
from policies import Policy
from policies.learned.ensemble import is_learned

__all__ = ["BATCH_LANES", "Sent", "Work", "chunk_size", "seeds_text", "sent", "unit_label"]

#: Most seeds run as the lanes of one batch (bounds the memory of the step logs in flight).
BATCH_LANES = 256
#: Seed ranges a unit's label lists before it elides the middle ones.
_LABEL_RANGES = 4

EnvConfigSpec = str | Mapping[str, Any] | Any
Reducer = Callable[[Any], Any]


class Sent(NamedTuple):
    """A grid's policy as its units carry it (:func:`sent`)."""

    #: The spec a worker builds the policy from (an agent's path made absolute).
    spec: PolicySpec
    #: The name its episodes carry when ``spec`` is not the name given (an absolute path), else
    #: None (the policy's own).
    name: str | None
    #: Its label in the run's tables (``pn:tuned``, ``pn:tuned@mecanum``, ``runs/agent``).
    label: str
    #: :func:`eval.provenance.model_sha256` of its files as the driver read them, None for a law.
    model: str | None


class Work(NamedTuple):
    """One work unit (:func:`work_units`), run by :func:`eval.rollout._run_task`."""

    policy: PolicySpec
    scenario: str
    seeds: tuple[int, ...]
    config: EnvConfigSpec
    reduce: Reducer | None
    task: str
    #: :attr:`Sent.name`.
    name: str | None
    #: The driver's :func:`eval.provenance.running_sources_sha256`.
    code: str
    #: :attr:`Sent.label`: how messages name the unit (:func:`unit_label`).
    label: str
    #: :attr:`Sent.model`: the worker refuses the unit if its files' digest differs.
    model: str | None


def sent(given: PolicySpec, policy: Policy, platform: str | None) -> Sent:
    """How units carry ``given``, built here as ``policy`` for ``platform`` (None: the config's).

    An agent named by its relative path (not ``ppo``: each node's own install) is sent as its
    absolute path, named as given; anything else as given. A Ray worker finds a relative path
    from the folder its ``ray start`` ran in: another agent than the one read here (and
    ``meta.json`` records).
    """
    label = policy.name if platform is None else f"{policy.name}@{platform}"
    model = model_sha256(policy)
    spec = policy_spec(given)[0] if isinstance(given, str) else given
    path = getattr(policy, "path", None) if is_learned(policy) else None
    relative = isinstance(spec, str) and not Path(spec).is_absolute()
    if not relative or path is None or Path(path) != Path(spec):
        return Sent(given, None, label, model)
    where = str(Path(spec).absolute())
    return Sent(where if platform is None else f"{where}@{platform}", policy.name, label, model)


def chunk_size(seeds: int, slots: int, cells: int = 1) -> int:
    """Seeds per work unit for ``cells`` (policy, scenario) cells of ``seeds`` seeds on ``slots``
    slots (pool workers, Ray CPUs): as many as a batch takes (:data:`BATCH_LANES`: the lanes of
    one batch step together, far faster than apart) while every slot still gets about two
    units. The episodes do not depend on it (lane ``i`` of a batch is the env seeded ``s_i``)."""
    splits = math.ceil(2 * slots / max(cells, 1)) if slots > 1 else 1
    return max(1, min(BATCH_LANES, math.ceil(seeds / splits)))


def work_units(
    policies: Sequence[PolicySpec | Sent],
    scenarios: Sequence[str],
    seeds: Sequence[int],
    config: EnvConfigSpec,
    reduce: Reducer | None,
    size: int,
    task: str,
) -> list[Work]:
    """The work units in grid order (policy, scenario, then chunks of at most ``size`` seeds);
    ``policies`` are :func:`sent`'s (a bare spec is sent as given, labelled by its name, and
    its files are not checked)."""
    if isinstance(size, bool) or not isinstance(size, int) or size < 1:
        raise ValueError(f"chunk={size!r} is out of range: must be an integer >= 1")
    code = running_sources_sha256()
    grid = [p if isinstance(p, Sent) else Sent(p, None, _spec_label(p), None) for p in policies]
    units = []
    for p in grid:
        for s in scenarios:
            for k in range(0, len(seeds), size):
                chunk = tuple(int(x) for x in seeds[k : k + size])
                given = (p.spec, s, chunk, config, reduce, task)
                units.append(Work(*given, p.name, code, p.label, p.model))
    return units


def _spec_label(spec: PolicySpec) -> str:
    """A bare spec's label: its text, or a policy object's name."""
    return spec if isinstance(spec, str) else str(getattr(spec, "name", type(spec).__name__))


def seeds_text(seeds: Sequence[int]) -> str:
    """Seeds as a message names them: ``seed 7``, ``seeds 0-19``, ``seeds 3, 5-8``; past
    :data:`_LABEL_RANGES` ranges the middle ones elided and the count given."""
    if len(seeds) == 1:
        return f"seed {seeds[0]}"
    ranges: list[list[int]] = []
    for seed in seeds:
        if ranges and seed == ranges[-1][1] + 1:
            ranges[-1][1] = seed
        else:
            ranges.append([seed, seed])
    parts = [str(a) if a == b else f"{a}-{b}" for a, b in ranges]
    if len(parts) <= _LABEL_RANGES:
        return f"seeds {', '.join(parts)}"
    shown = [*parts[: _LABEL_RANGES - 1], "...", parts[-1]]
    return f"{len(seeds)} seeds {', '.join(shown)}"


def unit_label(work: Work) -> str:
    """How messages name a unit (:func:`execution.execute`'s ``describe``): its policy's label,
    scenario and seeds, e.g. ``pn:tuned on straight, seeds 0-19``."""
    return f"{work.label} on {work.scenario}, {seeds_text(work.seeds)}"

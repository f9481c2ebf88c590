"""Fitting a policy's action onto a platform's, by the entries' names.

A policy names what it commands in ``action_names`` (a guidance law: ``("v_mps", "w_radps")``,
:data:`policies.base.LAW_ACTION_NAMES`); a platform names its action's entries the same way
(the differential drive ``v_mps, w_radps``; the mecanum base ``v_mps, vy_mps, w_radps``). The
rule: each entry of the platform's action takes the policy's entry of the same name, and an
entry the policy does not command is 0. So PN on the mecanum base drives with ``vy = 0``, and a
policy that commands an entry the platform lacks (a strafing law on the differential drive) is
refused, since dropping a command silently would change the law.

A policy made for one platform (a learned agent, trained on that platform's dynamics) says so
in a ``platform`` attribute: it runs only where the action is exactly its own, so a mecanum agent
is refused on the differential drive and a differential-drive agent on the mecanum base (whose
``vy = 0`` would be accepted for a law), each with one error naming the agent's platform.

The adapter keeps the policy's name, memory and batching (``act_batch``), so evaluation runs it
exactly as the policy itself.

A law that differentiates also needs the control period its observations arrive at: the
reference's ``dt`` is that period (SPEC §1.5: ``rate = (o - o_prev) / dt``), so
:func:`at_period` sets a law's ``dt_s`` to the env's (or the robot's) period wherever the harness
knows it. Run at 0.05 s, a law left at 0.1 s would read every offset rate at half its size.
"""

from __future__ import annotations

import copy
import dataclasses
from collections.abc import Sequence
from typing import Any

import numpy as np

from policies.base import LAW_ACTION_NAMES, BatchPolicy, Policy

__all__ = ["BatchPlatformAction", "PlatformAction", "action_names", "at_period", "for_platform"]


def action_names(policy: Policy) -> tuple[str, ...]:
    """The names of ``policy``'s action entries (a law's ``(v_mps, w_radps)`` by default)."""
    return tuple(getattr(policy, "action_names", LAW_ACTION_NAMES))


class PlatformAction:
    """``policy`` acting in a platform's action ``names`` (module docstring).

    :param policy: the policy. :param names: the platform's action entries, in order.
    :raises ValueError: if the policy commands an entry the platform does not have.
    """

    def __init__(self, policy: Policy, names: Sequence[str]) -> None:
        own = action_names(policy)
        trained_on = getattr(policy, "platform", None)
        if trained_on is not None and own != tuple(names):
            raise ValueError(
                f"policy {policy.name!r} was trained on the {trained_on} platform, acting "
                f"[{', '.join(own)}]; it cannot drive a platform acting [{', '.join(names)}] "
                f"(train an agent for that platform, or run it @{trained_on})"
            )
        missing = [n for n in own if n not in names]
        if missing:
            raise ValueError(
                f"policy {policy.name!r} commands {', '.join(missing)}, which a platform acting "
                f"[{', '.join(names)}] does not have"
            )
        self.policy = policy
        self.name = policy.name
        self.action_names = tuple(names)
        self._columns = [list(names).index(n) for n in own]

    def reset(self) -> None:
        """Reset the policy."""
        self.policy.reset()

    def act(self, obs: np.ndarray) -> np.ndarray:
        """The policy's action with its entries in the platform's places (others 0)."""
        out = np.zeros(len(self.action_names), dtype=np.float32)
        out[self._columns] = self.policy.act(obs)
        return out

    def __getattr__(self, name: str) -> Any:
        # The policy's other attributes (params, ...) as they are.
        if name.startswith("_") or name in ("reset_batch", "act_batch"):
            raise AttributeError(name)
        return getattr(self.policy, name)

    def __repr__(self) -> str:
        return f"PlatformAction({self.policy!r}, {list(self.action_names)})"


class BatchPlatformAction(PlatformAction):
    """:class:`PlatformAction` of a policy that acts for many lanes at once (``act_batch``)."""

    def reset_batch(self, n: int) -> None:
        """Start ``n`` lanes' episodes."""
        self.policy.reset_batch(n)  # type: ignore[attr-defined]

    def act_batch(self, obs: np.ndarray) -> np.ndarray:
        """The policy's batched actions, entries in the platform's places (others 0)."""
        inner = np.asarray(self.policy.act_batch(obs))  # type: ignore[attr-defined]
        out = np.zeros((len(inner), len(self.action_names)), dtype=np.float32)
        out[:, self._columns] = inner
        return out


def for_platform(policy: Policy, names: Sequence[str]) -> Policy:
    """``policy`` itself when it acts in ``names`` already, else its adapter (module
    docstring); a batching policy's adapter batches too.

    :raises ValueError: if the policy commands an entry ``names`` lacks, or was made for one
        platform (``platform``) and ``names`` are not its action's.
    """
    if action_names(policy) == tuple(names):
        return policy
    cls = BatchPlatformAction if isinstance(policy, BatchPolicy) else PlatformAction
    return cls(policy, names)  # type: ignore[return-value]


def at_period(policy: Policy, dt_s: float) -> Policy:
    """``policy`` as it should run when its observations arrive every ``dt_s`` seconds.

    A law whose parameters hold a period of their own (``params.dt_s``: MPN's and GS-MPN's
    offset rate, the line PID's integral and derivative) gets a copy with ``dt_s`` set to the
    period, memory fresh and name kept; every other policy (a memoryless law, a learned agent,
    a law already at that period) is returned as it is. The period is the loop's, not the
    law's tuning (module docstring).

    :raises ValueError: if ``dt_s`` is outside the law's range for ``dt_s`` (its params check it).
    """
    params = getattr(policy, "params", None)
    if not dataclasses.is_dataclass(params) or "dt_s" not in {
        f.name for f in dataclasses.fields(params)
    }:
        return policy
    if params.dt_s == dt_s:  # type: ignore[union-attr]
        return policy
    # A shallow copy shares the memory arrays; reset() and reset_batch() replace them, and the
    # harness calls one of them before the first step.
    adapted = copy.copy(policy)
    adapted.params = dataclasses.replace(params, dt_s=float(dt_s))  # type: ignore[arg-type,attr-defined]
    adapted.reset()
    return adapted

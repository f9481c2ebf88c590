"""A policy acting for many lanes at once, whatever it is: the shape evaluation runs policies in.

A :class:`~policies.base.BatchPolicy` acts for every lane itself (one object, per-lane
memory); any other policy gets one copy per lane, so that lanes never share memory. Either
way each lane gets exactly the action the policy would give its episode alone.
"""

from __future__ import annotations

import copy
from collections.abc import Callable

import numpy as np

from policies.adapt import for_platform
from policies.base import BatchPolicy, Policy

__all__ = ["Lanes"]


class Lanes:
    """Actions for ``n`` lanes from ``first``, fitted to a platform's ``actions`` (entry names).

    :param first: the policy (it acts for lane 0, or for all lanes when it is a batch policy).
    :param n: lanes.
    :param actions: the platform's action entries (:func:`~policies.adapt.for_platform`).
    :param fresh: builds another copy of the policy (a name's fresh instance); None: copies
        of ``first``.
    """

    def __init__(
        self,
        first: Policy,
        n: int,
        actions: tuple[str, ...],
        fresh: Callable[[], Policy] | None = None,
    ) -> None:
        first = for_platform(first, actions)
        self.name = first.name
        self.size = len(actions)
        self.batch: BatchPolicy | None = None
        self.lanes: list[Policy] = []
        if isinstance(first, BatchPolicy):
            self.batch = first
            first.reset_batch(n)
            return
        self.lanes = [first] + [
            for_platform(fresh(), actions) if fresh is not None else copy.deepcopy(first)
            for _ in range(n - 1)
        ]
        for law in self.lanes:
            law.reset()

    def act(self, obs: np.ndarray, active: np.ndarray) -> np.ndarray:
        """Actions ``(n, size)`` float32 for observations ``(n, k)``; lanes not ``active`` get
        zeros from a per-lane policy (a batch policy acts for all)."""
        if self.batch is not None:
            return np.asarray(self.batch.act_batch(obs), dtype=np.float32)
        out = np.zeros((len(obs), self.size), dtype=np.float32)
        for i in np.flatnonzero(active):
            out[i] = np.asarray(self.lanes[i].act(obs[i]), dtype=np.float32)
        return out

"""A guidance law's command as part of the agent's view, numpy only (:class:`LawHint`).

The agent sees what a law (``pn:thesis``, say) would command on the same observation, in the
agent's action units; :class:`~policies.learned.incremental.IncrementalAction` with
``prior_index`` can then track that command, so that an agent whose action is zero drives as a
rate-limited copy of the law and learns only where to depart from it (residual learning).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from policies.base import LaneActing
from policies.learned.boxes import Box, per_entry
from policies.learned.feature import Feature, append_entries

__all__ = ["LawHint", "guidance_laws", "use_laws"]

# How a law's name becomes a law, and which names are guidance laws: the registry, which
# imports this module (through the learned agents' loaders), hands them in when it is imported
# (policies.registry), so this module imports neither the registry nor the learned agents.
_make_law: Callable[[str], Any] | None = None
_law_names: Callable[[], list[str]] | None = None


def use_laws(make: Callable[[str], Any], names: Callable[[], list[str]]) -> None:
    """Set how :class:`LawHint` builds its law from a name (:func:`policies.make_policy`), and
    the names it takes (``names()``: the registered guidance laws, no learned agent)."""
    global _make_law, _law_names
    _make_law, _law_names = make, names


def guidance_laws() -> list[str]:
    """The names :class:`LawHint` takes: the registered guidance laws, sorted."""
    return sorted(_law_names()) if _law_names is not None else []


class LawHint(Feature):
    """Append the command of ``law`` on the observation, divided by ``units``, clipped to
    [-1, 1].

    The law sees the observation this step is given (list it after the gate on jumps, so the
    law reads what the agent reads; before :class:`ScaleObservation`, so it reads metres and
    pixels), one copy of its memory per lane, reset with the lane's episode.

    :param law: a registered guidance law's name (:func:`guidance_laws`), e.g.
        ``"pn:thesis"``; a learned agent (``ppo``, a run folder) is refused.
    :param units: one value per action entry: the law's command that reads as 1 (SI, in the
        entry's unit; the agent's ranges of ``RescaleAction``, e.g. ``[1.484375, 2.0]``).
    """

    def __init__(self, law: str = "pn:thesis", units: Sequence[float] = (1.484375, 2.0)) -> None:
        self.law_name = law
        self.given_units = units

    def bind(self, obs: Box, act: Box, n: int) -> tuple[Box, Box]:
        if _make_law is None:  # importing the package imports the registry, which sets it
            raise RuntimeError("policies.registry has not handed LawHint its laws")
        units = per_entry(f"{self.owner}.units", self.given_units, act)
        # Decided on the name, before anything is built: a learned agent as the law would load
        # an agent while this one loads (its own path once hung for ever), and an agent's view
        # holds a guidance law's command, not another agent's.
        laws = guidance_laws()
        if self.law_name not in laws:
            raise ValueError(
                f"{self.owner}.law={self.law_name!r} is out of range: must be a guidance law, "
                f"not a learned agent or a path (registered guidance laws: {', '.join(laws)})"
            )
        law = _make_law(self.law_name)
        if not isinstance(law, LaneActing) or tuple(law.action_names) != act.entry_names():
            raise ValueError(
                f"{self.owner}.law={self.law_name!r} is out of range: must be a guidance law "
                f"commanding [{', '.join(act.entry_names())}], not a learned agent"
            )
        self.law, self.units, self.n = law, units, n
        ones = np.ones(act.shape[0])
        outer = Box(np.concatenate([obs.low, -ones]), np.concatenate([obs.high, ones]))
        return outer, act

    def start(self, obs: np.ndarray) -> np.ndarray:
        self.law.reset_batch(self.n)
        return self._join(obs, self.law.act_batch(self._law_rows(obs)))

    def observe(self, obs: np.ndarray, done: np.ndarray) -> np.ndarray:
        if np.any(done):
            self.law.reset_lanes(np.asarray(done, dtype=bool))
        return self._join(obs, self.law.act_batch(self._law_rows(obs)))

    def terminal(self, obs: np.ndarray, lane: int) -> np.ndarray:
        row = np.asarray(obs)[None, :]
        return self._join(row, self.law.peek(self._law_rows(row)[0], lane)[None, :])[0]

    @staticmethod
    def _law_rows(obs: np.ndarray) -> np.ndarray:
        """The entries a law reads: distance and offset."""
        return np.asarray(obs, dtype=np.float64)[:, :2]

    def _join(self, obs: np.ndarray, command: np.ndarray) -> np.ndarray:
        return append_entries(obs, np.clip(np.asarray(command) / self.units, -1.0, 1.0))

"""The contract of one step of a learned agent's view (:mod:`policies.learned.features` chains
the steps; :mod:`train.wrappers` wraps each for training), numpy only."""

from __future__ import annotations

import numpy as np

from policies.learned.boxes import Box

__all__ = ["Feature"]


class Feature:
    """One step of an agent's view (:mod:`policies.learned.features`). The defaults pass things
    through.

    :meth:`bind` is called once with the boxes seen from inside (the env's side) and returns
    the boxes seen from outside; :meth:`start` begins every lane's episode; :meth:`observe`
    follows a step (lanes flagged in ``done`` have just been reset: their observation is a new
    episode's first); :meth:`act` turns the outer action into the inner one.
    """

    training_only = False

    @property
    def owner(self) -> str:
        """The name errors are reported under (a training wrapper gives its own)."""
        return getattr(self, "_owner", type(self).__name__)

    @owner.setter
    def owner(self, name: str) -> None:
        self._owner = name

    def bind(self, obs: Box, act: Box, n: int) -> tuple[Box, Box]:
        """Remember the inner boxes and the lane count; return the outer boxes."""
        return obs, act

    def start(self, obs: np.ndarray) -> np.ndarray:
        """Every lane starts an episode with observation ``obs`` (n, k)."""
        return self.observe(obs, np.zeros(len(obs), dtype=bool))

    def observe(self, obs: np.ndarray, done: np.ndarray) -> np.ndarray:
        """The outer observation after a step."""
        return obs

    def terminal(self, obs: np.ndarray, lane: int) -> np.ndarray:
        """The outer view of lane ``lane``'s final observation (SB3's ``terminal_observation``),
        taken before :meth:`observe` of the step that ended it."""
        return obs

    def act(self, action: np.ndarray) -> np.ndarray:
        """The inner action for the outer ``action`` (n, m)."""
        return action

"""The contract of one step of a learned agent's view (:mod:`policies.learned.features` chains
the steps; :mod:`train.wrappers` wraps each for training), numpy only."""

from __future__ import annotations

from typing import Any

import numpy as np

from policies.learned.boxes import Box

__all__ = ["IN_TRAINING", "Feature", "append_entries", "split_in_training", "wrapper_entries"]

#: The keyword a ``vec_env_wrapper`` entry of a feature step may carry: ``in_training: false``
#: leaves the step out of the training env (observations pass through there) and keeps it in the
#: exported agent's view, for a filter measured in front of agents trained without it. Only a
#: step that keeps the observation and action shapes can be left out of training.
IN_TRAINING = "in_training"


def append_entries(obs: np.ndarray, entries: np.ndarray) -> np.ndarray:
    """``obs`` (n, k) with ``entries`` (n, m) after its own entries, float32: a step that adds
    to the observation (the command in force, a law's command)."""
    return np.concatenate(
        [np.asarray(obs, dtype=np.float32), np.asarray(entries, dtype=np.float32)], axis=-1
    )


def wrapper_entries(value: Any) -> list[Any]:
    """rl-zoo3's ``vec_env_wrapper`` value as the list of its entries, as written: a single
    entry may stand alone, and none (null, missing) is an empty list."""
    return list(value) if isinstance(value, list) else [value] if value else []


def split_in_training(kwargs: dict[str, Any], where: str) -> tuple[bool, dict[str, Any]]:
    """``(in_training, the step's own arguments)`` of a wrapper entry's keyword arguments.

    :raises ValueError: ``in_training`` is not a bool (naming ``where``, the entry's name).
    """
    own = dict(kwargs)
    flag = own.pop(IN_TRAINING, True)
    if not isinstance(flag, bool):
        raise ValueError(f"{where}.{IN_TRAINING}={flag!r} must be true or false")
    return flag, own


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

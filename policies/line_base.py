"""The shared part of the line-tracing laws: the observation they read and how they act.

A line law sees LineTrace-v0 only through its spec (:mod:`follow_env.tasks.line_trace.spec`):
the 25 readings of the 5 x 5 light-sensor grid, row-major, row 0 the front row and column 0 the
leftmost cell, 0 over white floor and 1 on the line; :func:`cell_positions` gives each cell's
place in cells (x forward, y to the left). It acts in the body twist's entries by name
(``action_names``), which :func:`policies.for_platform` fits onto a platform's action: a law
commanding ``vy_mps`` runs only on a base that strafes.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from follow_env.tasks.line_trace.spec import SPEC, cell_offsets
from policies.base import LaneMemory, real_obs

__all__ = ["CELL_XY", "LINE_OBS_SIZE", "LineLaw", "validate_readings"]

LINE_OBS_SIZE = SPEC.observation_size
"""Readings in one observation (25)."""
CELL_XY = np.array(cell_offsets())
"""Each cell's ``(x forward, y left)`` from the grid's centre, in cells, observation order."""


def validate_readings(obs: ArrayLike, batch: bool = False) -> np.ndarray:
    """The readings as float64 ``(25,)`` (``batch``: ``(n, 25)``, every row checked before
    any lane acts); ``ValueError`` on another shape, a NaN/inf or entries that are not real
    numbers (strings would be parsed, silently)."""
    arr = real_obs(obs)
    shape = (arr.shape[0], LINE_OBS_SIZE) if batch and arr.ndim == 2 else (LINE_OBS_SIZE,)
    if arr.shape != shape:
        rows = "(n, 25): rows of" if batch else f"({LINE_OBS_SIZE},):"
        raise ValueError(
            f"obs must have shape {rows} the 5 x 5 grid's readings (cell_00 .. cell_44), "
            f"got shape {arr.shape}"
        )
    if not np.all(np.isfinite(arr)):
        if batch:
            bad = np.flatnonzero(~np.isfinite(arr).all(axis=1)).tolist()
            raise ValueError(f"obs of lanes {bad} must be finite readings in [0, 1]")
        raise ValueError("obs must be finite readings in [0, 1]")
    return arr


class LineLaw(LaneMemory, ABC):
    """Base of the line-tracing laws: validates the readings, runs the law, remembers per lane.

    A law sets ``name``, ``params`` and ``action_names`` and implements :meth:`_command`
    (readings to the command's entries, in ``action_names`` order) and, if it has memory,
    :meth:`reset`, :meth:`_memory` and :meth:`_set_memory`.
    """

    name: str
    params: Any
    action_names: tuple[str, ...]
    task = "line_trace"
    """The task whose observation this law reads."""

    def act(self, obs: np.ndarray) -> np.ndarray:
        """Map the 25 readings to the command (``action_names`` order), float32.

        :raises ValueError: if ``obs`` is not 25 finite readings.
        """
        return np.asarray(self._command(validate_readings(obs)), dtype=np.float32)

    @abstractmethod
    def _command(self, readings: np.ndarray) -> tuple[float, ...]:
        """The command for these readings (SI)."""

    def act_batch(self, obs: np.ndarray) -> np.ndarray:
        """Actions ``(n, m)`` float32: :meth:`act` for each lane with that lane's memory
        (:class:`~policies.base.LaneMemory`)."""
        return self._act_lanes(validate_readings(obs, batch=True))

    def __repr__(self) -> str:
        return f"{type(self).__name__}(name={self.name!r}, params={self.params!r})"

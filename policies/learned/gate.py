"""A gate on the detection's jumps: the agent's own data association, numpy only.

The perception follows the first detection (reference §1.4), so when the detector misses the
person for a frame, a bystander 4-6 m away can take their place: the reported distance climbs by
a metre a frame and the offset jumps by hundreds of pixels, which no person walking beside a
robot can do in 0.1 s. :class:`JumpGate` holds the last accepted detection instead (the
observation then repeats, so :class:`~policies.learned.features.ObservationAge` counts it as
stale, as when the detector sees nobody) until the reading comes back within reach of it, or
until the new one has been detected afresh ``accept_after`` times, after which it is taken.
Only fresh readings count: while the detector sees nobody the perception repeats its last
values, and a bystander's reading repeated through a detection gap is no evidence that the
person is where the bystander was.
"""

from __future__ import annotations

import numpy as np

from follow_env.sim.checks import check_number
from policies.learned.boxes import Box
from policies.learned.feature import Feature

__all__ = ["JumpGate"]


class JumpGate(Feature):
    """Hold the detection (entries 0 and 1: distance, offset) when it jumps; the rest passes.

    A reading is a jump when both it and the held one are valid (distance > 0) and its
    distance differs from the held one's by more than ``max_jump_m``, or its offset by more than
    ``max_jump_px``. A jump is replaced by the held detection; once ``accept_after`` fresh
    readings (ones that differ from the step before's: not the perception repeating itself)
    have been held off in a row, the next jump is taken (the person may really be there now).

    :param max_jump_m: the largest change of distance a step [m], or None (not gated).
    :param max_jump_px: the largest change of offset a step [px], or None (not gated).
    :param accept_after: fresh readings a jump is held off at most (an integer >= 1).
    """

    def __init__(
        self,
        max_jump_m: float | None = 0.5,
        max_jump_px: float | None = None,
        accept_after: int = 10,
    ) -> None:
        self.max_jump_m, self.max_jump_px, self.accept_after = max_jump_m, max_jump_px, accept_after

    def bind(self, obs: Box, act: Box, n: int) -> tuple[Box, Box]:
        where = self.owner
        for field in ("max_jump_m", "max_jump_px"):
            limit = check_number(
                f"{where}.{field}", getattr(self, field), 0.0, lo_open=True, optional=True
            )
            setattr(self, field, limit)
        self.accept_after = check_number(
            f"{where}.accept_after", self.accept_after, 1, integer=True
        )
        if obs.shape[0] < 2:
            raise ValueError(
                f"{where} needs [distance_m, offset_px, ...], got {obs.shape[0]} entries"
            )
        self._held = np.zeros((n, 2), dtype=np.float32)  # the detection passed on last
        self._raw = np.zeros((n, 2), dtype=np.float32)  # the perception's, last step
        self._count = np.zeros(n, dtype=np.int64)  # fresh readings held off in a row
        return obs, act

    def start(self, obs: np.ndarray) -> np.ndarray:
        obs = np.array(obs, dtype=np.float32)
        self._held = obs[:, :2].copy()
        self._raw = obs[:, :2].copy()
        self._count[:] = 0
        return obs

    def _jumps(self, obs: np.ndarray, held: np.ndarray, count: np.ndarray) -> np.ndarray:
        """Which rows of ``obs`` are jumps from ``held`` to be held off."""
        valid = (obs[:, 0] > 0) & (held[:, 0] > 0)
        jump = np.zeros(len(obs), dtype=bool)
        if self.max_jump_m is not None:
            jump |= np.abs(obs[:, 0] - held[:, 0]) > self.max_jump_m
        if self.max_jump_px is not None:
            jump |= np.abs(obs[:, 1] - held[:, 1]) > self.max_jump_px
        return valid & jump & (count < self.accept_after)

    def observe(self, obs: np.ndarray, done: np.ndarray) -> np.ndarray:
        obs = np.array(obs, dtype=np.float32)
        fresh = np.any(obs[:, :2] != self._raw, axis=1)
        self._raw = obs[:, :2].copy()
        gate = self._jumps(obs, self._held, self._count) & ~done
        obs[gate, :2] = self._held[gate]
        self._count = np.where(gate, self._count + fresh, 0)
        self._held = obs[:, :2].copy()
        return obs

    def terminal(self, obs: np.ndarray, lane: int) -> np.ndarray:
        obs = np.array(obs, dtype=np.float32)
        if self._jumps(obs[None], self._held[lane : lane + 1], self._count[lane : lane + 1])[0]:
            obs[:2] = self._held[lane]
        return obs

"""The meeting point of the robot's driver and the web monitor's clients (thread-safe).

The driver (the runner's control loop, or :class:`~bridge.monitor.sim.SimDriver`) calls
:meth:`MonitorHub.publish` once per control step and reads :attr:`MonitorHub.mode` and
:meth:`MonitorHub.manual_command`; the WebSocket handlers read :meth:`MonitorHub.latest` and
call :meth:`MonitorHub.set_mode` and :meth:`MonitorHub.set_manual`.
"""

from __future__ import annotations

import math
import threading
import time
from typing import Any

__all__ = ["MANUAL_LIMITS", "MODES", "MonitorHub"]

MODES: tuple[str, ...] = ("pn", "mpn", "gsmpn", "ppo", "stop", "manual")
"""The operating modes a browser can select (the reference robot's web UI, reference §1)."""

MANUAL_LIMITS = (2.0, 8.0)
"""Largest manual command accepted: (m/s, rad/s); the platform clips further."""


class MonitorHub:
    """State out, modes and manual commands in.

    :param mode: the starting mode (one of :data:`MODES`, or a policy name the driver runs).
    :param manual_timeout_s: a manual command older than this reads as zero, s (a browser that
        stops sending must not leave the robot driving).
    :param scene: static drawing data sent to every client on connect (e.g. ``{"walls":
        [[x1, y1, x2, y2], ...]}`` in m).
    """

    def __init__(
        self, mode: str = "stop", manual_timeout_s: float = 0.5, scene: dict[str, Any] | None = None
    ) -> None:
        self._lock = threading.Lock()
        self._mode = mode
        self._manual = (0.0, 0.0)
        self._manual_at = -math.inf
        self.manual_timeout_s = manual_timeout_s
        self._state: dict[str, Any] | None = None
        self._seq = 0
        self.scene: dict[str, Any] = dict(scene or {})
        self.mode_changes = 0

    @property
    def mode(self) -> str:
        """The current mode."""
        with self._lock:
            return self._mode

    def set_mode(self, mode: str) -> None:
        """Select a mode (``ValueError`` for one not in :data:`MODES`)."""
        if mode not in MODES:
            raise ValueError(f"mode={mode!r} is out of range: must be one of {', '.join(MODES)}")
        with self._lock:
            if mode != self._mode:
                self.mode_changes += 1
            self._mode = mode
            if mode != "manual":
                self._manual, self._manual_at = (0.0, 0.0), -math.inf

    def set_manual(self, v_mps: float, w_radps: float) -> None:
        """A manual command (used while the mode is ``manual``)."""
        v_max, w_max = MANUAL_LIMITS
        for name, value, limit in (("v_mps", v_mps, v_max), ("w_radps", w_radps, w_max)):
            if not (math.isfinite(value) and abs(value) <= limit):
                raise ValueError(
                    f"{name}={value!r} is out of range: must be in [-{limit}, {limit}]"
                )
        with self._lock:
            self._manual, self._manual_at = (float(v_mps), float(w_radps)), time.monotonic()

    def manual_command(self) -> tuple[float, float]:
        """The newest manual command, or zero once it is older than ``manual_timeout_s``."""
        with self._lock:
            if time.monotonic() - self._manual_at > self.manual_timeout_s:
                return 0.0, 0.0
            return self._manual

    def publish(self, state: dict[str, Any]) -> None:
        """The driver's newest state (JSON-ready values); stamped with ``seq`` and ``t_wall``."""
        with self._lock:
            self._seq += 1
            self._state = {"type": "state", **state, "seq": self._seq, "t_wall": time.time()}

    def latest(self) -> dict[str, Any] | None:
        """The newest state, or ``None`` before the first."""
        with self._lock:
            return None if self._state is None else dict(self._state)

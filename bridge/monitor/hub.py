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
from collections.abc import Sequence
from typing import Any

__all__ = ["LABELS", "MANUAL_LIMITS", "MODES", "MonitorHub", "monitor_modes"]

MODES: tuple[str, ...] = ("pn", "mpn", "gsmpn", "ppo", "stop", "manual")
"""The operating modes a browser can always select (the reference robot's web UI, reference
§1); a hub may offer more policies (:func:`monitor_modes`)."""

LABELS: dict[str, str] = {
    "pn": "PN",
    "mpn": "MPN",
    "gsmpn": "GS-MPN",
    "ppo": "PPO",
    "ppo_ahead": "PPO (ahead)",
    "ppo_law": "PPO (law)",
    "ppo_ensemble": "PPO (ensemble)",
    "stop": "STOP",
    "manual": "manual",
}
"""The page's button label of a mode (a mode without one is labelled by its name)."""


def monitor_modes(policies: Sequence[str] = ()) -> tuple[str, ...]:
    """The modes of a hub that also offers ``policies`` (names the driver's policy factory
    builds, e.g. ``"ppo_ahead"``): :data:`MODES`'s policies, then these, then ``manual`` and
    ``stop``, in the page's order."""
    driven = [m for m in MODES if m not in ("stop", "manual")]
    extra = [p for p in policies if p not in MODES]
    return (*driven, *dict.fromkeys(extra), "manual", "stop")


MANUAL_LIMITS = (2.0, 8.0)
"""Largest manual command accepted: (m/s, rad/s); the platform clips further."""


class MonitorHub:
    """State out, modes and manual commands in.

    :param mode: the starting mode (one of ``modes``, or a policy name the driver runs).
    :param manual_timeout_s: a manual command older than this reads as zero, s (a browser that
        stops sending must not leave the robot driving).
    :param scene: static drawing data sent to every client on connect (e.g. ``{"walls":
        [[x1, y1, x2, y2], ...]}`` in m).
    :param modes: the modes a browser may select, in the page's order (default: :data:`MODES`,
        as :func:`monitor_modes` orders them; it also adds policies). ``stop`` must be one.
    """

    def __init__(
        self,
        mode: str = "stop",
        manual_timeout_s: float = 0.5,
        scene: dict[str, Any] | None = None,
        modes: Sequence[str] | None = None,
    ) -> None:
        self.modes = monitor_modes() if modes is None else modes
        self._lock = threading.Lock()
        self._mode = mode
        self._manual = (0.0, 0.0)
        self._manual_at = -math.inf
        self.manual_timeout_s = manual_timeout_s
        self._state: dict[str, Any] | None = None
        self._seq = 0
        self.scene: dict[str, Any] = dict(scene or {})
        self.mode_changes = 0
        self._notice = ""
        self.refusals = 0

    @property
    def modes(self) -> tuple[str, ...]:
        """The modes a browser may select, in the page's order (set before serving)."""
        return self._modes

    @modes.setter
    def modes(self, modes: Sequence[str]) -> None:
        modes = tuple(modes)
        if "stop" not in modes or len(set(modes)) != len(modes):
            raise ValueError(f"modes={modes!r} is out of range: must hold 'stop', each mode once")
        if not all(isinstance(m, str) and m for m in modes):
            raise ValueError(f"modes={modes!r} is out of range: must be non-empty names")
        self._modes = modes

    @property
    def mode(self) -> str:
        """The current mode."""
        with self._lock:
            return self._mode

    def set_mode(self, mode: str) -> None:
        """Select a mode (``ValueError`` for one not in :attr:`modes`)."""
        if mode not in self.modes:
            raise ValueError(
                f"mode={mode!r} is out of range: must be one of {', '.join(self.modes)}"
            )
        with self._lock:
            if mode != self._mode:
                self.mode_changes += 1
            self._mode = mode
            if mode != "manual":
                self._manual, self._manual_at = (0.0, 0.0), -math.inf

    def refuse(self, mode: str, back_to: str, reason: str) -> None:
        """The driver cannot run ``mode`` (say, an agent that needs a reading the robot's
        perception does not publish): if it is still the selected mode, go back to ``back_to``
        (the mode the driver kept running), and tell every client ``reason``, which names the
        policy (each state carries it as ``notice``, and the count so far as ``refusals``)."""
        with self._lock:
            if self._mode == mode:
                self._mode = back_to
            self._notice = reason
            self.refusals += 1

    @property
    def notice(self) -> str:
        """The newest refusal (:meth:`refuse`), ``""`` before any."""
        with self._lock:
            return self._notice

    def buttons(self) -> list[list[str]]:
        """``[[mode, label], ...]``: the page's mode buttons, in order (:data:`LABELS`)."""
        return [[m, LABELS.get(m, m)] for m in self.modes]

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
            self._state = {
                "type": "state",
                **state,
                "notice": self._notice,
                "refusals": self.refusals,
                "seq": self._seq,
                "t_wall": time.time(),
            }

    def latest(self) -> dict[str, Any] | None:
        """The newest state, or ``None`` before the first."""
        with self._lock:
            return None if self._state is None else dict(self._state)

"""The meeting point of the robot's driver and the web monitor's clients (thread-safe).

The driver (the runner's control loop, or :class:`~bridge.monitor.sim.SimDriver`) calls
:meth:`MonitorHub.publish` once per control step, sets :attr:`MonitorHub.scene` when the world
changes (each episode's walls) and reads :attr:`MonitorHub.mode` and
:meth:`MonitorHub.manual_command`; the WebSocket handlers read :meth:`MonitorHub.latest` and
:meth:`MonitorHub.scene_message` and call :meth:`MonitorHub.set_mode` and
:meth:`MonitorHub.set_manual`, naming the client (its connection) so that manual commands are
taken only from the page that selected ``manual``.
"""

from __future__ import annotations

import math
import secrets
import threading
import time
from collections.abc import Hashable, Sequence
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
    :param scene: drawing data sent to every client on connect and again whenever it changes
        (e.g. ``{"walls": [[x1, y1, x2, y2], ...]}`` in m; :attr:`scene`).
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
        self._scene: dict[str, Any] = dict(scene or {})
        self.scene_version = 0
        """Counts the changes of :attr:`scene` (each is sent to every connected client)."""
        self.session = secrets.token_hex(8)
        """This hub's id: a page left open across two robot sessions tells them apart by it."""
        self._manual_owner: Hashable | None = None
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
    def scene(self) -> dict[str, Any]:
        """The drawing data (walls, m); setting a different one counts :attr:`scene_version`
        up, and every connected client is sent it (the driver sets it per episode)."""
        with self._lock:
            return dict(self._scene)

    @scene.setter
    def scene(self, scene: dict[str, Any]) -> None:
        scene = dict(scene)
        with self._lock:
            if scene != self._scene:
                self._scene = scene
                self.scene_version += 1

    def scene_message(self) -> tuple[int, dict[str, Any]]:
        """``(scene_version, message)``: the ``scene`` message a client is sent (the drawing
        data, the mode buttons and the session id), with the version it shows."""
        with self._lock:
            version, scene = self.scene_version, dict(self._scene)
        return version, {
            "type": "scene",
            **scene,
            "modes": self.buttons(),
            "session": self.session,
            "version": version,
        }

    @property
    def mode(self) -> str:
        """The current mode."""
        with self._lock:
            return self._mode

    def set_mode(self, mode: str, client: Hashable | None = None) -> None:
        """Select a mode (``ValueError`` for one not in :attr:`modes`); ``client`` (a
        connection's id) selecting ``manual`` becomes the one whose manual commands are taken."""
        if mode not in self.modes:
            raise ValueError(
                f"mode={mode!r} is out of range: must be one of {', '.join(self.modes)}"
            )
        with self._lock:
            if mode != self._mode:
                self.mode_changes += 1
            self._mode = mode
            if mode == "manual":
                self._manual_owner = client
            else:
                self._manual, self._manual_at = (0.0, 0.0), -math.inf
                self._manual_owner = None

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

    def set_manual(self, v_mps: float, w_radps: float, client: Hashable | None = None) -> None:
        """A manual command, m/s and rad/s (used while the mode is ``manual``).

        :param client: the connection it came from: taken only from the one that selected
            ``manual`` last (``None``: the driver's own process, always taken).
        :raises ValueError: a value out of range, or a client other than that one (another
            page left open must not drive, nor fight the one that does).
        """
        v_max, w_max = MANUAL_LIMITS
        for name, value, limit in (("v_mps", v_mps, v_max), ("w_radps", w_radps, w_max)):
            if not (math.isfinite(value) and abs(value) <= limit):
                raise ValueError(
                    f"{name}={value!r} is out of range: must be in [-{limit}, {limit}]"
                )
        with self._lock:
            if client is not None and (self._mode != "manual" or client != self._manual_owner):
                raise ValueError(
                    "manual commands are taken only from the page that selected manual last "
                    "(select manual on this page to drive from it)"
                )
            self._manual, self._manual_at = (float(v_mps), float(w_radps)), time.monotonic()

    def manual_command(self) -> tuple[float, float]:
        """The newest manual command, or zero once it is older than ``manual_timeout_s``."""
        with self._lock:
            if time.monotonic() - self._manual_at > self.manual_timeout_s:
                return 0.0, 0.0
            return self._manual

    def publish(self, state: dict[str, Any]) -> None:
        """The driver's newest state (JSON-ready values); stamped with ``seq``, ``t_wall`` and
        ``manual_by`` (the id of the client whose manual commands are taken, or ``None``)."""
        with self._lock:
            self._seq += 1
            self._state = {
                "type": "state",
                **state,
                "notice": self._notice,
                "refusals": self.refusals,
                "manual_by": self._manual_owner if self._mode == "manual" else None,
                "seq": self._seq,
                "t_wall": time.time(),
            }

    def latest(self) -> dict[str, Any] | None:
        """The newest state, or ``None`` before the first."""
        with self._lock:
            return None if self._state is None else dict(self._state)

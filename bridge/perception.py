"""Where the runner's observations come from: one interface, three sources.

A source hands the runner a :class:`Frame` at every control step: the published observation
``[distance_m, offset_px]`` (reference §1.4: held when nothing is detected), whether it is a
fresh detection, the reading ahead when the source publishes it (``ahead_m``: the nearest valid
depth across the image's middle row, ``PerceptionConfig.ahead_rays``; an agent trained with it
needs it), and, where the source knows it, ground truth for the step log.

* :class:`SimCamera` (``--perception sim``): the camera of the emulator's simulated world
  (:mod:`bridge.emulator`), over its JSON-lines socket; the robot is the emulated one, so this
  is hardware-in-the-loop on one machine.
* :class:`Replay` (``--perception replay:LOG.csv``): the observations of a step log, in time.
* ``realsense`` (:mod:`bridge.realsense`, the ``realsense`` extra): a RealSense colour and
  depth stream and a YOLO person detector.

:func:`bridge.sources.open_source` builds one from the runner's ``--perception`` value.
"""

from __future__ import annotations

import bisect
import contextlib
import json
import socket
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol
from urllib.parse import urlsplit

import numpy as np

from bridge.address import host_text
from follow_env.sim.steplog import LogLayout, StepLogError, read_columns
from follow_env.tasks.person_follow.steplog import AHEAD_COLUMN, REQUIRED_COLUMNS, TEXT_COLUMNS

__all__ = [
    "Frame",
    "PerceptionError",
    "PerceptionSource",
    "Replay",
    "SimCamera",
    "parse_socket_url",
    "perception_address",
]


def parse_socket_url(url: str) -> tuple[str, int]:
    """``socket://HOST:PORT`` as ``(host, port)``; ``ValueError`` naming the URL otherwise."""
    parts = urlsplit(url)
    try:
        port = parts.port
    except ValueError:  # urllib's own words name neither the URL nor the range's reason
        text = parts.netloc.rpartition(":")[2]
        what = "is out of range" if text.lstrip("+-").isdigit() else "is not a number"
        raise ValueError(f"{url!r}: port {text!r} {what}: must be in 0-65535") from None
    if parts.scheme != "socket" or not parts.hostname or port is None:
        raise ValueError(f"{url!r} is not a socket://HOST:PORT address")
    return parts.hostname, port


def perception_address(url: str) -> tuple[str, int]:
    """Where the emulator at serial URL ``socket://HOST:PORT`` serves its camera: PORT + 1."""
    host, port = parse_socket_url(url)
    return host, port + 1


class PerceptionError(Exception):
    """The perception source failed (unreachable, closed, malformed); the message says which."""


@dataclass(frozen=True)
class Frame:
    """One published observation.

    :param distance_m: filtered distance, m (0: no reading yet).
    :param offset_px: box centre column minus ``width // 2``, px (> 0: right of centre).
    :param detected: a fresh detection (not a held value).
    :param done: the source has nothing more (the replay ended, the world's episode is over).
    :param termination: why it is over, if it is.
    :param truth: ground truth by step-log column name (simulated sources only).
    :param ahead_m: the reading ahead, m (``None``: the source does not publish it).
    """

    distance_m: float
    offset_px: float
    detected: bool
    done: bool = False
    termination: str = ""
    truth: dict[str, float | None] = field(default_factory=dict)
    ahead_m: float | None = None

    def observation(self) -> list[float]:
        """The observation a policy reads: ``[distance_m, offset_px]``, then ``ahead_m`` when
        the frame has it."""
        extra = [] if self.ahead_m is None else [self.ahead_m]
        return [self.distance_m, self.offset_px, *extra]


class PerceptionSource(Protocol):
    """What the runner reads from.

    ``ahead``: the settings of the reading ahead the source publishes (``PerceptionConfig``'s
    ``ahead_rays``, ``ahead_half_angle_deg``, ``ahead_target``), ``None`` if it publishes none,
    or ``"unknown"`` (a replay's log does not say); known after :meth:`start`.
    """

    name: str
    ahead: dict[str, Any] | str | None

    def start(self) -> None:
        """Get ready (connect, reset the world, rewind); called once before the first read."""

    def read(self) -> Frame:
        """The newest frame."""
        ...

    def close(self) -> None:
        """Release everything (idempotent)."""


class SimCamera:
    """The camera of the emulator's world (``HOST:PORT+1`` of its ``socket://HOST:PORT``).

    :param host: the emulator's host.
    :param port: its camera port (the serial port + 1).
    :param seed: reset the world to this seed at :meth:`start` (``None``: the emulator's).
    :param timeout_s: longest wait for an answer, s.
    """

    def __init__(
        self, host: str, port: int, seed: int | None = None, timeout_s: float = 1.0
    ) -> None:
        self.name = "sim"
        self.address = (host, port)
        self.seed = seed
        self.timeout_s = timeout_s
        self._sock: socket.socket | None = None
        self._file: Any = None
        self.info: dict[str, Any] = {}
        self.ahead: dict[str, Any] | str | None = None

    def start(self) -> None:
        try:
            self._sock = socket.create_connection(self.address, timeout=self.timeout_s)
        except OSError as exc:
            host, port = self.address
            raise PerceptionError(
                f"no emulator camera at {host_text(host)}:{port} ({exc.strerror or exc}); start "
                "`follow-robot emulate` first"
            ) from exc
        self._sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self._file = self._sock.makefile("rwb")
        self.info = self._ask({"op": "info"})
        self.ahead = self.info.get("ahead")
        request: dict[str, Any] = {"op": "reset"}
        if self.seed is not None:
            request["seed"] = self.seed
        self._ask(request)

    def read(self) -> Frame:
        reply = self._ask({"op": "frame"})
        truth = {k: v for k, v in reply.items() if k not in _FRAME_KEYS}
        try:
            return Frame(
                float(reply["distance_m"]),
                float(reply["offset_px"]),
                bool(reply["detected"]),
                bool(reply["done"]),
                str(reply["termination"]),
                truth,
                None if reply.get("ahead_m") is None else float(reply["ahead_m"]),
            )
        except KeyError as exc:
            raise PerceptionError(f"the emulator camera's frame has no {exc.args[0]!r}") from None
        except (TypeError, ValueError) as exc:
            raise PerceptionError(f"the emulator camera's frame is malformed: {exc}") from None

    def _ask(self, request: dict[str, Any]) -> dict[str, Any]:
        if self._file is None:
            raise PerceptionError("the sim camera is not started")
        try:
            self._file.write(json.dumps(request).encode() + b"\n")
            self._file.flush()
            line = self._file.readline()
        except OSError as exc:
            raise PerceptionError(f"the emulator camera failed: {exc}") from exc
        if not line:
            raise PerceptionError("the emulator closed its camera connection")
        try:
            reply = json.loads(line)
        except (ValueError, RecursionError):  # JSONDecodeError and bad UTF-8 are ValueErrors
            reply = None
        if not isinstance(reply, dict):
            raise PerceptionError(
                f"the emulator camera sent a malformed reply to {request}: {_excerpt(line)} "
                "(a JSON object was due)"
            )
        if "error" in reply:
            raise PerceptionError(f"the emulator camera refused {request}: {reply['error']}")
        return reply

    def close(self) -> None:
        for part in (self._file, self._sock):
            if part is not None:
                with contextlib.suppress(OSError):
                    part.close()
        self._file = self._sock = None


def _excerpt(line: bytes, limit: int = 80) -> str:
    """The start of a reply, for a message (``repr`` of its text, cut at ``limit`` chars)."""
    text = line.decode("utf-8", "replace").rstrip("\n")
    return repr(text if len(text) <= limit else text[:limit] + "...")


# Not ground truth: the observation itself, and the world's own clock (the log keeps the runner's).
_FRAME_KEYS = frozenset(
    {"distance_m", "offset_px", "ahead_m", "detected", "done", "termination", "time_s", "step"}
)


class Replay:
    """The observations of a step log, replayed in time: at ``t`` seconds after :meth:`start`
    the frame is the last row with ``time_s <= t``; done after the last row.

    :param path: a step log CSV (``time_s``, ``obs_distance_m``, ``obs_offset_px``; ``detected``
        and ``obs_ahead_m``, the reading ahead, optional).
    :raises PerceptionError: naming the file and what is wrong with it.
    """

    def __init__(self, path: str | Path, clock: Any = time.monotonic) -> None:
        self.name = f"replay:{path}"
        self.path = Path(path)
        self._clock = clock
        self._t0 = 0.0
        self.rows = _read_replay(self.path)
        self._times = [row[0] for row in self.rows]  # strictly increasing (read_columns checks)
        # The log holds the reading but not the settings it was taken with.
        self.ahead: dict[str, Any] | str | None = "unknown" if self.rows[0][4] is not None else None

    def start(self) -> None:
        self._t0 = self._clock()

    def read(self) -> Frame:
        t = self._clock() - self._t0 + self.rows[0][0]
        # a bisection, not a scan: an hour's log has 36,000 rows, read ten times a second
        index = max(0, bisect.bisect_right(self._times, t + 1e-9) - 1)
        _, distance, offset, detected, ahead = self.rows[index]
        done = index == len(self.rows) - 1 and t >= self.rows[-1][0]
        return Frame(distance, offset, detected, done, "replay_over" if done else "", {}, ahead)

    def close(self) -> None:
        pass


# A replay needs what the controller reads (time, distance, offset), not the acceleration the
# evaluation's metrics need.
_REPLAY_LAYOUT = LogLayout(REQUIRED_COLUMNS, TEXT_COLUMNS)


def _read_replay(path: Path) -> list[tuple[float, float, float, bool, float | None]]:
    """The replay's rows ``(time_s, distance_m, offset_px, detected, ahead_m)``, read and
    checked by the reader ``follow-eval metrics`` uses (every row as wide as the header: a log
    cut off mid-row is refused, not replayed short), each problem named by file, line and
    column. A blank ``detected`` cell reads as a detection, as a log without the column does;
    a log with the reading ahead needs it in every row."""
    try:
        columns, lines = read_columns(path, _REPLAY_LAYOUT)
    except StepLogError as exc:
        raise PerceptionError(str(exc)) from None
    n = len(columns["time_s"])
    detected = np.asarray(columns.get("detected", np.ones(n)))
    ahead = np.asarray(columns.get(AHEAD_COLUMN, np.full(n, np.nan)))
    if AHEAD_COLUMN in columns and np.isnan(ahead).any():
        # an agent that reads ahead needs the reading on every frame, as on the robot
        line = lines[int(np.flatnonzero(np.isnan(ahead))[0])]
        raise PerceptionError(f"{path}: line {line}, column {AHEAD_COLUMN}: value is missing")
    for name in ("obs_distance_m", "obs_offset_px", AHEAD_COLUMN):
        # a policy reads float32: a finite value beyond its range would reach it as infinity
        values = np.asarray(columns.get(name, []))
        with np.errstate(over="ignore"):
            big = np.flatnonzero(np.isinf(values.astype(np.float32)) & np.isfinite(values))
        if big.size:
            k = int(big[0])
            raise PerceptionError(
                f"{path}: line {lines[k]}, column {name}: {values[k]:g} is out of range: "
                f"must be within +-{float(np.finfo(np.float32).max):g} (the policy reads float32)"
            )
    return [
        (
            float(t),
            float(d),
            float(o),
            bool(np.isnan(seen) or seen > 0.5),
            None if np.isnan(a) else float(a),
        )
        for t, d, o, seen, a in zip(
            columns["time_s"],
            columns["obs_distance_m"],
            columns["obs_offset_px"],
            detected,
            ahead,
            strict=True,
        )
    ]

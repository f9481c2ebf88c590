"""``follow-robot emulate``: the robot's wheel microcontroller and its world, on this machine.

The emulator listens where a robot's serial port would be, speaks either framing as the MCU
(:mod:`bridge.mcu`: the simulator's wheel models under the ``reference`` or the ``fixed``
firmware), and hosts the simulated world around the robot (:mod:`bridge.world`), so that
``follow-robot run --port socket://HOST:PORT --perception sim`` closes the loop on one
machine: the runner's commands turn the emulated wheels, the wheels move the body in the
world, and the world's camera gives the runner its observations.

Two sockets:

* ``socket://HOST:PORT``: the serial line, raw bytes as on the robot's UART (one PC at a
  time; a new connection replaces the old one, as replugging a cable would);
* ``HOST:PORT+1``: the world's camera, one JSON object per line. Requests: ``{"op": "frame"}``
  (the newest frame), ``{"op": "reset", "seed": S}`` (start the episode again; the world then
  waits for the first wheel command, so the person does not walk off before the robot is
  driven), ``{"op": "info"}`` (what is emulated, and the wheels' state), ``{"op": "cut",
  "seconds": S}`` (fault injection: the MCU sends nothing for S seconds, as a loose cable
  would; commands still arrive). A malformed request gets ``{"error": ...}`` and the
  connection stays open.

Time is this machine's monotonic clock. The wheels tick every 10 ms. The world's clock starts
with the first wheel command after a reset and counts whole control periods (0.1 s); the
camera takes its picture when a frame is asked for, bringing the world up to the current
period with the wheels' travel since the last one (as the simulator's step does), so a runner
at the control rate sees every period once.
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import select
import socket
import struct
import sys
import threading
import time
from dataclasses import dataclass
from typing import Any

from bridge.address import host_text, socket_url
from bridge.mcu import FIRMWARES, EmulatedMCU, Firmware
from bridge.perception import parse_socket_url, perception_address
from bridge.protocol import (
    FRAMINGS,
    CommandKind,
    Feedback,
    Framing,
    Hello,
    ReferenceCodec,
    VersionMismatch,
    WheelCommand,
    make_codec,
)
from bridge.protocol.reference import FRAME_LEN, HEADER
from bridge.world import EmulatedWorld
from follow_env.tasks.person_follow.config import THESIS, EnvConfig

__all__ = ["Emulator", "EmulatorStats", "perception_address"]

_IDLE_FLUSH_S = 0.02  # a pending reference frame is decided after this much silence (link.py)
_MAX_REQUEST = 4096  # bytes of one perception request line


@dataclass
class EmulatorStats:
    """What the serial side saw."""

    connections: int = 0
    bytes_received: int = 0
    hellos: int = 0
    version_mismatches: int = 0
    encode_errors: int = 0
    misaligned_blocks: int = 0  # reference firmware: 6-byte blocks without the header
    perception_requests: int = 0
    perception_errors: int = 0


class Emulator:
    """The emulated robot: serial line, MCU, world; run it with :meth:`start` or
    :meth:`serve_forever`.

    :param listen: ``socket://HOST:PORT`` (port 0: any free port, see :attr:`url`).
    :param framing: ``"reference"`` or ``"robust"``.
    :param firmware: ``"reference"`` (the thesis's main.c) or ``"fixed"``.
    :param config: the environment configuration (scenario, noise, the robot's platform).
    :param seed: the world's episode seed.
    """

    def __init__(
        self,
        listen: str = "socket://127.0.0.1:5760",
        framing: Framing = "reference",
        firmware: Firmware = "reference",
        config: EnvConfig | None = None,
        seed: int = 0,
    ) -> None:
        if framing not in FRAMINGS:
            raise ValueError(f"framing={framing!r} is out of range: must be one of {FRAMINGS}")
        if firmware not in FIRMWARES:
            raise ValueError(f"firmware={firmware!r} is out of range: must be one of {FIRMWARES}")
        host, port = parse_socket_url(listen)
        self.framing: Framing = framing
        self.world = EmulatedWorld(config if config is not None else THESIS, seed)
        self.mcu = EmulatedMCU(self.world.robot, firmware, framing, gains=self.world.motor_gains())
        self.stats = EmulatorStats()
        self._t0 = time.monotonic()
        self._serial, self._camera = _listeners(host, port)
        self.host = host
        self._stop = threading.Event()
        self._threads: list[threading.Thread] = []
        self._client: socket.socket | None = None
        self._codec = self._make_codec()
        self._last_rx = 0.0
        self._muted = False
        self._cut_until = -1.0
        self._mcu_lock = threading.Lock()  # the MCU and the world's clock: serial vs camera
        self._arm_world()

    # ---- addresses and life cycle -------------------------------------------------------

    @property
    def url(self) -> str:
        """The serial line's address, ``socket://HOST:PORT`` (an IPv6 host in brackets)."""
        return socket_url(self.host, self._serial.getsockname()[1])

    @property
    def camera_address(self) -> tuple[str, int]:
        """Where the world's camera is served."""
        return self.host, self._camera.getsockname()[1]

    def now(self) -> float:
        """The emulator's clock, s since it started."""
        return time.monotonic() - self._t0

    def start(self) -> Emulator:
        """Serve in background threads (returns at once)."""
        self._threads = [
            threading.Thread(target=self._serve_serial, name="emulator-serial", daemon=True),
            threading.Thread(target=self._serve_camera, name="emulator-camera", daemon=True),
        ]
        for thread in self._threads:
            thread.start()
        return self

    def serve_forever(self) -> None:
        """Serve in this thread until :meth:`stop` (or Ctrl-C)."""
        camera = threading.Thread(target=self._serve_camera, name="emulator-camera", daemon=True)
        camera.start()
        self._threads = [camera]
        try:
            self._serve_serial()
        finally:
            self.stop()

    def stop(self) -> None:
        """Stop serving and close every socket (idempotent)."""
        self._stop.set()
        for thread in self._threads:
            if thread is not threading.current_thread():
                thread.join(timeout=2.0)
        for sock in (self._client, self._serial, self._camera):
            if sock is not None:
                with contextlib.suppress(OSError):
                    sock.close()

    def __enter__(self) -> Emulator:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def mute(self, muted: bool = True) -> None:
        """Stop (or resume) sending anything on the serial line, as a cut cable would."""
        self._muted = muted

    @property
    def muted(self) -> bool:
        """Whether the serial line sends nothing now (:meth:`mute`, or a ``cut`` request)."""
        return self._muted or self.now() < self._cut_until

    # ---- the serial line and the MCU ----------------------------------------------------

    def _arm_world(self) -> None:
        with self._mcu_lock:
            self._world_running = False
            self._world_angles = (0.0, 0.0)
            self._world_t0 = 0.0
            self._world_steps = 0

    def _serve_serial(self) -> None:
        while not self._stop.is_set():
            now = self.now()
            with self._mcu_lock:
                feedback = self.mcu.advance(now)
            self._send(feedback)
            wait = self.mcu.t_tick + self.mcu.tick_s - self.now()
            sockets = [self._serial] + ([self._client] if self._client is not None else [])
            try:
                readable, _, _ = select.select(sockets, [], [], max(0.0, min(wait, 0.05)))
            except (OSError, ValueError):
                if self._stop.is_set():
                    return
                self._drop_client()
                continue
            if self._serial in readable:
                self._accept()
            if self._client is not None and self._client in readable:
                self._receive()
            elif self._idle_flush_due():
                self._handle(self._codec.flush())

    def _camera_frame(self) -> dict[str, Any]:
        """The world brought up to now, in whole control periods, and its newest frame.

        The camera takes its picture when asked (at the runner's control instants), as the
        simulator's step does, so a runner at the control rate sees each period once and no
        older than the simulator would show it. The wheels' travel since the last frame moves
        the body.
        """
        with self._mcu_lock:
            if not self._world_running:
                return self.world.latest()
            now = self.now()
            target = round((now - self._world_t0) / self.world.dt)
            periods = target - self._world_steps
            if periods <= 0:
                return self.world.latest()
            self._world_steps = target
            angles = self.mcu.wheel_angles(now)
            d_r, d_l = angles[0] - self._world_angles[0], angles[1] - self._world_angles[1]
            self._world_angles = angles
        return self.world.step(d_r, d_l, periods)

    def _accept(self) -> None:
        try:
            client, _ = self._serial.accept()
        except OSError:
            return
        self._drop_client()
        client.setblocking(False)
        client.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self._client = client
        self._codec = self._make_codec()
        self.stats.connections += 1

    def _make_codec(self) -> Any:
        if self.framing == "reference" and self.mcu.firmware == "reference":
            return _HalReceive(self.stats)
        return make_codec(self.framing, "mcu")

    def _drop_client(self) -> None:
        if self._client is not None:
            with contextlib.suppress(OSError):
                self._client.close()
        self._client = None

    def _receive(self) -> None:
        assert self._client is not None
        try:
            data = self._client.recv(4096)
        except BlockingIOError:
            return
        except OSError:
            data = b""
        if not data:  # the PC went away; the MCU goes on (the fixed firmware's watchdog stops)
            self._drop_client()
            return
        self.stats.bytes_received += len(data)
        self._last_rx = self.now()
        self._handle(self._codec.feed(data))

    def _idle_flush_due(self) -> bool:
        if not isinstance(self._codec, ReferenceCodec) or isinstance(self._codec, _HalReceive):
            return False
        pending = self._codec.decoder.pending_bytes > 0  # (a _HalReceive never pends)
        return pending and self.now() - self._last_rx >= _IDLE_FLUSH_S

    def _handle(self, items: list[Any]) -> None:
        for item in items:
            if isinstance(item, WheelCommand):
                with self._mcu_lock:
                    now = self.now()
                    if not self._world_running:  # the world's clock starts with the robot
                        self._world_running = True
                        self._world_angles = self.mcu.wheel_angles(now)
                        self._world_t0 = now
                    feedback = self.mcu.command(item, now)
                self._send(feedback)
            elif isinstance(item, Hello):
                self.stats.hellos += 1
                self._send([self.mcu.hello()])
            elif isinstance(item, VersionMismatch):
                self.stats.version_mismatches += 1  # refused, as the firmware does

    def _send(self, messages: list[Feedback] | list[Hello]) -> None:
        if not messages or self._client is None or self.muted:
            return
        try:
            data = b"".join(self._codec.encode(m) for m in messages)
        except ValueError as exc:  # a bug here must not take the emulated robot down
            self.stats.encode_errors += 1
            print(f"emulator: cannot send {messages[0]!r}: {exc}", file=sys.stderr, flush=True)
            return
        try:
            self._client.sendall(data)
        except OSError:
            self._drop_client()

    # ---- the world's camera -------------------------------------------------------------

    def _serve_camera(self) -> None:
        self._camera.settimeout(0.1)
        while not self._stop.is_set():
            try:
                conn, _ = self._camera.accept()
            except TimeoutError:
                continue
            except OSError:
                return
            threading.Thread(
                target=self._camera_client, args=(conn,), name="emulator-camera-client", daemon=True
            ).start()

    def _camera_client(self, conn: socket.socket) -> None:
        conn.settimeout(0.2)
        lines = _RequestLines()
        with conn:
            while not self._stop.is_set():
                try:
                    chunk = conn.recv(4096)
                except TimeoutError:
                    continue
                except OSError:
                    return
                if not chunk:
                    return
                for line in lines.feed(chunk):
                    if line is None:  # one reply per request, an overlong one's too
                        self.stats.perception_errors += 1
                        reply: dict[str, Any] = {
                            "error": f"request longer than {_MAX_REQUEST} bytes"
                        }
                    else:
                        reply = self._answer(line)
                    try:
                        conn.sendall(json.dumps(reply).encode() + b"\n")
                    except OSError:
                        return

    def _answer(self, line: bytes) -> dict[str, Any]:
        self.stats.perception_requests += 1
        try:
            request = json.loads(line)
            if not isinstance(request, dict):
                raise ValueError("a request is a JSON object")
            op = request.get("op")
            if op == "frame":
                return self._camera_frame()
            if op == "reset":
                seed = request.get("seed")
                if seed is not None and (isinstance(seed, bool) or not isinstance(seed, int)):
                    raise ValueError(f"seed={seed!r} must be an integer")
                if seed is not None and not 0 <= seed < 2**256:  # the env's seeds
                    raise ValueError(f"seed={seed} is out of range: must be in [0, 2**256 - 1]")
                self._arm_world()
                frame = self.world.reset(seed)
                self.mcu.gains = self.world.motor_gains()
                return frame
            if op == "info":
                return self._info()
            if op == "cut":
                seconds = request.get("seconds")
                if isinstance(seconds, bool) or not isinstance(seconds, int | float):
                    raise ValueError(f"seconds={seconds!r} must be a number")
                if not 0 <= seconds <= 3600:
                    raise ValueError(f"seconds={seconds} is out of range: must be in [0, 3600]")
                self._cut_until = self.now() + float(seconds)
                return {"cut_s": float(seconds)}
            raise ValueError(
                f"op={op!r} is out of range: must be 'frame', 'reset', 'info' or 'cut'"
            )
        except (ValueError, TypeError, RecursionError) as exc:  # JSONDecodeError: a ValueError
            self.stats.perception_errors += 1  # RecursionError: JSON nested thousands deep
            return {"error": str(exc)}
        except Exception as exc:  # a bug here must not take the camera down with a traceback
            self.stats.perception_errors += 1
            return {"error": f"the emulator could not answer: {type(exc).__name__}: {exc}"}

    def _info(self) -> dict[str, Any]:
        with self._mcu_lock:
            mcu = self.mcu
            wheels = {
                "duty_pct": list(mcu.duty),
                "target_mps": list(mcu.target),
                "omega_radps": list(mcu.omega),
                "watchdog_stopped": mcu.watchdog_stopped,
            }
        return {
            "framing": self.framing,
            "firmware": mcu.firmware,
            "scenario": self.world.config.scenario.name,
            "seed": self.world.seed,
            "control_dt_s": self.world.dt,
            "ahead": self.world.ahead,
            "walls": self.world.walls(),
            "wheels": wheels,
            "mcu": dataclasses.asdict(mcu.stats),
            "serial": dataclasses.asdict(self.stats),
        }


class _RequestLines:
    """Splits the camera's byte stream into request lines of at most :data:`_MAX_REQUEST`
    bytes. An overlong line is given as ``None`` once, and the rest of it, up to its newline,
    is dropped, so that every request gets exactly one reply and the client stays in step."""

    def __init__(self) -> None:
        self._buffer = b""
        self._dropping = False  # inside an overlong line: skip to its newline

    def feed(self, chunk: bytes) -> list[bytes | None]:
        """The complete lines in ``chunk`` with what came before it (``None``: overlong)."""
        out: list[bytes | None] = []
        self._buffer += chunk
        while True:
            end = self._buffer.find(b"\n")
            if self._dropping:
                if end < 0:
                    self._buffer = b""
                    return out
                self._buffer, self._dropping = self._buffer[end + 1 :], False
                continue
            if end < 0:
                if len(self._buffer) > _MAX_REQUEST:  # answered now, not at its newline
                    out.append(None)
                    self._buffer, self._dropping = b"", True
                return out
            line, self._buffer = self._buffer[:end], self._buffer[end + 1 :]
            out.append(None if len(line) > _MAX_REQUEST else line)


class _HalReceive(ReferenceCodec):
    """The reference firmware's receive: ``HAL_UART_Receive(&huart, rx, 6, HAL_MAX_DELAY)``.

    It takes the bytes six at a time as they come, with no search for the header: a block
    that starts with ``A5 A5`` is a command (whole percent duty, right then left, big-endian),
    any other block is ignored (choice: the listing's parse is not given; it is taken to
    check the header). A lost byte therefore misaligns every later block, as on the robot;
    the fixed firmware uses the resynchronising decoder instead.
    """

    def __init__(self, stats: EmulatorStats) -> None:
        super().__init__("mcu", CommandKind.DUTY_PERCENT)
        self._buffer = bytearray()
        self._emulator_stats = stats

    def feed(self, data: bytes | bytearray | memoryview) -> list[Any]:
        self._buffer += data
        self.stats.bytes_received += len(data)
        out: list[Any] = []
        while len(self._buffer) >= FRAME_LEN:
            block = bytes(self._buffer[:FRAME_LEN])
            del self._buffer[:FRAME_LEN]
            if block[:2] != HEADER:
                self._emulator_stats.misaligned_blocks += 1
                self.stats.bytes_skipped += FRAME_LEN
                continue
            right, left = struct.unpack(">hh", block[2:])
            self.stats.frames_ok += 1
            out.append(WheelCommand(right, left, CommandKind.DUTY_PERCENT))
        return out

    def flush(self) -> list[Any]:
        return []


def _listeners(host: str, port: int) -> tuple[socket.socket, socket.socket]:
    """The serial line's listening socket at ``port`` and the camera's at ``port + 1``; with
    port 0, a free pair."""
    for _ in range(50 if port == 0 else 1):
        serial_sock = _listener(host, port)
        try:
            return serial_sock, _listener(host, serial_sock.getsockname()[1] + 1)
        except OSError:
            serial_sock.close()
            if port != 0:
                raise
    raise OSError(f"cannot find two free consecutive ports on {host}")


def _listener(host: str, port: int) -> socket.socket:
    sock = socket.socket(socket.AF_INET6 if ":" in host else socket.AF_INET, socket.SOCK_STREAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    try:
        sock.bind((host, port))
    except OSError as exc:
        sock.close()
        raise OSError(f"cannot listen on {host_text(host)}:{port}: {exc.strerror or exc}") from exc
    sock.listen(1)
    return sock

"""A serial link to the wheel microcontroller (or its emulator), in either framing.

Every transport goes through pyserial's ``serial.serial_for_url``: a real port
(``/dev/ttyUSB0``, ``COM3``) at the reference robot's 115200 baud (reference §1), ``socket://host:port``
(an emulator, a serial-over-TCP bridge), ``loop://`` (tests), or any other URL pyserial knows.

    >>> from bridge import SerialLink, WheelCommand, CommandKind
    >>> with SerialLink("loop://", framing="robust") as link:  # loop:// echoes what we write
    ...     link.send(WheelCommand(1000, -1000, CommandKind.SPEED_MM_S))
    ...     link.receive(timeout_s=0.5)
    [WheelCommand(right=1000, left=-1000, kind=<CommandKind.SPEED_MM_S: 1>)]

Reads never block longer than the timeout the caller gives (0 = return what is there);
writes give up after ``write_timeout_s``. One thread may read while another writes (pyserial
allows it); the link is not meant to be shared otherwise.
"""

from __future__ import annotations

import errno
import math
import socket
import time
from collections import deque
from typing import Any

import serial

from .protocol import (
    Codec,
    Framing,
    Hello,
    LinkStats,
    Message,
    Received,
    ReferenceCodec,
    Role,
    VersionMismatch,
    make_codec,
)

try:  # pyserial's POSIX port drains with termios.tcdrain, whose error is not an OSError
    from termios import error as termios_error
except ImportError:  # Windows
    termios_error = OSError

_PORT_ERRORS = (serial.SerialException, OSError, termios_error)
"""What a port that fails or disappears raises from pyserial's read, write and flush."""

REFERENCE_BAUD = 115200
"""The reference robot's serial speed, baud (reference §1)."""
_READ_CHUNK = 4096  # bytes asked of one non-blocking read


class LinkError(Exception):
    """The serial link failed: it could not be opened, read or written."""


class LinkOpenError(LinkError):
    """The URL could not be opened (unknown scheme, no such port, nobody listening)."""


class IncompatibleVersionError(LinkError):
    """The peer speaks another protocol version: its frames were refused, not decoded.

    :ivar version: the version the peer sent.
    :ivar expected: the version this software speaks.
    """

    def __init__(self, url: str, mismatch: VersionMismatch) -> None:
        self.version = mismatch.version
        self.expected = mismatch.expected
        super().__init__(
            f"{url}: the peer speaks protocol version {mismatch.version}, this software speaks "
            f"version {mismatch.expected}; update the firmware or the software so they match"
        )


class SerialLink:
    """One end of a serial link: encode and write messages, read and decode what arrives.

    :param url: anything ``serial.serial_for_url`` opens: ``/dev/ttyUSB0``,
        ``socket://127.0.0.1:5760``, ``loop://``.
    :param framing: ``"reference"`` (the reference robot's 6-byte frames, reference §1) or
        ``"robust"`` (COBS + version + sequence + CRC-16, for new firmware).
    :param role: ``"pc"`` (sends commands, receives feedback) or ``"mcu"`` (the other end,
        e.g. an emulator that connects out).
    :param baudrate: serial speed in baud for real ports (ignored by ``socket://`` and
        ``loop://``).
    :param write_timeout_s: how long a write may block before it fails, s.
    :param idle_flush_s: reference framing only: when no byte has arrived for this long, s,
        a pending frame is decided as if the stream ended (a frame whose data contains 0xA5
        otherwise waits for the next frame's first bytes: with the reference firmware, which
        sends feedback only after a command, that can be 100 ms). Keep it above the
        receive latency of the adapter (USB-serial chips buffer up to 16 ms); ``None``
        turns it off.
    :param codec: a codec to use instead of ``make_codec(framing, role, **codec_options)``.
    :param codec_options: passed to ``make_codec`` (``command_kind``, ``start_seq``).
    :raises LinkOpenError: the URL cannot be opened; the message names it.
    """

    def __init__(
        self,
        url: str,
        framing: Framing = "reference",
        *,
        role: Role = "pc",
        baudrate: int = REFERENCE_BAUD,
        write_timeout_s: float = 0.1,
        idle_flush_s: float | None = 0.02,
        codec: Codec | None = None,
        **codec_options: object,
    ) -> None:
        if idle_flush_s is not None and not _positive(idle_flush_s):
            raise ValueError(f"idle_flush_s={idle_flush_s} must be a finite number > 0 s or None")
        if not _positive(write_timeout_s):
            raise ValueError(f"write_timeout_s={write_timeout_s} must be a finite number > 0 s")
        self.url = url
        self.codec: Codec = (
            codec if codec is not None else make_codec(framing, role, **codec_options)
        )
        self.framing = self.codec.framing
        self.idle_flush_s = idle_flush_s
        self._inbox: deque[Received] = deque()
        self._last_rx = time.monotonic()
        try:
            # exclusive: a device another link (another follow-robot run) holds is refused; two
            # of them would both command the wheels. pyserial takes a flock on a POSIX device;
            # socket:// and loop:// ignore it.
            self._port = serial.serial_for_url(
                url, baudrate=baudrate, timeout=0, write_timeout=write_timeout_s, exclusive=True
            )
        except (serial.SerialException, ValueError, OSError) as exc:
            # pyserial's flock failed because another holds it (not a file system without locks)
            held = "exclusively lock" in str(exc) and getattr(exc, "errno", None) == errno.EAGAIN
            why = "another program has it open (another follow-robot run?)" if held else exc
            raise LinkOpenError(f"cannot open serial link {url!r}: {why}") from exc
        _no_nagle(self._port)

    # ---- life cycle ---------------------------------------------------------------------

    def close(self) -> None:
        """Close the port (idempotent)."""
        self._port.close()

    @property
    def is_open(self) -> bool:
        """Whether the port is open."""
        return bool(self._port.is_open)

    def __enter__(self) -> SerialLink:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    def __repr__(self) -> str:
        state = "open" if self.is_open else "closed"
        return f"SerialLink({self.url!r}, framing={self.framing!r}, {state})"

    # ---- sending ------------------------------------------------------------------------

    @property
    def stats(self) -> LinkStats:
        """Live counters: the decoder's, plus ``frames_sent`` and ``bytes_sent``."""
        return self.codec.stats

    def send(self, message: Message) -> None:
        """Encode and write one message.

        :raises ValueError: the message cannot be carried by this framing (nothing is sent).
        :raises LinkError: the write failed or timed out.
        """
        data = self.codec.encode(message)
        try:
            written = self._port.write(data)
            self._port.flush()
        except _PORT_ERRORS as exc:
            raise LinkError(f"{self.url}: write failed: {exc}") from exc
        if written != len(data):
            raise LinkError(f"{self.url}: wrote {written} of {len(data)} bytes")
        self.stats.frames_sent += 1
        self.stats.bytes_sent += len(data)

    # ---- receiving ----------------------------------------------------------------------

    def receive(self, timeout_s: float = 0.0) -> list[Message]:
        """Messages received so far, oldest first; waits up to ``timeout_s`` for the first.

        :param timeout_s: longest wait when nothing has arrived, s (0: do not wait).
        :returns: possibly empty.
        :raises IncompatibleVersionError: a frame of another protocol version arrived (the
            messages received before it were returned by the previous call; those after it
            stay queued for the next).
        :raises LinkError: the port failed or the peer closed the connection.
        """
        _check_timeout(timeout_s)
        if not self._inbox:
            self._inbox.extend(self._read(timeout_s))
        out: list[Message] = []
        while self._inbox:
            item = self._inbox[0]
            if isinstance(item, VersionMismatch):
                if out:
                    break  # deliver what came before it first
                self._inbox.popleft()
                raise IncompatibleVersionError(self.url, item)
            out.append(self._inbox.popleft())
        return out

    def handshake(self, hello: Hello, timeout_s: float = 1.0) -> Hello:
        """Send our hello and wait for the peer's (robust framing).

        Messages other than a hello that arrive meanwhile stay queued for :meth:`receive`.

        :returns: the peer's hello (check its role, capabilities and firmware version).
        :raises LinkError: no hello within ``timeout_s`` s, or the framing has none.
        :raises IncompatibleVersionError: the peer speaks another protocol version.
        """
        if isinstance(self.codec, ReferenceCodec):
            raise LinkError(f"{self.url}: the reference framing has no hello (reference §1)")
        _check_timeout(timeout_s)
        self.send(hello)
        deadline = time.monotonic() + timeout_s
        others: list[Message] = []
        try:
            while True:
                batch = self.receive(max(0.0, deadline - time.monotonic()))
                for k, message in enumerate(batch):
                    if isinstance(message, Hello):
                        others.extend(batch[k + 1 :])  # what came after it in the same read
                        return message
                    others.append(message)
                if time.monotonic() >= deadline:
                    raise LinkError(f"{self.url}: no hello from the peer within {timeout_s} s")
        finally:
            self._inbox.extendleft(reversed(others))

    def _read(self, timeout_s: float) -> list[Received]:
        """Read and decode until something is decoded or ``timeout_s`` has passed."""
        deadline = time.monotonic() + timeout_s
        while True:
            data = self._pull(max(0.0, deadline - time.monotonic()))
            now = time.monotonic()
            items = self.codec.feed(data) if data else []
            if data:
                self._last_rx = now
            elif self._idle_flush_due(now):
                items = self.codec.flush()
            if items or now >= deadline:
                return items

    def _idle_flush_due(self, now: float) -> bool:
        # A reference frame whose data contains 0xA5 may wait for the next bytes; after a
        # silence the stream is over for now (reference §1: frames are sent whole, back to back).
        if self.idle_flush_s is None or not isinstance(self.codec, ReferenceCodec):
            return False
        return self.codec.decoder.pending_bytes > 0 and now - self._last_rx >= self.idle_flush_s

    def _pull(self, wait_s: float) -> bytes:
        """What has arrived; if nothing, wait up to ``wait_s`` s for a first byte."""
        port = self._port
        try:
            data = port.read(_READ_CHUNK)  # timeout 0: returns at once with what is there
            if data or wait_s <= 0:
                return bytes(data)
            if self.idle_flush_s is not None and isinstance(self.codec, ReferenceCodec):
                # wake up in time to notice the line has gone idle
                wait_s = min(wait_s, self.idle_flush_s)
            port.timeout = wait_s
            try:
                first = port.read(1)
            finally:
                port.timeout = 0
            if not first:
                return b""
            return bytes(first) + bytes(port.read(_READ_CHUNK))
        except _PORT_ERRORS as exc:
            raise LinkError(f"{self.url}: read failed: {exc}") from exc


def _positive(value: float) -> bool:
    return isinstance(value, (int, float)) and math.isfinite(value) and value > 0


def _check_timeout(timeout_s: float) -> None:
    # NaN passes a `< 0` test and then never reaches the deadline: a read that spins for ever
    if not (isinstance(timeout_s, (int, float)) and math.isfinite(timeout_s) and timeout_s >= 0):
        raise ValueError(f"timeout_s={timeout_s} must be a finite number >= 0 s")


def _no_nagle(port: Any) -> None:
    """Send each frame at once on a ``socket://`` link (pyserial leaves Nagle's algorithm on).

    A serial line sends every byte as it is written. Over TCP, Nagle's algorithm holds a small
    write until the previous one is acknowledged, and the receiver delays an acknowledgement by
    up to 40 ms when it has nothing to send back: commands to the reference firmware, which
    answers only some of them, then arrive in bunches of four, and it answers one per bunch.
    """
    sock = getattr(port, "_socket", None)
    if isinstance(sock, socket.socket) and sock.family in (socket.AF_INET, socket.AF_INET6):
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)

"""The robust framing for new firmware: COBS frames on a 0x00 delimiter, versioned, with a
sequence number and a CRC-16. The C codec in ``firmware/`` speaks exactly this.

**On the wire.** Every frame is sent as ``00 | COBS(frame) | 00``. COBS removes every 0x00
from the frame, so 0x00 only ever delimits. The leading 0x00 ends whatever came before (noise,
a cut frame), so garbage between frames can never swallow the next one; two delimiters in a
row are an empty frame, which is ignored.

**A frame** (before COBS), all multi-byte fields big-endian (the byte order of the reference
protocol, reference §1)::

    offset  size  field
    0       1     protocol version (PROTOCOL_VERSION = 1)
    1       1     message type (MsgType)
    2       2     sequence number, uint16: +1 per frame sent by this end, wrapping 65535 -> 0
    4       n     payload, 0..64 bytes, layout fixed by the type (below)
    4+n     2     CRC-16/CCITT-FALSE of bytes 0 .. 4+n-1, high byte first

CRC-16/CCITT-FALSE (also catalogued as CRC-16/IBM-3740): polynomial 0x1021, initial value
0xFFFF, no input or output reflection, final XOR 0x0000; check value 0x29B1 for the ASCII
bytes ``123456789``. Sent high byte first, the CRC of a whole intact frame (CRC included) is 0.

The envelope (delimiters, COBS, version first, CRC last, at most ``MAX_FRAME`` bytes before
COBS) is frozen for every protocol version; only what sits between may change. So a frame of
another version is always recognised as such and refused (``VersionMismatch``), never
decoded under the wrong schema, as MAVLink refuses messages of another dialect.

**Payloads** (version 1)::

    HELLO (0x01), 7 bytes:   role u8 (1 = PC, 2 = MCU), capabilities u8 (Capability bits),
                             feedback period u16 ms, firmware major u8, minor u8, patch u8
    WHEEL_COMMAND (0x02), 5: kind u8 (0 = duty in 0.01 %, 1 = speed target in mm/s),
                             right int16, left int16
    FEEDBACK (0x03), 17:     right speed int16 mm/s, left speed int16 mm/s,
                             right count int32, left count int32 (encoder counts, 4x mode),
                             MCU time uint32 ms, status u8 (bit 0: watchdog stop)

A receiver checks, in this order: COBS, length (at least the 6 bytes of the envelope),
CRC, version, then the sequence number (on every intact frame of our version, whatever its
type), then the type and payload length. The first failure drops the frame and counts it.

Library choice: COBS comes from the PyPI ``cobs`` package (a C extension with a pure-Python
fallback; COBS byte by byte in Python would be the slowest part of the decoder). The CRC
comes from the standard library: ``binascii.crc_hqx(data, 0xFFFF)`` is exactly
CRC-16/CCITT-FALSE, in C, with no dependency; the PyPI ``crc`` package computes the same
in pure Python, much slower.
"""

from __future__ import annotations

import binascii
import struct
from enum import IntEnum

from cobs import cobs

from .messages import (
    UINT8_MAX,
    UINT16_MAX,
    Capability,
    CommandKind,
    Feedback,
    Hello,
    Message,
    PeerRole,
    Received,
    Role,
    VersionMismatch,
    WheelCommand,
    check_range,
)
from .stats import LinkStats

PROTOCOL_VERSION = 1
"""The schema version this software speaks (byte 0 of every frame)."""
DELIMITER = 0x00
HEADER_LEN = 4
"""version, type, sequence number (2): bytes."""
CRC_LEN = 2
MAX_PAYLOAD = 64
"""Largest payload of any version, bytes (frozen with the envelope)."""
MAX_FRAME = HEADER_LEN + MAX_PAYLOAD + CRC_LEN
"""Largest frame before COBS, bytes (70)."""
MAX_ENCODED = MAX_FRAME + 1
"""Largest frame after COBS, delimiters excluded, bytes: COBS adds one byte per 254, and
frames are shorter than 254."""
MIN_FRAME = HEADER_LEN + CRC_LEN


class MsgType(IntEnum):
    """The message type byte (byte 1 of a frame)."""

    HELLO = 0x01
    WHEEL_COMMAND = 0x02
    FEEDBACK = 0x03


_HEADER = struct.Struct(">BBH")
_CRC = struct.Struct(">H")
_HELLO = struct.Struct(">BBHBBB")
_COMMAND = struct.Struct(">Bhh")
_FEEDBACK = struct.Struct(">hhiiIB")
PAYLOAD_LEN = {MsgType.HELLO: _HELLO.size, MsgType.WHEEL_COMMAND: 5, MsgType.FEEDBACK: 17}
"""Payload length of each message type, bytes."""
_WIRE_KINDS = (CommandKind.DUTY_CENTI_PERCENT, CommandKind.SPEED_MM_S)


def crc16_ccitt_false(data: bytes | bytearray | memoryview, crc: int = 0xFFFF) -> int:
    """CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF, no reflection, xorout 0) of ``data``.

    :param crc: running value, to continue a CRC over several pieces.
    """
    return binascii.crc_hqx(data, crc)


def encode_frame(
    msg_type: int, seq: int, payload: bytes = b"", *, version: int = PROTOCOL_VERSION
) -> bytes:
    """One frame on the wire: ``00 | COBS(version, type, seq, payload, CRC) | 00``.

    :param msg_type: message type byte (any uint8: unknown types are the receiver's problem).
    :param seq: sequence number, uint16.
    :param payload: 0..``MAX_PAYLOAD`` bytes.
    :param version: protocol version byte; anything but ``PROTOCOL_VERSION`` is for tests and
        emulating other firmware.
    :returns: the bytes to write, ``len(payload) + 9`` of them.
    """
    check_range("frame", "msg_type", msg_type, 0, UINT8_MAX)
    check_range("frame", "seq", seq, 0, UINT16_MAX)
    check_range("frame", "version", version, 0, UINT8_MAX)
    if len(payload) > MAX_PAYLOAD:
        raise ValueError(f"payload of {len(payload)} bytes is too long: at most {MAX_PAYLOAD}")
    body = _HEADER.pack(version, msg_type, seq) + bytes(payload)
    raw = body + _CRC.pack(crc16_ccitt_false(body))
    return b"\x00" + cobs.encode(raw) + b"\x00"


def pack_message(message: Message) -> tuple[MsgType, bytes]:
    """The type and payload of a message (layouts in the module docstring)."""
    if isinstance(message, WheelCommand):
        if message.kind not in _WIRE_KINDS:
            raise ValueError(
                f"the robust framing carries duty in 0.01 % (DUTY_CENTI_PERCENT) or speed "
                f"targets (SPEED_MM_S), not {message.kind.name}: multiply percent by 100"
            )
        return MsgType.WHEEL_COMMAND, _COMMAND.pack(message.kind, message.right, message.left)
    if isinstance(message, Feedback):
        missing = [
            name
            for name in ("right_count", "left_count", "mcu_time_ms", "status")
            if getattr(message, name) is None
        ]
        if missing:
            raise ValueError(f"robust feedback needs every field; missing: {', '.join(missing)}")
        payload = _FEEDBACK.pack(
            message.right_mm_s,
            message.left_mm_s,
            message.right_count,
            message.left_count,
            message.mcu_time_ms,
            message.status,
        )
        return MsgType.FEEDBACK, payload
    if isinstance(message, Hello):
        major, minor, patch = message.firmware_version
        payload = _HELLO.pack(
            message.role, int(message.capabilities), message.feedback_period_ms, major, minor, patch
        )
        return MsgType.HELLO, payload
    raise TypeError(f"cannot encode {type(message).__name__}: not a message")


def unpack_message(msg_type: int, payload: bytes) -> Message | None:
    """The message in a payload, or ``None`` if the type is unknown, the length wrong for
    the type, or a field holds a value no sender may send (a command kind, a hello role)."""
    try:
        kind = MsgType(msg_type)
    except ValueError:
        return None
    if len(payload) != PAYLOAD_LEN[kind]:
        return None
    if kind is MsgType.FEEDBACK:
        return Feedback(*_FEEDBACK.unpack(payload))
    if kind is MsgType.WHEEL_COMMAND:
        wire_kind, right, left = _COMMAND.unpack(payload)
        if wire_kind not in _WIRE_KINDS:
            return None
        return WheelCommand(right, left, CommandKind(wire_kind))
    role, caps, period, major, minor, patch = _HELLO.unpack(payload)
    if role not in (PeerRole.PC, PeerRole.MCU):
        return None
    return Hello(PeerRole(role), Capability(caps), period, (major, minor, patch))


def encode_message(message: Message, seq: int) -> bytes:
    """``encode_frame`` of ``pack_message(message)`` with sequence number ``seq``."""
    msg_type, payload = pack_message(message)
    return encode_frame(msg_type, seq, payload)


class RobustDecoder:
    """Streaming decoder of robust frames: feed any chunks, get messages and refusals.

    **Guarantee.** Every frame that arrives intact between its own delimiters is decoded, in
    order, whatever garbage lies between frames (the leading delimiter ends it). Garbage
    yields a false message only if some run of it between two 0x00 passes COBS, the CRC-16
    (1 in 65536 for random bytes), the version byte and the type's exact payload length;
    a corrupted frame is dropped and counted, never decoded to other values unless the
    corruption happens to keep the CRC (1 in 65536 for errors longer than 16 bits; never
    for a burst of 16 bits or fewer in the frame before COBS).

    ``feed`` returns messages and, for intact frames of another protocol version,
    :class:`VersionMismatch` events: the caller must treat those as an incompatible peer.

    :ivar stats: ``frames_ok``, ``bytes_received``, ``bytes_skipped``, ``crc_failures``,
        ``false_frames``, ``oversized_frames``, ``version_mismatches``, ``seq_gaps``,
        ``frames_lost``, ``seq_resets``.
    :ivar last_seq: sequence number of the last intact frame, or ``None``.
    """

    def __init__(self) -> None:
        self.stats = LinkStats()
        self.last_seq: int | None = None
        self._run = bytearray()  # encoded bytes of the frame being received (at most MAX_ENCODED)
        self._run_len = 0  # its length, counting bytes dropped from an oversized run

    def feed(self, data: bytes | bytearray | memoryview) -> list[Received]:
        """Add received bytes; return what completed, oldest first."""
        data = bytes(data)
        self.stats.bytes_received += len(data)
        out: list[Received] = []
        start = 0
        while True:
            zero = data.find(b"\x00", start)
            piece = data[start:] if zero < 0 else data[start:zero]
            if piece:
                room = MAX_ENCODED + 1 - len(self._run)  # one more marks the run oversized
                if room > 0:
                    self._run += piece[:room]
                self._run_len += len(piece)
            if zero < 0:
                return out
            self._end_run(out)
            start = zero + 1

    def flush(self) -> list[Received]:
        """The stream ended: a partial frame is counted as skipped. Returns ``[]`` (a robust
        frame is complete at its delimiter, so nothing is ever pending)."""
        self.stats.bytes_skipped += self._run_len
        self._run.clear()
        self._run_len = 0
        return []

    def _end_run(self, out: list[Received]) -> None:
        n = self._run_len
        run = bytes(self._run)
        self._run.clear()
        self._run_len = 0
        if n == 0:
            return  # an empty frame: two delimiters in a row
        stats = self.stats
        if n > MAX_ENCODED:
            stats.oversized_frames += 1
            stats.bytes_skipped += n + 1
            return
        try:
            raw = cobs.decode(run)
        except cobs.DecodeError:
            raw = b""
        if len(raw) < MIN_FRAME:
            stats.false_frames += 1
            stats.bytes_skipped += n + 1
            return
        (crc,) = _CRC.unpack_from(raw, len(raw) - CRC_LEN)
        if crc16_ccitt_false(raw[:-CRC_LEN]) != crc:
            stats.crc_failures += 1
            stats.bytes_skipped += n + 1
            return
        version, msg_type, seq = _HEADER.unpack_from(raw)
        if version != PROTOCOL_VERSION:
            stats.version_mismatches += 1
            stats.bytes_skipped += n + 1
            out.append(VersionMismatch(version, PROTOCOL_VERSION, msg_type))
            return
        self._track(msg_type, seq)
        message = unpack_message(msg_type, raw[HEADER_LEN:-CRC_LEN])
        if message is None:
            stats.false_frames += 1
            stats.bytes_skipped += n + 1
            return
        stats.frames_ok += 1
        out.append(message)

    def _track(self, msg_type: int, seq: int) -> None:
        """Count lost frames from the sequence numbers (modulo 2^16)."""
        if msg_type == MsgType.HELLO:
            self.last_seq = None  # a hello starts a new sequence (the peer has (re)started)
        if self.last_seq is not None:
            delta = (seq - self.last_seq) & 0xFFFF
            if 2 <= delta <= 0x8000:
                self.stats.seq_gaps += 1
                self.stats.frames_lost += delta - 1
            elif delta != 1:  # 0 (repeated) or backwards: a restart without hello
                self.stats.seq_resets += 1
        self.last_seq = seq


class RobustCodec:
    """The robust framing for one end of a link: numbers what it sends, decodes what comes.

    :param role: ``"pc"`` or ``"mcu"``; either end may send any message (the role says who
        is expected to send what, and what :meth:`hello` announces).
    :param start_seq: sequence number of the first frame sent, uint16.
    """

    framing = "robust"

    def __init__(self, role: Role = "pc", start_seq: int = 0) -> None:
        if role not in ("pc", "mcu"):
            raise ValueError(f"role={role!r} must be 'pc' or 'mcu'")
        self.role: Role = role
        self.next_seq = check_range("RobustCodec", "start_seq", start_seq, 0, UINT16_MAX)
        self.decoder = RobustDecoder()

    @property
    def stats(self) -> LinkStats:
        """The decoder's counters."""
        return self.decoder.stats

    def encode(self, message: Message) -> bytes:
        """The bytes for ``message`` with the next sequence number (then +1, wrapping)."""
        data = encode_message(message, self.next_seq)
        self.next_seq = (self.next_seq + 1) & 0xFFFF
        return data

    def feed(self, data: bytes | bytearray | memoryview) -> list[Received]:
        """Decode received bytes (see :class:`RobustDecoder`)."""
        return self.decoder.feed(data)

    def flush(self) -> list[Received]:
        """End of stream (see :meth:`RobustDecoder.flush`)."""
        return self.decoder.flush()

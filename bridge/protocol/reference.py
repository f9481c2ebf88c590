"""The reference robot's framing, exactly as its firmware speaks it (reference §1).

Both directions use the same 6-byte frame, with no checksum and no length::

    A5 A5 | right int16 big-endian | left int16 big-endian

PC -> MCU: the two motor commands (the reference firmware reads whole percent duty, clamped to
+-99 by its driver). MCU -> PC, every 10 ms: the two encoder speeds, mm/s.

Without a checksum a decoder can only go by where ``A5 A5`` appears, and ``A5 A5`` can appear
inside the data. :class:`ReferenceDecoder` documents exactly what it recovers and where it can
be fooled; read its docstring before relying on this framing. New firmware should use the
robust framing (``bridge.protocol.robust``).
"""

from __future__ import annotations

import struct

from .messages import (
    INT16_MAX,
    INT16_MIN,
    CommandKind,
    Feedback,
    Hello,
    Message,
    Role,
    WheelCommand,
    check_range,
)
from .stats import LinkStats

HEADER = b"\xa5\xa5"
"""The two header bytes of every reference frame (reference §1)."""
FRAME_LEN = 6
"""Bytes in a reference frame: 2 header + 2 x int16."""
_A5 = 0xA5
_FRAME = struct.Struct(">2shh")  # big-endian, as the reference firmware writes it (reference §1)
_COMPACT_BYTES = 1 << 16  # drop consumed bytes from the buffer once this many have piled up


def encode_reference(right: int, left: int) -> bytes:
    """One reference frame: ``A5 A5``, then ``right`` and ``left`` as big-endian int16.

    :param right: right wheel value (command or encoder speed), int16.
    :param left: left wheel value, int16.
    :returns: 6 bytes.
    """
    check_range("reference frame", "right", right, INT16_MIN, INT16_MAX)
    check_range("reference frame", "left", left, INT16_MIN, INT16_MAX)
    return _FRAME.pack(HEADER, right, left)


class _NeedMoreError(Exception):
    """The decision needs a byte that has not arrived yet."""


class ReferenceDecoder:
    """Streaming decoder of reference frames: feed any chunks, get ``(right, left)`` pairs.

    **How it decides.** Every ``A5 A5`` followed by 4 more bytes is a *candidate*. A
    candidate at byte ``p`` is

    * *confirmed* if another ``A5 A5`` starts 6 bytes later, at ``p + 6`` (the next frame's
      header), or the stream ends (``flush``) exactly at ``p + 6``;
    * *suspect* if the high byte of either of its values is ``0xA5``: every candidate that
      starts 1 to 4 bytes before a real frame's header carries that header in its data, which
      puts ``0xA5`` in a high byte; and a high byte ``0xA5`` is a value in -23296..-23041,
      far outside any speed (mm/s) or duty (%) of the reference robot;
    * *locked* if it starts exactly where the previously accepted frame ended, or at the
      start of the stream (a stream is assumed to start with a frame; so is one after
      ``flush``).

    Candidates are taken left to right. A candidate with no other ``A5 A5`` starting inside
    it (at bytes 1..5) is accepted at once, as soon as its 6 bytes are in (one more byte if
    its byte 5 is 0xA5): a frame without 0xA5 in its data costs no latency. Otherwise a locked
    and confirmed candidate is accepted (a running stream of frames is never broken by what
    its data contains); failing that, it is rejected (counted in ``false_frames``) if an
    overlapping later candidate ranks at least as high by (not suspect, confirmed), and
    accepted if none does. Ties go to the later candidate: a cut frame is followed by the
    frame sent after it. A decision needs at most 13 bytes from the candidate's start (one
    frame more); ``flush()`` decides the rest as if the stream ended there.

    **Guarantees** (property-tested in ``tests/bridge/test_reference.py``). Call a value
    *plausible* if its high byte is not ``0xA5`` (every int16 but -23296..-23041, which no
    speed or duty of the reference robot comes near).

    1. A stream of frames without garbage is decoded exactly, whatever the values (-23131 =
       ``0xA5A5``, a low byte ``A5`` followed by a high byte ``A5``, ``A5`` runs across
       frames): the stream is locked from its first byte and stays locked.
    2. Frames with plausible values, interleaved anywhere with *noise* (any bytes but 0xA5,
       any length) and *cut frames* (the first 1 to 5 bytes of a frame, e.g. a frame
       interrupted by a reset or a reconnect), are all recovered, in order, with no false
       frame, provided every cut frame is followed directly by a whole frame, that frame by
       another frame, a cut frame or the end of the stream (so it is confirmed), and a cut
       frame of 1 byte (a lone ``A5``) not by a frame whose left low byte is 0xA5 (below).
    3. Chunking does not matter: every split of the same bytes gives the same frames.

    **Where it can be fooled.** Without a checksum these streams are ambiguous: the bytes
    are consistent with two readings, and no decoder can know which was sent.

    * Garbage that contains ``A5 A5`` and 4 more bytes, not overlapping a real frame, is a
      frame as far as any decoder can tell: it is emitted (a false frame). Random bytes do
      this about once per 64 KiB; a cut frame followed by noise does it too.
    * A cut frame followed by a frame that is itself followed by noise (not confirmed):
      ``A5 A5 a b c`` + ``A5 A5 d e f g`` + noise reads equally as ``A5 A5 a b c A5`` (a frame
      whose left low byte is 0xA5) + garbage. The later candidate wins the tie, which is
      right for a cut frame; in the other reading a frame is lost and a false one emitted.
    * A lone ``A5`` of garbage directly before a frame whose left low byte is 0xA5 and which
      is followed by a header: the alignment one byte early is as well confirmed as the true
      one, and wins when locked (straight after a frame, or at the start). Frames are then
      read one byte early (false values, the true frames lost) until a frame whose left low
      byte is not 0xA5 ends it.
    * Frames with implausible values next to garbage lose to a plausible alignment that
      straddles them.

    :ivar stats: counters: ``frames_ok``, ``bytes_received``, ``bytes_skipped`` (bytes
        outside accepted frames), ``false_frames`` (candidates rejected).
    """

    def __init__(self) -> None:
        self.stats = LinkStats()
        self._buf = bytearray()
        self._base = 0  # absolute stream offset of self._buf[0]
        self._pos = 0  # absolute offset where the search for the next candidate starts
        self._skip_from = 0  # absolute offset from which bytes are not yet counted
        # Absolute end of the last accepted frame: the lock. The start of the stream counts as
        # one, so a stream that starts with a frame is locked from its first byte.
        self._last_end = 0
        self._final = False

    # ---- public -------------------------------------------------------------------------

    def feed(self, data: bytes | bytearray | memoryview) -> list[tuple[int, int]]:
        """Add received bytes; return the frames that are now decided, oldest first.

        :param data: any number of bytes (an empty chunk is fine).
        :returns: ``(right, left)`` int16 pairs.
        """
        self._buf += data
        self.stats.bytes_received += len(data)
        return self._run()

    def flush(self) -> list[tuple[int, int]]:
        """The stream ended (or paused: nothing continues across this point).

        Decides every pending candidate as if no byte followed, returns the frames, counts
        the rest as skipped and starts afresh (no lock) with the next byte fed.
        """
        self._final = True
        try:
            frames = self._run()
        finally:
            self._final = False
        end = self._base + len(self._buf)
        self.stats.bytes_skipped += end - self._skip_from
        self._buf.clear()
        self._base = self._pos = self._skip_from = self._last_end = end
        return frames

    @property
    def pending_bytes(self) -> int:
        """Bytes received but not yet decided (a partial or undecided frame), bytes."""
        return self._base + len(self._buf) - self._pos

    # ---- the decision -------------------------------------------------------------------

    def _run(self) -> list[tuple[int, int]]:
        frames: list[tuple[int, int]] = []
        buf = self._buf
        while True:
            end = self._base + len(buf)
            i = buf.find(HEADER, self._pos - self._base)
            if i < 0:
                # No header: all but a trailing A5 (which may start one) is garbage.
                keep = 1 if (not self._final and buf and buf[-1] == _A5) else 0
                self._pos = max(self._pos, end - keep)
                break
            p = self._base + i
            if p + FRAME_LEN > end:
                if self._final:  # no complete candidate can follow
                    self._pos = end
                else:
                    self._pos = p
                break
            try:
                accept = self._decide(p)
            except _NeedMoreError:
                self._pos = p
                break
            if accept:
                _, right, left = _FRAME.unpack_from(buf, i)
                frames.append((right, left))
                self.stats.frames_ok += 1
                self.stats.bytes_skipped += p - self._skip_from
                self._skip_from = self._pos = self._last_end = p + FRAME_LEN
            else:
                self.stats.false_frames += 1
                self._pos = p + 1
        # No later frame can start before _pos: count what lies behind it now, so the link
        # statistics show garbage as it arrives.
        self.stats.bytes_skipped += self._pos - self._skip_from
        self._skip_from = self._pos
        self._compact()
        return frames

    def _compact(self) -> None:
        drop = self._pos - self._base
        if drop >= _COMPACT_BYTES:
            del self._buf[:drop]
            self._base += drop

    def _byte(self, k: int) -> int:
        """Stream byte at absolute offset ``k``; -1 past the end of a flushed stream."""
        idx = k - self._base
        if idx < len(self._buf):
            return self._buf[idx]
        if self._final:
            return -1
        raise _NeedMoreError

    def _header_at(self, p: int) -> bool:
        return self._byte(p) == _A5 and self._byte(p + 1) == _A5

    def _candidate_at(self, p: int) -> bool:
        return self._header_at(p) and self._byte(p + FRAME_LEN - 1) >= 0

    def _confirmed(self, p: int) -> bool:
        nxt = self._byte(p + FRAME_LEN)
        if nxt < 0:  # a candidate is complete, so the stream ends exactly at p + 6
            return True
        return nxt == _A5 and self._byte(p + FRAME_LEN + 1) == _A5

    def _rank(self, p: int) -> tuple[bool, bool]:
        suspect = self._byte(p + 2) == _A5 or self._byte(p + 4) == _A5
        return (not suspect, self._confirmed(p))

    def _decide(self, p: int) -> bool:
        """Accept (True) or reject (False) the candidate at ``p``; may raise ``_NeedMoreError``."""
        rivals = [q for q in range(p + 1, p + FRAME_LEN) if self._header_at(q)]
        if not rivals:
            return True
        if p == self._last_end and self._confirmed(p):
            return True
        rank = self._rank(p)
        return not any(self._candidate_at(q) and self._rank(q) >= rank for q in rivals)


class ReferenceCodec:
    """The reference framing for one end of a link (see :class:`ReferenceDecoder`).

    :param role: ``"pc"`` decodes :class:`Feedback` (speeds, mm/s); ``"mcu"`` decodes
        :class:`WheelCommand`.
    :param command_kind: what the firmware at the MCU end does with the two command values;
        the wire does not say. The reference firmware reads whole percent duty
        (``CommandKind.DUTY_PERCENT``, reference §1).
    """

    framing = "reference"

    def __init__(self, role: Role = "pc", command_kind: CommandKind = CommandKind.DUTY_PERCENT):
        if role not in ("pc", "mcu"):
            raise ValueError(f"role={role!r} must be 'pc' or 'mcu'")
        self.role: Role = role
        self.command_kind = CommandKind(command_kind)
        self.decoder = ReferenceDecoder()

    @property
    def stats(self) -> LinkStats:
        """The decoder's counters."""
        return self.decoder.stats

    def encode(self, message: Message) -> bytes:
        """6 bytes for a :class:`WheelCommand` (of this codec's ``command_kind``) or a
        :class:`Feedback` (its two speeds; counts, time and status cannot be carried)."""
        if isinstance(message, WheelCommand):
            if message.kind != self.command_kind:
                raise ValueError(
                    f"the reference framing carries {self.command_kind.name} commands here "
                    f"(the firmware's unit; the wire cannot say), got {message.kind.name}"
                )
            return encode_reference(message.right, message.left)
        if isinstance(message, Feedback):
            return encode_reference(message.right_mm_s, message.left_mm_s)
        if isinstance(message, Hello):
            raise ValueError("the reference framing has no hello message (reference §1)")
        raise TypeError(f"cannot encode {type(message).__name__}: not a message")

    def feed(self, data: bytes | bytearray | memoryview) -> list[Message]:
        """Decode received bytes into messages of the other end (see ``role``)."""
        return self._wrap(self.decoder.feed(data))

    def flush(self) -> list[Message]:
        """Decide pending bytes as if the stream ended (see :meth:`ReferenceDecoder.flush`)."""
        return self._wrap(self.decoder.flush())

    def _wrap(self, pairs: list[tuple[int, int]]) -> list[Message]:
        if self.role == "pc":
            return [Feedback(right, left) for right, left in pairs]
        return [WheelCommand(right, left, self.command_kind) for right, left in pairs]

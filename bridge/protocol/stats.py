"""Per-link counters, shared by both framings (fields a framing cannot observe stay 0)."""

from __future__ import annotations

from dataclasses import asdict, dataclass


@dataclass(slots=True)
class LinkStats:
    """What a decoder (and the link around it) has seen so far. All counts since creation.

    :param frames_ok: frames decoded and handed to the caller.
    :param bytes_received: bytes fed to the decoder, bytes.
    :param bytes_skipped: received bytes that were not part of a frame handed to the caller
        (garbage, cut frames, rejected frames, their delimiters), bytes. Lone 0x00 delimiters
        of the robust framing (empty frames, sent before every frame) are not counted.
    :param crc_failures: robust framing: frames whose CRC-16 did not match.
    :param false_frames: frames rejected as not real. Reference framing: ``A5 A5`` headers
        that were candidates but lost to an overlapping, better-supported alignment. Robust
        framing: runs that are not valid COBS, too short for the envelope, or of an unknown
        message type / wrong payload length for their type.
    :param oversized_frames: robust framing: runs longer than the largest frame, dropped.
    :param version_mismatches: robust framing: intact frames of another protocol version,
        refused.
    :param seq_gaps: robust framing: times the sequence number jumped forward by more than one.
    :param frames_lost: robust framing: frames missing according to the sequence numbers (the
        sum of the jumps minus one), modulo 2^16.
    :param seq_resets: robust framing: sequence numbers that repeated or went backwards
        (the peer restarted without a hello); not counted as lost.
    :param frames_sent: frames written by the link (link-level; 0 in a bare decoder).
    :param bytes_sent: bytes written by the link, bytes.
    """

    frames_ok: int = 0
    bytes_received: int = 0
    bytes_skipped: int = 0
    crc_failures: int = 0
    false_frames: int = 0
    oversized_frames: int = 0
    version_mismatches: int = 0
    seq_gaps: int = 0
    frames_lost: int = 0
    seq_resets: int = 0
    frames_sent: int = 0
    bytes_sent: int = 0

    def as_dict(self) -> dict[str, int]:
        """The counters as a plain dict (for logs, JSON and the web monitor)."""
        return asdict(self)

    def copy(self) -> LinkStats:
        """A snapshot that does not change as the link goes on."""
        return LinkStats(**asdict(self))

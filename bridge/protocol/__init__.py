"""The serial link's protocol: messages, the two framings and their statistics.

Two framings, selectable by name, behind one interface (:class:`Codec`):

* ``"reference"``: the reference robot's 6-byte ``A5 A5`` frames, exactly (reference §1);
* ``"robust"``: COBS frames with a version byte, a sequence number and a CRC-16, for new
  firmware (the C codec in ``firmware/`` is its MCU side).

    >>> from bridge.protocol import make_codec, WheelCommand, CommandKind
    >>> pc, mcu = make_codec("robust", role="pc"), make_codec("robust", role="mcu")
    >>> mcu.feed(pc.encode(WheelCommand(2500, -2500, CommandKind.DUTY_CENTI_PERCENT)))
    [WheelCommand(right=2500, left=-2500, kind=<CommandKind.DUTY_CENTI_PERCENT: 0>)]
"""

from __future__ import annotations

from typing import Literal, Protocol

from .messages import (
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
)
from .reference import ReferenceCodec, ReferenceDecoder, encode_reference
from .robust import (
    PROTOCOL_VERSION,
    MsgType,
    RobustCodec,
    RobustDecoder,
    crc16_ccitt_false,
    encode_frame,
    encode_message,
    pack_message,
    unpack_message,
)
from .stats import LinkStats

Framing = Literal["reference", "robust"]
FRAMINGS: tuple[Framing, ...] = ("reference", "robust")


class Codec(Protocol):
    """One end of a link in one framing: encode what it sends, decode what it receives."""

    framing: str
    role: Role

    @property
    def stats(self) -> LinkStats:
        """The decoder's counters."""
        ...

    def encode(self, message: Message) -> bytes:
        """The bytes to write for ``message``."""
        ...

    def feed(self, data: bytes | bytearray | memoryview) -> list[Received]:
        """Received bytes in, decided messages (and refusals) out, oldest first."""
        ...

    def flush(self) -> list[Received]:
        """Decide what is pending as if the stream ended here."""
        ...


def make_codec(framing: Framing, role: Role = "pc", **options: object) -> Codec:
    """A codec by framing name.

    :param framing: ``"reference"`` or ``"robust"``.
    :param role: ``"pc"`` or ``"mcu"``.
    :param options: passed on: ``command_kind`` (reference), ``start_seq`` (robust).
    """
    if framing not in _OPTIONS:
        raise ValueError(f"framing={framing!r} is unknown: choose one of {', '.join(FRAMINGS)}")
    for name in options:
        if name not in _OPTIONS[framing]:
            allowed = ", ".join(_OPTIONS[framing])
            raise ValueError(
                f"option {name!r} does not apply to the {framing} framing (it takes: {allowed})"
            )
    if framing == "reference":
        return ReferenceCodec(role, **options)  # type: ignore[arg-type]
    return RobustCodec(role, **options)  # type: ignore[arg-type]


_OPTIONS: dict[str, tuple[str, ...]] = {"reference": ("command_kind",), "robust": ("start_seq",)}


__all__ = [
    "FRAMINGS",
    "PROTOCOL_VERSION",
    "Capability",
    "Codec",
    "CommandKind",
    "Feedback",
    "Framing",
    "Hello",
    "LinkStats",
    "Message",
    "MsgType",
    "PeerRole",
    "Received",
    "ReferenceCodec",
    "ReferenceDecoder",
    "RobustCodec",
    "RobustDecoder",
    "Role",
    "VersionMismatch",
    "WheelCommand",
    "crc16_ccitt_false",
    "encode_frame",
    "encode_message",
    "encode_reference",
    "make_codec",
    "pack_message",
    "unpack_message",
]

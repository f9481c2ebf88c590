"""The bridge between PersonFollow and a real (or emulated) robot: the serial link.

A leaf package: it imports numpy at most, never the simulator, training or evaluation, so it
runs on a robot's PC with nothing else installed.

* ``bridge.protocol``: messages, the reference framing (reference §1) and the robust framing,
  streaming decoders and their statistics;
* ``bridge.link``: :class:`SerialLink`, either framing over any pyserial URL.

The MCU side of the robust framing, in C99, is in ``firmware/``.
"""

from __future__ import annotations

from .link import IncompatibleVersionError, LinkError, LinkOpenError, SerialLink
from .protocol import (
    FRAMINGS,
    PROTOCOL_VERSION,
    Capability,
    Codec,
    CommandKind,
    Feedback,
    Framing,
    Hello,
    LinkStats,
    Message,
    MsgType,
    PeerRole,
    Received,
    ReferenceCodec,
    ReferenceDecoder,
    RobustCodec,
    RobustDecoder,
    Role,
    VersionMismatch,
    WheelCommand,
    make_codec,
)

__all__ = [
    "FRAMINGS",
    "PROTOCOL_VERSION",
    "Capability",
    "Codec",
    "CommandKind",
    "Feedback",
    "Framing",
    "Hello",
    "IncompatibleVersionError",
    "LinkError",
    "LinkOpenError",
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
    "SerialLink",
    "VersionMismatch",
    "WheelCommand",
    "make_codec",
]

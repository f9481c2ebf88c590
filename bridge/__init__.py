"""The bridge between PersonFollow and a real (or emulated) robot.

The same Policy object that runs in the simulator drives a robot through this package:

* ``bridge.protocol``: messages, the reference framing (reference §1) and the robust framing,
  streaming decoders and their statistics;
* ``bridge.link``: :class:`SerialLink`, either framing over any pyserial URL;
* ``bridge.runner``: ``follow-robot run``: a policy at the control rate, wheel commands, the
  PC's wheel PID where the firmware takes duties, safety stops, a step log (with
  ``bridge.runconfig``, its settings and result, ``bridge.runlog``, the log on disk, and
  ``bridge.interrupts``, a shutdown a second Ctrl-C cannot cut short);
* ``bridge.perception``: the runner's observation sources (the emulator's simulated camera, a
  replayed step log, a RealSense camera with a YOLO detector in ``bridge.realsense``);
* ``bridge.emulator`` (with ``bridge.mcu``, ``bridge.world``): ``follow-robot emulate``: the
  wheel MCU under the reference or the fixed firmware, and the world around the robot;
* ``bridge.monitor``: the live web monitor (FastAPI, a WebSocket, a Canvas2D page);
* ``bridge.cli``: ``follow-robot``.

The link, the protocol, the runner and the perception sources import neither the simulator's
kernels, nor training, nor evaluation code (they run on a robot's PC); the emulator and the
monitor's ``--sim`` driver run the simulator. The MCU side of the robust framing, in C99, is in
``firmware/``.
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

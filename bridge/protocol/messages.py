"""What travels on the serial link, independent of how it is framed.

Three messages and one event, shared by both framings (``reference`` and ``robust``):

* :class:`WheelCommand`: PC -> MCU, one value per wheel, in the unit named by its ``kind``;
* :class:`Feedback`: MCU -> PC, the encoder speeds (and, with the robust framing, counts, MCU
  time and status);
* :class:`Hello`: either way, once after opening the link (robust framing only): who is
  talking, what it accepts, which firmware it runs;
* :class:`VersionMismatch`: not a message but an event, produced when a well-formed frame of
  another protocol version arrives; it is refused, never decoded (see ``bridge.protocol.robust``).

Field values are plain ``int``s as they are on the wire; constructors check ranges, so a value
that cannot be sent raises ``ValueError`` naming the field instead of being wrapped or clipped.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum, IntFlag
from typing import Literal

Role = Literal["pc", "mcu"]
"""Which end of the link a codec sits on: ``"pc"`` sends commands and receives feedback,
``"mcu"`` (the wheel microcontroller, or an emulator of it) does the opposite."""

INT16_MIN, INT16_MAX = -(2**15), 2**15 - 1
INT32_MIN, INT32_MAX = -(2**31), 2**31 - 1
UINT8_MAX, UINT16_MAX, UINT32_MAX = 2**8 - 1, 2**16 - 1, 2**32 - 1


def check_range(owner: str, name: str, value: int, lo: int, hi: int) -> int:
    """Return ``value`` if it is an int in ``[lo, hi]``, else raise ``ValueError`` naming it."""
    if isinstance(value, bool) or not isinstance(value, int):
        raise TypeError(f"{owner}.{name} must be an int, got {type(value).__name__} {value!r}")
    if not lo <= value <= hi:
        raise ValueError(f"{owner}.{name}={value} is out of range: must be [{lo}, {hi}]")
    return value


class CommandKind(IntEnum):
    """The unit of a :class:`WheelCommand`'s two values.

    The values double as the robust framing's wire code (``DUTY_PERCENT`` has none: the
    reference framing does not say what its numbers mean, the firmware does).
    """

    DUTY_CENTI_PERCENT = 0
    """Motor duty in 0.01 % (-10000 = full reverse, 10000 = full forward), for firmware whose
    wheel PID runs on the PC (as the reference robot's does, reference §1.2)."""
    SPEED_MM_S = 1
    """Wheel speed target in mm/s, for firmware that runs the wheel PID itself."""
    DUTY_PERCENT = 2
    """Motor duty in whole percent: what the reference firmware reads from its 6-byte command
    (reference §1: clamped to +-99 by its driver). Reference framing only."""


class Capability(IntFlag):
    """What a peer announces in its :class:`Hello` (a bit field on the wire)."""

    NONE = 0
    DUTY_COMMANDS = 1
    """Accepts ``CommandKind.DUTY_CENTI_PERCENT`` (the PID runs on the PC)."""
    SPEED_COMMANDS = 2
    """Accepts ``CommandKind.SPEED_MM_S`` (the PID runs on the MCU)."""
    ENCODER_COUNTS = 4
    """Fills the encoder counts in its feedback."""
    WATCHDOG = 8
    """Stops the motors by itself when commands stop arriving."""


class PeerRole(IntEnum):
    """The ``role`` byte of a :class:`Hello`."""

    PC = 1
    MCU = 2


@dataclass(frozen=True, slots=True)
class WheelCommand:
    """PC -> MCU: one command per wheel.

    :param right: right wheel value, int16, in the unit given by ``kind``.
    :param left: left wheel value, int16, same unit.
    :param kind: what the values mean (duty in 0.01 %, speed target in mm/s, or the reference
        firmware's whole percent).
    """

    right: int
    left: int
    kind: CommandKind = CommandKind.DUTY_CENTI_PERCENT

    def __post_init__(self) -> None:
        check_range("WheelCommand", "right", self.right, INT16_MIN, INT16_MAX)
        check_range("WheelCommand", "left", self.left, INT16_MIN, INT16_MAX)
        object.__setattr__(self, "kind", CommandKind(self.kind))


@dataclass(frozen=True, slots=True)
class Feedback:
    """MCU -> PC: what the wheel controller measured, sent every 10 ms (reference §1).

    The reference framing carries only the two speeds; the other fields are then ``None``.

    :param right_mm_s: right wheel linear speed from its encoder, mm/s, int16.
    :param left_mm_s: left wheel linear speed, mm/s, int16.
    :param right_count: right encoder count since the MCU started, counts (4x mode), int32,
        wrapping.
    :param left_count: left encoder count, counts, int32, wrapping.
    :param mcu_time_ms: MCU time when the speeds were measured, ms since its start, uint32
        (wraps after 49.7 days).
    :param status: bit field, uint8; bit 0 (``STATUS_WATCHDOG_STOP``): the motors are stopped
        because no command arrived within the firmware's watchdog time.
    """

    right_mm_s: int
    left_mm_s: int
    right_count: int | None = None
    left_count: int | None = None
    mcu_time_ms: int | None = None
    status: int | None = None

    STATUS_WATCHDOG_STOP = 1

    def __post_init__(self) -> None:
        check_range("Feedback", "right_mm_s", self.right_mm_s, INT16_MIN, INT16_MAX)
        check_range("Feedback", "left_mm_s", self.left_mm_s, INT16_MIN, INT16_MAX)
        for name, lo, hi in (
            ("right_count", INT32_MIN, INT32_MAX),
            ("left_count", INT32_MIN, INT32_MAX),
            ("mcu_time_ms", 0, UINT32_MAX),
            ("status", 0, UINT8_MAX),
        ):
            value = getattr(self, name)
            if value is not None:
                check_range("Feedback", name, value, lo, hi)


@dataclass(frozen=True, slots=True)
class Hello:
    """Either way, once after the link opens (robust framing): who is talking.

    :param role: ``PeerRole.PC`` or ``PeerRole.MCU``.
    :param capabilities: what the sender accepts and sends (:class:`Capability` bits).
    :param feedback_period_ms: the MCU's feedback period, ms (10 on the reference robot,
        reference §1); 0 from a PC.
    :param firmware_version: (major, minor, patch) of the sender's software, each uint8.
    """

    role: PeerRole
    capabilities: Capability = Capability.NONE
    feedback_period_ms: int = 0
    firmware_version: tuple[int, int, int] = (0, 0, 0)

    def __post_init__(self) -> None:
        try:
            object.__setattr__(self, "role", PeerRole(self.role))
        except ValueError:
            msg = f"Hello.role={self.role!r} is not a PeerRole (1 = PC, 2 = MCU)"
            raise ValueError(msg) from None
        check_range("Hello", "capabilities", int(self.capabilities), 0, UINT8_MAX)
        object.__setattr__(self, "capabilities", Capability(int(self.capabilities)))
        check_range("Hello", "feedback_period_ms", self.feedback_period_ms, 0, UINT16_MAX)
        version = tuple(self.firmware_version)
        if len(version) != 3:
            raise ValueError(f"Hello.firmware_version={version!r} must be (major, minor, patch)")
        for name, part in zip(("major", "minor", "patch"), version, strict=True):
            check_range("Hello", f"firmware_version.{name}", part, 0, UINT8_MAX)
        object.__setattr__(self, "firmware_version", version)


@dataclass(frozen=True, slots=True)
class VersionMismatch:
    """Event: a frame intact in every check but of another protocol version was refused.

    :param version: the version byte the peer sent.
    :param expected: the version this software speaks (``PROTOCOL_VERSION``).
    :param msg_type: the frame's message type byte (meaningless to us: another schema).
    """

    version: int
    expected: int
    msg_type: int


Message = WheelCommand | Feedback | Hello
"""Anything one end sends the other."""

Received = WheelCommand | Feedback | Hello | VersionMismatch
"""Anything a decoder hands back: a message, or the refusal of an incompatible frame."""

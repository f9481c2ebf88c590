"""The wheel microcontroller, emulated with the simulator's own wheel models.

The two wheels turn under the differential drive's DC motor model, are counted by its
quadrature encoders and, where the firmware runs one, are held on target by its PID: the same
compiled functions the simulator's kernel uses (:mod:`follow_env.platforms.wheels`), ticked
every encoder period (10 ms, reference §1.1) of the emulator's clock. On top of them, one of two
firmwares:

``reference``: the reference robot's ``main.c`` as its listings build it. The loop blocks in
    ``HAL_UART_Receive`` until a whole 6-byte command has arrived, sets the two motor duties
    (percent, clamped to +-99, reference §1.1), and then, if 10 ms have passed since the last
    time, runs ``Encoder_Interrupt`` and sends the feedback. So it measures once per command,
    yet divides by its fixed 10 ms period: the published speed is the true speed times (real
    interval / 10 ms). Its count is the timer's 16-bit register (it wraps every 65536 counts,
    which shows up as one absurd speed), and the speed is cast to int16. It accepts only duty
    commands: its PID runs on the PC (reference §1.2).
``fixed``: the same hardware with the loop fixed: a 10 ms timer measures the wheels over the
    real interval (a 32-bit count difference) and sends feedback every period whether or not a
    command came; it takes duty commands (PID on the PC) or, with the robust framing, wheel
    speed targets in mm/s (PID on the MCU, exactly the simulator's); a watchdog stops the
    motors when no command arrives for ``watchdog_s``.

Times are seconds on the emulator's clock (monotonic, 0 at start); the caller advances it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

from bridge.protocol import Capability, CommandKind, Feedback, Hello, PeerRole, WheelCommand
from follow_env.platforms.diff_drive import DiffDriveConfig
from follow_env.platforms.wheels import encoder_count, encoder_speed, motor_step, wheel_tick

__all__ = ["FIRMWARES", "EmulatedMCU", "Firmware", "MCUStats"]

Firmware = Literal["reference", "fixed"]
FIRMWARES: tuple[Firmware, ...] = ("reference", "fixed")

FIRMWARE_VERSION = (1, 0, 0)
"""What the emulated MCU announces in its hello."""

_REFERENCE_PERIOD_S = 0.01  # reference §1.1: Encoder_Interrupt divides by a fixed 10 ms
_HAL_TICK_S = 0.001  # HAL_GetTick counts whole milliseconds
_UINT16 = 1 << 16


def _int16(value: float) -> int:
    """``(int16_t)value`` as the MCU's compiler does it: truncate, then wrap modulo 2**16."""
    return (int(value) + 0x8000) % _UINT16 - 0x8000


def _int32(value: int) -> int:
    """Wrap to a signed 32-bit count."""
    return (value + (1 << 31)) % (1 << 32) - (1 << 31)


def _saturate16(value: float) -> int:
    """Truncate towards zero and saturate to int16 (what the fixed firmware sends)."""
    return max(-0x8000, min(0x7FFF, int(value)))


@dataclass
class MCUStats:
    """What the emulated MCU did, for tests and the emulator's report."""

    commands: int = 0
    commands_refused: int = 0  # a command kind this firmware does not take
    feedback_sent: int = 0
    watchdog_stops: int = 0


class EmulatedMCU:
    """Two wheels and a firmware, on the emulator's clock.

    :param platform: the differential drive's configuration (motor, encoder, PID, wheel
        radius); its defaults are the simulated reference robot.
    :param firmware: ``"reference"`` or ``"fixed"`` (module docstring).
    :param framing: ``"reference"`` (duty commands in whole percent) or ``"robust"``.
    :param gains: the two motors' gain factors (right, left); the emulator passes the ones the
        simulator draws for the same seed.
    :param watchdog_s: the fixed firmware stops the motors when no command came for this long.
    """

    def __init__(
        self,
        platform: DiffDriveConfig | None = None,
        firmware: Firmware = "reference",
        framing: str = "reference",
        *,
        gains: tuple[float, float] = (1.0, 1.0),
        watchdog_s: float = 0.1,
    ) -> None:
        if firmware not in FIRMWARES:
            raise ValueError(f"firmware={firmware!r} is out of range: must be one of {FIRMWARES}")
        if watchdog_s <= 0:
            raise ValueError(f"watchdog_s={watchdog_s} is out of range: must be > 0 s")
        self.platform = platform if platform is not None else DiffDriveConfig()
        self.firmware: Firmware = firmware
        self.framing = framing
        self.watchdog_s = watchdog_s
        self.gains = (float(gains[0]), float(gains[1]))
        p = self.platform
        self.tick_s = p.encoder.sample_period_s
        self._cpr = float(p.encoder.counts_per_rev)
        self._diameter = 2.0 * p.robot.wheel_radius_m
        self._quantum = p.encoder.speed_quantum_mps
        m = p.motor
        self._alpha = 1.0 - math.exp(-self.tick_s / m.time_constant_s)
        self._motor = (m.no_load_speed_radps, self._alpha, m.friction_duty_pct, m.stall_duty_pct)
        pid = p.pid
        # wheel_tick's constants (the simulator's kernel builds the same tuple, diff_drive.drive)
        self._consts = (
            pid.kp,
            pid.ki,
            pid.kd,
            pid.tau_s,
            self.tick_s,
            m.max_duty_pct,
            pid.anti_windup == "clamp",
            m.no_load_speed_radps,
            self._alpha,
            m.friction_duty_pct,
            m.stall_duty_pct,
            self._cpr,
            self._diameter,
            self._quantum,
        )
        self.stats = MCUStats()
        self._warm_up()
        self.reset(0.0)

    def _warm_up(self) -> None:
        # The wheel models are compiled functions: load (or compile) them now, not at the first
        # command, where a pause of a second would look like a dead MCU.
        wheel_tick(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0, 0, 1.0, self._consts)
        motor_step(0.0, 0.0, 1.0, *self._motor)
        encoder_speed(encoder_count(0.0, self._cpr), 0, self._cpr, self.tick_s, 1.0, 0.0)

    # ---- state ------------------------------------------------------------------------

    def reset(self, t_s: float) -> None:
        """Power-on at time ``t_s``: wheels at rest, counters and controller state zero."""
        self.t_tick = t_s  # time of the last physics tick
        self.omega = [0.0, 0.0]  # true wheel speeds, rad/s
        self.angle = [0.0, 0.0]  # true wheel angles, rad
        self.duty = [0.0, 0.0]  # applied duty, %
        self.target = [0.0, 0.0]  # speed targets, m/s (speed mode)
        self.mode = CommandKind.DUTY_PERCENT
        self.meas = [0.0, 0.0]  # the MCU's last speed estimate, m/s
        self.count = [0, 0]  # encoder counts at the last tick (unbounded ints)
        self._pid = [[0.0, 0.0, 0.0], [0.0, 0.0, 0.0]]  # integral, e_prev, d_filt per wheel
        self.last_command_s = t_s
        self.watchdog_stopped = False
        self._ref_last_s = t_s  # reference firmware: HAL tick of the last feedback
        self._ref_prev_rot = [0.0, 0.0]
        self._fixed_last_count = [0, 0]
        self._queued: list[Feedback] = []

    def hello(self) -> Hello:
        """What this MCU announces (robust framing)."""
        caps = Capability.DUTY_COMMANDS
        if self.firmware == "fixed":
            caps |= Capability.ENCODER_COUNTS | Capability.WATCHDOG
            if self.framing == "robust":
                caps |= Capability.SPEED_COMMANDS
        period = round(self.tick_s * 1000) if self.firmware == "fixed" else 0
        return Hello(PeerRole.MCU, caps, period, FIRMWARE_VERSION)

    def wheel_angles(self, t_s: float) -> tuple[float, float]:
        """True wheel angles (rad) at ``t_s`` (between ticks the wheels turn at their speed)."""
        dt = max(0.0, t_s - self.t_tick)
        return self.angle[0] + self.omega[0] * dt, self.angle[1] + self.omega[1] * dt

    # ---- time ---------------------------------------------------------------------------

    def advance(self, t_s: float) -> list[Feedback]:
        """Run every 10 ms tick up to ``t_s``; returns the feedback the timer sent (fixed)."""
        while self.t_tick + self.tick_s <= t_s + 1e-12:
            self._tick()
        out, self._queued = self._queued, []
        return out

    def _tick(self) -> None:
        self.t_tick += self.tick_s
        fixed = self.firmware == "fixed"
        if fixed and self.t_tick - self.last_command_s > self.watchdog_s:
            if not self.watchdog_stopped:
                self.stats.watchdog_stops += 1
            self.watchdog_stopped = True
            self.duty = [0.0, 0.0]
            self.target = [0.0, 0.0]
            # the integrators too: a stale integral would kick the wheels at the next command
            self._pid = [[0.0, 0.0, 0.0], [0.0, 0.0, 0.0]]
        speed_mode = fixed and self.mode == CommandKind.SPEED_MM_S and not self.watchdog_stopped
        for k in (0, 1):
            if speed_mode:
                integral, e_prev, d_filt = self._pid[k]
                duty, integral, d_filt, e_prev, omega, angle, count, meas = wheel_tick(
                    self.target[k],
                    self.meas[k],
                    e_prev,
                    integral,
                    d_filt,
                    self.omega[k],
                    self.angle[k],
                    self.count[k],
                    0,
                    self.gains[k],
                    self._consts,
                )
                self._pid[k] = [integral, e_prev, d_filt]
                self.duty[k], self.omega[k], self.angle[k] = duty, omega, angle
                self.count[k], self.meas[k] = count, meas
            else:
                self.omega[k] = motor_step(self.omega[k], self.duty[k], self.gains[k], *self._motor)
                self.angle[k] += self.omega[k] * self.tick_s
                count = encoder_count(self.angle[k], self._cpr)
                self.meas[k] = encoder_speed(
                    count, self.count[k], self._cpr, self.tick_s, self._diameter, self._quantum
                )
                self.count[k] = count
        if fixed:
            self._queued.append(self._fixed_feedback())

    def _fixed_feedback(self) -> Feedback:
        self.stats.feedback_sent += 1
        status = Feedback.STATUS_WATCHDOG_STOP if self.watchdog_stopped else 0
        mm = [_saturate16(1000.0 * v) for v in self.meas]
        if self.framing != "robust":
            return Feedback(mm[0], mm[1])
        return Feedback(
            mm[0],
            mm[1],
            _int32(self.count[0]),
            _int32(self.count[1]),
            round(self.t_tick * 1000) % (1 << 32),
            status,
        )

    # ---- commands -----------------------------------------------------------------------

    def command(self, message: WheelCommand, t_s: float) -> list[Feedback]:
        """A command arrived (whole) at ``t_s``; returns the feedback sent in answer."""
        out = self.advance(t_s)
        self.stats.commands += 1
        kind = message.kind
        if kind == CommandKind.SPEED_MM_S and self.firmware == "reference":
            self.stats.commands_refused += 1  # the reference firmware has no wheel PID
            return out
        self.last_command_s = t_s
        self.watchdog_stopped = False
        max_duty = self.platform.motor.max_duty_pct
        if kind == CommandKind.SPEED_MM_S:
            self.mode = CommandKind.SPEED_MM_S
            self.target = [message.right / 1000.0, message.left / 1000.0]
        else:
            scale = 0.01 if kind == CommandKind.DUTY_CENTI_PERCENT else 1.0
            if self.mode == CommandKind.SPEED_MM_S:
                self._pid = [[0.0, 0.0, 0.0], [0.0, 0.0, 0.0]]
            self.mode = kind
            # Clamped to +-99 % (the gate driver, reference §1.1); the firmware negates both for
            # the mirrored motors, which cancels out at the wheels.
            self.duty = [
                min(max(message.right * scale, -max_duty), max_duty),
                min(max(message.left * scale, -max_duty), max_duty),
            ]
        if self.firmware == "reference":
            out.extend(self._reference_feedback(t_s))
        return out

    def _reference_feedback(self, t_s: float) -> list[Feedback]:
        # if (HAL_GetTick() - last >= 10) { Encoder_Interrupt(); transmit; last = HAL_GetTick(); }
        now = math.floor(t_s / _HAL_TICK_S + 1e-9) * _HAL_TICK_S
        if now - self._ref_last_s < _REFERENCE_PERIOD_S - 1e-9:
            return []
        self._ref_last_s = now
        angles = self.wheel_angles(t_s)
        mm, registers = [], []
        for k in (0, 1):
            register = encoder_count(angles[k], self._cpr) % _UINT16  # the 16-bit timer
            rot = register / self._cpr
            rps = (rot - self._ref_prev_rot[k]) / _REFERENCE_PERIOD_S
            self._ref_prev_rot[k] = rot
            mm.append(_int16(1000.0 * rps * math.pi * self._diameter))
            registers.append(register)
        self.stats.feedback_sent += 1
        if self.framing != "robust":
            return [Feedback(mm[0], mm[1])]
        # The robust framing carries counts and time too: the timer registers (16-bit, as this
        # firmware has them) and HAL_GetTick.
        return [
            Feedback(mm[0], mm[1], registers[0], registers[1], round(now * 1000) % (1 << 32), 0)
        ]

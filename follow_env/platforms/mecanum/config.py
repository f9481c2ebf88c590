"""Configuration of the mecanum platform (reference §2): every constant with its unit and source.

Sections: ``body`` (geometry and mass), ``motor`` (DC gear-motors on PWM duty 0..255), ``floor``
(the rollers' traction), ``drive`` (open loop on duty as in the paper, or wheel PIDs), ``encoder``
and ``pid`` (the wheels' encoders and PIDs, shared with the differential drive).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import ClassVar

from follow_env.platforms.base import PlatformConfig
from follow_env.platforms.wheels import EncoderConfig, PIDConfig
from follow_env.sim.checks import out_of_range
from follow_env.sim.config import Validated, param

__all__ = ["BodyConfig", "DriveConfig", "FloorConfig", "MecanumConfig", "MecanumMotorConfig"]


@dataclass(frozen=True)
class BodyConfig(Validated):
    """Geometry and mass of the base (reference §2: the paper's robot)."""

    wheel_radius_m: float = param(
        0.030, 0.005, 0.2, "m", "reference §2: 60 mm outer diameter; rolling radius = half of it"
    )
    half_wheelbase_m: float = param(0.086, 0.02, 1.0, "m", "reference §2: a = 86 mm")
    half_track_m: float = param(0.076, 0.02, 1.0, "m", "reference §2: b = 76 mm")
    mass_kg: float = param(2.3, 0.1, 100.0, "kg", "reference §2: 2.3 kg")
    yaw_inertia_kgm2: float = param(
        0.019, 1e-4, 50.0, "kg m^2", "choice: a uniform 0.24 x 0.20 m box of 2.3 kg"
    )
    wheel_inertia_kgm2: float = param(
        1.5e-4, 1e-7, 0.1, "kg m^2", "choice: wheel plus the rotor seen through the gears"
    )
    footprint_length_m: float = param(
        0.24, 0.05, 3.0, "m", "choice: wheelbase plus a wheel, centred on the body"
    )
    footprint_width_m: float = param(0.20, 0.05, 3.0, "m", "choice: track plus a wheel's width")

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.footprint_width_m < 2.0 * self.half_track_m:
            raise out_of_range(
                "BodyConfig.footprint_width_m",
                self.footprint_width_m,
                f">= 2 half_track_m ({2.0 * self.half_track_m} m): the wheels are inside it",
            )


@dataclass(frozen=True)
class MecanumMotorConfig(Validated):
    """DC gear-motor per wheel, driven by PWM duty 0..255 (reference §2: an Arduino Due).

    Torque at the wheel ``tau_s (g u - omega / omega_0)`` with ``u = duty / max_duty``; gear
    friction as the duty it takes: kinetic ``friction_duty``, static ``start_duty``.
    """

    max_duty: float = param(255.0, 1.0, 65535.0, "duty", "reference §2: PWM duty 0-255")
    no_load_speed_radps: float = param(
        50.0,
        1.0,
        500.0,
        "rad/s",
        "choice: ~480 rpm, 1.5 m/s at the wheel, to keep up with a walker",
    )
    stall_torque_nm: float = param(
        0.25, 0.001, 50.0, "N m", "choice: a small 12 V gear-motor of that speed"
    )
    friction_duty: float = param(
        26.0, 0.0, 65535.0, "duty", "choice: 10 % of full duty, a small gear-motor's no-load draw"
    )
    start_duty: float = param(
        41.0,
        0.0,
        65535.0,
        "duty",
        "choice: small gear-motors start at 15-20 % of their voltage (16 %); reference §2 "
        "reports stalls at low duty",
    )
    gain_spread: float = param(
        0.05, 0.0, 0.5, "", "choice: std of each motor's speed ratio (reference §2's P_i spread)"
    )
    start_spread: float = param(
        0.1, 0.0, 0.5, "", "choice: std of each motor's static friction factor"
    )
    zero_duty: str = param(
        "coast",
        doc="choice: at duty 0 the driver leaves the motor free ('coast'; reference §2's robot "
        "kept turning after its motors stopped) or shorts it ('brake')",
        choices=("coast", "brake"),
    )

    def __post_init__(self) -> None:
        super().__post_init__()
        if not self.friction_duty <= self.start_duty < self.max_duty:
            raise out_of_range(
                "MecanumMotorConfig.start_duty",
                self.start_duty,
                f"in [friction_duty, max_duty) = [{self.friction_duty}, {self.max_duty})",
            )


@dataclass(frozen=True)
class FloorConfig(Validated):
    """The rollers on the floor: traction along a wheel's push direction only."""

    traction_mu: float = param(0.6, 0.01, 3.0, "", "choice: rubber rollers on a hard floor")
    roller_resistance: float = param(
        0.03, 0.0, 1.0, "", "choice: rolling resistance of the free rollers, share of the load"
    )
    slip_speed_mps: float = param(
        0.005, 1e-4, 0.5, "m/s", "choice: Coulomb friction is linear below this slip"
    )
    spread: float = param(
        0.1, 0.0, 0.9, "", "choice: traction and roller resistance scale by U(1 - s, 1 + s)"
    )


@dataclass(frozen=True)
class DriveConfig(Validated):
    """How the wheel commands are made (reference §2)."""

    mode: str = param(
        "open_loop",
        doc="reference §2: the paper's robot ran open loop on duty; 'pid' closes a wheel PID "
        "(reference §1.2) on the encoders",
        choices=("open_loop", "pid"),
    )
    duty_scale: float | None = param(
        None,
        0.0,
        1e5,
        "duty/(rad/s)",
        "reference §2 Pd; None: max_duty / no_load_speed_radps, the duty an ideal motor needs",
        lo_open=True,
        optional=True,
    )
    ratio_1: float = param(1.0, 0.1, 10.0, "", "reference §2 P_1 (front-left); choice: 1")
    ratio_2: float = param(1.0, 0.1, 10.0, "", "reference §2 P_2 (rear-left); choice: 1")
    ratio_3: float = param(1.0, 0.1, 10.0, "", "reference §2 P_3 (rear-right); choice: 1")
    ratio_4: float = param(1.0, 0.1, 10.0, "", "reference §2 P_4 (front-right); choice: 1")
    tick_s: float = param(
        0.002, 1e-4, 0.01, "s", "choice: physics tick; the experiments use 1 ms for 1 ms slices"
    )


def _pid() -> PIDConfig:
    return PIDConfig(kp=150.0, ki=1500.0, kd=0.0, tau_s=0.01)


@dataclass(frozen=True)
class MecanumConfig(PlatformConfig):
    """The mecanum platform's sections: body, motors, floor, drive, encoders, wheel PIDs."""

    NAME: ClassVar[str] = "mecanum"
    SPREADS: ClassVar[tuple[str, ...]] = ("motor.gain_spread", "motor.start_spread", "floor.spread")

    body: BodyConfig = field(default_factory=BodyConfig)
    motor: MecanumMotorConfig = field(default_factory=MecanumMotorConfig)
    floor: FloorConfig = field(default_factory=FloorConfig)
    drive: DriveConfig = field(default_factory=DriveConfig)
    encoder: EncoderConfig = field(default_factory=EncoderConfig)
    pid: PIDConfig = field(default_factory=_pid)

    @property
    def footprint_length_m(self) -> float:
        """Footprint along the heading (m)."""
        return self.body.footprint_length_m

    @property
    def footprint_width_m(self) -> float:
        """Footprint across (m)."""
        return self.body.footprint_width_m

    def check_control_period(self, control_dt_s: float) -> None:
        """The control period and the encoder period must be whole numbers of ticks."""
        tick = self.drive.tick_s
        periods = (
            ("EpisodeConfig.control_dt_s", control_dt_s),
            ("EncoderConfig.sample_period_s", self.encoder.sample_period_s),
        )
        for where, period in periods:
            ratio = period / tick
            if abs(ratio - round(ratio)) > 1e-9 or not 1 <= round(ratio) <= 2048:
                if tick != DriveConfig().tick_s:  # the tick the user set, not the period
                    both = " and ".join(f"{name} ({value:g} s)" for name, value in periods)
                    rule = f"a tick that divides {both} into 1 to 2048 whole ticks"
                    raise out_of_range("DriveConfig.tick_s", tick, rule)
                raise out_of_range(where, period, f"1 to 2048 whole drive ticks of {tick} s")

    @property
    def duty_per_radps(self) -> float:
        """Pd (duty per rad/s of wheel speed)."""
        scale = self.drive.duty_scale
        return self.motor.max_duty / self.motor.no_load_speed_radps if scale is None else scale

    @property
    def max_wheel_speed_radps(self) -> float:
        """Steady wheel speed at full duty, gear friction taken off (rad/s)."""
        m = self.motor
        return m.no_load_speed_radps * (1.0 - m.friction_duty / m.max_duty)

    @property
    def max_speed_mps(self) -> float:
        """Bound of vx and vy (m/s): every wheel at its top speed."""
        return self.max_wheel_speed_radps * self.body.wheel_radius_m

    @property
    def max_turn_rate_radps(self) -> float:
        """Bound of w (rad/s): every wheel at its top speed, turning on the spot."""
        b = self.body
        return self.max_speed_mps / (b.half_wheelbase_m + b.half_track_m)

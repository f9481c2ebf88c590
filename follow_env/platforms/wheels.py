"""Wheels: the DC gear-motor, the quadrature encoder, the wheel speed PID (reference §1.1, §1.2).

Their configuration sections (:class:`MotorConfig`, :class:`EncoderConfig`, :class:`PIDConfig`)
and their compiled models, one wheel and one 10 ms tick at a time: every wheeled platform runs
:func:`wheel_tick` for each of its wheels inside its control step. Each model is importable on
its own so the tests can check it in isolation.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from follow_env.sim.config import Validated, param
from follow_env.sim.jit import njit

__all__ = [
    "EncoderConfig",
    "MotorConfig",
    "PIDConfig",
    "encoder_count",
    "encoder_speed",
    "lag_factor",
    "motor_advance",
    "motor_step",
    "pid_step",
    "wheel_tick",
]


@dataclass(frozen=True)
class MotorConfig(Validated):
    """DC gear-motor model, one per wheel: first-order lag from duty to speed, with friction.

    Steady-state wheel speed for duty ``u`` (%): ``no_load * sign(u) * (|u| - friction) /
    (100 - friction)`` when ``|u| > friction``, else 0; a stopped wheel stays stopped while
    ``|u| < stall_duty_pct`` (static friction; reference §2 reports such stalls on hardware).
    """

    no_load_speed_radps: float = param(
        20.0, 1.0, 200.0, "rad/s", "choice: ~190 rpm at the wheel, i.e. 1.5 m/s with 75 mm wheels"
    )
    time_constant_s: float = param(
        0.08, 0.001, 2.0, "s", "choice: mechanical lag of a loaded gear-motor", lo_open=True
    )
    friction_duty_pct: float = param(
        4.0,
        0.0,
        50.0,
        "%",
        "choice: friction as the duty it eats, taken off |duty| (a dead band: it acts against "
        "the duty, not the motion, so it does not slow a coasting wheel)",
    )
    stall_duty_pct: float = param(
        8.0, 0.0, 50.0, "%", "choice: static friction; reference §2 observes stalls at low duty"
    )
    max_duty_pct: float = param(
        99.0, 1.0, 100.0, "%", "reference §1.1: the gate driver cannot hold 100 %"
    )
    gain_spread: float = param(
        0.02, 0.0, 0.5, "", "choice: std of a per-episode, per-motor gain factor (reference §2 P_i)"
    )

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.stall_duty_pct < self.friction_duty_pct:
            raise ValueError(
                f"MotorConfig.stall_duty_pct={self.stall_duty_pct!r} is out of range: must be "
                f">= friction_duty_pct ({self.friction_duty_pct} %)"
            )
        if self.max_duty_pct <= self.friction_duty_pct:
            raise ValueError(
                f"MotorConfig.max_duty_pct={self.max_duty_pct!r} is out of range: must be "
                f"> friction_duty_pct ({self.friction_duty_pct} %)"
            )


@dataclass(frozen=True)
class EncoderConfig(Validated):
    """Quadrature wheel encoder and the firmware's speed estimate (reference §1.1)."""

    ppr: int = param(2048, 1, 1_000_000, "pulses/rev", "reference §1.1: AMT102-V", integer=True)
    quadrature: int = param(
        4, 1, 4, "counts/pulse", "reference §1.1: counted in 4x mode", integer=True
    )
    sample_period_s: float = param(
        0.01, 0.0005, 0.1, "s", "reference §1.1: firmware estimates speed every 10 ms"
    )
    speed_quantum_mps: float = param(
        0.001,
        0.0,
        0.1,
        "m/s",
        "reference §1.1: speed sent as an int16 in mm/s (truncated); 0 disables the quantisation",
    )

    @property
    def counts_per_rev(self) -> int:
        """Encoder counts per wheel revolution (``ppr * quadrature``)."""
        return self.ppr * self.quadrature


@dataclass(frozen=True)
class PIDConfig(Validated):
    """Wheel speed PID with the low-pass filtered derivative of reference §1.2.

    Input: target minus measured linear wheel speed (m/s); output: duty (%). The thesis gives no
    gains; the defaults are tuned here (``tests/follow_env/test_drive.py`` shows the step
    response settles within 0.3 s without sustained oscillation).
    """

    kp: float = param(120.0, 0.0, 1e4, "%/(m/s)", "choice: tuned, see class docstring")
    ki: float = param(1500.0, 0.0, 1e5, "%/m", "choice: tuned, see class docstring")
    kd: float = param(0.5, 0.0, 1e3, "%·s/(m/s)", "choice: tuned, see class docstring")
    tau_s: float = param(0.01, 0.0, 1.0, "s", "reference §1.2: derivative low-pass time constant")
    anti_windup: str = param(
        "clamp",
        doc="choice: stop integrating while the duty is saturated and the error "
        "pushes further into saturation ('none' disables it)",
        choices=("clamp", "none"),
    )


# Below this speed (rad/s) a wheel whose duty cannot overcome static friction is held at rest.
_STICTION_SPEED_RADPS = 0.2


@njit(inline="always")
def encoder_count(angle_rad: float, counts_per_rev: float) -> int:
    """Integer quadrature count for a wheel angle (counts in 4x mode, floor quantisation)."""
    return int(np.floor(angle_rad * (counts_per_rev / (2.0 * np.pi))))


@njit(inline="always")
def encoder_speed(
    count: int,
    prev_count: int,
    counts_per_rev: float,
    period_s: float,
    wheel_diameter_m: float,
    quantum_mps: float,
) -> float:
    """Linear wheel speed (m/s) as the firmware estimates it (reference §1.1).

    ``rot = count / ppr``, ``rps = (rot - prev_rot) / period``, ``velocity = rps pi D``; the
    firmware sends it as an int16 in mm/s, so it is truncated towards zero to ``quantum_mps``
    (0 disables that).
    """
    # rps * pi * D with rps = (count - prev) / ppr / period; the constant factor is written
    # apart so the compiler can hoist it out of the tick loop.
    vel = (count - prev_count) * (np.pi * wheel_diameter_m / (counts_per_rev * period_s))
    if quantum_mps > 0.0:
        vel = np.trunc(vel * (1.0 / quantum_mps)) * quantum_mps
    return vel


@njit(inline="always")
def pid_step(
    error: float,
    prev_error: float,
    integral: float,
    d_filt: float,
    kp: float,
    ki: float,
    kd: float,
    tau_s: float,
    dt_s: float,
    max_duty: float,
    anti_windup: bool,
) -> tuple[float, float, float]:
    """One PID update with the low-pass filtered derivative of reference §1.2.

    ``integral += e dt``; ``raw = (e - e_prev) / dt``; ``D = (tau D_prev + dt raw) / (tau + dt)``;
    ``u = Kp e + Ki integral + Kd D``, clamped to ``+-max_duty`` (reference §1.1). Anti-windup by
    clamping (conditional integration): while the output saturates and the error pushes further
    into saturation the integral is not advanced, and the duty stays at the limit.

    :return: ``(duty %, new integral, new filtered derivative)``.
    """
    # D = (tau D_prev + dt raw) / (tau + dt) with dt raw = e - e_prev.
    d_new = (tau_s * d_filt + (error - prev_error)) / (tau_s + dt_s)
    i_new = integral + error * dt_s
    u = kp * error + ki * i_new + kd * d_new
    if anti_windup and abs(u) > max_duty and u * error > 0.0:
        # Hold the integral, and send the saturated duty: the output computed again from the
        # held integral falls below the limit, so a wheel asked for more than its top speed
        # ran below it, slower the more it was asked (a target of 2.08 m/s gave 1.34 m/s).
        i_new = integral
    if u > max_duty:
        u = max_duty
    elif u < -max_duty:
        u = -max_duty
    return u, i_new, d_new


def lag_factor(tau_s: float, dt_s: float) -> float:
    """``1 - exp(-dt / tau)``: the share of the gap to its steady speed a motor closes in one
    tick of ``dt_s`` seconds (time constant ``tau_s``)."""
    return float(1.0 - np.exp(-dt_s / tau_s))


@njit(inline="always")
def motor_step(
    omega_radps: float,
    duty_pct: float,
    gain: float,
    no_load_radps: float,
    alpha: float,
    friction_pct: float,
    stall_pct: float,
) -> float:
    """Wheel speed after one tick under ``duty_pct``: a first-order lag towards the steady speed.

    Steady speed: ``gain * no_load * sign(u) * (|u| - friction) / (100 - friction)`` for
    ``|u| > friction``, else 0 (friction eats the first ``friction`` % of duty: a dead band
    against the duty, not the motion). A wheel turning slower than a small stiction speed while
    ``|u| < stall`` stops dead (static friction: reference §2 reports motors stalling at low
    duty). The lag of time constant ``tau`` is
    integrated exactly over a tick ``dt``: ``omega += (omega_ss - omega) alpha`` with
    ``alpha = 1 - exp(-dt / tau)`` (see :func:`lag_factor`).
    """
    mag = abs(duty_pct)
    if mag <= stall_pct and abs(omega_radps) < _STICTION_SPEED_RADPS:
        return 0.0
    if mag > friction_pct:
        target = (
            gain * no_load_radps * np.sign(duty_pct) * (mag - friction_pct) / (100.0 - friction_pct)
        )
    else:
        target = 0.0
    return omega_radps + (target - omega_radps) * alpha


@njit(inline="always")
def motor_advance(
    omega_radps: float, angle_rad: float, duty_pct: float, gain: float, dt_s: float, motor: tuple
) -> tuple[float, float]:
    """The motor of :func:`motor_step` over ``dt_s`` of constant duty, integrated exactly.

    The same model (steady speed, friction dead band, static stall) with the lag in closed form:
    ``omega(t) = ss + (omega0 - ss) exp(-t / tau)`` and its integral for the angle, so that an
    event-driven chain (:mod:`follow_env.platforms.diff_drive.chain`) may step by any interval.

    :param motor: ``(tau_s, no_load_radps, friction_pct, stall_pct)``.
    :return: ``(omega rad/s, angle rad)`` at the end.
    """
    tau_s, no_load_radps, friction_pct, stall_pct = motor
    mag = abs(duty_pct)
    if mag <= stall_pct and abs(omega_radps) < _STICTION_SPEED_RADPS:
        return 0.0, angle_rad
    if mag > friction_pct:
        ss = (
            gain * no_load_radps * np.sign(duty_pct) * (mag - friction_pct) / (100.0 - friction_pct)
        )
    else:
        ss = 0.0
    decay = np.exp(-dt_s / tau_s)
    angle_rad += ss * dt_s + (omega_radps - ss) * tau_s * (1.0 - decay)
    return ss + (omega_radps - ss) * decay, angle_rad


@njit(inline="always")
def wheel_tick(
    target_mps: float,
    measured_mps: float,
    prev_error: float,
    integral: float,
    d_filt: float,
    omega_radps: float,
    angle_rad: float,
    count: int,
    count_noise: int,
    gain: float,
    consts: tuple,
) -> tuple[float, float, float, float, float, float, int, float]:
    """One 10 ms tick of one wheel: PID on the last encoder estimate, the motor under the new
    duty, the wheel turning, and the encoder's count (with ``count_noise`` extra counts read)
    and speed estimate at the tick's end.

    ``consts`` holds the tick's constants: ``(kp, ki, kd, tau_s, dt_s, max_duty, anti_windup,
    no_load_radps, alpha, friction_pct, stall_pct, counts_per_rev, wheel_diameter_m,
    quantum_mps)``, as in :func:`pid_step`, :func:`motor_step` and :func:`encoder_speed`.

    :return: ``(duty %, integral, filtered D, error, omega rad/s, angle rad, count,
        measured speed m/s)``.
    """
    (
        kp,
        ki,
        kd,
        tau_s,
        dt_s,
        max_duty,
        anti_windup,
        no_load_radps,
        alpha,
        friction_pct,
        stall_pct,
        counts_per_rev,
        wheel_diameter_m,
        quantum_mps,
    ) = consts
    error = target_mps - measured_mps
    duty, integral, d_filt = pid_step(
        error, prev_error, integral, d_filt, kp, ki, kd, tau_s, dt_s, max_duty, anti_windup
    )
    omega_radps = motor_step(omega_radps, duty, gain, no_load_radps, alpha, friction_pct, stall_pct)
    angle_rad += omega_radps * dt_s
    new_count = encoder_count(angle_rad, counts_per_rev) + count_noise
    measured_mps = encoder_speed(
        new_count, count, counts_per_rev, dt_s, wheel_diameter_m, quantum_mps
    )
    return duty, integral, d_filt, error, omega_radps, angle_rad, new_count, measured_mps

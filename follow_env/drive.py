"""Wheel drive, one 10 ms tick at a time: encoder, PID, DC motor (SPEC §1.1, §1.2).

Each function handles one wheel and is compiled with numba; the core's kernel calls them for
every wheel of every lane inside each control step. They are also importable on their own so
the tests can check each model in isolation.
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["encoder_count", "encoder_speed", "lag_factor", "motor_step", "pid_step", "wheel_tick"]

# Below this speed (rad/s) a wheel whose duty cannot overcome static friction is held at rest.
_STICTION_SPEED_RADPS = 0.2


@njit(cache=True, inline="always")
def encoder_count(angle_rad: float, counts_per_rev: float) -> int:
    """Integer quadrature count for a wheel angle (counts in 4x mode, floor quantisation)."""
    return int(np.floor(angle_rad * (counts_per_rev / (2.0 * np.pi))))


@njit(cache=True, inline="always")
def encoder_speed(
    count: int,
    prev_count: int,
    counts_per_rev: float,
    period_s: float,
    wheel_diameter_m: float,
    quantum_mps: float,
) -> float:
    """Linear wheel speed (m/s) as the firmware estimates it (SPEC §1.1).

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


@njit(cache=True, inline="always")
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
    """One PID update with the low-pass filtered derivative of SPEC §1.2.

    ``integral += e dt``; ``raw = (e - e_prev) / dt``; ``D = (tau D_prev + dt raw) / (tau + dt)``;
    ``u = Kp e + Ki integral + Kd D``, clamped to ``+-max_duty`` (SPEC §1.1). Anti-windup by
    clamping: while the output saturates and the error pushes further into saturation the
    integral is not advanced.

    :return: ``(duty %, new integral, new filtered derivative)``.
    """
    # D = (tau D_prev + dt raw) / (tau + dt) with dt raw = e - e_prev.
    d_new = (tau_s * d_filt + (error - prev_error)) / (tau_s + dt_s)
    i_new = integral + error * dt_s
    u = kp * error + ki * i_new + kd * d_new
    if anti_windup and abs(u) > max_duty and u * error > 0.0:
        i_new = integral
        u = kp * error + ki * i_new + kd * d_new
    if u > max_duty:
        u = max_duty
    elif u < -max_duty:
        u = -max_duty
    return u, i_new, d_new


def lag_factor(tau_s: float, dt_s: float) -> float:
    """``1 - exp(-dt / tau)``: the share of the gap to its steady speed a motor closes in one
    tick of ``dt_s`` seconds (time constant ``tau_s``)."""
    return float(1.0 - np.exp(-dt_s / tau_s))


@njit(cache=True, inline="always")
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
    ``|u| > friction``, else 0 (Coulomb friction eats the first ``friction`` % of duty). A wheel
    turning slower than a small stiction speed while ``|u| < stall`` stops dead (static
    friction: SPEC §2 reports motors stalling at low duty). The lag of time constant ``tau`` is
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


@njit(cache=True, inline="always")
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

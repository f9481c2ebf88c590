"""Wheel drive, one 10 ms tick at a time: encoder, PID, DC motor (SPEC §1.1, §1.2).

Each function handles one wheel and is compiled with numba; the core's kernel calls them for
every wheel of every lane inside each control step. They are also importable on their own so
the tests can check each model in isolation.
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["encoder_count", "encoder_speed", "motor_step", "pid_step"]

# Below this speed (rad/s) a wheel whose duty cannot overcome static friction is held at rest.
_STICTION_SPEED_RADPS = 0.2


@njit(cache=True, inline="always")
def encoder_count(angle_rad: float, counts_per_rev: float) -> int:
    """Integer quadrature count for a wheel angle (counts in 4x mode, floor quantisation)."""
    return int(np.floor(angle_rad * counts_per_rev / (2.0 * np.pi)))


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
    rps = (count - prev_count) / counts_per_rev / period_s
    vel = rps * np.pi * wheel_diameter_m
    if quantum_mps > 0.0:
        vel = np.trunc(vel / quantum_mps) * quantum_mps
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
    raw = (error - prev_error) / dt_s
    d_new = (tau_s * d_filt + dt_s * raw) / (tau_s + dt_s)
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


@njit(cache=True, inline="always")
def motor_step(
    omega_radps: float,
    duty_pct: float,
    gain: float,
    no_load_radps: float,
    tau_s: float,
    friction_pct: float,
    stall_pct: float,
    dt_s: float,
) -> float:
    """Wheel speed after ``dt_s`` under ``duty_pct``: a first-order lag towards the steady speed.

    Steady speed: ``gain * no_load * sign(u) * (|u| - friction) / (100 - friction)`` for
    ``|u| > friction``, else 0 (Coulomb friction eats the first ``friction`` % of duty). A wheel
    turning slower than a small stiction speed while ``|u| < stall`` stops dead (static
    friction: SPEC §2 reports motors stalling at low duty). The lag is integrated exactly:
    ``omega += (omega_ss - omega) (1 - exp(-dt / tau))``.
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
    return omega_radps + (target - omega_radps) * (1.0 - np.exp(-dt_s / tau_s))

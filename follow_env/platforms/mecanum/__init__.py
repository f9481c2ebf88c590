"""The four-wheel mecanum base of the mecanum paper (reference §2): one platform package.

Its configuration sections are in :mod:`.config`; this module holds the rest (kinematics, the
parameter and state blocks, the compiled drive, the randomisation and the registration).

Wheels in the paper's order, read in REP 103 axes (x forward, y left, yaw counter-clockwise):
1 front-left, 2 rear-left, 3 rear-right, 4 front-right, at ``(+-a, +-b)``; wheel ``i`` pushes
along ``d_i = (1, s_i) / sqrt(2)`` with ``s = (-1, +1, -1, +1)``, which gives the paper's rows
``M_i = [1, s_i, s_i x_i - y_i] = [1, -+1, -+(a+b)]``. The action is the body twist
``[v_mps, vy_mps, w_radps]`` (vx forward, vy to the left, w counter-clockwise).

Drive (:func:`drive_ticks`), every tick of ``drive.tick_s``:

1. Inverse kinematics (reference §2): ``phi = M [vx, vy, w] / Rw``; open loop (the paper's
   robot) the duty is ``Pd P_i phi_i`` clipped to +-255; with ``drive.mode = "pid"`` a wheel PID
   (reference §1.2) on the encoder speed sets it instead.
2. Each DC motor gives ``tau_s (g_i u_i - omega_i / omega_0)`` (``u`` = duty / 255; a zero duty
   leaves the motor free: it coasts), minus Coulomb friction of its gears; a wheel at rest
   stays at rest while its torque is under the static friction (the stall the paper observed).
3. Each roller pushes the floor only along ``d_i`` and rolls freely across it (directional
   friction): the traction is Coulomb friction ``-mu N sat(slip / v_eps)`` on the slip
   ``(M_i q - Rw omega_i) / sqrt(2)``, plus a small rolling resistance of the rollers across.
4. Wheels and body (mass, yaw inertia: the robot keeps turning after the motors stop) move
   together: implicit in the stiff traction (the wheels are eliminated, a 3 x 3 solve remains),
   then the pose in the world frame.

The encoders are always simulated (they give the measured speed the task logs); the paper's
robot ran open loop, so the default drive ignores them.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from follow_env.platforms import register_platform
from follow_env.platforms.base import (
    ENCODER_NOISE,
    ENCODER_NOISE_CONST,
    FRICTION,
    GEOMETRY_ERROR,
    ActionField,
    Platform,
    base_param_fields,
    motor_gains,
    push_velocity,
)
from follow_env.platforms.mecanum.config import (
    BodyConfig,
    DriveConfig,
    FloorConfig,
    MecanumConfig,
    MecanumMotorConfig,
)
from follow_env.platforms.wheels import encoder_count, encoder_speed
from follow_env.platforms.wheels import pid_step as wheel_pid
from follow_env.sim import streams
from follow_env.sim.jit import njit
from follow_env.sim.rng import LaneRandom, normal_pair_at
from follow_env.sim.schema import Block, f8, i8

__all__ = [
    "PLATFORM",
    "BodyConfig",
    "DriveConfig",
    "FloorConfig",
    "MecanumConfig",
    "MecanumMotorConfig",
    "command",
    "drive",
    "drive_ticks",
    "mecanum_fk",
    "mecanum_ik",
    "reset",
    "wheel_outlines",
]

G = 9.81
SIDE = np.array([-1.0, 1.0, -1.0, 1.0])
"""``s_i``: wheel i pushes along ``(1, s_i)`` (reference §2's rows of M)."""
WHEELS = ("fl", "rl", "rr", "fr")
_X_SIGN = (1.0, -1.0, -1.0, 1.0)  # wheel i at (x_sign a, y_sign b)
_Y_SIGN = (1.0, 1.0, -1.0, -1.0)
_STILL_RADPS = 0.05  # below this a wheel counts as at rest (Karnopp's stiction band)


# --- kinematics (reference §2) -------------------------------------------------------------


@njit(inline="always")
def mecanum_ik(vx: float, vy: float, w: float, r: float, ab: float) -> tuple:
    """Wheel speeds (rad/s, wheels 1..4) for a body twist: ``phi = M [vx, vy, w] / r`` with the
    rows of M ``[1, -1, -(a+b)], [1, 1, -(a+b)], [1, -1, a+b], [1, 1, a+b]`` (reference §2).

    :param vx: forward (m/s). :param vy: to the left (m/s). :param w: yaw rate (rad/s, CCW).
    :param r: wheel radius (m). :param ab: a + b (m).
    """
    return (
        (vx - vy - ab * w) / r,
        (vx + vy - ab * w) / r,
        (vx - vy + ab * w) / r,
        (vx + vy + ab * w) / r,
    )


@njit(inline="always")
def mecanum_fk(p1: float, p2: float, p3: float, p4: float, r: float, ab: float) -> tuple:
    """Body twist ``(vx, vy, w)`` from wheel speeds (rad/s): the least-squares inverse of
    :func:`mecanum_ik`, ``(M^T M)^-1 M^T r phi`` (exact when the wheels agree)."""
    return (
        0.25 * r * (p1 + p2 + p3 + p4),
        0.25 * r * (-p1 + p2 - p3 + p4),
        0.25 * r / ab * (-p1 - p2 + p3 + p4),
    )


# --- parameters and state of a lane ---------------------------------------------------------


def _tick_count(cfg: Any, period: float) -> int:
    return round(period / cfg.platform.drive.tick_s)


PARAMS = Block(
    "mecanum_params",
    "the mecanum base's parameters (SI; the true geometry and motors may differ from the assumed)",
    [
        *base_param_fields(),
        f8("r", "m", "wheel radius the controller assumes", source="platform.body.wheel_radius_m"),
        f8("a", "m", "half wheelbase", source="platform.body.half_wheelbase_m"),
        f8("b", "m", "half track the controller assumes", source="platform.body.half_track_m"),
        f8("r_true", "m", "the wheels' real radius", source="platform.body.wheel_radius_m"),
        f8("b_true", "m", "the real half track", source="platform.body.half_track_m"),
        f8("mass", "kg", "mass", source="platform.body.mass_kg"),
        f8("iz", "kg m^2", "yaw inertia", source="platform.body.yaw_inertia_kgm2"),
        f8("jw", "kg m^2", "wheel inertia", source="platform.body.wheel_inertia_kgm2"),
        f8("v_max", "m/s", "vx and vy bound", source="platform.max_speed_mps"),
        f8("w_max", "rad/s", "turn rate bound", source="platform.max_turn_rate_radps"),
        f8("duty_max", "duty", "full duty", source="platform.motor.max_duty"),
        f8("omega0", "rad/s", "no-load speed", source="platform.motor.no_load_speed_radps"),
        f8("tau_s", "N m", "stall torque", source="platform.motor.stall_torque_nm"),
        f8("brake", "", "1: duty 0 shorts the motor", source=lambda c: _brake(c)),
        f8("gain", "", "per-episode speed ratio of each motor", shape=(4,), source=lambda c: 1.0),
        f8(
            "fric", "N m", "kinetic gear friction per motor", shape=(4,), source=lambda c: _tq(c, 0)
        ),
        f8(
            "start", "N m", "static gear friction per motor", shape=(4,), source=lambda c: _tq(c, 1)
        ),
        f8("mu", "", "traction coefficient", source="platform.floor.traction_mu"),
        f8("c_roll", "", "roller rolling resistance", source="platform.floor.roller_resistance"),
        f8("v_eps", "m/s", "friction regularisation", source="platform.floor.slip_speed_mps"),
        f8("pd", "duty/(rad/s)", "duty scale Pd", source="platform.duty_per_radps"),
        f8("ratio", "", "P_1..P_4", shape=(4,), source=lambda c: _ratios(c)),
        f8("pid_on", "", "1: wheel PIDs set the duty", source=lambda c: _pid_on(c)),
        f8("tick", "s", "physics tick", source="platform.drive.tick_s"),
        i8("sub_steps", "ticks", "ticks per control step", source=lambda c: _sub(c)),
        i8("enc_ticks", "ticks", "ticks per encoder sample", source=lambda c: _enc(c)),
        f8("dt_enc", "s", "encoder and PID period", source="platform.encoder.sample_period_s"),
        f8(
            "cpr", "counts/rev", "encoder counts per turn", source="platform.encoder.counts_per_rev"
        ),
        f8("speed_q", "m/s", "speed quantum", source="platform.encoder.speed_quantum_mps"),
        f8("kp", "%/(m/s)", "PID proportional gain", source="platform.pid.kp"),
        f8("ki", "%/m", "PID integral gain", source="platform.pid.ki"),
        f8("kd", "%·s/(m/s)", "PID derivative gain", source="platform.pid.kd"),
        f8("tau_d", "s", "derivative filter time constant", source="platform.pid.tau_s"),
        f8("aw", "", "1: clamping anti-windup", source=lambda c: _aw(c)),
        f8(
            "enc_noise",
            "counts",
            "extra counts per sample",
            source="randomization.encoder_noise_counts",
        ),
    ],
)


def _brake(c: Any) -> float:
    return 1.0 if c.platform.motor.zero_duty == "brake" else 0.0


def _tq(c: Any, static: int) -> tuple[float, ...]:
    m = c.platform.motor
    duty = m.start_duty if static else m.friction_duty
    return (m.stall_torque_nm * duty / m.max_duty,) * 4


def _ratios(c: Any) -> tuple[float, ...]:
    d = c.platform.drive
    return d.ratio_1, d.ratio_2, d.ratio_3, d.ratio_4


def _pid_on(c: Any) -> float:
    return 1.0 if c.platform.drive.mode == "pid" else 0.0


def _sub(c: Any) -> int:
    return _tick_count(c, c.episode.control_dt_s)


def _enc(c: Any) -> int:
    return _tick_count(c, c.platform.encoder.sample_period_s)


def _aw(c: Any) -> float:
    return 1.0 if c.platform.pid.anti_windup == "clamp" else 0.0


STATE = Block(
    "mecanum_state",
    "per wheel (1 front-left, 2 rear-left, 3 rear-right, 4 front-right)",
    [
        f8("target", "m/s", "linear wheel speed target", shape=(4,)),
        f8("meas", "m/s", "wheel speed from the encoder", shape=(4,)),
        f8("omega", "rad/s", "true wheel speed", shape=(4,)),
        f8("angle", "rad", "true wheel angle", shape=(4,)),
        f8("duty", "duty", "duty applied (0..255, signed)", shape=(4,)),
        f8("slip", "m/s", "roller slip along the push direction", shape=(4,)),
        f8("scratch", "", "tick scratch: p_i, then c_i, of each wheel", shape=(8,)),
        f8("integral", "m", "PID integral", shape=(4,)),
        f8("e_prev", "m/s", "PID error at the previous sample", shape=(4,)),
        f8("d_filt", "m/s^2", "PID filtered derivative", shape=(4,)),
        i8("count", "counts", "encoder count", shape=(4,)),
        i8("ticks", "ticks", "ticks since the episode began"),
    ],
)

_RANDOMIZE = streams.RANDOMIZE.index
_ENC_STRIDE = ENCODER_NOISE.stride
START_SPREAD = streams.per_episode(
    "platform.mecanum.start",
    streams.MOTOR,
    8,
    4,
    space="normal",
    doc="each motor's static friction factor (mecanum), motor i at offset 8 + i",
)
FLOOR = streams.per_episode(
    "platform.mecanum.floor",
    streams.RANDOMIZE,
    9,
    2,
    space="uniform",
    doc="traction and roller resistance scales (mecanum)",
)


@njit(inline="always")
def reset(prm: np.void, st: np.void, body: np.void) -> None:
    """A new episode: wheels and body at rest (the runner has zeroed the state already)."""


@njit(inline="always")
def _sat(x: float, eps: float) -> float:
    """``x / eps`` clipped to [-1, 1]: regularised sign."""
    return min(max(x / eps, -1.0), 1.0)


@njit(inline="always")
def _tick(prm: np.void, st: np.void, body: np.void, h: float) -> None:
    """One physics tick of wheels and body under the duties in ``st.duty`` (module docstring,
    steps 2-4); ``body.v, vy, w`` is the body-frame twist ``q``.

    Implicit Euler in the traction (its secant stiffness at the current slip), the wheels
    eliminated: each free wheel gives ``omega+ = p_i + c_i M_i q+``, a wheel held by static
    friction ``omega+ = 0``, and the body solves ``A q+ = rhs`` (3 x 3, symmetric).
    """
    r, a, b = prm.r_true, prm.a, prm.b_true
    vx, vy, w = body.v, body.vy, body.w
    load = prm.mass * G * 0.25
    f_max, g_max, eps = prm.mu * load, prm.c_roll * load, prm.v_eps
    k = f_max / eps
    inv2 = 0.7071067811865476
    a00, a11, a22 = prm.mass / h, prm.mass / h, prm.iz / h
    a01, a02, a12 = 0.0, 0.0, 0.0
    rhs0 = prm.mass * (vx / h + w * vy)  # body-frame velocities: the Coriolis terms
    rhs1 = prm.mass * (vy / h - w * vx)
    rhs2 = prm.iz * w / h
    sc = st.scratch
    for i in range(4):
        s = SIDE[i]
        x_i, y_i = _X_SIGN[i] * a, _Y_SIGN[i] * b
        c_i = s * x_i - y_i
        om = st.omega[i]
        mq = vx + s * vy + c_i * w
        sig = (mq - r * om) * inv2
        ki = k if abs(sig) <= eps else f_max / abs(sig)
        # Rolling resistance of the free rollers, across the push direction (explicit).
        rho = (-s * (vx - w * y_i - r * om) + vy + w * x_i) * inv2
        gi = -g_max * _sat(rho, eps)
        rhs0 -= s * gi * inv2
        rhs1 += gi * inv2
        rhs2 += gi * inv2 * (x_i + s * y_i)
        u = st.duty[i] / prm.duty_max
        tau = prm.tau_s * prm.gain[i] * u + r * s * gi * inv2
        damp = prm.tau_s / prm.omega0 if (u != 0.0 or prm.brake > 0.0) else 0.0
        # The torque on the wheel if it stood still: motor and the floor's reaction.
        held = tau + r * inv2 * f_max * _sat(mq * inv2, eps)
        if abs(om) < _STILL_RADPS and abs(held) <= prm.start[i]:
            e = 0.5 * ki  # held by static friction: traction acts on the body alone
            sc[i], sc[4 + i] = 0.0, 0.0
        else:
            direction = np.sign(om) if abs(om) >= _STILL_RADPS else np.sign(held)
            d = prm.jw / h + damp + 0.5 * ki * r * r
            cw = 0.5 * ki * r
            p = (prm.jw * om / h + tau - prm.fric[i] * direction) / d
            e = 0.5 * ki - cw * cw / d
            sc[i], sc[4 + i] = p, cw / d
            rhs0 += cw * p
            rhs1 += cw * p * s
            rhs2 += cw * p * c_i
        a00 += e
        a11 += e
        a22 += e * c_i * c_i
        a01 += e * s
        a02 += e * c_i
        a12 += e * s * c_i
    # The symmetric 3 x 3 system by cofactors.
    c00 = a11 * a22 - a12 * a12
    c01 = a02 * a12 - a01 * a22
    c02 = a01 * a12 - a02 * a11
    c11 = a00 * a22 - a02 * a02
    c12 = a01 * a02 - a00 * a12
    c22 = a00 * a11 - a01 * a01
    inv_det = 1.0 / (a00 * c00 + a01 * c01 + a02 * c02)
    vx = (c00 * rhs0 + c01 * rhs1 + c02 * rhs2) * inv_det
    vy = (c01 * rhs0 + c11 * rhs1 + c12 * rhs2) * inv_det
    w = (c02 * rhs0 + c12 * rhs1 + c22 * rhs2) * inv_det
    for i in range(4):
        s = SIDE[i]
        mq = vx + s * vy + (s * _X_SIGN[i] * a - _Y_SIGN[i] * b) * w
        om = st.omega[i]
        new = sc[i] + sc[4 + i] * mq
        if new * om < 0.0 and abs(new) < 4.0 * _STILL_RADPS:
            new = 0.0  # gear friction stops a wheel; it does not reverse it
        st.omega[i] = new
        st.angle[i] += new * h
        st.slip[i] = (mq - r * new) * inv2
    # The pose in the world frame.
    c, sn = np.cos(body.th), np.sin(body.th)
    body.x += (vx * c - vy * sn) * h
    body.y += (vx * sn + vy * c) * h
    th = body.th + w * h
    if th > np.pi:
        th -= 2.0 * np.pi
    elif th <= -np.pi:
        th += 2.0 * np.pi
    body.th = th
    body.v, body.vy, body.w = vx, vy, w


@njit(inline="always")
def _sample(prm: np.void, st: np.void, keys: np.ndarray, step: int, k: int) -> None:
    """Encoder sample ``k`` of the control step (and the wheel PIDs, in PID mode)."""
    n = (0, 0, 0, 0)
    if prm.enc_noise > 0.0:
        kn = keys[_RANDOMIZE] ^ ENCODER_NOISE_CONST
        z1, z2 = normal_pair_at(kn, step * _ENC_STRIDE + 2 * k)
        z3, z4 = normal_pair_at(kn, step * _ENC_STRIDE + 2 * k + 1)
        e = prm.enc_noise
        n = (int(np.round(z1 * e)), int(np.round(z2 * e)), int(np.round(z3 * e)),
             int(np.round(z4 * e)))  # fmt: skip
    for i in range(4):
        count = encoder_count(st.angle[i], prm.cpr) + n[i]
        st.meas[i] = encoder_speed(
            count, st.count[i], prm.cpr, prm.dt_enc, 2.0 * prm.r, prm.speed_q
        )
        st.count[i] = count
        if prm.pid_on > 0.0:
            err = st.target[i] - st.meas[i]
            pct, st.integral[i], st.d_filt[i] = wheel_pid(
                err, st.e_prev[i], st.integral[i], st.d_filt[i], prm.kp, prm.ki, prm.kd,
                prm.tau_d, prm.dt_enc, 100.0, prm.aw > 0.0,
            )  # fmt: skip
            st.e_prev[i] = err
            st.duty[i] = pct * 0.01 * prm.duty_max


@njit(inline="always")
def command(prm: np.void, st: np.void, action: np.ndarray) -> None:
    """Wheel targets for ``action = [vx, vy, w]`` (clipped to the bounds) and, open loop, the
    duties ``Pd P_i phi_i`` (reference §2)."""
    vx = min(max(action[0], -prm.v_max), prm.v_max)
    vy = min(max(action[1], -prm.v_max), prm.v_max)
    w = min(max(action[2], -prm.w_max), prm.w_max)
    phi = mecanum_ik(vx, vy, w, prm.r, prm.a + prm.b)
    for i in range(4):
        st.target[i] = phi[i] * prm.r
        if prm.pid_on == 0.0:
            duty = prm.pd * prm.ratio[i] * phi[i]
            st.duty[i] = min(max(duty, -prm.duty_max), prm.duty_max)


@njit(inline="always")
def drive_ticks(
    prm: np.void, st: np.void, body: np.void, keys: np.ndarray, step: int, n_ticks: int
) -> None:
    """``n_ticks`` physics ticks under the current wheel commands, with an encoder sample (and
    PID update) every ``enc_ticks`` ticks since the episode began; pushes move the body."""
    h = prm.tick
    push_x, push_y = push_velocity(prm.push_p, prm.push_v, keys, step)
    body.push_vx, body.push_vy = push_x, push_y
    for j in range(n_ticks):
        _tick(prm, st, body, h)
        body.x += push_x * h
        body.y += push_y * h
        st.ticks += 1
        if st.ticks % prm.enc_ticks == 0:
            _sample(prm, st, keys, step, j // prm.enc_ticks)


@njit(inline="always")
def drive(
    prm: np.void, st: np.void, body: np.void, action: np.ndarray, keys: np.ndarray, step: int
) -> None:
    """One control step under ``action = [vx m/s, vy m/s, w rad/s]`` (module docstring); then
    the robot's forward speed from its encoders and its finite difference (what it logs)."""
    command(prm, st, action)
    drive_ticks(prm, st, body, keys, step, prm.sub_steps)
    m = st.meas
    body.v_meas_prev = body.v_meas
    body.v_meas = 0.25 * (m[0] + m[1] + m[2] + m[3])
    body.accel = (body.v_meas - body.v_meas_prev) / prm.dt


def randomize(
    params: np.ndarray, base: np.void, lanes: np.ndarray, cfg: Any, keys: np.ndarray
) -> None:
    """Per-episode draws of ``lanes``: motor speed ratios and static friction, true wheel
    radius and half track, gear friction, traction and roller resistance.

    :param params: the platform parameter records of all lanes (written in place).
    :param base: the configured parameter record. :param lanes: lane indices.
    :param cfg: the env configuration. :param keys: the lanes' keys ``(len(lanes), N_STREAMS)``.
    """
    m = cfg.platform.motor
    if m.gain_spread > 0.0:
        params["gain"][lanes] = motor_gains(keys, 4, m.gain_spread)
    start = np.ones((len(lanes), 4))
    if m.start_spread > 0.0:
        z = LaneRandom(keys[:, streams.MOTOR.index]).normal(4, at=START_SPREAD)
        start = np.clip(1.0 + m.start_spread * z, 0.5, 1.5)
    rc = cfg.randomization
    rng = LaneRandom(keys[:, _RANDOMIZE])
    err = rng.normal(2, at=GEOMETRY_ERROR)  # wheel radius, track
    params["r_true"][lanes] = base["r"] * np.clip(1.0 + rc.wheel_radius_error * err[:, 0], 0.5, 1.5)
    params["b_true"][lanes] = base["b"] * np.clip(1.0 + rc.track_width_error * err[:, 1], 0.5, 1.5)
    fric = 1.0 + rc.friction_spread * rng.uniform(low=-1.0, high=1.0, at=FRICTION)
    params["fric"][lanes] = base["fric"] * fric[:, None]
    params["start"][lanes] = base["start"] * fric[:, None] * start
    s = cfg.platform.floor.spread
    floor = 1.0 + s * rng.uniform(2, low=-1.0, high=1.0, at=FLOOR)
    params["mu"][lanes] = base["mu"] * floor[:, 0]
    params["c_roll"][lanes] = base["c_roll"] * floor[:, 1]


def action_high(cfg: Any) -> np.ndarray:
    """Symmetric action bounds ``[v_max m/s, v_max m/s, w_max rad/s]``, each rounded up to the
    nearest float32 at or above it: the action space is float32, and a bound rounded down
    (1.3470588 m/s to 1.34705877) would sit below the kernel's clip (:func:`command`), so an
    action clipped to the space (``ClipAction``) would drive slower than the same action past
    the bound. Rounded up, clipping to the space and then the kernel's clip give the kernel's
    bound either way, and no action within the bounds changes."""
    p = cfg.platform
    high = np.array([p.max_speed_mps, p.max_speed_mps, p.max_turn_rate_radps])
    high32 = high.astype(np.float32)
    below = high32.astype(np.float64) < high
    high32[below] = np.nextafter(high32[below], np.float32(np.inf))
    return high32.astype(np.float64)


def wheel_outlines(cfg: Any) -> np.ndarray:
    """Wheels for drawing: ``(x, y, length, width, roller slope)`` in the body frame (m)."""
    b = cfg.platform.body
    d = 2.0 * b.wheel_radius_m
    rows = [(sx * b.half_wheelbase_m, sy * b.half_track_m, d, 0.5 * d, s) for sx, sy, s in
            zip(_X_SIGN, _Y_SIGN, SIDE, strict=True)]  # fmt: skip
    return np.array(rows)


def _info() -> tuple[tuple[str, str, int, str], ...]:
    rows = []
    for field_name, key, unit, what in (
        ("target", "wheel_target_{}_mps", "m/s", "speed target"),
        ("meas", "wheel_measured_{}_mps", "m/s", "speed from its encoder"),
        ("omega", "wheel_true_{}_radps", "rad/s", "true speed"),
        ("duty", "duty_{}", "of 255", "motor duty"),
    ):
        for i, name in enumerate(WHEELS):
            rows.append((key.format(name), field_name, i, f"{name} wheel {what} ({unit})"))
    return tuple(rows)


PLATFORM = register_platform(
    Platform(
        name="mecanum",
        config=MecanumConfig,
        params=PARAMS,
        state=STATE,
        actions=(
            ActionField("v_mps", "m/s", "forward speed vx"),
            ActionField("vy_mps", "m/s", "sideways speed vy, to the left"),
            ActionField("w_radps", "rad/s", "turn rate, counter-clockwise positive"),
        ),
        module=__name__,
        action_high=action_high,
        randomize=randomize,
        info=_info(),
        doc="four mecanum wheels, open loop on PWM duty (the mecanum paper's robot)",
        wheels=wheel_outlines,
    )
)

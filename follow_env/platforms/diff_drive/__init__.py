"""The differential-drive base of the reference robot (reference §1.1, §1.2): one platform module.

Two wheels (right, left, as in the reference robot's serial protocol) under speed PIDs, each
with its DC gear-motor and quadrature encoder (:mod:`follow_env.platforms.wheels`). Its action is
the body twist ``[v_mps, w_radps]``; each control step runs the inverse kinematics, then
``sub_steps`` ticks of 10 ms of encoder, PID and motor per wheel with forward kinematics and an
Euler pose step (:func:`drive`).

Everything a task or an env needs of the platform is in :data:`PLATFORM` (registered as
``"diff_drive"``): the config sections, the parameter and state blocks, the action and its
bounds, the per-episode randomisation, and the info keys.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from follow_env.platforms import register_platform
from follow_env.platforms.base import (
    ENCODER_NOISE,
    ENCODER_NOISE_CONST,
    FRICTION,
    GEOMETRY_ERROR,
    ActionField,
    Platform,
    PlatformConfig,
    base_param_fields,
    motor_gains,
    push_velocity,
)
from follow_env.platforms.diff_drive.chain import (
    ChainConfig,
    chain_param_fields,
    chain_state_fields,
    drive_pc,
)
from follow_env.platforms.diff_drive.kinematics import (
    DiffDrive,
    diff_drive_fk,
    diff_drive_ik,
    euler_pose_step,
)
from follow_env.platforms.wheels import (
    EncoderConfig,
    MotorConfig,
    PIDConfig,
    lag_factor,
    wheel_tick,
)
from follow_env.sim import streams
from follow_env.sim.checks import out_of_range
from follow_env.sim.config import Validated, param
from follow_env.sim.jit import njit
from follow_env.sim.rng import LaneRandom, normal_pair_at
from follow_env.sim.schema import Block, f8, i8

__all__ = [
    "PLATFORM",
    "DiffDrive",
    "DiffDriveConfig",
    "RobotConfig",
    "diff_drive_fk",
    "diff_drive_ik",
    "drive",
    "euler_pose_step",
    "reset",
]

MAX_SUB_STEPS = 4096
"""Most encoder periods per control step (the encoder-noise counters are laid out for it)."""


@dataclass(frozen=True)
class RobotConfig(Validated):
    """Geometry of the differential-drive base (reference §1.1; the thesis gives no r, L, size)."""

    wheel_radius_m: float = param(
        0.075,
        0.01,
        0.5,
        "m",
        "choice: 150 mm wheels, usual for a small indoor transport robot",
        lo_open=True,
    )
    track_width_m: float = param(
        0.40,
        0.05,
        2.0,
        "m",
        "choice: distance between the wheels of a ~0.5 m wide base",
        lo_open=True,
    )
    footprint_length_m: float = param(
        0.50, 0.05, 3.0, "m", "choice: rectangular footprint, centred on the wheel axle"
    )
    footprint_width_m: float = param(
        0.45, 0.05, 3.0, "m", "choice: footprint width, wheels included"
    )

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.footprint_width_m < self.track_width_m:
            raise ValueError(
                f"RobotConfig.footprint_width_m={self.footprint_width_m!r} is out of range: "
                f"must be >= track_width_m ({self.track_width_m} m), the wheels are inside it"
            )


@dataclass(frozen=True)
class DiffDriveConfig(PlatformConfig):
    """The differential-drive platform's sections: geometry, motors, encoders, wheel PIDs."""

    NAME: ClassVar[str] = "diff_drive"
    SPREADS: ClassVar[tuple[str, ...]] = ("motor.gain_spread",)

    robot: RobotConfig = field(default_factory=RobotConfig)
    motor: MotorConfig = field(default_factory=MotorConfig)
    encoder: EncoderConfig = field(default_factory=EncoderConfig)
    pid: PIDConfig = field(default_factory=PIDConfig)
    chain: ChainConfig = field(default_factory=ChainConfig)

    @property
    def footprint_length_m(self) -> float:
        """Footprint along the heading (m)."""
        return self.robot.footprint_length_m

    @property
    def footprint_width_m(self) -> float:
        """Footprint across (m)."""
        return self.robot.footprint_width_m

    def check_control_period(self, control_dt_s: float) -> None:
        """The control period must be a whole number (1 .. 4096) of encoder periods."""
        ratio = control_dt_s / self.encoder.sample_period_s
        if abs(ratio - round(ratio)) > 1e-9 or round(ratio) < 1:
            raise out_of_range(
                "EpisodeConfig.control_dt_s",
                control_dt_s,
                f"a whole multiple of encoder.sample_period_s ({self.encoder.sample_period_s} s)",
            )
        if round(ratio) > MAX_SUB_STEPS:
            raise out_of_range(
                "EpisodeConfig.control_dt_s",
                control_dt_s,
                f"at most {MAX_SUB_STEPS} encoder periods per control step",
            )

    def sub_steps(self, control_dt_s: float) -> int:
        """Inner drive-loop steps per control step (10 with the defaults)."""
        return round(control_dt_s / self.encoder.sample_period_s)

    @property
    def max_wheel_speed_mps(self) -> float:
        """Highest steady linear wheel speed the motors reach at the duty limit (m/s)."""
        m = self.motor
        frac = (m.max_duty_pct - m.friction_duty_pct) / (100.0 - m.friction_duty_pct)
        return m.no_load_speed_radps * self.robot.wheel_radius_m * frac

    @property
    def max_speed_mps(self) -> float:
        """Action bound on forward speed ``v`` (m/s): both wheels at their top speed."""
        return self.max_wheel_speed_mps

    @property
    def max_turn_rate_radps(self) -> float:
        """Action bound on turn rate ``w`` (rad/s): wheels at top speed in opposite senses."""
        return 2.0 * self.max_wheel_speed_mps / self.robot.track_width_m


# --- parameters and state of a lane ---------------------------------------------------------

PARAMS = Block(
    "diff_drive_params",
    "the differential drive's parameters (SI; the true geometry may differ from the assumed)",
    [
        *base_param_fields(),
        f8(
            "wheel_r",
            "m",
            "wheel radius the controller assumes",
            source="platform.robot.wheel_radius_m",
        ),
        f8(
            "track",
            "m",
            "track width the controller assumes",
            source="platform.robot.track_width_m",
        ),
        f8("wheel_r_true", "m", "the wheels' real radius", source="platform.robot.wheel_radius_m"),
        f8("track_true", "m", "the real track width", source="platform.robot.track_width_m"),
        f8("v_max", "m/s", "forward speed bound", source="platform.max_speed_mps"),
        f8("w_max", "rad/s", "turn rate bound", source="platform.max_turn_rate_radps"),
        f8(
            "motor_wmax",
            "rad/s",
            "no-load wheel speed",
            source="platform.motor.no_load_speed_radps",
        ),
        f8(
            "motor_alpha",
            "",
            "1 - exp(-dt_in / tau): the motor lag over one encoder tick",
            source=lambda c: lag_factor(
                c.platform.motor.time_constant_s, c.platform.encoder.sample_period_s
            ),
        ),
        f8("fric", "%", "Coulomb friction as duty", source="platform.motor.friction_duty_pct"),
        f8("stall", "%", "static friction (stall) duty", source="platform.motor.stall_duty_pct"),
        f8("max_duty", "%", "duty limit", source="platform.motor.max_duty_pct"),
        f8(
            "gain",
            "",
            "per-episode motor gain (right, left)",
            shape=(2,),
            source=lambda c: (1.0, 1.0),
        ),
        f8(
            "cpr",
            "counts/rev",
            "encoder counts per wheel turn",
            source="platform.encoder.counts_per_rev",
        ),
        f8("dt_in", "s", "encoder and PID period", source="platform.encoder.sample_period_s"),
        f8(
            "speed_q",
            "m/s",
            "speed quantum of the firmware",
            source="platform.encoder.speed_quantum_mps",
        ),
        i8(
            "sub_steps",
            "ticks",
            "encoder ticks per control step",
            source=lambda c: c.platform.sub_steps(c.episode.control_dt_s),
        ),
        f8("kp", "%/(m/s)", "PID proportional gain", source="platform.pid.kp"),
        f8("ki", "%/m", "PID integral gain", source="platform.pid.ki"),
        f8("kd", "%·s/(m/s)", "PID derivative gain", source="platform.pid.kd"),
        f8("tau_d", "s", "derivative filter time constant", source="platform.pid.tau_s"),
        f8(
            "anti_windup",
            "",
            "1: clamping anti-windup, 0: none",
            source=lambda c: 1.0 if c.platform.pid.anti_windup == "clamp" else 0.0,
        ),
        f8(
            "enc_noise",
            "counts",
            "std of extra encoder counts per tick",
            source="randomization.encoder_noise_counts",
        ),
        *chain_param_fields(),
    ],
)

STATE = Block(
    "diff_drive_state",
    "per wheel (right, left): PID, motor and encoder state",
    [
        f8("target", "m/s", "linear wheel speed target", shape=(2,)),
        f8("meas", "m/s", "wheel speed as the encoder estimates it", shape=(2,)),
        f8("omega", "rad/s", "true wheel speed", shape=(2,)),
        f8("angle", "rad", "true wheel angle", shape=(2,)),
        f8("integral", "m", "PID integral", shape=(2,)),
        f8("e_prev", "m/s", "PID error at the previous tick", shape=(2,)),
        f8("d_filt", "m/s^2", "PID filtered derivative", shape=(2,)),
        f8("duty", "%", "duty applied", shape=(2,)),
        i8("count", "counts", "encoder count", shape=(2,)),
        *chain_state_fields(),
    ],
)

_RANDOMIZE = streams.RANDOMIZE.index
_ENC_STRIDE = ENCODER_NOISE.stride


@njit(inline="always")
def reset(prm: np.void, st: np.void, body: np.void) -> None:
    """A new episode: the wheels at rest (the runner has zeroed the state already)."""


@njit(inline="always")
def _drive_mcu(
    prm: np.void,
    st: np.void,
    body: np.void,
    keys: np.ndarray,
    step: int,
    consts: tuple,
    push: tuple[float, float],
) -> None:
    """The default chain: ``sub_steps`` ticks of wheel PID, motor and encoder on the MCU."""
    dt_in = prm.dt_in
    g_r, g_l = prm.gain[0], prm.gain[1]
    t_r, t_l = st.target[0], st.target[1]
    m_r, m_l = st.meas[0], st.meas[1]
    e_r, e_l = st.e_prev[0], st.e_prev[1]
    i_r, i_l = st.integral[0], st.integral[1]
    d_r, d_l = st.d_filt[0], st.d_filt[1]
    u_r, u_l = st.duty[0], st.duty[1]
    o_r, o_l = st.omega[0], st.omega[1]
    a_r, a_l = st.angle[0], st.angle[1]
    c_r, c_l = st.count[0], st.count[1]
    x, y, th, v, w = body.x, body.y, body.th, body.v, body.w
    # Real wheels and track may differ from what the controller assumes (randomisation).
    r_true, L_true = prm.wheel_r_true, prm.track_true
    enc_noise = prm.enc_noise
    k_noise = keys[_RANDOMIZE] ^ ENCODER_NOISE_CONST
    push_x, push_y = push
    for tick in range(prm.sub_steps):
        n_r, n_l = 0, 0
        if enc_noise > 0.0:  # extra counts read this tick, per wheel
            z_r, z_l = normal_pair_at(k_noise, step * _ENC_STRIDE + tick)
            n_r, n_l = int(np.round(z_r * enc_noise)), int(np.round(z_l * enc_noise))
        u_r, i_r, d_r, e_r, o_r, a_r, c_r, m_r = wheel_tick(
            t_r, m_r, e_r, i_r, d_r, o_r, a_r, c_r, n_r, g_r, consts
        )
        u_l, i_l, d_l, e_l, o_l, a_l, c_l, m_l = wheel_tick(
            t_l, m_l, e_l, i_l, d_l, o_l, a_l, c_l, n_l, g_l, consts
        )
        v, w = diff_drive_fk(o_r, o_l, r_true, L_true)
        x, y, th = euler_pose_step(x, y, th, v, w, dt_in)
        x += push_x * dt_in
        y += push_y * dt_in
    st.meas[0], st.meas[1] = m_r, m_l
    st.e_prev[0], st.e_prev[1] = e_r, e_l
    st.integral[0], st.integral[1] = i_r, i_l
    st.d_filt[0], st.d_filt[1] = d_r, d_l
    st.duty[0], st.duty[1] = u_r, u_l
    st.omega[0], st.omega[1] = o_r, o_l
    st.angle[0], st.angle[1] = a_r, a_l
    st.count[0], st.count[1] = c_r, c_l
    body.x, body.y, body.th, body.v, body.w = x, y, th, v, w


@njit(inline="always")
def drive(
    prm: np.void, st: np.void, body: np.void, action: np.ndarray, keys: np.ndarray, step: int
) -> None:
    """One control step under ``action = [v m/s, w rad/s]`` (clipped to the platform's bounds).

    1. Inverse kinematics to wheel targets, as linear wheel speeds (reference §1.1).
    2. ``sub_steps`` ticks: per wheel PID on the last encoder estimate, the motor, the encoder
       (reference §1.1, §1.2); forward kinematics with the *true* geometry and an Euler pose step.
    3. The robot's own speed estimate (mean of the wheels' encoder speeds) and its finite
       difference over the control step: the acceleration the robot logs.

    With ``chain.pid_on="pc"`` step 2 is the thesis's chain instead (:func:`chain.drive_pc`):
    the PID on the PC's timer, the firmware measuring per command, the PC's serial reader.
    """
    v_cmd = min(max(action[0], -prm.v_max), prm.v_max)
    w_cmd = min(max(action[1], -prm.w_max), prm.w_max)
    r, L = prm.wheel_r, prm.track
    w_r, w_l = diff_drive_ik(v_cmd, w_cmd, r, L)
    st.target[0], st.target[1] = w_r * r, w_l * r
    dt_in = prm.dt_in
    # The constants of every wheel tick, in wheels.wheel_tick's order.
    consts = (
        prm.kp,
        prm.ki,
        prm.kd,
        prm.tau_d,
        dt_in,
        prm.max_duty,
        prm.anti_windup > 0.0,
        prm.motor_wmax,
        prm.motor_alpha,
        prm.fric,
        prm.stall,
        prm.cpr,
        2.0 * r,
        prm.speed_q,
    )
    push_x, push_y = push_velocity(prm.push_p, prm.push_v, keys, step)
    body.push_vx, body.push_vy = push_x, push_y
    if prm.pid_pc > 0.0:  # the thesis's chain: the PID on the PC (chain.py)
        drive_pc(prm, st, body, keys, step, (push_x, push_y))
    else:
        _drive_mcu(prm, st, body, keys, step, consts, (push_x, push_y))
    # The robot's speed as it computes it, and its finite difference (what it logs).
    body.v_meas_prev = body.v_meas
    body.v_meas = 0.5 * (st.meas[0] + st.meas[1])
    body.accel = (body.v_meas - body.v_meas_prev) / prm.dt


def randomize(
    params: np.ndarray, base: np.void, lanes: np.ndarray, cfg: Any, keys: np.ndarray
) -> None:
    """Per-episode draws of ``lanes``: motor gains, true wheel radius and track width, friction.

    :param params: the platform parameter records of all lanes (written in place).
    :param base: the configured parameter record (what the draws scale).
    :param lanes: lane indices.
    :param cfg: the env configuration.
    :param keys: the lanes' stream keys, ``(len(lanes), N_STREAMS)``.
    """
    spread = cfg.platform.motor.gain_spread
    if spread > 0.0:
        params["gain"][lanes] = motor_gains(keys, 2, spread)
    rc = cfg.randomization
    rng = LaneRandom(keys[:, _RANDOMIZE])
    err = rng.normal(2, at=GEOMETRY_ERROR)  # wheel radius, track width
    params["wheel_r_true"][lanes] = base["wheel_r"] * np.clip(
        1.0 + rc.wheel_radius_error * err[:, 0], 0.5, 1.5
    )
    params["track_true"][lanes] = base["track"] * np.clip(
        1.0 + rc.track_width_error * err[:, 1], 0.5, 1.5
    )
    fric = 1.0 + rc.friction_spread * rng.uniform(low=-1.0, high=1.0, at=FRICTION)
    params["fric"][lanes] = base["fric"] * fric
    params["stall"][lanes] = base["stall"] * fric


def action_high(cfg: Any) -> np.ndarray:
    """Symmetric action bounds ``[v_max m/s, w_max rad/s]``."""
    return np.array([cfg.platform.max_speed_mps, cfg.platform.max_turn_rate_radps])


def wheel_outlines(cfg: Any) -> np.ndarray:
    """The two wheels for drawing: ``(x, y, length, width, 0)`` in the body frame (m); the
    width, 40 mm, is for the picture only."""
    r, L = cfg.platform.robot.wheel_radius_m, cfg.platform.robot.track_width_m
    return np.array([(0.0, -0.5 * L, 2.0 * r, 0.04, 0.0), (0.0, 0.5 * L, 2.0 * r, 0.04, 0.0)])


PLATFORM = register_platform(
    Platform(
        name="diff_drive",
        config=DiffDriveConfig,
        params=PARAMS,
        state=STATE,
        actions=(
            ActionField("v_mps", "m/s", "forward speed"),
            ActionField("w_radps", "rad/s", "turn rate, counter-clockwise positive"),
        ),
        module=__name__,
        action_high=action_high,
        randomize=randomize,
        info=(
            ("wheel_target_r_mps", "target", 0, "right wheel speed target (m/s)"),
            ("wheel_target_l_mps", "target", 1, "left wheel speed target (m/s)"),
            ("wheel_measured_r_mps", "meas", 0, "right wheel speed from its encoder (m/s)"),
            ("wheel_measured_l_mps", "meas", 1, "left wheel speed from its encoder (m/s)"),
            ("wheel_true_r_radps", "omega", 0, "right wheel's true speed (rad/s)"),
            ("wheel_true_l_radps", "omega", 1, "left wheel's true speed (rad/s)"),
            ("duty_r_pct", "duty", 0, "right motor duty (%)"),
            ("duty_l_pct", "duty", 1, "left motor duty (%)"),
        ),
        doc="two driven wheels on one axle (the reference robot)",
        wheels=wheel_outlines,
    )
)

"""The reference robot's wheel chain as its listings build it: the PID on the PC (reference §1.2).

The simulator's default chain runs the wheel PID on the MCU every 10 ms on the encoder speed
measured over the real 10 ms (``ChainConfig(pid_on="mcu")``, a corrected robot). The thesis's
robot did otherwise; its listings (quoted in the reference, §1.1, §1.2, §1.7) build:

* ``PID_node``: the wheel PID runs on the PC, on a ROS timer, with ``dt`` taken from the
  clock and, as listed, neither an output clamp nor anti-windup; its output travels as whole
  percent duty in the 6-byte command (the firmware clamps it to +-99);
* ``main.c``: the MCU loop blocks in ``HAL_UART_Receive`` until a 6-byte command has arrived;
  then, if 10 ms have passed (``HAL_GetTick``), ``Encoder_Interrupt`` reads the 16-bit timer
  register and divides the count difference by its *fixed* 10 ms period: it measures once per
  command, so the speed it publishes is the true speed times (real interval / 10 ms); the
  register wraps every 65536 counts (one absurd speed) and the speed is cast to int16 mm/s;
* ``serial_read_node``: reads the feedback every 0.1 s (as printed it reads 8 bytes and
  unpacks ``data[2:]``, which raises on every read, and a ``data[2:6]`` reading misframes; the
  reader that worked is modelled: it hands on the newest whole frame at each read; the
  printed variants fail as ``bridge/serial_read_node.py`` demonstrates on a real port). The
  PID node and the logged encoder speed see that value.

What the thesis does not give (the PC timer's period and lateness, stalls under detector load,
the USB latency) are parameters, fitted to Table 4.1 by ``python -m eval.thesis --fit``
(README, "What the reference robot's numbers mean").

:func:`drive_pc` advances a lane through one control step of this chain as a sequence of events
(PC timer ticks, command arrivals, reader reads, and the fixed firmware's 10 ms ticks), with the
motor model of :mod:`follow_env.platforms.wheels` integrated exactly between events
(:func:`~follow_env.platforms.wheels.motor_advance`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from follow_env.platforms.diff_drive.kinematics import diff_drive_fk, euler_pose_step
from follow_env.platforms.wheels import encoder_count, encoder_speed, motor_advance, pid_step
from follow_env.sim import streams
from follow_env.sim.config import Validated, param
from follow_env.sim.jit import njit
from follow_env.sim.rng import uniform_at
from follow_env.sim.schema import Field, f8

__all__ = ["PC_TIMER", "ChainConfig", "chain_param_fields", "chain_state_fields", "drive_pc"]

_REFERENCE_PERIOD_S = 0.01  # Encoder_Interrupt's fixed divisor (reference §1.1)
_HAL_TICK_S = 0.001  # HAL_GetTick counts milliseconds
_MAX_EVENTS = 4096  # per control step: a guard, far above any sane timer rate
_NO_CLAMP = 1e12  # the PC PID as listed has no output clamp


@dataclass(frozen=True)
class ChainConfig(Validated):
    """Where the wheel PID runs, which firmware measures, and the PC's timing (module doc)."""

    pid_on: str = param(
        "mcu",
        doc="choice: 'mcu', every 10 ms on the measured interval (a corrected chain); 'pc': "
        "the thesis's PID_node (reference §1.2)",
        choices=("mcu", "pc"),
    )
    firmware: str = param(
        "fixed",
        doc="choice: 'fixed' measures every 10 ms over the real interval; 'reference' is the "
        "thesis's main.c (once per command, fixed 10 ms divisor, 16-bit register)",
        choices=("fixed", "reference"),
    )
    pc_pid_period_s: float = param(
        0.01, 0.001, 0.1, "s", "fitted: the PID node's ROS timer period (the thesis omits it)"
    )
    pc_lateness_s: float = param(
        0.0, 0.0, 0.05, "s", "fitted: mean lateness of a PC timer tick (exponential)"
    )
    pc_stall_prob: float = param(
        0.0, 0.0, 1.0, "/step", "fitted: chance per control step that the PC stalls"
    )
    pc_stall_s: float = param(
        0.0, 0.0, 0.5, "s", "fitted: how long a stall delays the PID node (detector load)"
    )
    usb_latency_s: float = param(
        0.001, 0.0, 0.009, "s", "choice: USB full-speed serial adapters poll every 1 ms"
    )
    register_bits: int = param(
        16,
        16,
        32,
        "bits",
        "reference §1.1 listing: the timer's 16-bit count register (32: a 32-bit timer, no wrap)",
        integer=True,
    )
    reader_period_s: float = param(
        0.1,
        0.0,
        1.0,
        "s",
        "reference §1.7: serial_read_node reads every 0.1 s (0: every frame as it arrives)",
    )

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.firmware == "reference" and self.pid_on != "pc":
            raise ValueError(
                f"ChainConfig.firmware={self.firmware!r} is out of range with pid_on='mcu': "
                "the reference firmware has no wheel PID, set pid_on='pc'"
            )


def chain_param_fields() -> list[Field]:
    """The chain's parameters (in the differential drive's parameter block)."""
    return [
        f8("pid_pc", "", "1: the PID runs on the PC", source=lambda c: _flag(c, "pid_on", "pc")),
        f8(
            "fw_ref",
            "",
            "1: the reference firmware",
            source=lambda c: _flag(c, "firmware", "reference"),
        ),
        f8("pc_period", "s", "PC timer period", source="platform.chain.pc_pid_period_s"),
        f8("pc_late", "s", "PC timer mean lateness", source="platform.chain.pc_lateness_s"),
        f8("stall_p", "/step", "PC stall chance", source="platform.chain.pc_stall_prob"),
        f8("stall_s", "s", "PC stall length", source="platform.chain.pc_stall_s"),
        f8("usb_lat", "s", "command transit", source="platform.chain.usb_latency_s"),
        f8(
            "reader", "s", "reader period (0: every frame)", source="platform.chain.reader_period_s"
        ),
        f8("motor_tau", "s", "motor time constant", source="platform.motor.time_constant_s"),
        f8(
            "reg_mod",
            "counts",
            "the reference firmware's count register modulus",
            source=lambda c: float(2**c.platform.chain.register_bits),
        ),
    ]


def _flag(cfg: object, name: str, value: str) -> float:
    return 1.0 if getattr(cfg.platform.chain, name) == value else 0.0  # type: ignore[attr-defined]


def chain_state_fields() -> list[Field]:
    """The chain's state (in the differential drive's state block); zero at reset."""
    return [
        f8("t_pid", "s", "next PC timer tick (episode time)"),
        f8("t_pid_prev", "s", "previous PC timer tick"),
        f8("t_apply", "s", "arrival of the command in transit (< 0: none)"),
        f8("duty_sent", "%", "the command in transit", shape=(2,)),
        f8("fb", "m/s", "newest speeds the MCU published", shape=(2,)),
        f8("t_hal", "s", "reference firmware: HAL tick of its last measurement"),
        f8(
            "rot_prev",
            "rev",
            "reference firmware: register / ppr at its last measurement",
            shape=(2,),
        ),
        f8("t_read", "s", "next read of the PC's serial reader"),
        f8("t_tick", "s", "fixed firmware: next 10 ms measurement"),
        f8("count_prev", "counts", "fixed firmware: count at its last measurement", shape=(2,)),
    ]


PC_TIMER_KEY = streams.domain(
    "pc_timer", streams.RANDOMIZE, 0x5DEECE66D1A2B3C5, "the PC's timer lateness and stalls"
)
PC_TIMER = streams.per_step(
    "platform.pc_timer",
    PC_TIMER_KEY,
    0,
    256,
    stride=256,
    space="uniform",
    doc="counter step * 256 + k: the k-th PC timer tick of the step's lateness; 255: a stall",
)
_PC_TIMER_CONST = np.uint64(PC_TIMER_KEY.constant)
_STRIDE = PC_TIMER.stride
_RANDOMIZE = streams.RANDOMIZE.index


@njit(inline="always")
def _measure_reference(prm: np.void, st: np.void, a_r: float, a_l: float, t: float) -> None:
    # Encoder_Interrupt: the (16-bit) register, a fixed 10 ms divisor, an int16 mm/s cast.
    for k in range(2):
        angle = a_r if k == 0 else a_l
        register = encoder_count(angle, prm.cpr) % int(prm.reg_mod)
        rot = register / prm.cpr
        mm = (rot - st.rot_prev[k]) / _REFERENCE_PERIOD_S * np.pi * 2.0 * prm.wheel_r * 1000.0
        st.rot_prev[k] = rot
        mm_i = (int(mm) + 32768) % 65536 - 32768  # (int16_t): truncate, wrap
        st.fb[k] = mm_i / 1000.0
    st.t_hal = np.floor(t / _HAL_TICK_S + 1e-9) * _HAL_TICK_S


@njit(inline="always")
def drive_pc(
    prm: np.void, st: np.void, body: np.void, keys: np.ndarray, step: int, push: tuple[float, float]
) -> None:
    """One control step of the PC-PID chain (module docstring); wheel targets in ``st.target``.

    Events in time order: a PC timer tick computes the PID on the PC's measured speed (``dt``
    from the clock) and sends the command, which arrives ``usb_lat`` later; on arrival the
    reference firmware applies it and, 10 ms after its last one, measures; the fixed firmware
    measures every 10 ms over the real interval; the reader hands the newest measurement to the
    PC every ``reader`` s (or at once). The motors and the pose are integrated between events.
    """
    dt = prm.dt
    # ``step`` counts this control step from 1 (the runner advances the episode first), so
    # the step spans [(step - 1) dt, step dt]
    t0 = (step - 1) * dt
    t1 = t0 + dt
    if step == 1:  # the PC starts its timer, and the reader, with the episode
        st.t_apply = -1.0
        st.t_tick = prm.dt_in
        st.t_pid_prev = -prm.pc_period
    motor = (prm.motor_tau, prm.motor_wmax, prm.fric, prm.stall)
    k_timer = keys[_RANDOMIZE] ^ _PC_TIMER_CONST
    if prm.stall_p > 0.0 and uniform_at(k_timer, step * _STRIDE + 255) < prm.stall_p:
        st.t_pid = max(st.t_pid, t0) + prm.stall_s  # the PID node is held up by the detector
    r_true, L_true = prm.wheel_r_true, prm.track_true
    diameter = 2.0 * prm.wheel_r
    x, y, th, v, w = body.x, body.y, body.th, body.v, body.w
    o_r, o_l, a_r, a_l = st.omega[0], st.omega[1], st.angle[0], st.angle[1]
    push_x, push_y = push
    fixed = prm.fw_ref == 0.0
    t = t0
    n_timer = 0
    for _ in range(_MAX_EVENTS):
        te = st.t_pid
        kind = 0
        if st.t_apply >= 0.0 and st.t_apply < te:
            te, kind = st.t_apply, 1
        if prm.reader > 0.0 and st.t_read < te:
            te, kind = st.t_read, 2
        if fixed and st.t_tick < te:
            te, kind = st.t_tick, 3
        if te >= t1:
            te, kind = t1, 4
        seg = te - t
        if seg > 0.0:  # the motors under the applied duty, exactly; the pose by Euler
            a_r0, a_l0 = a_r, a_l
            o_r, a_r = motor_advance(o_r, a_r, st.duty[0], prm.gain[0], seg, motor)
            o_l, a_l = motor_advance(o_l, a_l, st.duty[1], prm.gain[1], seg, motor)
            # the pose by the mean twist over the segment (its wheel travel)
            v, w = diff_drive_fk((a_r - a_r0) / seg, (a_l - a_l0) / seg, r_true, L_true)
            x, y, th = euler_pose_step(x, y, th, v, w, seg)
            x += push_x * seg
            y += push_y * seg
        t = te
        if kind == 4:
            break
        if kind == 0:  # the PC's PID node: on what it was last told, dt from its clock
            dt_pid = max(t - st.t_pid_prev, 1e-6)
            st.t_pid_prev = t
            for k in range(2):
                err = st.target[k] - st.meas[k]
                u, st.integral[k], st.d_filt[k] = pid_step(
                    err,
                    st.e_prev[k],
                    st.integral[k],
                    st.d_filt[k],
                    prm.kp,
                    prm.ki,
                    prm.kd,
                    prm.tau_d,
                    dt_pid,
                    _NO_CLAMP if prm.anti_windup == 0.0 else prm.max_duty,
                    prm.anti_windup > 0.0,
                )
                st.e_prev[k] = err
                st.duty_sent[k] = min(max(float(int(u)), -32768.0), 32767.0)  # int16 percent
            st.t_apply = t + prm.usb_lat
            late = 0.0
            if prm.pc_late > 0.0 and n_timer < 255:
                late = -prm.pc_late * np.log(1.0 - uniform_at(k_timer, step * _STRIDE + n_timer))
            n_timer += 1
            st.t_pid = t + prm.pc_period + late
        elif kind == 1:  # the command arrives: the firmware clamps it to +-99 and applies it
            st.duty[0] = min(max(st.duty_sent[0], -prm.max_duty), prm.max_duty)
            st.duty[1] = min(max(st.duty_sent[1], -prm.max_duty), prm.max_duty)
            st.t_apply = -1.0
            if not fixed and np.floor(t / _HAL_TICK_S + 1e-9) * _HAL_TICK_S - st.t_hal >= (
                _REFERENCE_PERIOD_S - 1e-9
            ):
                _measure_reference(prm, st, a_r, a_l, t)
                if prm.reader == 0.0:
                    st.meas[0], st.meas[1] = st.fb[0], st.fb[1]
        elif kind == 2:  # serial_read_node: the newest whole frame
            st.meas[0], st.meas[1] = st.fb[0], st.fb[1]
            st.t_read += prm.reader
        else:  # the fixed firmware's 10 ms timer: the speed over the real interval
            for k in range(2):
                count = encoder_count(a_r if k == 0 else a_l, prm.cpr)
                st.fb[k] = encoder_speed(
                    count, int(st.count_prev[k]), prm.cpr, prm.dt_in, diameter, prm.speed_q
                )
                st.count_prev[k] = count
            if prm.reader == 0.0:
                st.meas[0], st.meas[1] = st.fb[0], st.fb[1]
            st.t_tick += prm.dt_in
    st.omega[0], st.omega[1], st.angle[0], st.angle[1] = o_r, o_l, a_r, a_l
    st.count[0], st.count[1] = encoder_count(a_r, prm.cpr), encoder_count(a_l, prm.cpr)
    body.x, body.y, body.th, body.v, body.w = x, y, th, v, w

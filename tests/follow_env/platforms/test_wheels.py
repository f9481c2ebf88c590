"""Encoder, PID and motor models (reference §1.1, §1.2), and the tuned wheel step response."""

from __future__ import annotations

import numpy as np
import pytest

from follow_env.platforms.wheels import (
    encoder_count,
    encoder_speed,
    lag_factor,
    motor_step,
    pid_step,
    wheel_tick,
)
from follow_env.tasks.person_follow.config import THESIS
from follow_env.tasks.person_follow.task import batched_sim

CPR = 2048 * 4
ALPHA = lag_factor(0.08, 0.01)  # tau 80 ms over a 10 ms tick


def test_encoder_counts_are_integers_floored_at_4x_resolution() -> None:
    assert encoder_count(0.0, CPR) == 0
    assert encoder_count(2 * np.pi, CPR) == CPR
    # A hair short of one count is still zero counts; a hair past -0 is -1.
    assert encoder_count(2 * np.pi / CPR * 0.999, CPR) == 0
    assert encoder_count(-1e-9, CPR) == -1


def test_encoder_speed_follows_the_firmware_formula() -> None:
    # 100 counts in 10 ms: rot = 100/8192, rps = rot / 0.01, v = rps * pi * D (D = 0.15 m)
    expected = 100 / CPR / 0.01 * np.pi * 0.15
    got = encoder_speed(1100, 1000, CPR, 0.01, 0.15, 0.0)
    assert np.isclose(got, expected)


def test_encoder_speed_is_truncated_to_whole_mm_per_s() -> None:
    raw = 100 / CPR / 0.01 * np.pi * 0.15  # 0.5752... m/s
    got = encoder_speed(1100, 1000, CPR, 0.01, 0.15, 0.001)
    assert np.isclose(got, 0.575)
    assert np.isclose(encoder_speed(900, 1000, CPR, 0.01, 0.15, 0.001), -0.575)
    assert got <= raw


def test_encoder_speed_resolution_is_one_count_per_period() -> None:
    one = encoder_speed(1, 0, CPR, 0.01, 0.15, 0.0)
    assert np.isclose(one, np.pi * 0.15 / CPR / 0.01)  # ~5.75 mm/s


def test_pid_derivative_is_low_pass_filtered() -> None:
    # e jumps 0 -> 1 over dt = 0.01 s: raw = 100 /s; D = (tau*0 + dt*raw)/(tau+dt) = 50 /s
    _, _, d = pid_step(1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.01, 0.01, 99.0, True)
    assert np.isclose(d, 50.0)
    # With tau = 0 the derivative is the raw difference quotient.
    _, _, d0 = pid_step(1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.01, 99.0, True)
    assert np.isclose(d0, 100.0)


def test_pid_output_is_the_sum_of_its_terms() -> None:
    u, integ, d = pid_step(0.2, 0.1, 0.5, 2.0, 10.0, 3.0, 0.5, 0.01, 0.01, 99.0, True)
    assert np.isclose(integ, 0.5 + 0.2 * 0.01)
    assert np.isclose(d, (0.01 * 2.0 + 0.01 * (0.1 / 0.01)) / 0.02)
    assert np.isclose(u, 10.0 * 0.2 + 3.0 * integ + 0.5 * d)


def test_duty_is_clamped_to_99_percent() -> None:
    u, _, _ = pid_step(10.0, 10.0, 0.0, 0.0, 100.0, 0.0, 0.0, 0.01, 0.01, 99.0, True)
    assert u == 99.0
    u, _, _ = pid_step(-10.0, -10.0, 0.0, 0.0, 100.0, 0.0, 0.0, 0.01, 0.01, 99.0, True)
    assert u == -99.0


def test_anti_windup_stops_integrating_in_saturation() -> None:
    _, integ, _ = pid_step(10.0, 10.0, 1.0, 0.0, 100.0, 1.0, 0.0, 0.01, 0.01, 99.0, True)
    assert integ == 1.0
    _, integ, _ = pid_step(10.0, 10.0, 1.0, 0.0, 100.0, 1.0, 0.0, 0.01, 0.01, 99.0, False)
    assert np.isclose(integ, 1.1)


def test_anti_windup_keeps_the_duty_at_the_limit() -> None:
    # Kp e + Ki (0 + e dt) = 98.95 + 0.1 saturates; the output used to be computed again
    # from the held integral, 98.95 %
    u, integ, _ = pid_step(1.0, 1.0, 0.0, 0.0, 98.95, 10.0, 0.0, 0.01, 0.01, 99.0, True)
    assert integ == 0.0
    assert u == 99.0


def test_a_wheel_asked_for_more_than_its_top_speed_runs_at_it() -> None:
    # the clamp's output dropped out of saturation, so a wheel slowed as its target rose above
    # its top speed (2.08 m/s gave 1.34): every such target now runs at 99 % duty, top speed
    top = 20.0 * 0.075 * (99.0 - 4.0) / 96.0  # no-load speed x radius x (99 - friction) / 96
    pid = (120.0, 1500.0, 0.5, 0.01, 0.01, 99.0, True)  # the default gains, 10 ms, 99 %
    consts = (*pid, 20.0, ALPHA, 4.0, 8.0, 8192.0, 0.15, 0.001)
    for target in (1.55, 1.9, 2.08, 3.0):
        e = i = d = omega = angle = meas = 0.0
        count = 0
        for _ in range(400):  # 4 s
            u, i, d, e, omega, angle, count, meas = wheel_tick(
                target, meas, e, i, d, omega, angle, count, 0, 1.0, consts
            )
        assert u == 99.0, target
        assert omega * 0.075 == pytest.approx(top, rel=1e-6), target


def test_motor_lags_towards_its_steady_speed() -> None:
    # friction 4 %, 52 % duty -> steady 20 * (52 - 4) / 96 = 10 rad/s; tau 0.08 s
    w = 0.0
    for _ in range(100):  # 1 s = 12.5 tau
        w = motor_step(w, 52.0, 1.0, 20.0, ALPHA, 4.0, 8.0)
    assert np.isclose(w, 10.0, rtol=1e-4)
    one = motor_step(0.0, 52.0, 1.0, 20.0, ALPHA, 4.0, 8.0)
    assert np.isclose(one, 10.0 * (1 - np.exp(-0.01 / 0.08)))


def test_motor_stalls_below_the_static_friction_duty() -> None:
    assert motor_step(0.0, 7.0, 1.0, 20.0, ALPHA, 4.0, 8.0) == 0.0
    assert motor_step(0.0, 9.0, 1.0, 20.0, ALPHA, 4.0, 8.0) > 0.0
    # A turning wheel keeps turning at the same low duty (only static friction holds it).
    assert motor_step(5.0, 7.0, 1.0, 20.0, ALPHA, 4.0, 8.0) > 0.0


def test_motor_speed_saturates_at_the_duty_limit() -> None:
    w = 0.0
    for _ in range(200):
        w = motor_step(w, 99.0, 1.0, 20.0, ALPHA, 4.0, 8.0)
    assert np.isclose(w, 20.0 * 95.0 / 96.0, rtol=1e-4)


def _wheel_step_response(target_mps: float) -> tuple[np.ndarray, np.ndarray]:
    """Right wheel's true linear speed and duty every 10 ms after a step in the target."""
    cfg = THESIS.replace(episode={"control_dt_s": 0.01}, motor={"gain_spread": 0.0})
    sim = batched_sim(cfg, 1)
    sim.reset_lanes(np.zeros(1, dtype=np.int64), [0])
    speed, duty = [], []
    for _ in range(150):
        sim.step(np.array([[target_mps, 0.0]]))
        speed.append(sim.state["platform"]["omega"][0, 0] * cfg.robot.wheel_radius_m)
        duty.append(sim.state["platform"]["duty"][0, 0])
    return np.array(speed), np.array(duty)


def test_default_pid_step_response_settles_within_0_3_s() -> None:
    for target in (0.3, 0.5, 1.0):
        speed, _ = _wheel_step_response(target)
        t = np.arange(1, len(speed) + 1) * 0.01
        outside = t[np.abs(speed - target) > 0.02 * target]
        assert outside.max() <= 0.3, f"step to {target} m/s settles at {outside.max():.2f} s"
        assert speed.max() <= 1.05 * target  # overshoot under 5 %


def test_default_pid_has_no_sustained_oscillation() -> None:
    speed, duty = _wheel_step_response(0.5)
    tail = speed[50:]  # after 0.5 s
    assert np.ptp(tail) < 0.01  # within 1 cm/s: encoder quantisation, not a limit cycle
    assert np.all(duty[50:] > 0)  # the duty never swings through zero


def test_measured_speed_tracks_true_speed_within_quantisation() -> None:
    cfg = THESIS.replace(motor={"gain_spread": 0.0})
    sim = batched_sim(cfg, 1)
    sim.reset_lanes(np.zeros(1, dtype=np.int64), [0])
    for _ in range(10):
        sim.step(np.array([[0.5, 0.0]]))
    true = sim.state["platform"]["omega"][0, 0] * cfg.robot.wheel_radius_m
    assert abs(sim.state["platform"]["meas"][0, 0] - true) < 0.02

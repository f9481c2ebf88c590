"""Differential-drive kinematics (reference §1.1)."""

from __future__ import annotations

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from follow_env.platforms.diff_drive import DiffDrive, diff_drive_fk, diff_drive_ik, euler_pose_step

speeds = st.floats(-3.0, 3.0, allow_nan=False)


@given(v=speeds, w=speeds, r=st.floats(0.02, 0.3), L=st.floats(0.1, 1.0))
def test_inverse_then_forward_returns_the_command(v: float, w: float, r: float, L: float) -> None:
    wr, wl = diff_drive_ik(v, w, r, L)
    v2, w2 = diff_drive_fk(wr, wl, r, L)
    assert np.isclose(v2, v, atol=1e-9)
    assert np.isclose(w2, w, atol=1e-9)


def test_inverse_matches_the_spec_formula() -> None:
    # wR = (v + L w / 2) / r = (0.5 + 0.4 * 1.0 / 2) / 0.075 = 9.333...
    wr, wl = diff_drive_ik(0.5, 1.0, 0.075, 0.4)
    assert np.isclose(wr, 0.7 / 0.075)
    assert np.isclose(wl, 0.3 / 0.075)


def test_turning_left_spins_the_right_wheel_faster() -> None:
    wr, wl = diff_drive_ik(0.0, 1.0, 0.075, 0.4)
    assert wr > 0 > wl


def test_class_and_compiled_functions_agree() -> None:
    dd = DiffDrive(0.075, 0.4)
    wheels = dd.inverse(np.array([0.3, -0.2]), np.array([0.5, 1.5]))
    assert wheels.shape == (2, 2)
    assert np.allclose(wheels[0], diff_drive_ik(0.3, 0.5, 0.075, 0.4))
    v, w = dd.forward(wheels)
    assert np.allclose(v, [0.3, -0.2])
    assert np.allclose(w, [0.5, 1.5])


def test_euler_step_moves_along_the_heading_and_wraps_the_angle() -> None:
    x, y, th = euler_pose_step(1.0, 2.0, np.pi / 2, 1.0, 0.0, 0.1)
    assert np.isclose(x, 1.0)
    assert np.isclose(y, 2.1)
    _, _, th = euler_pose_step(0.0, 0.0, np.pi - 0.01, 0.0, 1.0, 0.1)
    assert -np.pi < th <= np.pi
    assert np.isclose(th, -np.pi + 0.09)

"""Pinhole camera, extrinsics and body boxes (reference §1.3)."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from follow_env.sensors.camera import Camera, CameraConfig, back_project, body_box, project

CAM = Camera.from_config(CameraConfig())


def test_default_intrinsics_come_from_the_d435i_field_of_view() -> None:
    cfg = CameraConfig()
    assert math.isclose(cfg.fy, 240 / math.tan(math.radians(42.5 / 2)))
    assert 600 < cfg.fx < 630  # the 640 x 480 colour stream: fx ~ 615 px
    assert math.isclose(cfg.hfov_deg, 2 * math.degrees(math.atan(320 / cfg.fx)))
    assert (cfg.cx, cfg.cy) == (320.0, 240.0)


@given(u=st.floats(0, 639), v=st.floats(0, 479), z=st.floats(0.1, 10.0))
def test_back_projection_then_projection_returns_the_pixel(u: float, v: float, z: float) -> None:
    p = back_project(CAM, np.array([u, v]), np.array(z))
    uv = project(CAM, p)
    assert np.allclose(uv, [u, v], atol=1e-6)


def test_points_at_the_fov_edges_land_on_the_image_border() -> None:
    half_h = math.radians(CameraConfig().hfov_deg) / 2
    half_v = math.radians(CameraConfig().vfov_deg) / 2
    z = 3.0
    right = project(CAM, np.array([z * math.tan(half_h), 0.0, z]))
    bottom = project(CAM, np.array([0.0, z * math.tan(half_v), z]))
    assert np.allclose(right, [640.0, 240.0])
    assert np.allclose(bottom, [320.0, 480.0])


def test_points_behind_the_camera_do_not_project() -> None:
    assert np.all(np.isnan(project(CAM, np.array([0.0, 0.0, -1.0]))))


def test_extrinsics_map_the_optical_axis_to_robot_forward() -> None:
    # The camera looks along robot +x from its mount point.
    p = CAM.camera_to_robot(np.array([0.0, 0.0, 2.0]))
    assert np.allclose(p, [0.2 + 2.0, 0.0, 0.6])
    # Camera x (image right) is robot -y (the robot's right).
    right = CAM.camera_to_robot(np.array([1.0, 0.0, 0.0])) - CAM.T
    assert np.allclose(right, [0.0, -1.0, 0.0])
    assert np.allclose(
        CAM.robot_to_camera(CAM.camera_to_robot(np.array([0.3, -0.2, 4.0]))), [0.3, -0.2, 4.0]
    )


def test_pitch_down_moves_the_horizon_up_in_the_image() -> None:
    tilted = Camera.from_config(CameraConfig(pitch_deg=10.0))
    far_level = tilted.robot_to_camera(np.array([100.0, 0.0, 0.6]))
    assert project(tilted, far_level)[1] < 240.0


def _box(
    px: float, py: float, rx: float = 0.0, ry: float = 0.0, rth: float = 0.0, pth: float = 0.0
) -> tuple[float, float, float, float, bool]:
    return body_box(
        px,
        py,
        pth,
        0.45,
        0.25,
        1.7,
        rx,
        ry,
        rth,
        CAM.R.ravel(),
        CAM.T,
        CAM.fx,
        CAM.fy,
        CAM.cx,
        CAM.cy,
        np.zeros(24),
    )


def test_a_centred_person_gives_a_centred_box() -> None:
    u1, v1, u2, v2, found = _box(4.0, 0.0)
    assert found
    assert math.isclose((u1 + u2) / 2, 320.0, abs_tol=1e-9)
    # Nearest face at x = 3.875 m from the robot, 3.675 m from the camera: 0.45 m wide.
    assert math.isclose(u2 - u1, CAM.fx * 0.45 / 3.675, rel_tol=1e-9)
    # Head 1.7 m high and feet on the floor, camera at 0.6 m: the box spans both.
    assert v1 < 240.0 < v2


def test_a_person_to_the_right_has_a_positive_offset() -> None:
    u1, _, u2, _, _ = _box(3.0, -0.5)  # robot frame y < 0 is the robot's right
    assert (u1 + u2) / 2 > 320.0


def test_a_person_behind_the_camera_has_no_box() -> None:
    *_, found = _box(-3.0, 0.0)
    assert not found


def test_a_body_straddling_the_camera_plane_gets_the_box_of_its_front_part() -> None:
    # Person beside the camera, half in front of its plane (camera at x = 0.2 m).
    _u1, _v1, u2, _v2, found = _box(0.2, -0.6, pth=0.0)
    assert found
    assert u2 > 640.0  # the visible part reaches past the right border: a partial box

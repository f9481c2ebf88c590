"""Pinhole camera with camera-to-robot extrinsics ``[R T]`` (SPEC §1.3).

Frames: the camera frame has x right, y down, z forward (optical axis); the robot frame has
x forward, y left, z up, origin on the floor below the wheel axle's centre. A point maps camera
-> robot as ``p_r = R p_c + T``. Pixels: ``u = fx Xc / Zc + cx``, ``v = fy Yc / Zc + cy``, and
back ``Xc = (u - cx) Zc / fx``, ``Yc = (v - cy) Zc / fy`` (SPEC §1.3).

:func:`project` and :func:`back_project` are vectorised numpy functions for users and tests; the
compiled helpers below are what the core's kernel calls, one lane at a time.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from follow_env.config import CameraConfig

__all__ = ["Camera", "back_project", "body_box", "project"]

# Points closer than this to the camera plane are cut away before projecting (m).
NEAR_PLANE_M = 0.01


def _rot_x(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def _rot_y(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def _rot_z(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


# Camera axes (x right, y down, z forward) expressed in the robot frame (x fwd, y left, z up).
_BASE = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])


@dataclass(frozen=True)
class Camera:
    """Intrinsics ``K`` and extrinsics ``[R T]`` built from a :class:`CameraConfig`."""

    fx: float
    fy: float
    cx: float
    cy: float
    width_px: int
    height_px: int
    R: np.ndarray  # (3, 3) camera -> robot rotation
    T: np.ndarray  # (3,) camera position in the robot frame (m)

    @classmethod
    def from_config(cls, cfg: CameraConfig) -> Camera:
        """Build the camera; positive pitch tilts the optical axis down, positive yaw left."""
        rot = _rot_z(math.radians(cfg.yaw_deg)) @ _rot_y(math.radians(cfg.pitch_deg)) @ _BASE
        return cls(
            fx=cfg.fx,
            fy=cfg.fy,
            cx=cfg.cx,
            cy=cfg.cy,
            width_px=cfg.width_px,
            height_px=cfg.height_px,
            R=rot,
            T=np.array([cfg.mount_x_m, cfg.mount_y_m, cfg.mount_z_m]),
        )

    @property
    def K(self) -> np.ndarray:  # noqa: N802  (the intrinsic matrix is K by convention)
        """The 3 x 3 intrinsic matrix."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    def robot_to_camera(self, p_robot: np.ndarray) -> np.ndarray:
        """Points (..., 3) from the robot frame to the camera frame: ``R^T (p - T)``."""
        return (np.asarray(p_robot, dtype=float) - self.T) @ self.R

    def camera_to_robot(self, p_cam: np.ndarray) -> np.ndarray:
        """Points (..., 3) from the camera frame to the robot frame: ``R p + T``."""
        return np.asarray(p_cam, dtype=float) @ self.R.T + self.T


def project(cam: Camera, p_cam: np.ndarray) -> np.ndarray:
    """Pixel coordinates (..., 2) of camera-frame points (..., 3) (SPEC §1.3 pinhole).

    Points at or behind the camera plane (``Zc <= 0``) give NaN.
    """
    p = np.asarray(p_cam, dtype=float)
    z = p[..., 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        u = np.where(z > 0, cam.fx * p[..., 0] / z + cam.cx, np.nan)
        v = np.where(z > 0, cam.fy * p[..., 1] / z + cam.cy, np.nan)
    return np.stack([u, v], axis=-1)


def back_project(cam: Camera, uv: np.ndarray, depth_m: np.ndarray) -> np.ndarray:
    """Camera-frame points (..., 3) for pixels (..., 2) and depths Zc (...) (SPEC §1.3):
    ``Xc = (u - cx) Zc / fx``, ``Yc = (v - cy) Zc / fy``, ``Zc = D(u, v)``."""
    uv = np.asarray(uv, dtype=float)
    z = np.asarray(depth_m, dtype=float)
    x = (uv[..., 0] - cam.cx) * z / cam.fx
    y = (uv[..., 1] - cam.cy) * z / cam.fy
    return np.stack([x, y, z], axis=-1)


@njit(cache=True, inline="always")
def world_to_camera(
    px: float,
    py: float,
    pz: float,
    rx: float,
    ry: float,
    c: float,
    s: float,
    params: np.ndarray,
    p0: int,
) -> tuple[float, float, float]:
    """A world point to the camera frame of a robot at (rx, ry) with heading th, given
    ``c = cos(th)`` and ``s = sin(th)`` (the caller computes them once per frame).

    ``params[p0:p0 + 12]`` holds R row-major then T (the layout's ``P_R00`` .. ``P_TZ``).
    """
    dx, dy = px - rx, py - ry
    qx = c * dx + s * dy - params[p0 + 9]
    qy = -s * dx + c * dy - params[p0 + 10]
    qz = pz - params[p0 + 11]
    # R^T q: column j of R dotted with q.
    xc = params[p0 + 0] * qx + params[p0 + 3] * qy + params[p0 + 6] * qz
    yc = params[p0 + 1] * qx + params[p0 + 4] * qy + params[p0 + 7] * qz
    zc = params[p0 + 2] * qx + params[p0 + 5] * qy + params[p0 + 8] * qz
    return xc, yc, zc


@njit(cache=True, inline="always")
def body_box(
    px: float,
    py: float,
    pth: float,
    width: float,
    depth: float,
    height: float,
    rx: float,
    ry: float,
    rth: float,
    params: np.ndarray,
    p0: int,
    fx: float,
    fy: float,
    cx: float,
    cy: float,
    scratch: np.ndarray,
) -> tuple[float, float, float, float, bool]:
    """Image bounding box of an upright box body, before clipping to the image.

    The body is centred at (px, py) on the floor, facing ``pth``, ``width`` across, ``depth``
    along its heading, ``height`` tall. Its 8 corners go to the camera frame; the 12 edges are
    cut at the near plane so a body partly behind the camera still gets the box of its visible
    part; the box is the extent of the projected points.

    ``scratch`` is caller-owned room for 24 floats (the corners in the camera frame), so the
    function allocates nothing and lanes can run in parallel.

    :return: ``(u1, v1, u2, v2, any_in_front)`` in pixels.
    """
    cth, sth = np.cos(pth), np.sin(pth)
    rc, rs = np.cos(rth), np.sin(rth)
    hd, hw = 0.5 * depth, 0.5 * width
    cam = scratch  # corner k at cam[3k : 3k + 3]
    k = 0
    for a in (-hd, hd):
        for b in (-hw, hw):
            wx = px + a * cth - b * sth
            wy = py + a * sth + b * cth
            for z in (0.0, height):
                xc, yc, zc = world_to_camera(wx, wy, z, rx, ry, rc, rs, params, p0)
                cam[3 * k], cam[3 * k + 1], cam[3 * k + 2] = xc, yc, zc
                k += 1
    u1, v1, u2, v2 = np.inf, np.inf, -np.inf, -np.inf
    found = False
    # Corner k = 4 ia + 2 ib + iz; edges join corners differing in exactly one bit.
    for i in range(8):
        if cam[3 * i + 2] > NEAR_PLANE_M:
            u = fx * cam[3 * i] / cam[3 * i + 2] + cx
            v = fy * cam[3 * i + 1] / cam[3 * i + 2] + cy
            u1, v1, u2, v2 = min(u1, u), min(v1, v), max(u2, u), max(v2, v)
            found = True
        for bit in (1, 2, 4):
            j = i ^ bit
            if j < i:
                continue
            zi, zj = cam[3 * i + 2] - NEAR_PLANE_M, cam[3 * j + 2] - NEAR_PLANE_M
            if zi * zj < 0.0:  # the edge crosses the near plane: add the crossing point
                t = zi / (zi - zj)
                xq = cam[3 * i] + t * (cam[3 * j] - cam[3 * i])
                yq = cam[3 * i + 1] + t * (cam[3 * j + 1] - cam[3 * i + 1])
                u = fx * xq / NEAR_PLANE_M + cx
                v = fy * yq / NEAR_PLANE_M + cy
                u1, v1, u2, v2 = min(u1, u), min(v1, v), max(u2, u), max(v2, v)
                found = True
    return u1, v1, u2, v2, found

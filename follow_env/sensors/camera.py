"""Pinhole camera with camera-to-robot extrinsics ``[R T]`` (reference §1.3), and what it sees.

The camera's configuration (:class:`CameraConfig`: the Intel RealSense D435i's colour stream,
its mounting, and its depth figures), its per-lane parameters (:data:`PARAMS`), the compiled
projection helpers, and :func:`sight_box`: the part of a body in the camera's line of sight.

Frames: the camera frame has x right, y down, z forward (optical axis); the robot frame has
x forward, y left, z up, origin on the floor below the wheel axle's centre. A point maps camera
-> robot as ``p_r = R p_c + T``. Pixels: ``u = fx Xc / Zc + cx``, ``v = fy Yc / Zc + cy``, and
back ``Xc = (u - cx) Zc / fx``, ``Yc = (v - cy) Zc / fy`` (reference §1.3).

:func:`project` and :func:`back_project` are vectorised numpy functions for users and tests; the
compiled helpers below are what the core's kernel calls, one lane at a time.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from follow_env.sim import streams
from follow_env.sim.config import Validated, param
from follow_env.sim.jit import njit
from follow_env.sim.rng import LaneRandom
from follow_env.sim.schema import Block, f8
from follow_env.world.sight import list_occluders, list_people, sight_blocked, sight_blocked_by_any

__all__ = [
    "NEAR_PLANE_M",
    "PARAMS",
    "Camera",
    "CameraConfig",
    "back_project",
    "body_box",
    "camera_origin",
    "project",
    "sight_box",
    "world_to_camera",
]

# Points closer than this to the camera plane are cut away before projecting (m).
NEAR_PLANE_M = 0.01


@dataclass(frozen=True)
class CameraConfig(Validated):
    """Pinhole colour camera with aligned depth (Intel RealSense D435i, reference §1.3).

    Intrinsics derive from the field of view: ``fy = (height/2) / tan(vfov/2)``, ``fx = fy``
    (square pixels), principal point at the image centre. The D435i colour sensor has a
    69 x 42 deg field of view at 16:9; the 4:3 stream of 640 x 480 px (the usual detector input;
    the thesis does not give its resolution) crops it to about 55 x 42.5 deg, fx = fy ~ 617 px.
    Extrinsics: the camera sits at ``mount_*`` in the robot frame (x forward, y left, z up),
    looking forward, tilted by ``pitch_deg`` (positive looks down).
    """

    width_px: int = param(640, 16, 4096, "px", "choice: see class docstring", integer=True)
    height_px: int = param(480, 16, 4096, "px", "choice: see class docstring", integer=True)
    vfov_deg: float = param(
        42.5, 5.0, 150.0, "deg", "datasheet: D435i colour vertical field of view"
    )
    mount_x_m: float = param(0.20, -2.0, 2.0, "m", "choice: at the front of the base")
    mount_y_m: float = param(0.0, -2.0, 2.0, "m", "choice: on the centre line")
    mount_z_m: float = param(0.60, 0.05, 3.0, "m", "choice: on a mast above the cargo deck")
    pitch_deg: float = param(0.0, -60.0, 60.0, "deg", "choice: level")
    yaw_deg: float = param(0.0, -90.0, 90.0, "deg", "choice: straight ahead")
    depth_min_m: float = param(0.1, 0.0, 5.0, "m", "reference §1.3: range 0.1 to 10 m")
    depth_max_m: float = param(10.0, 0.5, 100.0, "m", "reference §1.3: range 0.1 to 10 m")
    depth_focal_px: float = param(
        424.0, 10.0, 5000.0, "px", "reference §1.3: depth focal length at 848 px width"
    )
    depth_baseline_m: float = param(0.05, 0.001, 1.0, "m", "reference §1.3: stereo baseline 50 mm")
    depth_subpixel: float = param(
        0.08, 0.0, 1.0, "px", "reference §1.3: RMS = Z^2 subpixel / (f B); 0.08 typical, 0.03 tuned"
    )
    depth_unit_m: float = param(
        0.001, 0.0, 0.1, "m", "datasheet: depth is reported in whole millimetres; 0 = exact"
    )
    depth_invalid_prob: float = param(
        0.02, 0.0, 1.0, "", "choice: share of random invalid (0) depth pixels"
    )

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.depth_max_m <= self.depth_min_m:
            raise ValueError(
                f"CameraConfig.depth_max_m={self.depth_max_m!r} is out of range: must be > "
                f"depth_min_m ({self.depth_min_m} m)"
            )

    @property
    def fy(self) -> float:
        """Vertical focal length (px) from the vertical field of view."""
        return (self.height_px / 2.0) / math.tan(math.radians(self.vfov_deg) / 2.0)

    @property
    def fx(self) -> float:
        """Horizontal focal length (px): square pixels, so equal to ``fy``."""
        return self.fy

    @property
    def cx(self) -> float:
        """Principal point column (px): the image centre."""
        return self.width_px / 2.0

    @property
    def cy(self) -> float:
        """Principal point row (px): the image centre."""
        return self.height_px / 2.0

    @property
    def hfov_deg(self) -> float:
        """Horizontal field of view (deg) implied by ``fx`` and the width."""
        return math.degrees(2.0 * math.atan(self.cx / self.fx))


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
    """Pixel coordinates (..., 2) of camera-frame points (..., 3) (reference §1.3 pinhole).

    Points at or behind the camera plane (``Zc <= 0``) give NaN.
    """
    p = np.asarray(p_cam, dtype=float)
    z = p[..., 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        u = np.where(z > 0, cam.fx * p[..., 0] / z + cam.cx, np.nan)
        v = np.where(z > 0, cam.fy * p[..., 1] / z + cam.cy, np.nan)
    return np.stack([u, v], axis=-1)


def back_project(cam: Camera, uv: np.ndarray, depth_m: np.ndarray) -> np.ndarray:
    """Camera-frame points (..., 3) for pixels (..., 2) and depths Zc (...) (reference §1.3):
    ``Xc = (u - cx) Zc / fx``, ``Yc = (v - cy) Zc / fy``, ``Zc = D(u, v)``."""
    uv = np.asarray(uv, dtype=float)
    z = np.asarray(depth_m, dtype=float)
    x = (uv[..., 0] - cam.cx) * z / cam.fx
    y = (uv[..., 1] - cam.cy) * z / cam.fy
    return np.stack([x, y, z], axis=-1)


@njit(inline="always")
def world_to_camera(
    px: float,
    py: float,
    pz: float,
    rx: float,
    ry: float,
    c: float,
    s: float,
    R: np.ndarray,
    T: np.ndarray,
) -> tuple[float, float, float]:
    """A world point to the camera frame of a robot at (rx, ry) with heading th, given
    ``c = cos(th)`` and ``s = sin(th)`` (the caller computes them once per frame).

    ``R`` is the camera -> robot rotation, row-major (9,), ``T`` the camera's position in the
    robot frame (3,), as in :data:`PARAMS`.
    """
    dx, dy = px - rx, py - ry
    qx = c * dx + s * dy - T[0]
    qy = -s * dx + c * dy - T[1]
    qz = pz - T[2]
    # R^T q: column j of R dotted with q.
    xc = R[0] * qx + R[3] * qy + R[6] * qz
    yc = R[1] * qx + R[4] * qy + R[7] * qz
    zc = R[2] * qx + R[5] * qy + R[8] * qz
    return xc, yc, zc


@njit(inline="always")
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
    R: np.ndarray,
    T: np.ndarray,
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
                xc, yc, zc = world_to_camera(wx, wy, z, rx, ry, rc, rs, R, T)
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


# --- per-lane parameters and randomisation ----------------------------------------------------


def _camera(cfg: Any) -> Camera:
    return Camera.from_config(cfg.camera)


PARAMS = Block(
    "camera_params",
    "the colour camera: image size, intrinsics, extrinsics",
    [
        f8("img_w", "px", "image width", source="camera.width_px"),
        f8("img_h", "px", "image height", source="camera.height_px"),
        f8("fx", "px", "horizontal focal length", source=lambda c: _camera(c).fx),
        f8("fy", "px", "vertical focal length", source=lambda c: _camera(c).fy),
        f8("cx", "px", "principal point column", source=lambda c: _camera(c).cx),
        f8("cy", "px", "principal point row", source=lambda c: _camera(c).cy),
        f8(
            "R",
            "",
            "camera -> robot rotation, row-major",
            shape=(9,),
            source=lambda c: _camera(c).R.ravel(),
        ),
        f8(
            "T",
            "m",
            "camera position in the robot frame",
            shape=(3,),
            source=lambda c: _camera(c).T,
        ),
    ],
)

TILT = streams.per_episode(
    "camera.tilt", streams.RANDOMIZE, 2, 1, space="normal", doc="the camera's real pitch error"
)


def randomize(params: np.ndarray, lanes: np.ndarray, cfg: Any, keys: np.ndarray) -> None:
    """Per-episode camera pitch error (``randomization.camera_tilt_deg``): drawn always, so
    switching it on never shifts another draw; the rotation is rebuilt only when it is on."""
    rc = cfg.randomization
    tilt = rc.camera_tilt_deg * LaneRandom(keys[:, streams.RANDOMIZE.index]).normal(at=TILT)
    if rc.camera_tilt_deg > 0.0:
        cam = cfg.camera
        for j, lane in enumerate(lanes):
            rot = Camera.from_config(
                dataclasses.replace(cam, pitch_deg=cam.pitch_deg + float(tilt[j]))
            ).R
            params["R"][lane] = rot.ravel()


# --- what the camera sees ---------------------------------------------------------------------

# Body sample points for line of sight: columns across the body, rows up it.
LOS_COLS = 3
LOS_ROWS = 5
# Occluders nearer than this (m) to a sight line, beyond the body's half width, are tested.
LOS_MARGIN_M = 0.1


@njit(inline="always")
def camera_origin(cam: np.void, rx: float, ry: float, c: float, s: float) -> tuple[float, float]:
    """Where the camera is on the floor plan (m), for a robot at (rx, ry) heading th
    (``c, s = cos th, sin th``)."""
    return rx + c * cam.T[0] - s * cam.T[1], ry + s * cam.T[0] + c * cam.T[1]


@njit(inline="always")
def sight_box(
    p: int,
    frac: float,
    box: tuple[float, float, float, float],
    clipped: tuple[float, float, float, float],
    pose: tuple[float, float, float, float, float, float],
    cam: np.void,
    people: np.ndarray,
    n_people: int,
    walls: np.ndarray,
    n_walls: int,
    body: tuple[float, float, float],
    cand: np.ndarray,
) -> tuple[float, float, float, float, float]:
    """Line of sight from the camera to person ``p``: the visible share and the box of the
    part in sight.

    Occluders near the sight line to the body (walls and obstacles, other people) are listed
    first (:mod:`follow_env.world.sight`); with none, the body is in plain sight and nothing
    changes. Otherwise a grid of ``LOS_COLS x LOS_ROWS`` points on the body's near face, each
    standing for its cell of the projected box, is tested: the visible share scales by the
    in-sight share of the points inside the image, and the box shrinks to the cells in sight (a
    partly hidden person gives the box of the visible part; a fully hidden one is not seen).

    :param frac: the share of the body's box inside the image.
    :param box: the body's projected box ``(u1, v1, u2, v2)`` before clipping (px).
    :param clipped: that box clipped to the image (px).
    :param pose: ``(rx, ry, cos th, sin th, ox, oy)``: the robot and the camera's origin (m).
    :param body: ``(width, depth, height)`` of every body (m).
    :param cand: caller-owned int64 room for the occluder list; when more occluders are near
        than it holds, every wall and person is tested instead (slower, as exact).
    :return: ``(visible share, u1, v1, u2, v2)``.
    """
    u1, v1, u2, v2 = box
    c1, c2, c3, c4 = clipped
    rx, ry, c_th, s_th, ox, oy = pose
    width, depth, height = body
    px, py = people[p].x, people[p].y
    dx, dy = px - ox, py - oy
    dist = np.sqrt(dx * dx + dy * dy)
    if dist < 1e-6:
        return frac, c1, c2, c3, c4
    half_w = 0.5 * width
    reach = half_w + LOS_MARGIN_M
    n_cand = list_occluders(ox, oy, px, py, reach, walls, n_walls, cand)
    n_cand = list_people(ox, oy, px, py, reach + half_w, p, people, n_people, cand, n_cand)
    if n_cand == 0:
        return frac, c1, c2, c3, c4
    # More occluders than ``cand`` holds (a wall of many short sides, a crowd): test every one.
    overflow = n_cand > cand.shape[0]
    ux, uy = dx / dist, dy / dist
    nx, ny = px - ux * 0.5 * depth, py - uy * 0.5 * depth  # near face
    oz = cam.T[2]
    W, H = cam.img_w, cam.img_h
    n_img, n_vis = 0, 0
    su1, sv1, su2, sv2 = np.inf, np.inf, -np.inf, -np.inf
    for ci in range(LOS_COLS):
        off = ((ci + 0.5) / LOS_COLS - 0.5) * 2.0 * half_w
        sx, sy = nx - uy * off, ny + ux * off
        for ri in range(LOS_ROWS):
            sz = (ri + 0.5) / LOS_ROWS * height
            xc, yc, zc = world_to_camera(sx, sy, sz, rx, ry, c_th, s_th, cam.R, cam.T)
            if zc <= NEAR_PLANE_M:
                continue
            su = cam.fx * xc / zc + cam.cx
            sv = cam.fy * yc / zc + cam.cy
            if su < 0.0 or su >= W or sv < 0.0 or sv >= H:
                continue
            n_img += 1
            if overflow:
                if sight_blocked_by_any(
                    ox, oy, oz, sx, sy, sz, walls, n_walls, people, n_people, p, half_w, height
                ):
                    continue
            elif sight_blocked(ox, oy, oz, sx, sy, sz, cand, n_cand, walls, people, half_w, height):
                continue
            n_vis += 1
            su1, sv1, su2, sv2 = min(su1, su), min(sv1, sv), max(su2, su), max(sv2, sv)
    if n_img == 0 or n_vis == n_img:
        return frac, c1, c2, c3, c4
    if n_vis == 0:
        return 0.0, c1, c2, c3, c4
    cw, ch = 0.5 * (u2 - u1) / LOS_COLS, 0.5 * (v2 - v1) / LOS_ROWS
    return (
        frac * n_vis / n_img,
        max(c1, su1 - cw),
        max(c2, sv1 - ch),
        min(c3, su2 + cw),
        min(c4, sv2 + ch),
    )

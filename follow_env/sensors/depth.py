"""Depth: the value at one pixel of the D435i's aligned depth image, and the robot's distance
filter (reference §1.3, §1.4).

:func:`depth_ray` casts the pixel's ray through the world (people as upright boxes, walls and
obstacles up to their height, the floor); :func:`measure` adds the D435i's noise (RMS growing
with Z^2), whole-millimetre quantisation, range limits and random invalid pixels (read as 0,
as on the camera); :func:`distance_filter` is the reference robot's asymmetric filter;
:func:`ahead` is the optional reading ahead, the nearest valid depth across the middle row.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from follow_env.sim import streams
from follow_env.sim.jit import njit
from follow_env.sim.rng import LaneRandom, normal_pair_at, uniform_at
from follow_env.sim.schema import Block, f8, i8
from follow_env.world.sight import cross_wall

__all__ = [
    "AHEAD_RAYS_MAX",
    "HISTORY_MAX",
    "PARAMS",
    "STATE",
    "ahead",
    "ahead_column",
    "depth_noise_std",
    "depth_ray",
    "distance_filter",
    "measure",
    "measure_at",
]

HISTORY_MAX = 32
"""Longest distance-filter history (``PerceptionConfig.filter_history``)."""
AHEAD_RAYS_MAX = 16
"""Most columns of the reading ahead (``PerceptionConfig.ahead_rays``)."""


@njit(inline="always")
def depth_noise_std(z_m: float, subpixel: float, focal_px: float, baseline_m: float) -> float:
    """D435i depth RMS error (m) at depth ``z_m`` (reference §1.3): ``Z^2 subpixel / (f B)``."""
    return z_m * z_m * subpixel / (focal_px * baseline_m)


PARAMS = Block(
    "depth_params",
    "the depth stream and the distance filter",
    [
        f8("depth_min", "m", "nearest valid depth", source="camera.depth_min_m"),
        f8("depth_max", "m", "farthest valid depth", source="camera.depth_max_m"),
        f8(
            "depth_k",
            "1/m",
            "depth RMS at 1 m (RMS = depth_k Z^2)",
            source=lambda c: depth_noise_std(
                1.0, c.camera.depth_subpixel, c.camera.depth_focal_px, c.camera.depth_baseline_m
            ),
        ),
        f8("depth_unit", "m", "depth quantum (0: exact)", source="camera.depth_unit_m"),
        f8("invalid_p", "", "share of random invalid pixels", source="camera.depth_invalid_prob"),
        f8(
            "hist_len",
            "samples",
            "distance-filter history length",
            source="perception.filter_history",
        ),
        f8("ahead_rays", "columns", "columns of the reading ahead", source="perception.ahead_rays"),
        f8(
            "ahead_tan",
            "",
            "tangent of the reading ahead's half-angle",
            source=lambda c: math.tan(math.radians(c.perception.ahead_half_angle_deg)),
        ),
        f8(
            "ahead_skip",
            "",
            "1: the reading ahead skips the published box's columns",
            source=lambda c: 1.0 if c.perception.ahead_target == "exclude" else 0.0,
        ),
    ],
)

STATE = Block(
    "distance_filter",
    "the distance filter's history ring buffer",
    [
        f8("hist", "m", "receding readings, newest at hist_head", shape=(HISTORY_MAX,)),
        i8("hist_n", "", "readings held"),
        i8("hist_head", "", "slot of the newest reading"),
    ],
)

NOISE = streams.per_step(
    "depth.noise", streams.DEPTH, 240, 2, doc="the noise (normal) and the invalid-pixel coin"
)
SCALE = streams.per_episode(
    "depth.scale", streams.RANDOMIZE, 7, 1, space="uniform", doc="depth noise scale (randomisation)"
)
AHEAD = streams.per_step(
    "depth.ahead",
    streams.DEPTH,
    0,
    2 * AHEAD_RAYS_MAX,
    doc="the reading ahead: per column the noise (normal) and the invalid-pixel coin",
)
_DEPTH = streams.DEPTH.index
_STRIDE = NOISE.stride
_OFFSET = NOISE.offset
_AHEAD_OFFSET = AHEAD.offset


def randomize(
    params: np.ndarray, base: np.void, lanes: np.ndarray, cfg: Any, keys: np.ndarray
) -> None:
    """Per-episode depth-noise scale, uniform in [1, ``depth_noise_scale_max``]."""
    rc = cfg.randomization
    u = LaneRandom(keys[:, streams.RANDOMIZE.index]).uniform(at=SCALE)
    params["depth_k"][lanes] = base["depth_k"] * (1.0 + (rc.depth_noise_scale_max - 1.0) * u)


@njit(inline="always")
def depth_ray(
    cu: int,
    cv: int,
    cam: np.void,
    ox: float,
    oy: float,
    c: float,
    s: float,
    people: np.ndarray,
    n_people: int,
    body: tuple[float, float, float],
    walls: np.ndarray,
    n_walls: int,
) -> float:
    """True depth Zc (m) seen at pixel (cu, cv) by a camera at (ox, oy) on a robot heading
    th (``c, s = cos th, sin th``): the nearest of people (upright boxes of ``body = (width,
    depth, height)``), walls and floor along the pixel's ray (reference §1.3 back-projection);
    ``inf`` if the ray hits nothing."""
    dcx = (cu - cam.cx) / cam.fx
    dcy = (cv - cam.cy) / cam.fy
    R = cam.R
    # Direction in the robot frame (R d_c with d_c = (dcx, dcy, 1)), so the ray parameter t
    # is the camera-frame depth Zc.
    drx = R[0] * dcx + R[1] * dcy + R[2]
    dry = R[3] * dcx + R[4] * dcy + R[5]
    drz = R[6] * dcx + R[7] * dcy + R[8]
    dwx, dwy, dwz = c * drx - s * dry, s * drx + c * dry, drz
    oz = cam.T[2]
    best = np.inf
    if dwz < -1e-12:  # the floor
        best = -oz / dwz
    for k in range(n_walls):
        t, u = cross_wall(ox, oy, dwx, dwy, walls[k])
        if 0.0 < t < best and 0.0 <= u <= 1.0 and oz + t * dwz <= walls[k].h:
            best = t
    width, depth, height = body
    hd, hw, hh = 0.5 * depth, 0.5 * width, height
    for p in range(n_people):
        pc, pss = np.cos(people[p].th), np.sin(people[p].th)
        qx = pc * (ox - people[p].x) + pss * (oy - people[p].y)
        qy = -pss * (ox - people[p].x) + pc * (oy - people[p].y)
        ex = pc * dwx + pss * dwy
        ey = -pss * dwx + pc * dwy
        # Slab test against the upright box |x| <= hd, |y| <= hw, 0 <= z <= hh.
        tmin, tmax = 0.0, best
        hit = True
        for axis in range(3):
            if axis == 0:
                o, dd, lo, hi = qx, ex, -hd, hd
            elif axis == 1:
                o, dd, lo, hi = qy, ey, -hw, hw
            else:
                o, dd, lo, hi = oz, dwz, 0.0, hh
            if abs(dd) < 1e-12:
                if o < lo or o > hi:
                    hit = False
                    break
            else:
                t1, t2 = (lo - o) / dd, (hi - o) / dd
                if t1 > t2:
                    t1, t2 = t2, t1
                tmin, tmax = max(tmin, t1), min(tmax, t2)
                if tmin > tmax:
                    hit = False
                    break
        if hit and tmin > 0.0 and tmin < best:
            best = tmin
    return best


@njit(inline="always")
def measure(prm: np.void, z: float, keys: np.ndarray, step: int) -> float:
    """What the depth stream reports for a true depth ``z`` (m) at the box centre of step
    ``step``: :func:`measure_at` with this step's own draws."""
    return measure_at(prm, z, keys[_DEPTH], step * _STRIDE + _OFFSET)


@njit(inline="always")
def measure_at(prm: np.void, z: float, kd: np.uint64, dslot: int) -> float:
    """What the depth stream reports for a true depth ``z`` (m): 0 (invalid) out of range or
    for a random invalid pixel, else ``z`` plus noise of RMS ``depth_k z^2`` (reference §1.3),
    quantised to ``depth_unit``. The noise is normal draw ``dslot`` of the depth key ``kd``,
    the invalid-pixel coin its uniform draw ``dslot + 1``."""
    if z < prm.depth_min or z > prm.depth_max:
        return 0.0
    z += normal_pair_at(kd, dslot)[0] * prm.depth_k * z * z  # RMS ~ Z^2 (reference §1.3)
    if prm.depth_unit > 0.0:
        z = np.round(z / prm.depth_unit) * prm.depth_unit
    invalid = uniform_at(kd, dslot + 1) < prm.invalid_p
    if invalid or z < prm.depth_min or z > prm.depth_max:
        return 0.0  # out of range reads as invalid too, as on the camera
    return z


@njit(inline="always")
def ahead_column(k: int, n: int, cx: float, fx: float, tan_half: float) -> int:
    """Image column (px) of the reading ahead's ``k``-th of ``n`` columns: evenly over
    ``cx +- tan_half fx`` (one column: ``cx``), rounded to a pixel (reference §1.3 pixels)."""
    frac = (2.0 * k / (n - 1) - 1.0) if n > 1 else 0.0
    return int(np.round(cx + frac * tan_half * fx))


@njit(inline="always")
def ahead(
    prm: np.void,
    cam: np.void,
    pose: tuple[float, float, float, float],
    people: np.ndarray,
    n_people: int,
    body: tuple[float, float, float],
    walls: np.ndarray,
    n_walls: int,
    keys: np.ndarray,
    step: int,
    skip: tuple[float, float],
) -> float:
    """The reading ahead (m): the nearest valid depth the camera reports at ``ahead_rays``
    columns of the middle row ``cy``, spread evenly over +- ``atan(ahead_tan)`` about the
    optical axis (one column: the axis), each through :func:`measure_at` with its own draws;
    columns in ``skip = (u1, u2)`` (px, inclusive; empty when u1 > u2) are not read.
    ``depth_max`` when no column reads a valid depth: beyond the range, too near (under
    ``depth_min``) or invalid all read 0 on the camera, and a 0 among them is skipped. The
    camera is at ``pose = (ox, oy, cos th, sin th)``; the rest is as for :func:`depth_ray`."""
    ox, oy, c, s = pose
    n = int(prm.ahead_rays)
    kd = keys[_DEPTH]
    base = step * _STRIDE + _AHEAD_OFFSET
    cv = int(cam.cy)
    best = prm.depth_max
    for k in range(n):
        cu = ahead_column(k, n, cam.cx, cam.fx, prm.ahead_tan)
        if skip[0] <= cu <= skip[1]:
            continue
        z = depth_ray(cu, cv, cam, ox, oy, c, s, people, n_people, body, walls, n_walls)
        reading = measure_at(prm, z, kd, base + 2 * k)
        if 0.0 < reading < best:
            best = reading
    return best


@njit(inline="always")
def distance_filter(
    raw_m: float, prev_m: float, history: np.ndarray, count: int, head: int, length: int
) -> tuple[float, int, int]:
    """The asymmetric distance filter of reference §1.4 step 4.

    * ``raw == 0`` (invalid depth): keep the previous value;
    * ``raw < prev`` (approaching): reset the history to ``[raw]`` and return ``raw``;
    * otherwise (receding): append ``raw`` to a history of fixed ``length`` (oldest dropped)
      and return the history's mean.

    ``history`` is a ring buffer of at least ``length`` slots holding ``count`` values, the
    newest at ``head``; it is updated in place.

    :return: ``(distance m, new count, new head)``.
    """
    if raw_m == 0.0:
        return prev_m, count, head
    if raw_m < prev_m:
        history[0] = raw_m
        return raw_m, 1, 0
    head = (head + 1) % length if count > 0 else 0
    history[head] = raw_m
    count = min(count + 1, length)
    total = 0.0
    for k in range(count):
        total += history[(head - k) % length]
    return total / count, count, head

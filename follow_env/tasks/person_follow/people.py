"""People walking along scenario paths with a human speed profile.

A path is a polyline of waypoints; each waypoint carries the arc length to it, a speed cap for
the leg that starts there (set by the scenario: cruise pace, slower in turns) and a pause (s) to
stand still on arrival. A person starts from rest, speeds up at ``accel``, brakes at ``decel`` so
as to reach every pause and the path's end at rest (and every slower leg at its cap), and faces
the direction of the leg it walks.

People also keep out of each other's way (a social-force step, :func:`social_forces`): others
closer than a personal radius push a walker sideways off the path (a damped spring pulls back)
and someone just ahead slows them down. They do not react to the robot, on purpose: then their
motion depends on nothing the policy does, so every policy meets the same people.
"""

from __future__ import annotations

import numpy as np

from follow_env.sim.jit import njit
from follow_env.sim.schema import Block, f8, i8

__all__ = ["PERSON", "WAYPOINT", "as_waypoints", "person_reset", "person_step", "social_forces"]

PERSON = Block(
    "person",
    "one walker: where on its path, how fast, and its sideways step off the path",
    [
        f8("s", "m", "arc length walked along the path"),
        f8("v", "m/s", "walking speed"),
        i8("seg", "", "index of the leg being walked"),
        f8("pause", "s", "time left standing still at a waypoint"),
        f8("x", "m", "position, x (world frame)"),
        f8("y", "m", "position, y"),
        f8("th", "rad", "heading (the direction of the leg walked)"),
        f8("done", "", "1 once the path's end is reached"),
        i8("npts", "", "waypoints of the path in use"),
        f8("lat", "m", "sideways offset from the path (left positive)"),
        f8("latv", "m/s", "rate of the sideways offset"),
        f8("force", "m/s^2", "sideways social force"),
        f8("slow", "", "share of the allowed speed (someone ahead)"),
    ],
)

WAYPOINT = Block(
    "waypoint",
    "a path waypoint; the fields in this order are the columns scenarios build paths with",
    [
        f8("x", "m", "position, x"),
        f8("y", "m", "position, y"),
        f8("s", "m", "arc length from the path's start"),
        f8("vmax", "m/s", "speed cap of the leg that starts here"),
        f8("pause", "s", "time to stand still on arrival"),
    ],
)
N_PW = len(WAYPOINT.fields)


def as_waypoints(paths: np.ndarray) -> np.ndarray:
    """Float paths ``(..., N_PW)`` (the columns of :data:`WAYPOINT`'s fields, as scenarios
    build them) as waypoint records ``(...)``, sharing their memory."""
    arr = np.ascontiguousarray(paths, dtype=np.float64)
    if arr.shape[-1] != N_PW:
        raise ValueError(f"paths must have {N_PW} columns (x, y, s, vmax, pause), got {arr.shape}")
    return arr.view(WAYPOINT.dtype)[..., 0]


# A person closing on a stop never walks slower than this, so they always arrive (m/s).
_CREEP_MPS = 0.05
# The sideways spring back to the path: stiffness (1/s^2), damping (1/s), farthest offset (m).
_LAT_K = 2.0
_LAT_C = 2.0
_LAT_MAX_M = 0.5
# Someone ahead within this lateral distance (m) slows a walker, never below this share.
_AHEAD_HALF_WIDTH_M = 0.4
_SLOW_MIN = 0.2
# Someone coming the other way this far ahead (m) and within this lateral distance (m) makes
# a walker keep to the right.
_MEET_AHEAD_M = 3.0
_MEET_HALF_WIDTH_M = 0.6


@njit(inline="always")
def _place(ps: np.ndarray, path: np.ndarray) -> None:
    """Set position and heading from the arc length and leg index."""
    n = int(ps.npts)
    k = int(ps.seg)
    if k >= n - 1:
        k = n - 2
    seg_len = path[k + 1].s - path[k].s
    t = 0.0 if seg_len <= 0.0 else (ps.s - path[k].s) / seg_len
    t = min(max(t, 0.0), 1.0)
    dx = path[k + 1].x - path[k].x
    dy = path[k + 1].y - path[k].y
    if dx != 0.0 or dy != 0.0:
        ps.th = np.arctan2(dy, dx)
    # Off the path by the lateral offset, to the walker's left when positive.
    lat = ps.lat
    ps.x = path[k].x + t * dx - lat * np.sin(ps.th)
    ps.y = path[k].y + t * dy + lat * np.cos(ps.th)


@njit
def person_reset(ps: np.ndarray, path: np.ndarray, n_points: int) -> None:
    """Put a person at rest at the start of ``path`` (``n_points`` >= 2 waypoints used)."""
    ps.s = ps.v = ps.pause = ps.x = ps.y = ps.th = ps.done = 0.0
    ps.lat = ps.latv = ps.force = 0.0
    ps.seg = 0
    ps.slow = 1.0
    ps.npts = n_points
    ps.pause = path[0].pause
    _place(ps, path)


@njit(inline="always")
def person_step(ps: np.ndarray, path: np.ndarray, accel: float, decel: float, dt: float) -> None:
    """Advance one person by ``dt`` seconds along its path (state ``ps`` updated in place)."""
    n = int(ps.npts)
    if ps.done > 0.0:
        ps.v = 0.0
        return
    if ps.pause > 0.0:
        ps.pause = max(ps.pause - dt, 0.0)
        ps.v = 0.0
        return
    k = int(ps.seg)
    s = ps.s
    v = ps.v
    # Speed allowed now: this leg's cap, and for every later waypoint the speed from which we
    # can still brake to its cap (0 at a pause or the end) over the distance left.
    allowed = path[k].vmax
    ad = decel * dt
    for j in range(k + 1, n):
        dist = path[j].s - s
        if 2.0 * decel * dist >= allowed * allowed:
            break  # too far to bind, and so is every waypoint after it
        cap = 0.0 if (j == n - 1 or path[j].pause > 0.0) else path[j].vmax
        # Fastest speed now from which braking at `decel` still meets `cap` at the waypoint,
        # counting this step's travel: v^2 = cap^2 + 2 decel (dist - v dt).
        disc = ad * ad + cap * cap + 2.0 * decel * max(dist, 0.0)
        allowed = min(allowed, -ad + np.sqrt(disc))
    allowed = max(allowed * ps.slow, _CREEP_MPS)
    v = min(v + accel * dt, allowed)
    # The sideways offset: social force against a damped spring back to the path.
    ps.latv += (ps.force - _LAT_K * ps.lat - _LAT_C * ps.latv) * dt
    ps.lat = min(max(ps.lat + ps.latv * dt, -_LAT_MAX_M), _LAT_MAX_M)
    s += v * dt
    while k < n - 1 and s >= path[k + 1].s:
        k += 1
        if k == n - 1:
            s = path[k].s
            v = 0.0
            ps.done = 1.0
            break
        if path[k].pause > 0.0:
            s = path[k].s
            v = 0.0
            ps.pause = path[k].pause
            break
    ps.s, ps.v, ps.seg = s, v, k
    _place(ps, path)


@njit(inline="always")
def social_forces(ps: np.ndarray, n_people: int, radius: float, strength: float) -> None:
    """Each person's sideways social force (``force``, m/s^2) and speed share (``slow``)
    from everyone's positions at the start of the step, so the order of people is irrelevant.

    Another person closer than ``radius`` pushes with ``strength (1 - d / radius)`` along the
    line between them, of which the walker feels the part across their path, plus a step to the
    right when they meet head-on; one ahead within a shoulder's width, going the same way,
    slows them in proportion to the gap.
    """
    for p in range(n_people):
        force, slow = 0.0, 1.0
        c, s = np.cos(ps[p].th), np.sin(ps[p].th)
        for q in range(n_people):
            if q == p:
                continue
            dx, dy = ps[q].x - ps[p].x, ps[q].y - ps[p].y
            d = np.sqrt(dx * dx + dy * dy)
            if d == 0.0:
                continue
            ahead, left = c * dx + s * dy, -s * dx + c * dy
            push = strength * max(1.0 - d / radius, 0.0)
            force -= push * left / d
            facing = c * np.cos(ps[q].th) + s * np.sin(ps[q].th)
            if facing < -0.5 and 0.0 < ahead < _MEET_AHEAD_M and abs(left) < _MEET_HALF_WIDTH_M:
                force -= strength  # someone coming the other way: keep to the right, early
            # Walking behind someone who goes the same way: slow down (one crossing the path
            # is passed by stepping aside instead).
            same_way = facing > 0.5
            if same_way and 0.0 < ahead < radius and abs(left) < _AHEAD_HALF_WIDTH_M:
                gap = (ahead - _AHEAD_HALF_WIDTH_M) / max(radius - _AHEAD_HALF_WIDTH_M, 1e-6)
                slow = min(slow, max(gap, _SLOW_MIN))
        ps[p].force = force
        ps[p].slow = slow

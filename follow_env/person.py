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
from numba import njit

from follow_env.layout import (
    PS_DONE,
    PS_FORCE,
    PS_LAT,
    PS_LATV,
    PS_NPTS,
    PS_PAUSE,
    PS_S,
    PS_SEG,
    PS_SLOW,
    PS_TH,
    PS_V,
    PS_X,
    PS_Y,
    PW_PAUSE,
    PW_S,
    PW_VMAX,
    PW_X,
    PW_Y,
)

__all__ = ["person_reset", "person_step", "social_forces"]

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


@njit(cache=True, inline="always")
def _place(ps: np.ndarray, path: np.ndarray) -> None:
    """Set position and heading from the arc length and leg index."""
    n = int(ps[PS_NPTS])
    k = int(ps[PS_SEG])
    if k >= n - 1:
        k = n - 2
    seg_len = path[k + 1, PW_S] - path[k, PW_S]
    t = 0.0 if seg_len <= 0.0 else (ps[PS_S] - path[k, PW_S]) / seg_len
    t = min(max(t, 0.0), 1.0)
    dx = path[k + 1, PW_X] - path[k, PW_X]
    dy = path[k + 1, PW_Y] - path[k, PW_Y]
    if dx != 0.0 or dy != 0.0:
        ps[PS_TH] = np.arctan2(dy, dx)
    # Off the path by the lateral offset, to the walker's left when positive.
    lat = ps[PS_LAT]
    ps[PS_X] = path[k, PW_X] + t * dx - lat * np.sin(ps[PS_TH])
    ps[PS_Y] = path[k, PW_Y] + t * dy + lat * np.cos(ps[PS_TH])


@njit(cache=True)
def person_reset(ps: np.ndarray, path: np.ndarray, n_points: int) -> None:
    """Put a person at rest at the start of ``path`` (``n_points`` >= 2 waypoints used)."""
    ps[:] = 0.0
    ps[PS_SLOW] = 1.0
    ps[PS_NPTS] = n_points
    ps[PS_PAUSE] = path[0, PW_PAUSE]
    _place(ps, path)


@njit(cache=True, inline="always")
def person_step(ps: np.ndarray, path: np.ndarray, accel: float, decel: float, dt: float) -> None:
    """Advance one person by ``dt`` seconds along its path (state ``ps`` updated in place)."""
    n = int(ps[PS_NPTS])
    if ps[PS_DONE] > 0.0:
        ps[PS_V] = 0.0
        return
    if ps[PS_PAUSE] > 0.0:
        ps[PS_PAUSE] = max(ps[PS_PAUSE] - dt, 0.0)
        ps[PS_V] = 0.0
        return
    k = int(ps[PS_SEG])
    s = ps[PS_S]
    v = ps[PS_V]
    # Speed allowed now: this leg's cap, and for every later waypoint the speed from which we
    # can still brake to its cap (0 at a pause or the end) over the distance left.
    allowed = path[k, PW_VMAX]
    ad = decel * dt
    for j in range(k + 1, n):
        dist = path[j, PW_S] - s
        if 2.0 * decel * dist >= allowed * allowed:
            break  # too far to bind, and so is every waypoint after it
        cap = 0.0 if (j == n - 1 or path[j, PW_PAUSE] > 0.0) else path[j, PW_VMAX]
        # Fastest speed now from which braking at `decel` still meets `cap` at the waypoint,
        # counting this step's travel: v^2 = cap^2 + 2 decel (dist - v dt).
        disc = ad * ad + cap * cap + 2.0 * decel * max(dist, 0.0)
        allowed = min(allowed, -ad + np.sqrt(disc))
    allowed = max(allowed * ps[PS_SLOW], _CREEP_MPS)
    v = min(v + accel * dt, allowed)
    # The sideways offset: social force against a damped spring back to the path.
    ps[PS_LATV] += (ps[PS_FORCE] - _LAT_K * ps[PS_LAT] - _LAT_C * ps[PS_LATV]) * dt
    ps[PS_LAT] = min(max(ps[PS_LAT] + ps[PS_LATV] * dt, -_LAT_MAX_M), _LAT_MAX_M)
    s += v * dt
    while k < n - 1 and s >= path[k + 1, PW_S]:
        k += 1
        if k == n - 1:
            s = path[k, PW_S]
            v = 0.0
            ps[PS_DONE] = 1.0
            break
        if path[k, PW_PAUSE] > 0.0:
            s = path[k, PW_S]
            v = 0.0
            ps[PS_PAUSE] = path[k, PW_PAUSE]
            break
    ps[PS_S], ps[PS_V], ps[PS_SEG] = s, v, k
    _place(ps, path)


@njit(cache=True, inline="always")
def social_forces(ps: np.ndarray, n_people: int, radius: float, strength: float) -> None:
    """Each person's sideways social force (``PS_FORCE``, m/s^2) and speed share (``PS_SLOW``)
    from everyone's positions at the start of the step, so the order of people is irrelevant.

    Another person closer than ``radius`` pushes with ``strength (1 - d / radius)`` along the
    line between them, of which the walker feels the part across their path, plus a step to the
    right when they meet head-on; one ahead within a shoulder's width, going the same way,
    slows them in proportion to the gap.
    """
    for p in range(n_people):
        force, slow = 0.0, 1.0
        c, s = np.cos(ps[p, PS_TH]), np.sin(ps[p, PS_TH])
        for q in range(n_people):
            if q == p:
                continue
            dx, dy = ps[q, PS_X] - ps[p, PS_X], ps[q, PS_Y] - ps[p, PS_Y]
            d = np.sqrt(dx * dx + dy * dy)
            if d == 0.0:
                continue
            ahead, left = c * dx + s * dy, -s * dx + c * dy
            push = strength * max(1.0 - d / radius, 0.0)
            force -= push * left / d
            facing = c * np.cos(ps[q, PS_TH]) + s * np.sin(ps[q, PS_TH])
            if facing < -0.5 and 0.0 < ahead < _MEET_AHEAD_M and abs(left) < _MEET_HALF_WIDTH_M:
                force -= strength  # someone coming the other way: keep to the right, early
            # Walking behind someone who goes the same way: slow down (one crossing the path
            # is passed by stepping aside instead).
            same_way = facing > 0.5
            if same_way and 0.0 < ahead < radius and abs(left) < _AHEAD_HALF_WIDTH_M:
                gap = (ahead - _AHEAD_HALF_WIDTH_M) / max(radius - _AHEAD_HALF_WIDTH_M, 1e-6)
                slow = min(slow, max(gap, _SLOW_MIN))
        ps[p, PS_FORCE] = force
        ps[p, PS_SLOW] = slow

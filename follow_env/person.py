"""People walking along scenario paths with a human speed profile.

A path is a polyline of waypoints; each waypoint carries the arc length to it, a speed cap for
the leg that starts there (set by the scenario: cruise pace, slower in turns) and a pause (s) to
stand still on arrival. A person starts from rest, speeds up at ``accel``, brakes at ``decel`` so
as to reach every pause and the path's end at rest (and every slower leg at its cap), and faces
the direction of the leg it walks.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from follow_env.layout import (
    PS_DONE,
    PS_NPTS,
    PS_PAUSE,
    PS_S,
    PS_SEG,
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

__all__ = ["person_reset", "person_step"]

# A person closing on a stop never walks slower than this, so they always arrive (m/s).
_CREEP_MPS = 0.05


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
    ps[PS_X] = path[k, PW_X] + t * dx
    ps[PS_Y] = path[k, PW_Y] + t * dy
    if dx != 0.0 or dy != 0.0:
        ps[PS_TH] = np.arctan2(dy, dx)


@njit(cache=True)
def person_reset(ps: np.ndarray, path: np.ndarray, n_points: int) -> None:
    """Put a person at rest at the start of ``path`` (``n_points`` >= 2 waypoints used)."""
    ps[:] = 0.0
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
    allowed = max(allowed, _CREEP_MPS)
    v = min(v + accel * dt, allowed)
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

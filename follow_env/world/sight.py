"""Line of sight: which walls, obstacles and people stand between an eye and a point.

Walls are vertical strips up to their height (:data:`~follow_env.world.geometry.WALL` records);
people are upright cylinders (records with ``x`` and ``y``; a radius and a height for all).
A caller first lists the candidate occluders near a sight line (:func:`list_occluders`: a
bounding-box reject, then a segment distance), then tests sight lines against that short list
(:func:`sight_blocked`). Both are compiled and allocate nothing: the list goes into a
caller-owned int64 array.
"""

from __future__ import annotations

import numpy as np

from follow_env.sim.jit import njit
from follow_env.world.geometry import point_segment_distance, segment_distance

__all__ = ["cross_wall", "list_occluders", "list_people", "sight_blocked"]


@njit(inline="always")
def cross_wall(ox: float, oy: float, dx: float, dy: float, wall: np.void) -> tuple[float, float]:
    """Where the line ``o + t d`` crosses the line of ``wall`` (seen from above): ``t`` along
    ``d`` and ``u`` along the wall (0..1 between its ends); ``t = inf`` when they are parallel.
    """
    ex, ey = wall.x2 - wall.x1, wall.y2 - wall.y1
    den = dx * ey - dy * ex
    if abs(den) < 1e-12:
        return np.inf, 0.0
    ax, ay = wall.x1 - ox, wall.y1 - oy
    return (ax * ey - ay * ex) / den, (ax * dy - ay * dx) / den


@njit(inline="always")
def list_occluders(
    ox: float,
    oy: float,
    px: float,
    py: float,
    reach: float,
    walls: np.ndarray,
    n_walls: int,
    out: np.ndarray,
) -> int:
    """List the walls that come nearer than ``reach`` (m) to the sight line from (ox, oy) to
    (px, py), as their index ``k`` in ``out``; returns how many were written (at most
    ``len(out)``). :func:`list_people` appends the people."""
    cap = out.shape[0]
    n = 0
    # Bounding box of the sight line, grown by the reach: walls outside it cannot be near.
    bx1, bx2 = min(ox, px) - reach, max(ox, px) + reach
    by1, by2 = min(oy, py) - reach, max(oy, py) + reach
    for k in range(n_walls):
        w = walls[k]
        if (
            max(w.x1, w.x2) < bx1
            or min(w.x1, w.x2) > bx2
            or max(w.y1, w.y2) < by1
            or min(w.y1, w.y2) > by2
        ):
            continue
        if n < cap and segment_distance(ox, oy, px, py, w.x1, w.y1, w.x2, w.y2) < reach:
            out[n] = k
            n += 1
    return n


@njit(inline="always")
def list_people(
    ox: float,
    oy: float,
    px: float,
    py: float,
    reach: float,
    skip: int,
    people: np.ndarray,
    n_people: int,
    out: np.ndarray,
    n: int,
) -> int:
    """Append the people (but ``skip``) nearer than ``reach`` (m) to the sight line from
    (ox, oy) to (px, py) to ``out`` as ``-(q + 1)``, after its first ``n`` entries; returns the
    new count."""
    cap = out.shape[0]
    for q in range(n_people):
        if q != skip and n < cap:
            d = point_segment_distance(people[q].x, people[q].y, ox, oy, px, py)
            if d < reach:
                out[n] = -(q + 1)
                n += 1
    return n


@njit(inline="always")
def sight_blocked(
    ox: float,
    oy: float,
    oz: float,
    sx: float,
    sy: float,
    sz: float,
    cand: np.ndarray,
    n_cand: int,
    walls: np.ndarray,
    people: np.ndarray,
    radius: float,
    height: float,
) -> bool:
    """Is the sight line from the eye (ox, oy, oz) to the point (sx, sy, sz) cut by one of the
    listed occluders ``cand[:n_cand]`` (wall k as k, person q as -(q + 1))? Walls are vertical
    strips up to their height, people upright cylinders of ``radius`` and ``height`` (m)."""
    dx, dy, dz = sx - ox, sy - oy, sz - oz
    for j in range(n_cand):
        k = cand[j]
        if k >= 0:
            t, u = cross_wall(ox, oy, dx, dy, walls[k])
            if 0.0 < t < 1.0 and 0.0 <= u <= 1.0 and oz + t * dz < walls[k].h:
                return True
        else:
            q = -k - 1
            qx, qy = people[q].x - ox, people[q].y - oy
            t = (qx * dx + qy * dy) / (dx * dx + dy * dy)
            if 0.0 < t < 1.0:
                ex, ey = t * dx - qx, t * dy - qy
                if ex * ex + ey * ey < radius * radius and oz + t * dz < height:
                    return True
    return False

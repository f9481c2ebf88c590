"""Line of sight: which walls, obstacles and people stand between an eye and a point.

Walls are vertical strips up to their height (:data:`~follow_env.world.geometry.WALL` records);
people are upright cylinders (records with ``x`` and ``y``; a radius and a height for all).
A caller first lists the candidate occluders near a sight line (:func:`list_occluders`: a
bounding-box reject, then a segment distance), then tests sight lines against that short list
(:func:`sight_blocked`). Both are compiled and allocate nothing: the list goes into a
caller-owned int64 array. The listing functions count every occluder they find, also those past
the array's end; a count above the array's length says the list overflowed, and the caller then
tests every wall and person instead (:func:`sight_blocked_by_any`), so a crowded scene is slower,
never wrong.
"""

from __future__ import annotations

import numpy as np

from follow_env.sim.jit import njit
from follow_env.world.geometry import point_segment_distance, segment_distance

__all__ = ["cross_wall", "list_occluders", "list_people", "sight_blocked", "sight_blocked_by_any"]


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
    (px, py), as their index ``k`` in ``out``; returns how many there are. Only the first
    ``len(out)`` are written: a count above ``len(out)`` means the list overflowed (module
    docstring). :func:`list_people` appends the people."""
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
        if segment_distance(ox, oy, px, py, w.x1, w.y1, w.x2, w.y2) < reach:
            if n < cap:
                out[n] = k
            n += 1  # counted past the end too: the caller sees the overflow
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
    new count, which like :func:`list_occluders`' counts the people past ``len(out)`` too."""
    cap = out.shape[0]
    for q in range(n_people):
        if q != skip:
            d = point_segment_distance(people[q].x, people[q].y, ox, oy, px, py)
            if d < reach:
                if n < cap:
                    out[n] = -(q + 1)
                n += 1
    return n


@njit(inline="always")
def _wall_cuts(
    ox: float, oy: float, oz: float, dx: float, dy: float, dz: float, wall: np.void
) -> bool:
    """Does ``wall`` cut the sight line from (ox, oy, oz) along (dx, dy, dz), between its ends?"""
    t, u = cross_wall(ox, oy, dx, dy, wall)
    return 0.0 < t < 1.0 and 0.0 <= u <= 1.0 and oz + t * dz < wall.h


@njit(inline="always")
def _person_cuts(
    ox: float,
    oy: float,
    oz: float,
    dx: float,
    dy: float,
    dz: float,
    person: np.void,
    radius: float,
    height: float,
) -> bool:
    """Does ``person`` (an upright cylinder of ``radius`` and ``height``, m) cut the sight line
    from (ox, oy, oz) along (dx, dy, dz), between its ends?"""
    qx, qy = person.x - ox, person.y - oy
    t = (qx * dx + qy * dy) / (dx * dx + dy * dy)
    if 0.0 < t < 1.0:
        ex, ey = t * dx - qx, t * dy - qy
        return ex * ex + ey * ey < radius * radius and oz + t * dz < height
    return False


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
    strips up to their height, people upright cylinders of ``radius`` and ``height`` (m).
    Reads at most ``len(cand)`` entries: for a list that overflowed (``n_cand > len(cand)``)
    the answer is :func:`sight_blocked_by_any`'s."""
    dx, dy, dz = sx - ox, sy - oy, sz - oz
    for j in range(min(n_cand, cand.shape[0])):
        k = cand[j]
        if k >= 0:
            if _wall_cuts(ox, oy, oz, dx, dy, dz, walls[k]):
                return True
        elif _person_cuts(ox, oy, oz, dx, dy, dz, people[-k - 1], radius, height):
            return True
    return False


@njit(inline="always")
def sight_blocked_by_any(
    ox: float,
    oy: float,
    oz: float,
    sx: float,
    sy: float,
    sz: float,
    walls: np.ndarray,
    n_walls: int,
    people: np.ndarray,
    n_people: int,
    skip: int,
    radius: float,
    height: float,
) -> bool:
    """:func:`sight_blocked` against every wall ``walls[:n_walls]`` and every person
    ``people[:n_people]`` but ``skip``: the answer when the list of occluders overflowed
    (module docstring). Same exact tests, no list; slower by the number of occluders."""
    dx, dy, dz = sx - ox, sy - oy, sz - oz
    for k in range(n_walls):
        if _wall_cuts(ox, oy, oz, dx, dy, dz, walls[k]):
            return True
    for q in range(n_people):
        if q != skip and _person_cuts(ox, oy, oz, dx, dy, dz, people[q], radius, height):
            return True
    return False

"""Post-processing of a planned path (deterministic, never leaves free space).

A greedy shortcut (from each waypoint, jump to the farthest later one whose straight segment is
free *and* no costlier at its worst than the stretch of path it replaces, so shortcuts do not hug
walls the tree kept away from), Chaikin corner cutting (a cut that would hit an obstacle keeps
its corner), and resampling by arc length to waypoints at most ``waypoint_spacing_m`` apart
(keeping any corner whose chord would not be free).
"""

from __future__ import annotations

import numpy as np

from follow_env.sim.jit import njit
from follow_env.world.costmap import trace_segment

__all__ = ["chaikin", "resample", "shortcut"]


@njit
def shortcut(
    path: np.ndarray,
    cost: np.ndarray,
    occ: np.ndarray,
    x0: float,
    y0: float,
    res: float,
    ceiling: float,
) -> np.ndarray:
    """Greedy shortcut: from each kept point, jump to the farthest later point whose segment is
    free and whose worst cost is no higher than that of the stretch of path it replaces, or
    than ``ceiling`` (cost units) if that is higher."""
    n = path.shape[0]
    seg_worst = np.empty(max(n - 1, 0))
    for k in range(n - 1):
        seg_worst[k] = trace_segment(
            cost, occ, x0, y0, res, path[k, 0], path[k, 1], path[k + 1, 0], path[k + 1, 1]
        )
    out = np.empty((n, 2))
    out[0] = path[0]
    m = 1
    i = 0
    while i < n - 1:
        target = i + 1
        stretch = seg_worst[i]
        for j in range(i + 2, n):
            stretch = max(stretch, seg_worst[j - 1])
            w = trace_segment(
                cost, occ, x0, y0, res, path[i, 0], path[i, 1], path[j, 0], path[j, 1]
            )
            if w <= max(stretch, ceiling) + 1e-12:
                target = j
        out[m] = path[target]
        m += 1
        i = target
    return out[:m]


@njit
def chaikin(
    path: np.ndarray,
    cost: np.ndarray,
    occ: np.ndarray,
    x0: float,
    y0: float,
    res: float,
    ceiling: float,
) -> np.ndarray:
    """One pass of Chaikin's corner cutting: each corner becomes two points at a quarter of
    its segments; a cut whose segment is not free, or costlier at its worst than both the
    corner it replaces and ``ceiling``, keeps the corner."""
    n = path.shape[0]
    if n < 3:
        return path.copy()
    out = np.empty((3 * n, 2))
    out[0] = path[0]
    m = 1
    for k in range(1, n - 1):
        a, b, c = path[k - 1], path[k], path[k + 1]
        rx, ry = 0.75 * b[0] + 0.25 * a[0], 0.75 * b[1] + 0.25 * a[1]  # on a-b, near b
        qx, qy = 0.75 * b[0] + 0.25 * c[0], 0.75 * b[1] + 0.25 * c[1]  # on b-c, near b
        cut = trace_segment(cost, occ, x0, y0, res, rx, ry, qx, qy)
        corner = max(
            trace_segment(cost, occ, x0, y0, res, rx, ry, b[0], b[1]),
            trace_segment(cost, occ, x0, y0, res, b[0], b[1], qx, qy),
        )
        out[m, 0], out[m, 1] = rx, ry
        m += 1
        if not cut <= max(corner, ceiling) + 1e-12:
            out[m] = b
            m += 1
        out[m, 0], out[m, 1] = qx, qy
        m += 1
    out[m] = path[n - 1]
    m += 1
    return out[:m]


@njit
def resample(
    path: np.ndarray,
    spacing: float,
    cost: np.ndarray,
    occ: np.ndarray,
    x0: float,
    y0: float,
    res: float,
) -> np.ndarray:
    """Points evenly spaced by arc length, at most ``spacing`` (m) apart, ends kept; a corner
    of ``path`` between two new points stays in when their chord would not be free."""
    n = path.shape[0]
    s = np.zeros(n)
    for k in range(1, n):
        s[k] = s[k - 1] + np.hypot(path[k, 0] - path[k - 1, 0], path[k, 1] - path[k - 1, 1])
    total = s[n - 1]
    if total <= 0.0:  # start == goal: still a path of two waypoints
        out = np.empty((2, 2))
        out[0], out[1] = path[0], path[n - 1]
        return out
    pieces = max(1, int(np.ceil(total / spacing - 1e-9)))
    out = np.empty((pieces + 1 + n, 2))
    out[0] = path[0]
    m = 1
    seg = 0  # path[seg] .. path[seg + 1] holds the current arc length
    for q in range(1, pieces + 1):
        target = total * q / pieces
        first_corner = seg + 1
        while seg < n - 2 and s[seg + 1] < target:
            seg += 1
        if q == pieces:
            x, y = path[n - 1, 0], path[n - 1, 1]
            seg = n - 2
        else:
            ds = s[seg + 1] - s[seg]
            f = 0.0 if ds <= 0.0 else (target - s[seg]) / ds
            x = path[seg, 0] + f * (path[seg + 1, 0] - path[seg, 0])
            y = path[seg, 1] + f * (path[seg + 1, 1] - path[seg, 1])
        # Corners passed since the last point: keep them if the chord cuts into an obstacle.
        if seg >= first_corner and (
            trace_segment(cost, occ, x0, y0, res, out[m - 1, 0], out[m - 1, 1], x, y) == np.inf
        ):
            for k in range(first_corner, seg + 1):
                if path[k, 0] != out[m - 1, 0] or path[k, 1] != out[m - 1, 1]:
                    out[m] = path[k]
                    m += 1
        out[m, 0], out[m, 1] = x, y
        m += 1
    return out[:m]

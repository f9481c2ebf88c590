"""Buckets for a nearest-point search over a growing set of points (the T-RRT's tree).

Points are kept in linked lists per square cell of ``g`` m (``head[cell]`` the newest point's
index, ``nxt[j]`` the one added before ``j`` in the same cell, -1 ends a list), so a query
visits the cells in rings around its own until no farther ring can hold a nearer point, and
finds exactly the point a scan over all points in index order would: the first of the
nearest. Compiled with numba (follow_env.sim.jit).
"""

from __future__ import annotations

import numpy as np

from follow_env.sim.jit import njit

__all__ = ["bucket_of", "nearest_in_buckets"]


@njit(inline="always")
def _bucket_xy(x: float, y: float, x0: float, y0: float, g: float, gnx: int, gny: int) -> tuple:
    """The bucket's column and row (cells of ``g`` m) holding point (x, y), clamped to the grid."""
    return min(max(int((x - x0) / g), 0), gnx - 1), min(max(int((y - y0) / g), 0), gny - 1)


@njit(inline="always")
def bucket_of(x: float, y: float, x0: float, y0: float, g: float, gnx: int, gny: int) -> int:
    """The grid bucket (cells of ``g`` m) holding point (x, y), clamped to the grid."""
    bx, by = _bucket_xy(x, y, x0, y0, g, gnx, gny)
    return by * gnx + bx


@njit
def nearest_in_buckets(
    nodes: np.ndarray,
    head: np.ndarray,
    nxt: np.ndarray,
    qx: float,
    qy: float,
    x0: float,
    y0: float,
    g: float,
    gnx: int,
    gny: int,
) -> tuple:
    """The tree node nearest (qx, qy) and its squared distance: the lowest index among equally
    near ones, exactly as a scan over all nodes in order finds it, but visiting only the
    buckets in rings around the query's until no farther ring can hold a nearer node (after
    rings 0..r every unvisited node is at least r * g away)."""
    cx, cy = _bucket_xy(qx, qy, x0, y0, g, gnx, gny)
    best, best_d2 = -1, np.inf
    r = 0
    while r <= max(gnx, gny):
        for by in range(cy - r, cy + r + 1):
            if by < 0 or by >= gny:
                continue
            on_edge = by == cy - r or by == cy + r
            bx = cx - r
            while bx <= cx + r:
                if 0 <= bx < gnx:
                    j = head[by * gnx + bx]
                    while j >= 0:
                        ddx, ddy = nodes[j, 0] - qx, nodes[j, 1] - qy
                        d2 = ddx * ddx + ddy * ddy
                        if d2 < best_d2 or (d2 == best_d2 and j < best):
                            best, best_d2 = j, d2
                        j = nxt[j]
                bx += 1 if on_edge else 2 * r if r > 0 else 1
        reach = r * g
        if best >= 0 and best_d2 < reach * reach:
            break
        r += 1
    return best, best_d2

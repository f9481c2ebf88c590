"""Lines on the floor: a centreline of straight segments, each drawn in ink or left out (a gap).

A line is held per lane as records of :data:`LINE_SEGMENT` in the order the line runs, each
knowing the arc length at its start, so compiled code can ask where along the line a point is
(:func:`nearest_on_line`) and how far a point is from the drawn part (:func:`segment_distance`).
Curves are chains of short chords (:func:`arc_points`); a gap is a stretch of segments with
``ink = 0``: the line runs on through it (progress is measured along it) but nothing is drawn.
:func:`line_segments` builds the records as a plain float array from a polyline.
"""

from __future__ import annotations

import math

import numpy as np

from follow_env.sim.jit import njit
from follow_env.sim.schema import Block, f8

__all__ = [
    "LINE_SEGMENT",
    "arc_points",
    "line_segments",
    "nearest_on_line",
    "segment_distance",
    "segment_frame",
]

LINE_SEGMENT = Block(
    "line_segment",
    "one straight piece of a floor line's centreline, in the order the line runs",
    [
        f8("x1", "m", "start, x (world frame)"),
        f8("y1", "m", "start, y"),
        f8("x2", "m", "end, x"),
        f8("y2", "m", "end, y"),
        f8("s", "m", "arc length of the line at the start"),
        f8("length", "m", "length of the piece"),
        f8("ink", "", "1: drawn; 0: a gap (the line is missing here)"),
        f8("mx", "m", "midpoint x (quick rejection)"),
        f8("my", "m", "midpoint y"),
    ],
)
SEG = LINE_SEGMENT.columns()
"""Column of each field in a plain float array of segments (``SEG.x1`` .. ``SEG.my``)."""


def line_segments(points: np.ndarray, ink: np.ndarray) -> np.ndarray:
    """Segments ``(m - 1, fields)`` of the polyline ``points`` (m, 2) (m) with ``ink[k]`` (1 or
    0) for the piece from point k to point k + 1; zero-length pieces are dropped."""
    points = np.asarray(points, dtype=np.float64)
    ink = np.asarray(ink, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] != 2 or len(points) < 2:
        raise ValueError(f"a line needs at least 2 points of (x, y), got shape {points.shape}")
    if ink.shape != (len(points) - 1,):
        raise ValueError(f"ink must give one flag per piece ({len(points) - 1}), got {ink.shape}")
    d = np.diff(points, axis=0)
    length = np.hypot(d[:, 0], d[:, 1])
    keep = length > 1e-9
    a, b, length, ink = points[:-1][keep], points[1:][keep], length[keep], ink[keep]
    out = np.zeros((len(a), len(LINE_SEGMENT.fields)))
    out[:, SEG.x1], out[:, SEG.y1] = a[:, 0], a[:, 1]
    out[:, SEG.x2], out[:, SEG.y2] = b[:, 0], b[:, 1]
    out[:, SEG.s] = np.concatenate([[0.0], np.cumsum(length)[:-1]])
    out[:, SEG.length] = length
    out[:, SEG.ink] = ink
    out[:, SEG.mx], out[:, SEG.my] = 0.5 * (a[:, 0] + b[:, 0]), 0.5 * (a[:, 1] + b[:, 1])
    return out


def arc_points(
    cx: float, cy: float, radius: float, a0: float, a1: float, max_step_rad: float = math.pi / 36
) -> np.ndarray:
    """Points (k, 2) of the arc of ``radius`` (m) round ``(cx, cy)`` from angle ``a0`` to ``a1``
    (rad, either direction), both ends included, chords at most ``max_step_rad`` apart (5 deg:
    a chord strays under 0.1 % of the radius from the arc)."""
    n = max(1, math.ceil(abs(a1 - a0) / max_step_rad))
    ang = np.linspace(a0, a1, n + 1)
    return np.stack([cx + radius * np.cos(ang), cy + radius * np.sin(ang)], axis=1)


@njit(inline="always")
def segment_frame(seg: np.void, px: float, py: float) -> tuple[float, float, float]:
    """``(distance, t, side)`` of point ``(px, py)`` to segment ``seg``: the distance (m), the
    nearest point's share of the way along it (0..1) and the cross product's sign (> 0: the
    point is left of the segment's direction)."""
    dx, dy = seg.x2 - seg.x1, seg.y2 - seg.y1
    ex, ey = px - seg.x1, py - seg.y1
    t = (ex * dx + ey * dy) / (seg.length * seg.length)
    t = min(max(t, 0.0), 1.0)
    qx, qy = ex - t * dx, ey - t * dy
    side = dx * ey - dy * ex
    return math.sqrt(qx * qx + qy * qy), t, side


@njit(inline="always")
def segment_distance(seg: np.void, px: float, py: float) -> float:
    """Distance (m) of point ``(px, py)`` to segment ``seg``."""
    return segment_frame(seg, px, py)[0]


@njit(inline="always")
def nearest_on_line(
    segs: np.ndarray, n: int, px: float, py: float, s_lo: float, s_hi: float
) -> tuple[int, float, float]:
    """The point of the line nearest ``(px, py)`` among the pieces overlapping the arc-length
    window ``[s_lo, s_hi]`` (m): ``(segment index, arc length s, signed distance)`` (> 0: the
    point is left of the line). The window keeps progress from jumping to a later part of the
    line that passes close by (a zigzag's next tooth); index -1 if no piece is in it."""
    best, best_d, best_s, best_side = -1, np.inf, 0.0, 0.0
    for k in range(n):
        seg = segs[k]
        if seg.s > s_hi or seg.s + seg.length < s_lo:
            continue
        d, t, side = segment_frame(seg, px, py)
        if d < best_d:
            best, best_d, best_s, best_side = k, d, seg.s + t * seg.length, side
    signed = best_d if best_side >= 0.0 else -best_d
    return best, best_s, signed

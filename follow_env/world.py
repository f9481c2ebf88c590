"""The world's geometry: walls held in a pymunk space, and the compiled contact tests.

pymunk holds the room (static segments with a thickness) and the robot's footprint (a box on a
kinematic body); :meth:`World.robot_touches_wall` asks pymunk whether they touch. The batched
core cannot afford a pymunk query per lane and step, so its kernel runs the same test in
compiled closed-form geometry over the same segments (:func:`rect_segment_distance`); the tests
check the two agree on thousands of random poses, so pymunk is the reference for contacts.
"""

from __future__ import annotations

import numpy as np
import pymunk
from numba import njit

__all__ = [
    "WALL_RADIUS_M",
    "World",
    "rect_rect_distance",
    "rect_segment_distance",
    "room_walls",
    "segment_distance",
]

WALL_RADIUS_M = 0.05
"""Half the thickness of a wall segment (m): pymunk's segment radius."""

_CAT_WALL = 0b01
_CAT_ROBOT = 0b10


def room_walls(length_m: float, width_m: float) -> np.ndarray:
    """The four walls of a rectangular room centred on the origin: (4, 4) ``x1, y1, x2, y2``."""
    hx, hy = 0.5 * length_m, 0.5 * width_m
    return np.array(
        [[-hx, -hy, hx, -hy], [hx, -hy, hx, hy], [hx, hy, -hx, hy], [-hx, hy, -hx, -hy]]
    )


@njit(cache=True, inline="always")
def _point_segment_distance(
    px: float, py: float, ax: float, ay: float, bx: float, by: float
) -> float:
    dx, dy = bx - ax, by - ay
    den = dx * dx + dy * dy
    t = 0.0 if den == 0.0 else ((px - ax) * dx + (py - ay) * dy) / den
    t = min(max(t, 0.0), 1.0)
    ex, ey = ax + t * dx - px, ay + t * dy - py
    return np.sqrt(ex * ex + ey * ey)


@njit(cache=True, inline="always")
def _cross(ax: float, ay: float, bx: float, by: float, cx: float, cy: float) -> float:
    return (bx - ax) * (cy - ay) - (by - ay) * (cx - ax)


@njit(cache=True)
def segment_distance(
    a1x: float, a1y: float, a2x: float, a2y: float, b1x: float, b1y: float, b2x: float, b2y: float
) -> float:
    """Shortest distance between segments a and b (m); 0 when they cross."""
    d1 = _cross(a1x, a1y, a2x, a2y, b1x, b1y)
    d2 = _cross(a1x, a1y, a2x, a2y, b2x, b2y)
    d3 = _cross(b1x, b1y, b2x, b2y, a1x, a1y)
    d4 = _cross(b1x, b1y, b2x, b2y, a2x, a2y)
    if d1 * d2 < 0.0 and d3 * d4 < 0.0:
        return 0.0
    return min(
        min(
            _point_segment_distance(a1x, a1y, b1x, b1y, b2x, b2y),
            _point_segment_distance(a2x, a2y, b1x, b1y, b2x, b2y),
        ),
        min(
            _point_segment_distance(b1x, b1y, a1x, a1y, a2x, a2y),
            _point_segment_distance(b2x, b2y, a1x, a1y, a2x, a2y),
        ),
    )


@njit(cache=True, inline="always")
def _rect_corner(
    cx: float, cy: float, th: float, length: float, width: float, k: int
) -> tuple[float, float]:
    """Corner k (0..3, counter-clockwise from rear-right) of a rectangle centred at (cx, cy)."""
    a = 0.5 * length * (1.0 if k in (1, 2) else -1.0)
    b = 0.5 * width * (1.0 if k in (2, 3) else -1.0)
    c, s = np.cos(th), np.sin(th)
    return cx + a * c - b * s, cy + a * s + b * c


@njit(cache=True, inline="always")
def _inside_rect(
    px: float, py: float, cx: float, cy: float, th: float, length: float, width: float
) -> bool:
    c, s = np.cos(th), np.sin(th)
    dx, dy = px - cx, py - cy
    return abs(c * dx + s * dy) <= 0.5 * length and abs(-s * dx + c * dy) <= 0.5 * width


@njit(cache=True)
def rect_segment_distance(
    cx: float,
    cy: float,
    th: float,
    length: float,
    width: float,
    x1: float,
    y1: float,
    x2: float,
    y2: float,
) -> float:
    """Distance (m) from a rectangle (centre, heading, length along it, width) to a segment;
    0 when they overlap."""
    if _inside_rect(x1, y1, cx, cy, th, length, width):
        return 0.0
    best = np.inf
    for k in range(4):
        ax, ay = _rect_corner(cx, cy, th, length, width, k)
        bx, by = _rect_corner(cx, cy, th, length, width, (k + 1) % 4)
        best = min(best, segment_distance(ax, ay, bx, by, x1, y1, x2, y2))
    return best


@njit(cache=True)
def rect_rect_distance(
    c1x: float,
    c1y: float,
    th1: float,
    l1: float,
    w1: float,
    c2x: float,
    c2y: float,
    th2: float,
    l2: float,
    w2: float,
) -> float:
    """Distance (m) between two rectangles; 0 when they overlap."""
    best = np.inf
    for k in range(4):
        ax, ay = _rect_corner(c2x, c2y, th2, l2, w2, k)
        bx, by = _rect_corner(c2x, c2y, th2, l2, w2, (k + 1) % 4)
        best = min(best, rect_segment_distance(c1x, c1y, th1, l1, w1, ax, ay, bx, by))
    if _inside_rect(c1x, c1y, c2x, c2y, th2, l2, w2):
        return 0.0
    return best


class World:
    """A pymunk space with the walls and the robot's footprint.

    :param walls: (n, 4) wall segments ``x1, y1, x2, y2`` (m).
    :param footprint_length_m: robot footprint along its heading (m).
    :param footprint_width_m: robot footprint across (m).
    """

    def __init__(
        self, walls: np.ndarray, footprint_length_m: float, footprint_width_m: float
    ) -> None:
        self.walls = np.asarray(walls, dtype=float).reshape(-1, 4)
        self.space = pymunk.Space()
        for x1, y1, x2, y2 in self.walls:
            seg = pymunk.Segment(self.space.static_body, (x1, y1), (x2, y2), WALL_RADIUS_M)
            seg.filter = pymunk.ShapeFilter(categories=_CAT_WALL)
            self.space.add(seg)
        self.robot_body = pymunk.Body(body_type=pymunk.Body.KINEMATIC)
        self.robot_shape = pymunk.Poly.create_box(
            self.robot_body, (footprint_length_m, footprint_width_m)
        )
        self.robot_shape.filter = pymunk.ShapeFilter(categories=_CAT_ROBOT, mask=_CAT_WALL)
        self.space.add(self.robot_body, self.robot_shape)

    def set_robot_pose(self, x: float, y: float, theta: float) -> None:
        """Move the robot's footprint (kinematic: pymunk never pushes it back)."""
        self.robot_body.position = (x, y)
        self.robot_body.angle = theta
        self.space.reindex_shapes_for_body(self.robot_body)

    def robot_touches_wall(self, x: float, y: float, theta: float) -> bool:
        """pymunk's answer: does the footprint at this pose touch any wall?"""
        self.set_robot_pose(x, y, theta)
        return len(self.space.shape_query(self.robot_shape)) > 0

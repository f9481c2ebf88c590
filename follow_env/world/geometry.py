"""The world's geometry: walls and obstacles, the compiled distance tests, pymunk as reference.

Walls and obstacles are segments with a height (:data:`WALL`: ``x1, y1, x2, y2, h``), held per
lane as records; :func:`room_walls`, :func:`box_walls` and :func:`polygon_walls` build them as
plain ``(n, 5)`` float arrays in that field order (:func:`as_wall_records` views them as
records without a copy).

pymunk holds the room (static segments with a thickness) and the robot's footprint (a box on a
kinematic body); :meth:`World.robot_touches_wall` asks pymunk whether they touch. The batched
core cannot afford a pymunk query per lane and step, so its kernel runs the same test in
compiled closed-form geometry over the same segments (:func:`rect_segment_distance`); the tests
check the two agree on thousands of random poses, so pymunk is the reference for contacts.
"""

from __future__ import annotations

import numpy as np
import pymunk

from follow_env.sim.jit import njit
from follow_env.sim.schema import Block, f8

__all__ = [
    "WALL",
    "WALL_HEIGHT_M",
    "WALL_RADIUS_M",
    "World",
    "as_wall_records",
    "box_walls",
    "point_segment_distance",
    "polygon_walls",
    "rect_rect_distance",
    "rect_segment_distance",
    "room_walls",
    "segment_distance",
    "wall_loops",
]

WALL = Block(
    "wall",
    "a wall or obstacle side: a segment seen from above, and its height",
    [
        f8("x1", "m", "first end, x (world frame)"),
        f8("y1", "m", "first end, y"),
        f8("x2", "m", "second end, x"),
        f8("y2", "m", "second end, y"),
        f8("h", "m", "height: walls and pillars are tall (hide people), furniture low"),
    ],
)
WALL_FIELDS = len(WALL.fields)
_COLUMNS = WALL.columns()


def as_wall_records(walls: np.ndarray) -> np.ndarray:
    """A float array ``(..., 5)`` of walls (``x1, y1, x2, y2, h``) as :data:`WALL` records
    ``(...)``, sharing its memory."""
    arr = np.ascontiguousarray(walls, dtype=np.float64)
    if arr.shape[-1] != WALL_FIELDS:
        raise ValueError(
            f"walls must have {WALL_FIELDS} columns (x1, y1, x2, y2, h), got {arr.shape}"
        )
    return arr.view(WALL.dtype)[..., 0]


WALL_RADIUS_M = 0.05
"""Half the thickness of a wall segment (m): pymunk's segment radius."""

_CAT_WALL = 0b01
_CAT_ROBOT = 0b10


WALL_HEIGHT_M = 3.0
"""Height of walls and pillars (m): taller than anyone, so they hide people entirely."""


def room_walls(length_m: float, width_m: float, height_m: float = WALL_HEIGHT_M) -> np.ndarray:
    """The four walls of a rectangular room centred on the origin: (4, 5)
    ``x1, y1, x2, y2, height``."""
    hx, hy = 0.5 * length_m, 0.5 * width_m
    corners = [(-hx, -hy), (hx, -hy), (hx, hy), (-hx, hy)]
    return polygon_walls(corners, height_m)


def polygon_walls(corners: list[tuple[float, float]], height_m: float) -> np.ndarray:
    """The closed outline through ``corners`` (m) as wall segments of ``height_m``: (n, 5)."""
    pts = np.asarray(corners, dtype=float)
    nxt = np.roll(pts, -1, axis=0)
    return np.column_stack([pts, nxt, np.full(len(pts), height_m)])


def box_walls(
    cx: float, cy: float, length_m: float, width_m: float, heading_rad: float, height_m: float
) -> np.ndarray:
    """A box obstacle (pillar, cabinet, table) as its four sides: (4, 5)."""
    c, s = np.cos(heading_rad), np.sin(heading_rad)
    hl, hw = 0.5 * length_m, 0.5 * width_m
    local = [(-hl, -hw), (hl, -hw), (hl, hw), (-hl, hw)]
    return polygon_walls([(cx + a * c - b * s, cy + a * s + b * c) for a, b in local], height_m)


def wall_loops(walls: np.ndarray, tol_m: float = 1e-6) -> list[tuple[int, int]]:
    """Runs ``[start, end)`` of wall segments (rows of :data:`WALL`'s fields, m) that form
    closed outlines: at least three segments listed head to tail whose last end meets the
    first start, as :func:`polygon_walls` and :func:`box_walls` write them. Open chains (a
    corridor's side, a partition) are not loops."""
    c = _COLUMNS
    loops = []
    n, k = len(walls), 0
    while k < n:
        j = k
        while (
            j + 1 < n
            and abs(walls[j, c.x2] - walls[j + 1, c.x1]) <= tol_m
            and abs(walls[j, c.y2] - walls[j + 1, c.y1]) <= tol_m
        ):
            j += 1
        closed = (
            abs(walls[j, c.x2] - walls[k, c.x1]) <= tol_m
            and abs(walls[j, c.y2] - walls[k, c.y1]) <= tol_m
        )
        if j - k >= 2 and closed:
            loops.append((k, j + 1))
        k = j + 1
    return loops


@njit(inline="always")
def _point_segment_distance(
    px: float, py: float, ax: float, ay: float, bx: float, by: float
) -> float:
    dx, dy = bx - ax, by - ay
    den = dx * dx + dy * dy
    t = 0.0 if den == 0.0 else ((px - ax) * dx + (py - ay) * dy) / den
    t = min(max(t, 0.0), 1.0)
    ex, ey = ax + t * dx - px, ay + t * dy - py
    return np.sqrt(ex * ex + ey * ey)


@njit(inline="always")
def segment_distance(
    a1x: float, a1y: float, a2x: float, a2y: float, b1x: float, b1y: float, b2x: float, b2y: float
) -> float:
    """Shortest distance (m) between segments a and b; 0 when they cross."""
    d1 = (a2x - a1x) * (b1y - a1y) - (a2y - a1y) * (b1x - a1x)
    d2 = (a2x - a1x) * (b2y - a1y) - (a2y - a1y) * (b2x - a1x)
    d3 = (b2x - b1x) * (a1y - b1y) - (b2y - b1y) * (a1x - b1x)
    d4 = (b2x - b1x) * (a2y - b1y) - (b2y - b1y) * (a2x - b1x)
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


@njit(inline="always")
def point_segment_distance(
    px: float, py: float, ax: float, ay: float, bx: float, by: float
) -> float:
    """Distance (m) from point (px, py) to the segment a-b."""
    return _point_segment_distance(px, py, ax, ay, bx, by)


@njit(inline="always")
def _point_box_distance(x: float, y: float, hl: float, hw: float) -> float:
    """Distance from (x, y) to the axis-aligned box |x| <= hl, |y| <= hw (0 inside)."""
    ex, ey = max(abs(x) - hl, 0.0), max(abs(y) - hw, 0.0)
    return np.sqrt(ex * ex + ey * ey)


@njit(inline="always")
def _segment_crosses_box(x1: float, y1: float, x2: float, y2: float, hl: float, hw: float) -> bool:
    """Does the segment meet the axis-aligned box? (Liang-Barsky clipping.)"""
    dx, dy = x2 - x1, y2 - y1
    t0, t1 = 0.0, 1.0
    for k in range(4):
        if k == 0:
            p, q = -dx, x1 + hl
        elif k == 1:
            p, q = dx, hl - x1
        elif k == 2:
            p, q = -dy, y1 + hw
        else:
            p, q = dy, hw - y1
        if p == 0.0:
            if q < 0.0:
                return False
        else:
            r = q / p
            if p < 0.0:
                t0 = max(t0, r)
            else:
                t1 = min(t1, r)
            if t0 > t1:
                return False
    return True


@njit(inline="always")
def _segment_box_distance(
    x1: float, y1: float, x2: float, y2: float, hl: float, hw: float
) -> float:
    """Distance from a segment to the axis-aligned box |x| <= hl, |y| <= hw; 0 if they meet.

    For two convex shapes that do not meet, the closest pair has a vertex of one of them: an
    end of the segment, or a corner of the box.
    """
    if _segment_crosses_box(x1, y1, x2, y2, hl, hw):
        return 0.0
    best = min(_point_box_distance(x1, y1, hl, hw), _point_box_distance(x2, y2, hl, hw))
    for k in range(4):
        cx = hl if k in (1, 2) else -hl
        cy = hw if k in (2, 3) else -hw
        best = min(best, _point_segment_distance(cx, cy, x1, y1, x2, y2))
    return best


@njit(inline="always")
def _to_frame(x: float, y: float, cx: float, cy: float, c: float, s: float) -> tuple[float, float]:
    """World point into the frame centred at (cx, cy) with x axis (c, s)."""
    dx, dy = x - cx, y - cy
    return c * dx + s * dy, -s * dx + c * dy


@njit(inline="always")
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
    c, s = np.cos(th), np.sin(th)
    ax, ay = _to_frame(x1, y1, cx, cy, c, s)
    bx, by = _to_frame(x2, y2, cx, cy, c, s)
    return _segment_box_distance(ax, ay, bx, by, 0.5 * length, 0.5 * width)


@njit(inline="always")
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
    c1, s1 = np.cos(th1), np.sin(th1)
    c2, s2 = np.cos(th2), np.sin(th2)
    hl2, hw2 = 0.5 * l2, 0.5 * w2
    # Rectangle 1 wholly inside rectangle 2 meets none of its edges: test its centre.
    qx, qy = _to_frame(c1x, c1y, c2x, c2y, c2, s2)
    if abs(qx) <= hl2 and abs(qy) <= hw2:
        return 0.0
    best = np.inf
    # Rectangle 2's edges, in rectangle 1's frame, against rectangle 1 as a box.
    px, py = 0.0, 0.0
    for k in range(5):
        a = hl2 if (k % 4) in (1, 2) else -hl2
        b = hw2 if (k % 4) in (2, 3) else -hw2
        x, y = _to_frame(c2x + a * c2 - b * s2, c2y + a * s2 + b * c2, c1x, c1y, c1, s1)
        if k > 0:
            best = min(best, _segment_box_distance(px, py, x, y, 0.5 * l1, 0.5 * w1))
        px, py = x, y
    return best


class World:
    """A pymunk space with the walls and the robot's footprint.

    :param walls: (n, 5) wall segments ``x1, y1, x2, y2, height`` (m); a height column is
        optional.
    :param footprint_length_m: robot footprint along its heading (m).
    :param footprint_width_m: robot footprint across (m).
    """

    def __init__(
        self, walls: np.ndarray, footprint_length_m: float, footprint_width_m: float
    ) -> None:
        walls = np.asarray(walls, dtype=float)
        self.walls = walls.reshape(-1, walls.shape[-1])
        self.space = pymunk.Space()
        for x1, y1, x2, y2 in self.walls[:, :4]:
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

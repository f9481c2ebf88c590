"""A 2-D cost map for walking paths: occupancy and a cost that rises near obstacles.

A grid of cells of ``resolution_m`` with its lower-left corner at ``(x0_m, y0_m)``; cell
``[iy, ix]`` covers ``x0 + ix res <= x < x0 + (ix + 1) res`` and likewise in y. Each cell has an
occupancy flag (the body of a walker, a disc of ``body_radius_m``, would touch an obstacle) and a
cost ``exp(-clearance / length_scale_m)`` in (0, 1], where ``clearance`` is the distance (m) from
the edge of the body to the nearest obstacle: 1 at contact, falling off over a few length
scales. A point outside the grid is never free. Segments are traced exactly through the grid
(Amanatides & Woo's traversal), in compiled code that the planner (:mod:`.trrt`) and the path
post-processing (:mod:`.paths`) share.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike
from scipy import ndimage

from follow_env.sim.checks import check_number, is_real, out_of_range, real_array
from follow_env.sim.jit import njit

__all__ = [
    "CostMap",
    "cell_of",
    "checked_point",
    "cost_map_from_obstacles",
    "segment_is_free",
    "trace_segment",
]


@dataclass(frozen=True, eq=False)
class CostMap:
    """A 2-D cost map with its occupancy grid.

    :param cost: (ny, nx) float, cost of each cell (finite, >= 0; dimensionless).
    :param occupied: (ny, nx) bool, True where a walker's body would touch an obstacle.
    :param x0_m: x of the grid's lower-left corner (m).
    :param y0_m: y of the grid's lower-left corner (m).
    :param resolution_m: side of a cell (m).
    """

    cost: np.ndarray
    occupied: np.ndarray
    x0_m: float
    y0_m: float
    resolution_m: float

    def __post_init__(self) -> None:
        cost = np.array(self.cost, dtype=np.float64, order="C")
        occupied = np.array(self.occupied, dtype=np.bool_, order="C")
        if cost.ndim != 2 or cost.shape[0] < 1 or cost.shape[1] < 1:
            raise ValueError(
                f"CostMap.cost has shape {cost.shape}: must be 2-D (ny, nx), non-empty"
            )
        if occupied.shape != cost.shape:
            raise ValueError(
                f"CostMap.occupied has shape {occupied.shape}: must match cost {cost.shape}"
            )
        if not np.all(np.isfinite(cost)) or np.any(cost < 0.0):
            raise ValueError("CostMap.cost is out of range: every cell must be finite and >= 0")
        # Python or numpy numbers, as everywhere (follow_env.sim.checks); not bools.
        check_number("CostMap.x0_m", self.x0_m, unit="m")
        check_number("CostMap.y0_m", self.y0_m, unit="m")
        check_number("CostMap.resolution_m", self.resolution_m, 0.0, None, unit="m", lo_open=True)
        cost.flags.writeable = False
        occupied.flags.writeable = False
        object.__setattr__(self, "cost", cost)
        object.__setattr__(self, "occupied", occupied)
        for name in ("x0_m", "y0_m", "resolution_m"):
            object.__setattr__(self, name, float(getattr(self, name)))

    @property
    def shape(self) -> tuple[int, int]:
        """Grid size (ny, nx) in cells."""
        return self.cost.shape  # type: ignore[return-value]

    @property
    def bounds(self) -> tuple[float, float, float, float]:
        """``(xmin, ymin, xmax, ymax)`` of the grid (m)."""
        ny, nx = self.shape
        r = self.resolution_m
        return self.x0_m, self.y0_m, self.x0_m + nx * r, self.y0_m + ny * r

    def cell_of(self, xy: ArrayLike) -> tuple[int, int] | None:
        """The cell ``(ix, iy)`` holding point ``xy`` (m), or None outside the grid."""
        x, y = (float(v) for v in np.asarray(xy, dtype=np.float64).reshape(2))
        ix, iy = cell_of(x, y, self.x0_m, self.y0_m, self.resolution_m, *self.shape)
        return None if ix < 0 else (ix, iy)

    def is_free(self, xy: ArrayLike) -> bool:
        """True when point ``xy`` (m) is inside the grid in an unoccupied cell."""
        cell = self.cell_of(xy)
        return cell is not None and not self.occupied[cell[1], cell[0]]

    def cost_at(self, xy: ArrayLike) -> float:
        """Cost of the cell holding point ``xy`` (m); ValueError outside the grid."""
        cell = self.cell_of(xy)
        if cell is None:
            raise ValueError(f"xy={tuple(np.asarray(xy).tolist())!r} is outside the cost map")
        return float(self.cost[cell[1], cell[0]])


def _as_rows(values: ArrayLike | None, widths: tuple[int, ...], name: str) -> np.ndarray:
    """``values`` as a float (n, w) array with w one of ``widths``; None or empty -> (0, w)."""
    if values is None:
        return np.zeros((0, widths[-1]))
    a = real_array(values)  # strings, None and ragged rows are no coordinates
    if a is None:
        raise ValueError(
            f"{name}={values!r} is out of range: must be real numbers in rows of "
            f"{' or '.join(map(str, widths))} (m)"
        )
    if a.size == 0:
        return np.zeros((0, widths[-1]))
    if a.ndim == 1:
        a = a[None, :]
    if a.ndim != 2 or a.shape[1] not in widths:
        raise ValueError(
            f"{name} has shape {a.shape}: must be (n, {' or '.join(map(str, widths))})"
        )
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name} holds a non-finite value: every coordinate must be finite")
    return a


def cost_map_from_obstacles(
    bounds: tuple[float, float, float, float],
    walls: ArrayLike | None = None,
    boxes: ArrayLike | None = None,
    *,
    resolution_m: float = 0.1,
    wall_thickness_m: float = 0.1,
    body_radius_m: float = 0.25,
    length_scale_m: float = 0.5,
) -> CostMap:
    """Rasterise walls and boxes into a :class:`CostMap` over ``bounds``.

    Obstacle cells are those whose centre lies within an obstacle grown by half a cell (so a
    wall thinner than a cell still makes an unbroken line). ``scipy.ndimage`` gives every cell
    its distance to the nearest obstacle cell; less half a cell, that is its clearance to the
    obstacle, accurate to about half a cell. A cell is occupied when a walker's disc of
    ``body_radius_m`` centred on it would touch an obstacle (clearance < body radius); its cost
    is ``exp(-(clearance - body_radius_m) / length_scale_m)``: 1 at the edge of free space,
    ``e**-1`` one length scale further out. The grid's border is not an obstacle by itself:
    pass walls for it (points outside the grid are never free to the planner).

    :param bounds: ``(xmin, ymin, xmax, ymax)`` of the map (m).
    :param walls: (n, 4) segments ``x1, y1, x2, y2`` (m), each ``wall_thickness_m`` thick
        (with rounded ends: every point within half the thickness of the segment).
    :param boxes: (m, 5) ``cx, cy, length, width, yaw`` (m, m, m, m, rad): rectangles of
        ``length`` along their heading ``yaw``; (m, 4) rows ``cx, cy, length, width`` are
        axis-aligned.
    :param resolution_m: cell side (m).
    :param wall_thickness_m: thickness of every wall (m).
    :param body_radius_m: radius of the walker's body (m): obstacles are inflated by it. The
        default is half an adult's shoulder width (~0.45 m) plus a few cm; a door then needs
        to be wider than about 2 x (0.25 + half the wall) + a cell to stay open.
    :param length_scale_m: distance over which the cost falls by a factor e (m).
    """
    rule = "four finite numbers (xmin, ymin, xmax, ymax) with xmax > xmin and ymax > ymin (m)"
    try:
        corners = tuple(bounds)
    except TypeError:  # not a sequence at all
        raise out_of_range("bounds", bounds, rule) from None
    if len(corners) != 4 or not all(is_real(v) and math.isfinite(v) for v in corners):
        raise out_of_range("bounds", bounds, rule)
    xmin, ymin, xmax, ymax = (float(v) for v in corners)
    if xmax <= xmin or ymax <= ymin:
        raise out_of_range("bounds", bounds, rule)
    for name, value, strict in (
        ("resolution_m", resolution_m, True),
        ("wall_thickness_m", wall_thickness_m, False),
        ("body_radius_m", body_radius_m, False),
        ("length_scale_m", length_scale_m, True),
    ):
        check_number(name, value, 0.0, None, unit="m", lo_open=strict)
    wall_rows = _as_rows(walls, (4,), "walls")
    box_rows = _as_rows(boxes, (4, 5), "boxes")
    if box_rows.shape[1] == 4:
        box_rows = np.column_stack([box_rows, np.zeros(len(box_rows))])
    if np.any(box_rows[:, 2:4] < 0.0):
        raise ValueError("boxes has a negative length or width: sizes must be >= 0 m")

    res = float(resolution_m)
    nx = max(1, math.ceil((xmax - xmin) / res - 1e-9))
    ny = max(1, math.ceil((ymax - ymin) / res - 1e-9))
    xc = xmin + (np.arange(nx) + 0.5) * res  # cell centres (m)
    yc = ymin + (np.arange(ny) + 0.5) * res
    obstacle = np.zeros((ny, nx), dtype=np.bool_)
    grow = 0.5 * res  # half a cell: thin walls still rasterise without gaps

    def window(x_lo: float, x_hi: float, y_lo: float, y_hi: float) -> tuple[slice, slice]:
        # Only the cells under an obstacle's bounding box are tested: obstacles are small.
        i0 = max(0, math.floor((x_lo - xmin) / res))
        i1 = min(nx, math.ceil((x_hi - xmin) / res) + 1)
        j0 = max(0, math.floor((y_lo - ymin) / res))
        j1 = min(ny, math.ceil((y_hi - ymin) / res) + 1)
        return slice(j0, max(j0, j1)), slice(i0, max(i0, i1))

    reach = 0.5 * wall_thickness_m + grow
    for x1, y1, x2, y2 in wall_rows:
        sy, sx = window(
            min(x1, x2) - reach, max(x1, x2) + reach, min(y1, y2) - reach, max(y1, y2) + reach
        )
        px, py = np.meshgrid(xc[sx], yc[sy])
        dx, dy = x2 - x1, y2 - y1
        den = dx * dx + dy * dy
        t = 0.0 if den == 0.0 else np.clip(((px - x1) * dx + (py - y1) * dy) / den, 0.0, 1.0)
        dist = np.hypot(x1 + t * dx - px, y1 + t * dy - py)
        obstacle[sy, sx] |= dist <= reach
    for cx, cy, length, width, yaw in box_rows:
        c, s = math.cos(yaw), math.sin(yaw)
        hl, hw = 0.5 * length, 0.5 * width
        ex = abs(c) * hl + abs(s) * hw + grow  # half extents of the bounding box
        ey = abs(s) * hl + abs(c) * hw + grow
        sy, sx = window(cx - ex, cx + ex, cy - ey, cy + ey)
        px, py = np.meshgrid(xc[sx] - cx, yc[sy] - cy)
        u, v = c * px + s * py, -s * px + c * py  # cell centres in the box's frame
        dist = np.hypot(np.maximum(np.abs(u) - hl, 0.0), np.maximum(np.abs(v) - hw, 0.0))
        obstacle[sy, sx] |= dist <= grow

    if obstacle.any():
        # Distance (m) from each cell centre to the nearest obstacle cell centre, less the half
        # cell the obstacles were grown by: the clearance to the obstacle itself.
        clearance = ndimage.distance_transform_edt(~obstacle) * res - grow
        clearance = np.maximum(clearance, 0.0)
        clearance[obstacle] = 0.0
    else:
        clearance = np.full((ny, nx), np.inf)
    body_clearance = clearance - body_radius_m
    occupied = obstacle | (body_clearance < 0.0)  # obstacle cells even for a point walker
    cost = np.exp(-np.maximum(body_clearance, 0.0) / length_scale_m)
    return CostMap(cost, occupied, xmin, ymin, res)


# --- compiled geometry -------------------------------------------------------------------------


@njit(inline="always")
def cell_of(x: float, y: float, x0: float, y0: float, res: float, ny: int, nx: int) -> tuple:
    """Cell (ix, iy) holding (x, y), or (-1, -1) outside the grid."""
    gx = (x - x0) / res
    gy = (y - y0) / res
    if not (gx >= 0.0 and gy >= 0.0 and gx < nx and gy < ny):  # also rejects NaN
        return -1, -1
    return int(gx), int(gy)


@njit
def trace_segment(
    cost: np.ndarray,
    occ: np.ndarray,
    x0: float,
    y0: float,
    res: float,
    ax: float,
    ay: float,
    bx: float,
    by: float,
) -> float:
    """Highest cost of the cells the segment a-b crosses, or inf if any is occupied or off the
    grid. Every crossed cell is visited (Amanatides & Woo's traversal), not sampled."""
    ny, nx = cost.shape
    ix, iy = cell_of(ax, ay, x0, y0, res, ny, nx)
    ex, ey = cell_of(bx, by, x0, y0, res, ny, nx)
    if ix < 0 or ex < 0 or occ[iy, ix] or occ[ey, ex]:
        return np.inf
    worst = max(cost[iy, ix], cost[ey, ex])
    gx, gy = (ax - x0) / res, (ay - y0) / res
    dx, dy = (bx - ax) / res, (by - ay) / res
    step_x = 1 if dx > 0.0 else -1
    step_y = 1 if dy > 0.0 else -1
    # Parameter t (0 at a, 1 at b) of the next vertical / horizontal cell border, and its step.
    if dx != 0.0:
        t_max_x = ((ix + 1 - gx) / dx) if dx > 0.0 else ((ix - gx) / dx)
        t_dx = abs(1.0 / dx)
    else:
        t_max_x, t_dx = np.inf, np.inf
    if dy != 0.0:
        t_max_y = ((iy + 1 - gy) / dy) if dy > 0.0 else ((iy - gy) / dy)
        t_dy = abs(1.0 / dy)
    else:
        t_max_y, t_dy = np.inf, np.inf
    for _ in range(abs(ex - ix) + abs(ey - iy)):
        if t_max_x < t_max_y:
            ix += step_x
            t_max_x += t_dx
        else:
            iy += step_y
            t_max_y += t_dy
        if ix < 0 or iy < 0 or ix >= nx or iy >= ny or occ[iy, ix]:
            return np.inf
        worst = max(worst, cost[iy, ix])
    return worst


def checked_point(cost_map: CostMap, xy: ArrayLike, name: str) -> tuple[float, float]:
    """``xy`` as two floats, checked to be a free point of the map; ValueError naming it."""
    try:
        a = np.asarray(xy, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"{name}={xy!r} is not a point: must be (x, y) in m") from None
    if a.shape != (2,) or not np.all(np.isfinite(a)):
        raise ValueError(f"{name}={xy!r} is not a point: must be two finite numbers (x, y) in m")
    x, y = float(a[0]), float(a[1])
    cell = cost_map.cell_of(a)
    if cell is None:
        xmin, ymin, xmax, ymax = cost_map.bounds
        raise ValueError(
            f"{name}=({x:g}, {y:g}) is outside the cost map: must have x in [{xmin:g}, {xmax:g})"
            f" m and y in [{ymin:g}, {ymax:g}) m"
        )
    if cost_map.occupied[cell[1], cell[0]]:
        raise ValueError(
            f"{name}=({x:g}, {y:g}) is inside an obstacle: cell (ix={cell[0]}, iy={cell[1]}) of "
            "the cost map is occupied (obstacles are inflated by the body radius)"
        )
    return x, y


def segment_is_free(cost_map: CostMap, a_xy: ArrayLike, b_xy: ArrayLike) -> bool:
    """True when the segment a-b (m) crosses only free cells of ``cost_map``."""
    a = np.asarray(a_xy, dtype=np.float64).reshape(2)
    b = np.asarray(b_xy, dtype=np.float64).reshape(2)
    w = trace_segment(
        cost_map.cost,
        cost_map.occupied,
        cost_map.x0_m,
        cost_map.y0_m,
        cost_map.resolution_m,
        a[0],
        a[1],
        b[0],
        b[1],
    )
    return bool(w < np.inf)

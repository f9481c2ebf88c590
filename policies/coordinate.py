"""The mecanum paper's "coordinate control" line tracer (reference §2), for a base that strafes.

From the 5 x 5 grid's readings:

1. *Active cells*: readings above ``threshold``; cell ``(i, j)`` at ``(x, y) = (2 - i, 2 - j)``
   cells (x forward, y to the left, from the grid's centre, the robot's centre).
2. A least-squares line ``y = a x + b`` through them (the paper's fit).
3. Its intersection ``(alpha, beta)`` with the circle of radius 3 cells round the centre:
   ``alpha`` across (to the right), ``beta`` ahead.
4. ``theta2 = atan(alpha / beta)``, ``Vx = sin(theta2)``, ``Vy = cos(theta2)``: a unit
   translation towards that point (the paper's Vx across, Vy ahead), scaled by ``speed_mps``;
   in REP 103 body axes ``v = speed cos(theta2)`` forward and ``vy = -speed sin(theta2)`` to
   the left.
5. ``wz = |pi/4 - theta1|``: a rotation from the line's angle ``theta1``.

## Where the paper is unclear, and what this law chooses
- **Axes.** The paper does not say which way x and y point. ``Vx = sin(theta2)``, ``Vy =
  cos(theta2)`` with ``theta2 = atan(alpha / beta)`` is a unit vector towards ``(alpha, beta)``
  only if ``alpha`` is the component that goes with Vx; read as a drawing of the grid (x to the
  right, y up the page, ahead), alpha is across and beta ahead, which is the reading here.
- **The fit's axis.** ``y = a x + b`` cannot represent a line along y. The fit is taken with x
  ahead (a line along the heading is ``y = b``, the case a tracer meets most); when the active
  cells spread more across than ahead (a line across the robot: a corner) it is taken the
  other way round, ``x = c y + d``. Active cells all in one row and at most two wide (a line's
  width: one cell, or the rear row where a gap begins) give no direction: the line is taken
  along the heading through them (slope 0). The fit is unweighted, over active cells, as the
  paper says.
- **Which intersection.** A line through the grid always cuts the circle (the grid's corners
  are 2.83 cells out) in two points; the one ahead along the line's direction is taken, the
  direction pointing forward (for a line straight across, towards the side with more of its
  active cells, else the last turn's side).
- **theta2.** ``atan2(alpha, beta)`` rather than ``atan``: the same for a point ahead, and
  still a direction towards the point when it lies behind.
- **theta1 and wz.** theta1 is read as the line's direction from the heading, positive to the
  right like theta2. ``|pi/4 - theta1|`` then turns the robot counter-clockwise at pi/4 rad/s
  on a straight line and never clockwise: it carries no direction. The ``literal`` preset
  commands exactly that (``w = |pi/4 - theta1|`` rad/s, counter-clockwise, times
  ``turn_gain``); the default ``signed`` preset reads the rotation as turning the heading onto
  the line, ``w = -turn_gain theta1`` (theta1 to the right: turn clockwise).
- **No active cell** (a gap, or the line lost): the paper is silent; the law keeps its last
  command (through a gap the robot goes on the way it was going). Before any line was seen it
  drives straight ahead at ``speed_mps``.
- **Speed.** The paper's command is a unit vector in duty; ``speed_mps`` (0.3 m/s) is a
  choice: on the simulated base open loop, wheels commanded below about 0.24 m/s stall (16 %
  duty of static friction), the stall the paper saw at low duty.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from types import MappingProxyType

import numpy as np

from follow_env.sim.checks import check_number, out_of_range
from policies.line_base import CELL_XY, LineLaw
from policies.space import ParamRange

__all__ = ["PRESETS", "SEARCH_SPACE", "Coordinate", "CoordinateParams", "fit_line", "intersection"]

ACROSS = 0.3
"""A fitted line whose direction is less than this ahead (cos, about 73 deg from the heading)
counts as running straight across the robot."""


@dataclass(frozen=True, kw_only=True)
class CoordinateParams:
    """Parameters of :class:`Coordinate` (module docstring).

    :param speed_mps: translation speed [m/s]. :param threshold: active above this [0..1].
    :param radius_cells: the circle's radius [cells] (reference §2: 3).
    :param turn: ``"signed"`` or ``"literal"`` (module docstring).
    :param turn_gain: rad/s per rad of theta1 (``signed``), or a factor on the paper's wz
        (``literal``).
    """

    speed_mps: float = 0.3
    threshold: float = 0.5
    radius_cells: float = 3.0
    turn: str = "signed"
    turn_gain: float = 2.0

    def __post_init__(self) -> None:
        name = type(self).__name__
        check_number(f"{name}.speed_mps", self.speed_mps, 0.0, 5.0, lo_open=True, unit="m/s")
        check_number(f"{name}.threshold", self.threshold, 0.0, 1.0)
        check_number(f"{name}.radius_cells", self.radius_cells, 2.9, 20.0, unit="cells")
        check_number(f"{name}.turn_gain", self.turn_gain, 0.0, 100.0)
        if self.turn not in ("signed", "literal"):
            raise out_of_range(f"{name}.turn", self.turn, "one of 'signed', 'literal'")


PRESETS = MappingProxyType(
    {
        "signed": CoordinateParams(),
        "literal": CoordinateParams(turn="literal", turn_gain=1.0),
        "tuned": CoordinateParams(speed_mps=0.5, turn_gain=4.0),
    }
)
"""``signed`` (the signed reading of wz, speed and turn gain chosen, not tuned), ``literal``
(the paper's wz as written) and ``tuned`` (the signed reading with the speed and turn gain of
the best candidate of :mod:`eval.line_tune`'s grid search, the same search that tunes the PID;
a bare ``coordinate`` means it)."""

SEARCH_SPACE = MappingProxyType(
    {"speed_mps": ParamRange(0.1, 0.8), "turn_gain": ParamRange(0.5, 32.0, log=True)}
)
"""What ``follow-tune coordinate --task line_trace`` searches (:mod:`policies.space`): the
speed 0.1..0.8 m/s and the signed reading's turn gain 0.5..32 rad/s per rad of theta1 (log
scale); the threshold, the circle and the reading of wz stay as preset."""


def fit_line(points: np.ndarray, last_side: float) -> tuple[np.ndarray, np.ndarray]:
    """A point on and the unit direction of the least-squares line through ``points`` (k, 2)
    (x ahead, y left; module docstring for the axis and the orientation), k >= 2."""
    x, y = points[:, 0], points[:, 1]
    mx, my = float(x.mean()), float(y.mean())
    vx, vy = float(((x - mx) ** 2).sum()), float(((y - my) ** 2).sum())
    if vx >= vy:  # y = a x + b: the direction (1, a) points ahead
        a = float(((x - mx) * (y - my)).sum()) / vx
        u = np.array([1.0, a]) / math.hypot(1.0, a)
        return np.array([mx, my]), u
    # x = c y + d: the line runs across the robot.
    c = float(((x - mx) * (y - my)).sum()) / vy
    u = np.array([c, 1.0]) / math.hypot(c, 1.0)
    if abs(u[0]) >= ACROSS:
        u = u if u[0] > 0.0 else -u  # still clearly ahead one way: take it
    else:  # nearly straight across: towards the side with most of the line, else the last
        side = float(np.sign(my)) or last_side or 1.0
        u = u if np.sign(u[1]) == side else -u
    return np.array([mx, my]), u


def intersection(p0: np.ndarray, u: np.ndarray, radius: float) -> np.ndarray:
    """Where the line ``p0 + t u`` meets the circle of ``radius`` round the origin, ahead
    along ``u`` (the larger root); the nearest point of the line if it misses the circle."""
    pu = float(p0 @ u)
    disc = pu * pu - float(p0 @ p0) + radius * radius
    t = -pu + math.sqrt(disc) if disc >= 0.0 else -pu
    return p0 + t * u


class Coordinate(LineLaw):
    """The coordinate-control line tracer (module docstring); acts ``[v, vy, w]``.

    :param params: its parameters. :param name: the name in tables and logs.
    """

    action_names = ("v_mps", "vy_mps", "w_radps")

    def __init__(
        self, params: CoordinateParams = PRESETS["signed"], name: str = "coordinate"
    ) -> None:
        self.params = params
        self.name = name
        self.reset()

    def reset(self) -> None:
        """Forget the last command and the last turn's side."""
        self._last: tuple[float, float, float] = (self.params.speed_mps, 0.0, 0.0)
        self._side = 0.0

    def _memory(self) -> tuple[tuple[float, float, float], float]:
        return self._last, self._side

    def _set_memory(self, memory: tuple[tuple[float, float, float], float]) -> None:
        self._last, self._side = memory

    def _command(self, readings: np.ndarray) -> tuple[float, float, float]:
        p = self.params
        active = CELL_XY[readings > p.threshold]
        if len(active) == 0:
            return self._last
        spread = np.ptp(active, axis=0)
        if spread[0] == 0.0 and spread[1] <= 1.0:
            # One row, at most a line's width across: no direction to fit; the line is taken
            # along the heading through these cells (slope 0), as y = a x + b would give.
            p0, u = active.mean(axis=0), np.array([1.0, 0.0])
        else:
            p0, u = fit_line(active, self._side)
        target = intersection(p0, u, p.radius_cells)
        theta1 = math.atan2(-u[1], u[0])  # the line's direction, positive to the right
        alpha, beta = -float(target[1]), float(target[0])  # across (right), ahead
        theta2 = math.atan2(alpha, beta)
        vx_paper, vy_paper = math.sin(theta2), math.cos(theta2)
        if p.turn == "literal":
            w = p.turn_gain * abs(math.pi / 4.0 - theta1)
        else:
            w = -p.turn_gain * theta1
        if theta1 != 0.0:
            self._side = -math.copysign(1.0, theta1)  # the side the line went: left is +1
        self._last = (p.speed_mps * vy_paper, -p.speed_mps * vx_paper, w)
        return self._last

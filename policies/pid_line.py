"""The PID line follower the mecanum paper compares coordinate control with (reference §2),
on 3 of the grid's 25 sensors.

The paper names the comparison but gives neither the sensors nor the gains, so all of this is a
choice, the textbook three-sensor follower: the front row's three middle cells (``cell_01``,
``cell_02``, ``cell_03``: left, centre, right, 24 mm ahead of the robot's centre with the
default grid) give the line's position ::

    e = (r_left - r_right) / (r_left + r_centre + r_right)      in [-1, 1], > 0: line to the left

and a PID on it steers while the robot drives ahead at a constant speed::

    w = kp e + ki sum(e dt) + kd (e - e_prev) / dt,    v = speed_mps

(w counter-clockwise positive: a line to the left turns the robot left). When the three
readings sum below ``lost_sum`` the line is not under them (a gap, a corner, the line lost):
the law turns on the spot towards the side it last saw the line on, at ``search_w_radps``,
driving at ``search_speed_mps`` (a gap is crossed straight on when the line was centred), and
its integral is frozen. It commands ``[v, w]``, so it runs on the differential drive and on the
mecanum base (``vy = 0``). Two presets: ``hand`` (0.3 m/s, kp 6, kd 0.15, set by hand: it
oscillates by up to 40 deg on a straight line and fails on zigzags) and ``tuned`` (0.2 m/s,
kp 20, kd 0.4: the best of :mod:`eval.line_tune`'s grid search, the same search that tunes
coordinate control).
"""

from __future__ import annotations

from dataclasses import dataclass
from types import MappingProxyType

import numpy as np

from follow_env.sim.checks import check_number
from follow_env.tasks.line_trace.spec import cell_index
from policies.line_base import LineLaw
from policies.space import ParamRange

__all__ = ["PID_SENSORS", "PRESETS", "SEARCH_SPACE", "PIDLine", "PIDLineParams"]

PID_SENSORS = (cell_index(0, 1), cell_index(0, 2), cell_index(0, 3))
"""The three cells read: front row, left of centre, centre, right of centre."""


@dataclass(frozen=True, kw_only=True)
class PIDLineParams:
    """Parameters of :class:`PIDLine` (module docstring), SI.

    :param speed_mps: forward speed [m/s]. :param kp: [rad/s]. :param ki: [rad/s^2].
    :param kd: [rad]. :param dt_s: control period [s] (the env's).
    :param lost_sum: the line is under the sensors when their readings sum to this [-].
    :param search_w_radps: turn rate while searching [rad/s].
    :param search_speed_mps: forward speed while searching [m/s].
    :param centred: |e| under this counts as centred: a gap is then crossed straight on [-].
    """

    speed_mps: float = 0.3
    kp: float = 6.0
    ki: float = 0.0
    kd: float = 0.15
    dt_s: float = 0.02
    lost_sum: float = 0.3
    search_w_radps: float = 3.0
    search_speed_mps: float = 0.0
    centred: float = 0.25

    def __post_init__(self) -> None:
        name = type(self).__name__
        check_number(f"{name}.speed_mps", self.speed_mps, 0.0, 5.0, unit="m/s")
        for field in ("kp", "ki", "kd"):
            check_number(f"{name}.{field}", getattr(self, field), 0.0, 1000.0)
        check_number(f"{name}.dt_s", self.dt_s, 0.0, 1.0, lo_open=True, unit="s")
        check_number(f"{name}.lost_sum", self.lost_sum, 0.0, 3.0)
        check_number(f"{name}.search_w_radps", self.search_w_radps, 0.0, 50.0, unit="rad/s")
        check_number(f"{name}.search_speed_mps", self.search_speed_mps, 0.0, 5.0, unit="m/s")
        check_number(f"{name}.centred", self.centred, 0.0, 1.0)


PRESETS = MappingProxyType(
    {"hand": PIDLineParams(), "tuned": PIDLineParams(speed_mps=0.2, kp=20.0, kd=0.4)}
)
"""``hand``: gains set by hand (module docstring); ``tuned``: the best of the search of
:mod:`eval.line_tune` (the environment's reward on tuning seeds and tracks), which a bare
``pid`` means."""

SEARCH_SPACE = MappingProxyType(
    {
        "speed_mps": ParamRange(0.1, 0.8),
        "kp": ParamRange(1.0, 80.0, log=True),
        "kd": ParamRange(0.0, 2.0),
    }
)
"""What ``follow-tune pid --task line_trace`` searches (:mod:`policies.space`): the speed
0.1..0.8 m/s, kp 1..80 rad/s per unit of e (log scale) and kd 0..2 rad per unit of e per s
(linear, so that 0 is in it); ki and the search behaviour stay as preset."""


class PIDLine(LineLaw):
    """The three-sensor PID line follower (module docstring); acts ``[v, w]``.

    :param params: its parameters. :param name: the name in tables and logs.
    """

    action_names = ("v_mps", "w_radps")

    def __init__(self, params: PIDLineParams = PRESETS["hand"], name: str = "pid") -> None:
        self.params = params
        self.name = name
        self.reset()

    def reset(self) -> None:
        """Forget the integral, the last error and the side the line was last seen on."""
        self._integral, self._e_prev, self._e_seen = 0.0, None, 0.0

    def _memory(self) -> tuple[float, float | None, float]:
        return self._integral, self._e_prev, self._e_seen

    def _set_memory(self, memory: tuple[float, float | None, float]) -> None:
        self._integral, self._e_prev, self._e_seen = memory

    def _command(self, readings: np.ndarray) -> tuple[float, float]:
        p = self.params
        left, centre, right = (float(readings[k]) for k in PID_SENSORS)
        total = left + centre + right
        if total < p.lost_sum or total <= 0.0:  # a blank row is lost, with lost_sum 0 too
            self._e_prev = None
            if abs(self._e_seen) < p.centred:
                return p.speed_mps, 0.0  # it was centred: a gap, cross it straight on
            return p.search_speed_mps, p.search_w_radps * float(np.sign(self._e_seen))
        e = (left - right) / total
        self._integral += e * p.dt_s
        rate = 0.0 if self._e_prev is None else (e - self._e_prev) / p.dt_s
        self._e_prev, self._e_seen = e, e
        return p.speed_mps, p.kp * e + p.ki * self._integral + p.kd * rate

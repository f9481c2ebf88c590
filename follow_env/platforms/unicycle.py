"""An ideal unicycle: a body that moves exactly as it is told (no wheels, motors or encoders).

Its action is the body twist ``[v_mps, w_radps]``, clipped to its bounds and applied at once;
the pose advances by ``integration_steps`` explicit Euler steps per control step (reference
§1.1, the same pose equations as the differential drive). The speed "as the robot measures
it" is the true speed.

Two uses:

* a perfect-drive baseline: ``gym.make("PersonFollow-v0", platform="unicycle")`` shows what a
  controller would do if the wheels, PIDs and motors were ideal;
* the world of the robot emulator (``bridge.emulator``): the emulated wheel microcontroller
  runs the differential drive's wheel models in real time, and the emulated world moves the
  body by the twist those wheels really produced over each control step, so the camera, the
  person and the contacts stay the task's own.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from follow_env.platforms import register_platform
from follow_env.platforms.base import (
    ActionField,
    Platform,
    PlatformConfig,
    base_param_fields,
    push_velocity,
)
from follow_env.platforms.diff_drive import euler_pose_step
from follow_env.sim.config import Validated, param
from follow_env.sim.jit import njit
from follow_env.sim.schema import Block, f8, i8

__all__ = ["PLATFORM", "UnicycleBody", "UnicycleConfig", "drive", "reset"]


@dataclass(frozen=True)
class UnicycleBody(Validated):
    """Footprint and speed bounds of the ideal body (defaults: the differential drive's)."""

    footprint_length_m: float = param(
        0.50, 0.05, 3.0, "m", "choice: the differential drive's default footprint"
    )
    footprint_width_m: float = param(
        0.45, 0.05, 3.0, "m", "choice: the differential drive's default footprint"
    )
    max_speed_mps: float = param(
        1.48,
        0.0,
        10.0,
        "m/s",
        "choice: the default differential drive's top speed (wheels at the duty limit)",
        lo_open=True,
    )
    max_turn_rate_radps: float = param(
        7.42,
        0.0,
        50.0,
        "rad/s",
        "choice: the default differential drive's top turn rate",
        lo_open=True,
    )
    integration_steps: int = param(
        10,
        1,
        4096,
        "steps",
        "choice: Euler steps per control step, as many as the differential drive's 10 ms ticks",
        integer=True,
    )


@dataclass(frozen=True)
class UnicycleConfig(PlatformConfig):
    """The ideal unicycle's one section: its body."""

    NAME: ClassVar[str] = "unicycle"

    body: UnicycleBody = field(default_factory=UnicycleBody)

    @property
    def footprint_length_m(self) -> float:
        """Footprint along the heading (m)."""
        return self.body.footprint_length_m

    @property
    def footprint_width_m(self) -> float:
        """Footprint across (m)."""
        return self.body.footprint_width_m

    @property
    def max_speed_mps(self) -> float:
        """Action bound on forward speed (m/s)."""
        return self.body.max_speed_mps

    @property
    def max_turn_rate_radps(self) -> float:
        """Action bound on turn rate (rad/s)."""
        return self.body.max_turn_rate_radps


PARAMS = Block(
    "unicycle_params",
    "the ideal unicycle's parameters",
    [
        *base_param_fields(),
        f8("v_max", "m/s", "forward speed bound", source="platform.max_speed_mps"),
        f8("w_max", "rad/s", "turn rate bound", source="platform.max_turn_rate_radps"),
        i8(
            "steps",
            "steps",
            "Euler steps per control step",
            source="platform.body.integration_steps",
        ),
    ],
)

STATE = Block(
    "unicycle_state",
    "the twist last applied",
    [
        f8("v_cmd", "m/s", "forward speed applied this control step"),
        f8("w_cmd", "rad/s", "turn rate applied this control step"),
    ],
)


@njit(inline="always")
def reset(prm: np.void, st: np.void, body: np.void) -> None:
    """A new episode: at rest (the runner has zeroed the state already)."""


@njit(inline="always")
def drive(
    prm: np.void, st: np.void, body: np.void, action: np.ndarray, keys: np.ndarray, step: int
) -> None:
    """One control step under ``action = [v m/s, w rad/s]``, clipped to the bounds: the body
    takes that twist at once and keeps it for the step (Euler pose steps, reference §1.1)."""
    v = min(max(action[0], -prm.v_max), prm.v_max)
    w = min(max(action[1], -prm.w_max), prm.w_max)
    st.v_cmd, st.w_cmd = v, w
    push_x, push_y = push_velocity(prm.push_p, prm.push_v, keys, step)
    body.push_vx, body.push_vy = push_x, push_y
    dt = prm.dt / prm.steps
    x, y, th = body.x, body.y, body.th
    for _ in range(prm.steps):
        x, y, th = euler_pose_step(x, y, th, v, w, dt)
        x += push_x * dt
        y += push_y * dt
    body.x, body.y, body.th, body.v, body.w = x, y, th, v, w
    body.v_meas_prev = body.v_meas
    body.v_meas = v
    body.accel = (body.v_meas - body.v_meas_prev) / prm.dt


def randomize(
    params: np.ndarray, base: np.void, lanes: np.ndarray, cfg: Any, keys: np.ndarray
) -> None:
    """Nothing to draw: an ideal body has no spread."""


def action_high(cfg: Any) -> np.ndarray:
    """Symmetric action bounds ``[v_max m/s, w_max rad/s]``."""
    return np.array([cfg.platform.max_speed_mps, cfg.platform.max_turn_rate_radps])


PLATFORM = register_platform(
    Platform(
        name="unicycle",
        config=UnicycleConfig,
        params=PARAMS,
        state=STATE,
        actions=(
            ActionField("v_mps", "m/s", "forward speed"),
            ActionField("w_radps", "rad/s", "turn rate, counter-clockwise positive"),
        ),
        module=__name__,
        action_high=action_high,
        randomize=randomize,
        info=(),
        doc="an ideal body that moves exactly as commanded (a perfect-drive baseline)",
    )
)

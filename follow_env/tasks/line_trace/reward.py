"""LineTrace's reward, term by term (weights in ``RewardConfig``; see the env's manual).

Dense, from ground truth, per step::

    r =   progress_weight    * (s - s_prev) / 1 cm              (progress along the line)
        - cross_track_weight * min(|e| / cross_track_scale_m, 1) (e: robot to the line)
        - accel_weight       * |(v, vy) - (v, vy)_prev| / dt     (smoothness)
        - yaw_accel_weight   * |w - w_prev| / dt
        - lost_penalty       * [the line is lost]           (once, at the end)
        - left_field_penalty * [the robot left the field]   (once, at the end)
        + finish_bonus       * [the track's end is reached] (once, at the end)

Each term is kept in the lane's state (``reward_terms``, in :data:`TERMS` order).
"""

from __future__ import annotations

import math

import numpy as np

from follow_env.sim.jit import njit
from follow_env.sim.schema import Block, f8

__all__ = ["PARAMS", "TERMS", "tracing_reward"]

TERMS = ("progress", "cross_track", "accel", "yaw_accel", "lost", "left_field", "finish")
"""The reward's named terms, in the order of the state's ``reward_terms``."""

_CM = 0.01


@njit(inline="always")
def tracing_reward(
    rp: np.void, ts: np.void, body: np.void, ds: float, dt: float, end: int
) -> float:
    """This step's reward for ``ds`` (m) of progress; ``end`` is 0 (running), 1 lost, 2 left
    the field or 3 finished (terms into ``ts.reward_terms``)."""
    terms = ts.reward_terms
    terms[0] = rp.progress_weight * ds / _CM
    terms[1] = rp.cross_track_weight * min(abs(ts.cte) / rp.cross_track_scale, 1.0)
    dv = math.hypot(body.v - ts.prev_v, body.vy - ts.prev_vy)
    terms[2] = rp.accel_weight * dv / dt
    terms[3] = rp.yaw_accel_weight * abs(body.w - ts.prev_w) / dt
    terms[4] = rp.lost_penalty if end == 1 else 0.0
    terms[5] = rp.left_field_penalty if end == 2 else 0.0
    terms[6] = rp.finish_bonus if end == 3 else 0.0
    return terms[0] - terms[1] - terms[2] - terms[3] - terms[4] - terms[5] + terms[6]


def _r(name: str) -> str:
    return f"reward.{name}"


PARAMS = Block(
    "line_reward_params",
    "the reward's weights (RewardConfig)",
    [
        f8("progress_weight", "/cm", "progress along the line", source=_r("progress_weight")),
        f8("cross_track_weight", "/step", "cross-track error", source=_r("cross_track_weight")),
        f8("cross_track_scale", "m", "error at full weight", source=_r("cross_track_scale_m")),
        f8("accel_weight", "/(m/s^2)", "change of (v, vy)", source=_r("accel_weight")),
        f8("yaw_accel_weight", "/(rad/s^2)", "change of w", source=_r("yaw_accel_weight")),
        f8("lost_penalty", "", "once, line lost", source=_r("lost_penalty")),
        f8("left_field_penalty", "", "once, off the field", source=_r("left_field_penalty")),
        f8("finish_bonus", "", "once, at the track's end", source=_r("finish_bonus")),
    ],
)
"""The reward's parameter block."""

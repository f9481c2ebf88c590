"""LineTrace's part of a control step, compiled (the platform's ``drive`` runs before it).

:func:`step` for one lane, after the platform has moved the robot: where the robot is along
the line (progress, cross-track and heading error, from the ground-truth centreline), what the
5 x 5 light-sensor grid reads (:func:`follow_env.sensors.light_grid.read`), whether the line is
lost or the field left, the reward (:mod:`.reward`) and the episode's end. :func:`reset` starts
a lane's episode. The kernel of a (platform, task) pair calls both
(:mod:`follow_env.sim.compose`).
"""

from __future__ import annotations

import math

import numpy as np

from follow_env.sensors.light_grid import read
from follow_env.sim.jit import njit
from follow_env.tasks.line_trace.reward import tracing_reward
from follow_env.tasks.line_trace.spec import (
    REASON_LEFT_FIELD,
    REASON_LOST,
    REASON_NONE,
    REASON_TIME_LIMIT,
    REASON_TRACK_END,
)
from follow_env.world.floor_line import nearest_on_line

__all__ = ["locate", "reset", "step"]


@njit(inline="always")
def locate(prm: np.void, st: np.void, segs: np.ndarray) -> None:
    """The line's point nearest the robot, searched in an arc-length window round the last
    one (``window_back_m`` behind, ``window_ahead_m`` ahead: progress cannot jump to a later
    part of the line that passes close by): progress, signed cross-track error, heading
    error, and whether that point lies in a gap."""
    tp, ts, body = prm.task, st.task, st.body
    j, s, signed = nearest_on_line(
        segs, ts.n_seg, body.x, body.y, ts.s - tp.window_back, ts.s + tp.window_ahead
    )
    if j < 0:
        return
    seg = segs[j]
    ts.seg_i, ts.s, ts.cte = j, s, signed
    err = body.th - math.atan2(seg.y2 - seg.y1, seg.x2 - seg.x1)
    ts.head_err = math.atan2(math.sin(err), math.cos(err))
    ts.in_gap = 1.0 - seg.ink


@njit(inline="always")
def _sense(prm: np.void, st: np.void, segs: np.ndarray, keys: np.ndarray, step: int) -> None:
    tp, ts, body = prm.task, st.task, st.body
    read(tp.sensor, ts.grid, body.x, body.y, body.th, segs, ts.n_seg, tp.half_w, keys, step)


@njit(inline="always")
def reset(prm: np.void, st: np.void, world: tuple, i: int, keys: np.ndarray) -> None:
    """Start lane ``i``'s episode: where the robot is along the line, the first reading (the
    state was zeroed and the line, the field and the start's arc length written by the task)."""
    segs = world[0][i]
    ts, body = st.task, st.body
    locate(prm, st, segs)
    _sense(prm, st, segs, keys, 0)
    ts.prev_v, ts.prev_vy, ts.prev_w = body.v, body.vy, body.w


@njit(inline="always")
def step(prm: np.void, st: np.void, world: tuple, i: int, keys: np.ndarray) -> None:
    """Lane ``i``'s step after the drive: locate, read the grid, loss and field, reward, end.

    Results land in the state: the observation (``task.grid.reading``), the episode's
    ``reward``, ``terminated``, ``truncated`` and ``reason``, and the ground truth.
    """
    segs = world[0][i]
    tp, ts, ep, body = prm.task, st.task, st.episode, st.body
    s_before = ts.s
    locate(prm, st, segs)
    _sense(prm, st, segs, keys, ep.step)
    # Gaps count as line: losing the line means no spot overlaps where the line runs.
    ts.lost_t = 0.0 if ts.grid.seen > 0.0 else ts.lost_t + tp.dt
    m = tp.field_margin
    off = body.x < ts.x0 - m or body.x > ts.x1 + m or body.y < ts.y0 - m or body.y > ts.y1 + m
    reason, term, trunc, end = REASON_NONE, 0.0, 0.0, 0
    if off:
        reason, term, end = REASON_LEFT_FIELD, 1.0, 2
    elif ts.lost_t > tp.lost_timeout + 1e-9:
        reason, term, end = REASON_LOST, 1.0, 1
    elif ts.s >= ts.length - tp.finish_margin:
        # The track's end is the task's goal (reference §2: trace the line to its end), paid
        # by finish_bonus: Gymnasium's terminated, so a learner does not bootstrap past it as
        # it does past the time limit.
        reason, term, end = REASON_TRACK_END, 1.0, 3
    elif ep.step >= tp.max_steps:
        reason, trunc = REASON_TIME_LIMIT, 1.0
    ep.reward = tracing_reward(tp.reward, ts, body, ts.s - s_before, tp.dt, end)
    ts.prev_v, ts.prev_vy, ts.prev_w = body.v, body.vy, body.w
    ep.terminated, ep.truncated, ep.reason = term, trunc, reason

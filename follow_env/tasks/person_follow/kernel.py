"""PersonFollow's part of a control step, compiled (the platform's ``drive`` runs before it).

:func:`step` for one lane, after the platform has moved the robot: the people walk (a social
force keeps them apart), the camera takes its frame (:mod:`.perception`), then contacts, the
reward (:mod:`.reward`) and the episode's end. :func:`reset` starts a lane's episode. The kernel
of a (platform, task) pair calls both (:mod:`follow_env.sim.compose`).
"""

from __future__ import annotations

import numpy as np

from follow_env.sensors.detector import reset as detector_reset
from follow_env.sim.jit import njit
from follow_env.tasks.person_follow.people import person_reset, person_step, social_forces
from follow_env.tasks.person_follow.perception import frame
from follow_env.tasks.person_follow.reward import collision_term, following_reward
from follow_env.tasks.person_follow.spec import (
    REASON_COLLISION_BYSTANDER,
    REASON_COLLISION_PERSON,
    REASON_COLLISION_WALL,
    REASON_LOST,
    REASON_NONE,
    REASON_STEP_LIMIT,
    REASON_WALK_OVER,
)
from follow_env.world.geometry import rect_rect_distance, rect_segment_distance

__all__ = ["contacts", "reset", "step"]


@njit(inline="always")
def contacts(prm: np.void, st: np.void, people: np.ndarray, walls: np.ndarray) -> int:
    """Clearances to walls and people; the collision reason (0 for none)."""
    tp, ts, body = prm.task, st.task, st.body
    x, y, th = body.x, body.y, body.th
    fl, fw = prm.platform.foot_l, prm.platform.foot_w
    wall = np.inf
    for k in range(ts.n_walls):
        w = walls[k]
        wall = min(wall, rect_segment_distance(x, y, th, fl, fw, w.x1, w.y1, w.x2, w.y2))
    # The followed person must stay beyond the clearance; others must not be touched.
    target = np.inf
    other = np.inf
    for p in range(ts.n_people):
        q = people[p]
        d = rect_rect_distance(x, y, th, fl, fw, q.x, q.y, q.th, tp.person_d, tp.person_w)
        if p == 0:
            target = d
        else:
            other = min(other, d)
    ts.clear_wall = wall - tp.wall_radius
    ts.clear_person = target
    ts.clear_other = other
    if ts.clear_wall <= 0.0:
        return REASON_COLLISION_WALL
    if target < tp.clearance:
        return REASON_COLLISION_PERSON
    if other <= 0.0:
        return REASON_COLLISION_BYSTANDER
    return REASON_NONE


@njit(inline="always")
def reset(prm: np.void, st: np.void, world: tuple, i: int, keys: np.ndarray) -> None:
    """Start lane ``i``'s episode: people at the start of their paths, the first frame (the
    state was zeroed and ``n_people``, ``n_walls`` and the paths written by the runner)."""
    people, paths, walls = world
    ts = st.task
    ts.walk_end_t = -1.0
    detector_reset(ts.detector)
    for p in range(ts.n_people):
        person_reset(people[i, p], paths[i, p], ts.n_points[p])
    frame(prm, st, people[i], walls[i], keys, 0)
    contacts(prm, st, people[i], walls[i])


@njit(inline="always")
def step(prm: np.void, st: np.void, world: tuple, i: int, keys: np.ndarray) -> None:
    """Lane ``i``'s step after the drive: people, camera frame, contacts, reward, episode end.

    Results land in the state: the observation (``task.obs_d``, ``task.obs_o``), the
    episode's ``reward``, ``terminated``, ``truncated`` and ``reason``, and the ground truth.
    """
    people, paths, walls = world
    tp, ts, ep = prm.task, st.task, st.episode
    ps = people[i]
    # 3. People walk, keeping out of each other's way.
    if ts.n_people > 1:
        social_forces(ps, ts.n_people, tp.social_radius, tp.social_strength)
    for p in range(ts.n_people):
        person_step(ps[p], paths[i, p], tp.person_accel, tp.person_decel, tp.dt)
    if ts.walk_end_t < 0.0 and ps[0].done > 0.0:
        ts.walk_end_t = ep.t
    # 4. Camera frame and perception (reference §1.4).
    frame(prm, st, ps, walls[i], keys, ep.step)
    # 5. Contacts, reward, episode end.
    reason = contacts(prm, st, ps, walls[i])
    reward = following_reward(tp.reward, ts, st.body.accel, 0.5 * tp.camera.img_w)
    term, trunc = 0.0, 0.0
    if reason != REASON_NONE:
        reward -= collision_term(tp.reward, ts)
        term = 1.0
    elif ts.lost_t > tp.lost_timeout + 1e-9:
        reason, term = REASON_LOST, 1.0
    elif ts.walk_end_t >= 0.0 and ep.t >= ts.walk_end_t + tp.settle - 1e-9:
        reason, trunc = REASON_WALK_OVER, 1.0
    elif ep.step >= tp.max_steps:
        reason, trunc = REASON_STEP_LIMIT, 1.0
    ep.reward, ep.terminated, ep.truncated = reward, term, trunc
    ep.reason = reason

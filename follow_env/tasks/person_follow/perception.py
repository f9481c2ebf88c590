"""The robot's camera node, one frame (reference §1.4): what the perception publishes this step.

Composed from the sensors: every person's body box (camera), the part of it in sight (camera
and world line of sight), the detector's view of it (bursts, misses, jitter, the list order),
the association rule (first detection or tracker), the depth at the chosen box's centre pixel,
the delay line of the detector's latency, and the distance filter. Nothing published leaves the
observation as it was (the guidance law keeps acting on the last values). When configured, the
reading ahead (the nearest depth across the middle row) is published every frame. The frame
also fills the ground truth of the target (person 0).
"""

from __future__ import annotations

import numpy as np

from follow_env.sensors.camera import body_box, camera_origin, sight_box, world_to_camera
from follow_env.sensors.depth import ahead, depth_ray, distance_filter, measure
from follow_env.sensors.detector import (
    associate,
    clip_box,
    consider,
    delay,
    detection,
    no_candidate,
    tracking,
)
from follow_env.sim.jit import njit

__all__ = ["frame"]


@njit(inline="always")
def frame(
    prm: np.void, st: np.void, people: np.ndarray, walls: np.ndarray, keys: np.ndarray, step: int
) -> None:
    """Take a camera frame for one lane (``prm``, ``st``: its parameter and state records;
    ``people`` and ``walls``: its arrays) at control step ``step`` (0 at reset)."""
    tp, ts = prm.task, st.task
    cam, dp, zp = tp.camera, tp.detector, tp.depth
    det, flt = ts.detector, ts.filter
    body = st.body
    W, H = cam.img_w, cam.img_h
    n_people, n_walls = ts.n_people, ts.n_walls
    dims = (tp.person_w, tp.person_d, tp.person_h)
    rx, ry, rth = body.x, body.y, body.th
    c_th, s_th = np.cos(rth), np.sin(rth)
    ox, oy = camera_origin(cam, rx, ry, c_th, s_th)
    pose = (rx, ry, c_th, s_th, ox, oy)
    was_tracking = tracking(dp, det)
    first, reid, match = no_candidate(-1.0), no_candidate(-1.0), no_candidate(dp.trk_iou)
    for p in range(n_people):
        u1, v1, u2, v2, found = body_box(
            people[p].x,
            people[p].y,
            people[p].th,
            tp.person_w,
            tp.person_d,
            tp.person_h,
            rx,
            ry,
            rth,
            cam.R,
            cam.T,
            cam.fx,
            cam.fy,
            cam.cx,
            cam.cy,
            ts.corners,
        )
        visible = False
        frac = 0.0
        c1, c2, c3, c4 = clip_box(u1, v1, u2, v2, W, H)
        if found and c3 > c1 and c4 > c2:
            frac = (c3 - c1) * (c4 - c2) / ((u2 - u1) * (v2 - v1))
            # Obstacles and other people may hide part of the body: keep the box of the part
            # in sight and scale the visible share.
            frac, c1, c2, c3, c4 = sight_box(
                p,
                frac,
                (u1, v1, u2, v2),
                (c1, c2, c3, c4),
                pose,
                cam,
                people,
                n_people,
                walls,
                n_walls,
                dims,
                ts.occluders,
            )
            visible = frac >= dp.min_vis and (c4 - c2) >= dp.min_box_h
        if p == 0:
            ts.in_frame = 1.0 if visible else 0.0
            ts.vis_frac = frac
        seen, j1, j2, j3, j4, area, app = detection(
            dp, det, keys, step, p, visible, (c1, c2, c3, c4), W, H
        )
        if seen:
            first, reid, match = consider(dp, det, p, j1, j2, j3, j4, area, app, first, reid, match)
    chosen = associate(dp, det, was_tracking, first, reid, match)

    # Measurement of this frame: box centre pixel and the depth there (reference §1.4 step 3).
    m_det, m_cu, m_cv, m_raw = 0.0, 0.0, 0.0, 0.0
    if chosen[0] >= 0:
        m_det = 1.0
        cu = min(max(int((chosen[1] + chosen[3]) / 2.0), 0), int(W) - 1)
        cv = min(max(int((chosen[2] + chosen[4]) / 2.0), 0), int(H) - 1)
        m_cu, m_cv = float(cu), float(cv)
        z = depth_ray(cu, cv, cam, ox, oy, c_th, s_th, people, n_people, dims, walls, n_walls)
        m_raw = measure(zp, z, keys, step)

    # Publish what left the delay line this frame, through the distance filter (step 4).
    out = delay(dp, det, step, m_det, m_cu, m_cv, m_raw, chosen)
    ts.detected = det.dl_det[out]
    ts.detected_id = int(det.dl_owner[out])  # whose detection is published (-1: none)
    if det.dl_det[out] > 0.0:
        d, n, h = distance_filter(
            det.dl_raw[out], ts.obs_d, flt.hist, flt.hist_n, flt.hist_head, int(zp.hist_len)
        )
        flt.hist_n, flt.hist_head = n, h
        ts.obs_d = d
        ts.obs_o = det.dl_cu[out] - float(int(W) // 2)  # offset_x = cu - width // 2
        ts.raw_depth = det.dl_raw[out]
        for k in range(4):
            ts.box[k] = det.dl_box[out, k]
        ts.lost_t = 0.0
    elif step > 0:
        ts.lost_t += tp.dt

    # The reading ahead, when configured: this frame's depth image, which needs no detector
    # and so none of its latency; without the columns of the box just published, if asked.
    if zp.ahead_rays > 0.0:
        skip = (1.0, 0.0)  # nothing
        if zp.ahead_skip > 0.0 and ts.detected > 0.0:
            skip = (ts.box[0], ts.box[2])
        ts.obs_ahead = ahead(
            zp, cam, (ox, oy, c_th, s_th), people, n_people, dims, walls, n_walls, keys, step, skip
        )

    # Ground truth of the target (person 0): distance from the camera to the body's centre less
    # half its depth, whichever way it faces (its near face when it faces towards or away from
    # the camera; a side is up to 0.1 m nearer: README, "What the perception model leaves out"),
    # and the pixel column of the body's axis at camera height.
    ts.true_d = np.hypot(people[0].x - ox, people[0].y - oy) - 0.5 * tp.person_d
    xc, _, zc = world_to_camera(
        people[0].x, people[0].y, cam.T[2], rx, ry, c_th, s_th, cam.R, cam.T
    )
    # Beside or behind the camera the offset is capped at one image width, on its side.
    side = W if xc >= 0.0 else -W
    ts.true_o = side
    if zc > 1e-3:
        o = cam.fx * xc / zc + cam.cx - float(int(W) // 2)
        ts.true_o = o if abs(o) < W else side

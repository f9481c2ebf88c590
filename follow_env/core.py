"""The batched simulation core: N lanes of robot, drive, camera, perception and people.

One implementation of every physical model, compiled with numba and looping over lanes, serves
the single environment (N = 1) and the vector environment (N lanes) alike. All state lives in a
few arrays with one row per lane (column names in :mod:`follow_env.layout`); one call of
:func:`step_kernel` advances every lane by one control step:

1. the action ``(v, w)`` goes through inverse kinematics to wheel speed targets (SPEC §1.1);
2. ``sub_steps`` ticks of 10 ms (SPEC §1.1, §1.2): PID on the encoder's speed estimate ->
   duty (clamped to +-99 %) -> motor -> wheel angle -> quantised encoder count and speed, and
   forward kinematics with an Euler pose step;
3. every person walks ``dt`` along their path;
4. the camera takes a frame: body boxes (pinhole, extrinsics), the detector model (visibility,
   bursts, misses, jitter), the first detection, depth at its centre pixel (ray cast, D435i
   noise, invalid pixels), a delay line of ``latency_frames``, and the distance filter
   (SPEC §1.4); nothing published leaves the observation as it was;
5. ground truth, contacts, reward and episode end.

Random draws come from :mod:`follow_env.rng` keyed by the episode's streams and counted by the
step index, so they never depend on the actions.
"""

from __future__ import annotations

import dataclasses
import os
from concurrent.futures import ThreadPoolExecutor

import numpy as np
from numba import njit

from follow_env.camera import NEAR_PLANE_M, Camera, body_box, world_to_camera
from follow_env.config import EnvConfig
from follow_env.drive import lag_factor, wheel_tick
from follow_env.kinematics import diff_drive_fk, diff_drive_ik, euler_pose_step
from follow_env.layout import (
    DL_FIELDS,
    HIST_MAX,
    I_BURST0,
    I_DETECTED_ID,
    I_DL_HEAD,
    I_ENC_L,
    I_ENC_R,
    I_HIST_HEAD,
    I_HIST_N,
    I_N_PEOPLE,
    I_N_WALLS,
    I_REASON,
    I_STEP,
    N_FSTATE,
    N_ISTATE,
    N_PARAMS,
    N_PSTATE,
    N_PW,
    N_SCRATCH,
    P_ANTI_WINDUP,
    P_APP_NOISE,
    P_ASSOC,
    P_BURST_END,
    P_BURST_START,
    P_CLEARANCE,
    P_COUNTS_PER_REV,
    P_CX,
    P_CY,
    P_DEPTH_K,
    P_DEPTH_MAX,
    P_DEPTH_MIN,
    P_DEPTH_UNIT,
    P_DT,
    P_DT_IN,
    P_ENC_NOISE,
    P_FOOT_L,
    P_FOOT_W,
    P_FRIC_DUTY,
    P_FX,
    P_FY,
    P_GAIN_L,
    P_GAIN_R,
    P_HIST_LEN,
    P_IMG_H,
    P_IMG_W,
    P_INVALID_P,
    P_JIT_C,
    P_JIT_S,
    P_KD,
    P_KI,
    P_KP,
    P_LATENCY,
    P_LOST_TIMEOUT,
    P_MAX_DUTY,
    P_MAX_STEPS,
    P_MIN_BOX_H,
    P_MIN_VIS,
    P_MISS_P,
    P_MOTOR_ALPHA,
    P_MOTOR_WMAX,
    P_PERSON_ACC,
    P_PERSON_D,
    P_PERSON_DEC,
    P_PERSON_H,
    P_PERSON_W,
    P_PUSH_P,
    P_PUSH_V,
    P_R00,
    P_R01,
    P_R02,
    P_R10,
    P_R11,
    P_R12,
    P_R20,
    P_R21,
    P_R22,
    P_R_ACC,
    P_R_ALIVE,
    P_R_COLL,
    P_R_DIST,
    P_R_LOST,
    P_R_OFF,
    P_SETTLE,
    P_SOCIAL_K,
    P_SOCIAL_R,
    P_SPEED_Q,
    P_STALL_DUTY,
    P_SUBSTEPS,
    P_TARGET_D,
    P_TAU_D,
    P_TRACK,
    P_TRACK_TRUE,
    P_TRK_APP_GATE,
    P_TRK_COAST,
    P_TRK_IOU,
    P_TX,
    P_TY,
    P_TZ,
    P_V_MAX,
    P_W_MAX,
    P_WALL_R,
    P_WHEEL_R,
    P_WHEEL_R_TRUE,
    PEOPLE_MAX,
    PS_DONE,
    PS_TH,
    PS_X,
    PS_Y,
    REASON_COLLISION_BYSTANDER,
    REASON_COLLISION_PERSON,
    REASON_COLLISION_WALL,
    REASON_LOST,
    REASON_NONE,
    REASON_STEP_LIMIT,
    REASON_WALK_OVER,
    S_ACCEL,
    S_ANG_L,
    S_ANG_R,
    S_BOX_X1,
    S_BOX_X2,
    S_BOX_Y1,
    S_BOX_Y2,
    S_CLEAR_PERSON,
    S_CLEAR_WALL,
    S_D_L,
    S_D_R,
    S_DETECTED,
    S_DL0,
    S_DUTY_L,
    S_DUTY_R,
    S_EPREV_L,
    S_EPREV_R,
    S_HIST0,
    S_IN_FRAME,
    S_INT_L,
    S_INT_R,
    S_LOST_T,
    S_OBS_D,
    S_OBS_O,
    S_OMEGA_L,
    S_OMEGA_R,
    S_PUSH_VX,
    S_PUSH_VY,
    S_RAW_DEPTH,
    S_REWARD,
    S_SCRATCH0,
    S_T,
    S_TERM,
    S_TH,
    S_TRK_APP,
    S_TRK_CX,
    S_TRK_CY,
    S_TRK_H,
    S_TRK_LOST,
    S_TRK_ON,
    S_TRK_VX,
    S_TRK_VY,
    S_TRK_W,
    S_TRUE_D,
    S_TRUE_O,
    S_TRUNC,
    S_V,
    S_VIS_FRAC,
    S_VMEAS_L,
    S_VMEAS_R,
    S_VROBOT_MEAS,
    S_VROBOT_PREV,
    S_VTGT_L,
    S_VTGT_R,
    S_W,
    S_WALK_END_T,
    S_X,
    S_Y,
    W_H,
    W_X1,
    W_X2,
    W_Y1,
    W_Y2,
    WALL_FIELDS,
)
from follow_env.perception import (
    box_iou,
    clip_box,
    depth_noise_std,
    distance_filter,
    jitter_box,
    listed_before,
)
from follow_env.person import person_reset, person_step, social_forces
from follow_env.rng import (
    N_STREAMS,
    STREAM_DEPTH,
    STREAM_DETECTOR,
    STREAM_MOTOR,
    STREAM_PERSON,
    STREAM_RANDOMIZE,
    LaneRandom,
    LaneSeeds,
    normal_pair_at,
    uniform_at,
)
from follow_env.scenarios import SCENARIOS, ScenarioSpec
from follow_env.world import (
    WALL_RADIUS_M,
    point_segment_distance,
    rect_rect_distance,
    rect_segment_distance,
    segment_distance,
)

__all__ = ["BatchedSim", "params_from_config", "reset_kernel", "step_kernel"]

# Counter slots per control step (detector draws of person p at p * 8 + 0..5; depth at 240+).
_SLOTS_PER_STEP = 256
_SLOTS_PER_PERSON = 8
_SLOT_DEPTH = 240
# Body sample points for line of sight: columns across the body, rows up it.
_LOS_COLS = 3
_LOS_ROWS = 5
# Occluders nearer than this (m) to a sight line, beyond the body's half width, are tested.
_LOS_MARGIN_M = 0.1
# Encoder-noise draws: their own key domain, counted by step and 10 ms tick.
_ENC_DOMAIN = np.uint64(0xA0761D6478BD642F)
_MAX_SUBSTEPS = 4096
# Appearance draws (re-identification): their own key domain, one per person index.
_APPEARANCE_DOMAIN = np.uint64(0xE7037ED1A0B428DB)
_TRK_ALPHA_APP = 0.05  # how fast the learnt look follows new views (slowly: no drift)
# Tracker gains: alpha-beta filter on the box centre (and alpha on its size).
_TRK_ALPHA = 0.6
_TRK_BETA = 0.2


def params_from_config(cfg: EnvConfig) -> np.ndarray:
    """The per-lane parameter vector (``P_*`` columns) of a configuration, in SI units."""
    p = np.zeros(N_PARAMS)
    r, m, e, k, c, d = cfg.robot, cfg.motor, cfg.encoder, cfg.pid, cfg.camera, cfg.perception
    cam = Camera.from_config(c)
    p[P_WHEEL_R], p[P_TRACK] = r.wheel_radius_m, r.track_width_m
    p[P_FOOT_L], p[P_FOOT_W] = r.footprint_length_m, r.footprint_width_m
    p[P_MOTOR_WMAX] = m.no_load_speed_radps
    p[P_MOTOR_ALPHA] = lag_factor(m.time_constant_s, e.sample_period_s)
    p[P_FRIC_DUTY], p[P_STALL_DUTY], p[P_MAX_DUTY] = (
        m.friction_duty_pct,
        m.stall_duty_pct,
        m.max_duty_pct,
    )
    p[P_GAIN_R] = p[P_GAIN_L] = 1.0
    p[P_COUNTS_PER_REV], p[P_DT_IN] = e.counts_per_rev, e.sample_period_s
    p[P_SPEED_Q], p[P_SUBSTEPS] = e.speed_quantum_mps, cfg.sub_steps
    p[P_KP], p[P_KI], p[P_KD], p[P_TAU_D] = k.kp, k.ki, k.kd, k.tau_s
    p[P_ANTI_WINDUP] = 1.0 if k.anti_windup == "clamp" else 0.0
    p[P_IMG_W], p[P_IMG_H] = c.width_px, c.height_px
    p[P_FX], p[P_FY], p[P_CX], p[P_CY] = cam.fx, cam.fy, cam.cx, cam.cy
    p[P_R00 : P_R22 + 1] = cam.R.ravel()
    p[P_TX : P_TZ + 1] = cam.T
    p[P_DEPTH_MIN], p[P_DEPTH_MAX] = c.depth_min_m, c.depth_max_m
    p[P_DEPTH_K] = depth_noise_std(1.0, c.depth_subpixel, c.depth_focal_px, c.depth_baseline_m)
    p[P_DEPTH_UNIT], p[P_INVALID_P] = c.depth_unit_m, c.depth_invalid_prob
    p[P_LATENCY], p[P_MISS_P] = d.latency_frames, d.miss_prob
    p[P_BURST_START], p[P_BURST_END] = d.burst_start_prob, 1.0 / d.burst_mean_frames
    p[P_JIT_C], p[P_JIT_S] = d.center_jitter_frac, d.size_jitter_frac
    p[P_MIN_VIS], p[P_MIN_BOX_H], p[P_HIST_LEN] = (
        d.min_visible_fraction,
        d.min_box_height_px,
        d.filter_history,
    )
    pe = cfg.person
    p[P_PERSON_H], p[P_PERSON_W], p[P_PERSON_D] = pe.height_m, pe.width_m, pe.depth_m
    p[P_PERSON_ACC], p[P_PERSON_DEC] = pe.accel_mps2, pe.decel_mps2
    w = cfg.reward
    p[P_TARGET_D], p[P_R_ALIVE], p[P_R_DIST] = (
        w.target_distance_m,
        w.alive_bonus,
        w.distance_weight,
    )
    p[P_R_OFF], p[P_R_ACC], p[P_R_LOST], p[P_R_COLL] = (
        w.offset_weight,
        w.accel_weight,
        w.lost_penalty,
        w.collision_penalty,
    )
    ep = cfg.episode
    p[P_DT], p[P_MAX_STEPS], p[P_LOST_TIMEOUT] = ep.control_dt_s, ep.max_steps, ep.lost_timeout_s
    p[P_CLEARANCE], p[P_SETTLE] = ep.person_clearance_m, cfg.scenario.settle_s
    p[P_WALL_R] = WALL_RADIUS_M
    p[P_V_MAX], p[P_W_MAX] = cfg.max_speed_mps, cfg.max_turn_rate_radps
    p[P_WHEEL_R_TRUE], p[P_TRACK_TRUE] = r.wheel_radius_m, r.track_width_m
    rnd = cfg.randomization
    p[P_ENC_NOISE], p[P_PUSH_P], p[P_PUSH_V] = (
        rnd.encoder_noise_counts,
        rnd.push_prob,
        rnd.push_speed_mps,
    )
    p[P_ASSOC] = 1.0 if d.association == "tracker" else 0.0
    p[P_TRK_IOU], p[P_TRK_COAST] = d.tracker_iou_gate, d.tracker_coast_frames
    p[P_TRK_APP_GATE], p[P_APP_NOISE] = d.tracker_appearance_gate, d.appearance_noise
    p[P_SOCIAL_R], p[P_SOCIAL_K] = pe.social_radius_m, pe.social_strength_mps2
    return p


# ----------------------------------------------------------------------------------------------
# Camera frame: depth ray cast, detection, ground truth
# ----------------------------------------------------------------------------------------------


@njit(cache=True, inline="always")
def _cross_wall(
    ox: float, oy: float, dx: float, dy: float, walls: np.ndarray, k: int
) -> tuple[float, float]:
    """Where the line ``o + t d`` crosses the line of wall k (seen from above): ``t`` along
    ``d`` and ``u`` along the wall (0..1 between its ends); ``t = inf`` when they are parallel.
    """
    ex, ey = walls[k, W_X2] - walls[k, W_X1], walls[k, W_Y2] - walls[k, W_Y1]
    den = dx * ey - dy * ex
    if abs(den) < 1e-12:
        return np.inf, 0.0
    ax, ay = walls[k, W_X1] - ox, walls[k, W_Y1] - oy
    return (ax * ey - ay * ex) / den, (ax * dy - ay * dx) / den


@njit(cache=True, inline="always")
def _depth_ray(
    cu: int,
    cv: int,
    prm: np.ndarray,
    ox: float,
    oy: float,
    c: float,
    s: float,
    ps: np.ndarray,
    n_people: int,
    walls: np.ndarray,
    n_walls: int,
) -> float:
    """True depth Zc (m) seen at pixel (cu, cv) by a camera at (ox, oy) on a robot heading
    th (``c, s = cos th, sin th``): the nearest of people, walls and floor along the pixel's
    ray (SPEC §1.3 back-projection); ``inf`` if the ray hits nothing."""
    dcx = (cu - prm[P_CX]) / prm[P_FX]
    dcy = (cv - prm[P_CY]) / prm[P_FY]
    # Direction in the robot frame (R d_c with d_c = (dcx, dcy, 1)), so the ray parameter t
    # is the camera-frame depth Zc.
    drx = prm[P_R00] * dcx + prm[P_R01] * dcy + prm[P_R02]
    dry = prm[P_R10] * dcx + prm[P_R11] * dcy + prm[P_R12]
    drz = prm[P_R20] * dcx + prm[P_R21] * dcy + prm[P_R22]
    dwx, dwy, dwz = c * drx - s * dry, s * drx + c * dry, drz
    oz = prm[P_TZ]
    best = np.inf
    if dwz < -1e-12:  # the floor
        best = -oz / dwz
    for k in range(n_walls):
        t, u = _cross_wall(ox, oy, dwx, dwy, walls, k)
        if 0.0 < t < best and 0.0 <= u <= 1.0 and oz + t * dwz <= walls[k, W_H]:
            best = t
    hd, hw, hh = 0.5 * prm[P_PERSON_D], 0.5 * prm[P_PERSON_W], prm[P_PERSON_H]
    for p in range(n_people):
        pc, pss = np.cos(ps[p, PS_TH]), np.sin(ps[p, PS_TH])
        qx = pc * (ox - ps[p, PS_X]) + pss * (oy - ps[p, PS_Y])
        qy = -pss * (ox - ps[p, PS_X]) + pc * (oy - ps[p, PS_Y])
        ex = pc * dwx + pss * dwy
        ey = -pss * dwx + pc * dwy
        # Slab test against the upright box |x| <= hd, |y| <= hw, 0 <= z <= hh.
        tmin, tmax = 0.0, best
        hit = True
        for axis in range(3):
            if axis == 0:
                o, dd, lo, hi = qx, ex, -hd, hd
            elif axis == 1:
                o, dd, lo, hi = qy, ey, -hw, hw
            else:
                o, dd, lo, hi = oz, dwz, 0.0, hh
            if abs(dd) < 1e-12:
                if o < lo or o > hi:
                    hit = False
                    break
            else:
                t1, t2 = (lo - o) / dd, (hi - o) / dd
                if t1 > t2:
                    t1, t2 = t2, t1
                tmin, tmax = max(tmin, t1), min(tmax, t2)
                if tmin > tmax:
                    hit = False
                    break
        if hit and tmin > 0.0 and tmin < best:
            best = tmin
    return best


@njit(cache=True, inline="always")
def _sight_blocked(
    ox: float,
    oy: float,
    oz: float,
    sx: float,
    sy: float,
    sz: float,
    scratch: np.ndarray,
    n_cand: int,
    walls: np.ndarray,
    ps: np.ndarray,
    radius: float,
    height: float,
) -> bool:
    """Is the sight line from the camera (ox, oy, oz) to the point (sx, sy, sz) cut by one of
    the candidate occluders listed in ``scratch[24:24 + n_cand]`` (wall k as k, person q as
    -(q + 1))? Walls are vertical strips up to their height, people upright cylinders."""
    dx, dy, dz = sx - ox, sy - oy, sz - oz
    for j in range(n_cand):
        k = int(scratch[24 + j])
        if k >= 0:
            t, u = _cross_wall(ox, oy, dx, dy, walls, k)
            if 0.0 < t < 1.0 and 0.0 <= u <= 1.0 and oz + t * dz < walls[k, W_H]:
                return True
        else:
            q = -k - 1
            qx, qy = ps[q, PS_X] - ox, ps[q, PS_Y] - oy
            t = (qx * dx + qy * dy) / (dx * dx + dy * dy)
            if 0.0 < t < 1.0:
                ex, ey = t * dx - qx, t * dy - qy
                if ex * ex + ey * ey < radius * radius and oz + t * dz < height:
                    return True
    return False


@njit(cache=True, inline="always")
def _sight_box(
    p: int,
    frac: float,
    u1: float,
    v1: float,
    u2: float,
    v2: float,
    c1: float,
    c2: float,
    c3: float,
    c4: float,
    ox: float,
    oy: float,
    prm: np.ndarray,
    ps: np.ndarray,
    n_people: int,
    walls: np.ndarray,
    n_walls: int,
    c_th: float,
    s_th: float,
    rx: float,
    ry: float,
    scratch: np.ndarray,
) -> tuple[float, float, float, float, float]:
    """Line of sight from the camera to person ``p``: the visible share and the box of the
    part in sight.

    Occluders near the sight line to the body (walls and obstacles, other people) are listed
    first; with none, the body is in plain sight and nothing changes. Otherwise a grid of
    _LOS_COLS x _LOS_ROWS points on the body's near face, each standing for its cell of the
    projected box, is tested: the visible share scales by the in-sight share of the points
    inside the image, and the box shrinks to the cells in sight (a partly hidden person gives
    the box of the visible part; a fully hidden one is not seen).
    """
    px, py = ps[p, PS_X], ps[p, PS_Y]
    dx, dy = px - ox, py - oy
    dist = np.sqrt(dx * dx + dy * dy)
    if dist < 1e-6:
        return frac, c1, c2, c3, c4
    half_w, height = 0.5 * prm[P_PERSON_W], prm[P_PERSON_H]
    reach = half_w + _LOS_MARGIN_M
    n_cand = 0
    # Bounding box of the sight line, grown by the reach: walls outside it cannot be near.
    bx1, bx2 = min(ox, px) - reach, max(ox, px) + reach
    by1, by2 = min(oy, py) - reach, max(oy, py) + reach
    for k in range(n_walls):
        if (
            max(walls[k, W_X1], walls[k, W_X2]) < bx1
            or min(walls[k, W_X1], walls[k, W_X2]) > bx2
            or max(walls[k, W_Y1], walls[k, W_Y2]) < by1
            or min(walls[k, W_Y1], walls[k, W_Y2]) > by2
        ):
            continue
        if (
            n_cand < N_SCRATCH - 24
            and segment_distance(
                ox, oy, px, py, walls[k, W_X1], walls[k, W_Y1], walls[k, W_X2], walls[k, W_Y2]
            )
            < reach
        ):
            scratch[24 + n_cand] = k
            n_cand += 1
    for q in range(n_people):
        if q != p and n_cand < N_SCRATCH - 24:
            d = point_segment_distance(ps[q, PS_X], ps[q, PS_Y], ox, oy, px, py)
            if d < reach + half_w:
                scratch[24 + n_cand] = -(q + 1)
                n_cand += 1
    if n_cand == 0:
        return frac, c1, c2, c3, c4
    ux, uy = dx / dist, dy / dist
    nx, ny = px - ux * 0.5 * prm[P_PERSON_D], py - uy * 0.5 * prm[P_PERSON_D]  # near face
    oz = prm[P_TZ]
    W, H = prm[P_IMG_W], prm[P_IMG_H]
    n_img, n_vis = 0, 0
    su1, sv1, su2, sv2 = np.inf, np.inf, -np.inf, -np.inf
    for ci in range(_LOS_COLS):
        off = ((ci + 0.5) / _LOS_COLS - 0.5) * 2.0 * half_w
        sx, sy = nx - uy * off, ny + ux * off
        for ri in range(_LOS_ROWS):
            sz = (ri + 0.5) / _LOS_ROWS * height
            xc, yc, zc = world_to_camera(sx, sy, sz, rx, ry, c_th, s_th, prm, P_R00)
            if zc <= NEAR_PLANE_M:
                continue
            su = prm[P_FX] * xc / zc + prm[P_CX]
            sv = prm[P_FY] * yc / zc + prm[P_CY]
            if su < 0.0 or su >= W or sv < 0.0 or sv >= H:
                continue
            n_img += 1
            if _sight_blocked(ox, oy, oz, sx, sy, sz, scratch, n_cand, walls, ps, half_w, height):
                continue
            n_vis += 1
            su1, sv1, su2, sv2 = min(su1, su), min(sv1, sv), max(su2, su), max(sv2, sv)
    if n_img == 0 or n_vis == n_img:
        return frac, c1, c2, c3, c4
    if n_vis == 0:
        return 0.0, c1, c2, c3, c4
    cw, ch = 0.5 * (u2 - u1) / _LOS_COLS, 0.5 * (v2 - v1) / _LOS_ROWS
    return (
        frac * n_vis / n_img,
        max(c1, su1 - cw),
        max(c2, sv1 - ch),
        min(c3, su2 + cw),
        min(c4, sv2 + ch),
    )


@njit(cache=True, inline="always")
def _track_update(
    fs: np.ndarray, b1: float, b2: float, b3: float, b4: float, matched: bool
) -> None:
    """The tracker takes a detection: an alpha-beta (constant-velocity) filter on the box
    centre (px/frame) and a smoothed size when it matched its track; a fresh track else."""
    cu, cv, w, h = 0.5 * (b1 + b3), 0.5 * (b2 + b4), b3 - b1, b4 - b2
    if matched:
        pu, pv = fs[S_TRK_CX] + fs[S_TRK_VX], fs[S_TRK_CY] + fs[S_TRK_VY]
        ru, rv = cu - pu, cv - pv
        fs[S_TRK_CX], fs[S_TRK_CY] = pu + _TRK_ALPHA * ru, pv + _TRK_ALPHA * rv
        fs[S_TRK_VX] += _TRK_BETA * ru
        fs[S_TRK_VY] += _TRK_BETA * rv
        fs[S_TRK_W] += _TRK_ALPHA * (w - fs[S_TRK_W])
        fs[S_TRK_H] += _TRK_ALPHA * (h - fs[S_TRK_H])
    else:
        fs[S_TRK_CX], fs[S_TRK_CY], fs[S_TRK_W], fs[S_TRK_H] = cu, cv, w, h
        fs[S_TRK_VX] = fs[S_TRK_VY] = 0.0
    fs[S_TRK_LOST] = 0.0
    fs[S_TRK_ON] = 1.0


@njit(cache=True, inline="always")
def _frame(
    i: int,
    prm: np.ndarray,
    fs: np.ndarray,
    ist: np.ndarray,
    ps: np.ndarray,
    walls: np.ndarray,
    keys: np.ndarray,
    step: int,
) -> None:
    """Take a camera frame: detect, pick the first detection, read depth, push it through the
    delay line and the distance filter, and publish (SPEC §1.4). Also fills the ground truth."""
    W, H = prm[P_IMG_W], prm[P_IMG_H]
    fx, fy, cx, cy = prm[P_FX], prm[P_FY], prm[P_CX], prm[P_CY]
    n_people = ist[I_N_PEOPLE]
    rx, ry, rth = fs[S_X], fs[S_Y], fs[S_TH]
    kdet = keys[STREAM_DETECTOR]
    base = step * _SLOTS_PER_STEP
    # The detector's list is walked as it is produced: the first listed detection is kept
    # (SPEC §1.4 step 2, order as in perception.first_detection), and so is the one that best
    # overlaps the tracker's predicted box.
    first, b1, b2, b3, b4, best_area = -1, 0.0, 0.0, 0.0, 0.0, -1.0
    tracking = prm[P_ASSOC] > 0.0 and fs[S_TRK_ON] > 0.0
    t_cx, t_cy = fs[S_TRK_CX] + fs[S_TRK_VX], fs[S_TRK_CY] + fs[S_TRK_VY]
    t_hw, t_hh = 0.5 * fs[S_TRK_W], 0.5 * fs[S_TRK_H]
    match, m1, m2, m3, m4, best_iou = -1, 0.0, 0.0, 0.0, 0.0, prm[P_TRK_IOU]
    # Re-identification: once the target's appearance is known the tracker only takes
    # detections that look like it; the best-listed such one when no track is running.
    known = prm[P_ASSOC] > 0.0 and fs[S_TRK_APP] >= 0.0
    reid, r1, r2, r3, r4, reid_area, reid_app = -1, 0.0, 0.0, 0.0, 0.0, -1.0, 0.0
    first_app = 0.0
    m_app = 0.0
    k_app = keys[STREAM_DETECTOR] ^ _APPEARANCE_DOMAIN
    c_th, s_th = np.cos(rth), np.sin(rth)
    ox = rx + c_th * prm[P_TX] - s_th * prm[P_TY]
    oy = ry + s_th * prm[P_TX] + c_th * prm[P_TY]
    scratch = fs[S_SCRATCH0 : S_SCRATCH0 + N_SCRATCH]
    for p in range(n_people):
        u1, v1, u2, v2, found = body_box(
            ps[p, PS_X],
            ps[p, PS_Y],
            ps[p, PS_TH],
            prm[P_PERSON_W],
            prm[P_PERSON_D],
            prm[P_PERSON_H],
            rx,
            ry,
            rth,
            prm,
            P_R00,
            fx,
            fy,
            cx,
            cy,
            scratch,
        )
        visible = False
        frac = 0.0
        c1, c2, c3, c4 = clip_box(u1, v1, u2, v2, W, H)
        if found and c3 > c1 and c4 > c2:
            frac = (c3 - c1) * (c4 - c2) / ((u2 - u1) * (v2 - v1))
            # Obstacles and other people may hide part of the body: keep the box of the
            # part in sight and scale the visible share (line of sight, see _sight_box).
            frac, c1, c2, c3, c4 = _sight_box(
                p,
                frac,
                u1,
                v1,
                u2,
                v2,
                c1,
                c2,
                c3,
                c4,
                ox,
                oy,
                prm,
                ps,
                n_people,
                walls,
                ist[I_N_WALLS],
                c_th,
                s_th,
                rx,
                ry,
                scratch,
            )
            visible = frac >= prm[P_MIN_VIS] and (c4 - c2) >= prm[P_MIN_BOX_H]
        if p == 0:
            fs[S_IN_FRAME] = 1.0 if visible else 0.0
            fs[S_VIS_FRAC] = frac
        # Bursts of occlusion: a two-state Markov chain per person, stepped every frame.
        slot = base + p * _SLOTS_PER_PERSON
        u_burst = uniform_at(kdet, slot)
        if ist[I_BURST0 + p] != 0:
            if u_burst < prm[P_BURST_END]:
                ist[I_BURST0 + p] = 0
        elif u_burst < prm[P_BURST_START]:
            ist[I_BURST0 + p] = 1
        if visible and ist[I_BURST0 + p] == 0 and uniform_at(kdet, slot + 1) >= prm[P_MISS_P]:
            z_cu, z_cv = normal_pair_at(kdet, slot + 2)
            z_w, z_h = normal_pair_at(kdet, slot + 3)
            j1, j2, j3, j4 = jitter_box(
                c1, c2, c3, c4, z_cu, z_cv, z_w, z_h, prm[P_JIT_C], prm[P_JIT_S]
            )
            j1, j2, j3, j4 = clip_box(j1, j2, j3, j4, W, H)
            if j3 > j1 and j4 > j2:
                area = (j3 - j1) * (j4 - j2)
                # What a re-identification network would see: the person's own appearance
                # (one number per person and episode) plus noise.
                app = 0.0
                if prm[P_ASSOC] > 0.0:
                    z_app = normal_pair_at(kdet, slot + 4)[0]
                    app = uniform_at(k_app, p) + prm[P_APP_NOISE] * z_app
                if listed_before(area, best_area):
                    first, b1, b2, b3, b4, best_area, first_app = p, j1, j2, j3, j4, area, app
                alike = not known or abs(app - fs[S_TRK_APP]) < prm[P_TRK_APP_GATE]
                if alike and listed_before(area, reid_area):
                    reid, r1, r2, r3, r4, reid_area, reid_app = p, j1, j2, j3, j4, area, app
                if tracking and alike:
                    iou = box_iou(
                        j1, j2, j3, j4, t_cx - t_hw, t_cy - t_hh, t_cx + t_hw, t_cy + t_hh
                    )
                    if iou >= best_iou:
                        match, m1, m2, m3, m4, best_iou, m_app = p, j1, j2, j3, j4, iou, app

    if prm[P_ASSOC] > 0.0:
        # Tracker: follow the matched detection; without one, coast on the prediction for a
        # while and publish nothing; with no track, take the best-listed detection that looks
        # like the target (the first detection before the target's look is known).
        if tracking and match >= 0:
            first, b1, b2, b3, b4, first_app = match, m1, m2, m3, m4, m_app
        elif tracking and fs[S_TRK_LOST] < prm[P_TRK_COAST]:
            first = -1
        else:
            first, b1, b2, b3, b4, first_app = reid, r1, r2, r3, r4, reid_app
        if first >= 0:
            _track_update(fs, b1, b2, b3, b4, tracking and match >= 0)
            # The target's look: learnt from the first track, refined while matched.
            if fs[S_TRK_APP] < 0.0:
                fs[S_TRK_APP] = first_app
            else:
                fs[S_TRK_APP] += _TRK_ALPHA_APP * (first_app - fs[S_TRK_APP])
        elif fs[S_TRK_ON] > 0.0:
            fs[S_TRK_LOST] += 1.0
            fs[S_TRK_CX] += fs[S_TRK_VX]
            fs[S_TRK_CY] += fs[S_TRK_VY]
            if fs[S_TRK_LOST] > prm[P_TRK_COAST]:
                fs[S_TRK_ON] = 0.0

    # Measurement of this frame: box centre pixel and the depth there (SPEC §1.4 step 3).
    m_det, m_cu, m_cv, m_raw = 0.0, 0.0, 0.0, 0.0
    if first >= 0:
        m_det = 1.0
        cu = min(max(int((b1 + b3) / 2.0), 0), int(W) - 1)
        cv = min(max(int((b2 + b4) / 2.0), 0), int(H) - 1)
        m_cu, m_cv = float(cu), float(cv)
        z = _depth_ray(cu, cv, prm, ox, oy, c_th, s_th, ps, n_people, walls, ist[I_N_WALLS])
        kd = keys[STREAM_DEPTH]
        dslot = base + _SLOT_DEPTH
        if z < prm[P_DEPTH_MIN] or z > prm[P_DEPTH_MAX]:
            z = 0.0
        else:
            z += normal_pair_at(kd, dslot)[0] * prm[P_DEPTH_K] * z * z  # RMS ~ Z^2 (SPEC §1.3)
            if prm[P_DEPTH_UNIT] > 0.0:
                z = np.round(z / prm[P_DEPTH_UNIT]) * prm[P_DEPTH_UNIT]
            invalid = uniform_at(kd, dslot + 1) < prm[P_INVALID_P]
            if invalid or z < prm[P_DEPTH_MIN] or z > prm[P_DEPTH_MAX]:
                z = 0.0  # out of range reads as invalid too, as on the camera
        m_raw = z

    # Delay line of latency_frames: write this frame, publish the one latency frames old.
    size = int(prm[P_LATENCY]) + 1
    head = (ist[I_DL_HEAD] + 1) % size
    if step == 0:  # reset: as if the robot had stood still for the whole delay
        for k in range(size):
            _write_slot(fs, k, m_det, m_cu, m_cv, m_raw, b1, b2, b3, b4, first)
        head = 0
    else:
        _write_slot(fs, head, m_det, m_cu, m_cv, m_raw, b1, b2, b3, b4, first)
    ist[I_DL_HEAD] = head
    out = S_DL0 + ((head + 1) % size) * DL_FIELDS
    fs[S_DETECTED] = fs[out]
    ist[I_DETECTED_ID] = int(fs[out + 8])  # whose detection is published (-1: none)
    if fs[out] > 0.0:
        d, n, h = distance_filter(
            fs[out + 3],
            fs[S_OBS_D],
            fs[S_HIST0 : S_HIST0 + HIST_MAX],
            ist[I_HIST_N],
            ist[I_HIST_HEAD],
            int(prm[P_HIST_LEN]),
        )
        ist[I_HIST_N], ist[I_HIST_HEAD] = n, h
        fs[S_OBS_D] = d
        fs[S_OBS_O] = fs[out + 1] - float(int(W) // 2)  # offset_x = cu - width // 2
        fs[S_RAW_DEPTH] = fs[out + 3]
        fs[S_BOX_X1], fs[S_BOX_Y1] = fs[out + 4], fs[out + 5]
        fs[S_BOX_X2], fs[S_BOX_Y2] = fs[out + 6], fs[out + 7]
        fs[S_LOST_T] = 0.0
    elif step > 0:
        fs[S_LOST_T] += prm[P_DT]

    # Ground truth of the target (person 0): distance from the camera to the body's front,
    # and the pixel column of the body's axis at camera height.
    fs[S_TRUE_D] = np.hypot(ps[0, PS_X] - ox, ps[0, PS_Y] - oy) - 0.5 * prm[P_PERSON_D]
    xc, _, zc = world_to_camera(ps[0, PS_X], ps[0, PS_Y], prm[P_TZ], rx, ry, c_th, s_th, prm, P_R00)
    # Beside or behind the camera the offset is capped at one image width, on its side.
    side = W if xc >= 0.0 else -W
    fs[S_TRUE_O] = side
    if zc > 1e-3:
        o = fx * xc / zc + cx - float(int(W) // 2)
        fs[S_TRUE_O] = o if abs(o) < W else side


@njit(cache=True, inline="always")
def _write_slot(
    fs: np.ndarray,
    k: int,
    det: float,
    cu: float,
    cv: float,
    raw: float,
    u1: float,
    v1: float,
    u2: float,
    v2: float,
    owner: int,
) -> None:
    o = S_DL0 + k * DL_FIELDS
    fs[o], fs[o + 1], fs[o + 2], fs[o + 3] = det, cu, cv, raw
    fs[o + 4], fs[o + 5], fs[o + 6], fs[o + 7] = u1, v1, u2, v2
    fs[o + 8] = owner


@njit(cache=True, inline="always")
def _contacts(
    prm: np.ndarray, fs: np.ndarray, ist: np.ndarray, ps: np.ndarray, walls: np.ndarray
) -> int:
    """Clearances to walls and people; the collision reason (0 for none)."""
    x, y, th = fs[S_X], fs[S_Y], fs[S_TH]
    fl, fw = prm[P_FOOT_L], prm[P_FOOT_W]
    wall = np.inf
    for k in range(ist[I_N_WALLS]):
        wall = min(
            wall,
            rect_segment_distance(
                x, y, th, fl, fw, walls[k, 0], walls[k, 1], walls[k, 2], walls[k, 3]
            ),
        )
    # The followed person must stay beyond the clearance; others must not be touched.
    target = np.inf
    other = np.inf
    for p in range(ist[I_N_PEOPLE]):
        d = rect_rect_distance(
            x,
            y,
            th,
            fl,
            fw,
            ps[p, PS_X],
            ps[p, PS_Y],
            ps[p, PS_TH],
            prm[P_PERSON_D],
            prm[P_PERSON_W],
        )
        if p == 0:
            target = d
        else:
            other = min(other, d)
    fs[S_CLEAR_WALL] = wall - prm[P_WALL_R]
    fs[S_CLEAR_PERSON] = target
    if fs[S_CLEAR_WALL] <= 0.0:
        return REASON_COLLISION_WALL
    if target < prm[P_CLEARANCE]:
        return REASON_COLLISION_PERSON
    if other <= 0.0:
        return REASON_COLLISION_BYSTANDER
    return REASON_NONE


# ----------------------------------------------------------------------------------------------
# Kernels
# ----------------------------------------------------------------------------------------------


@njit(cache=True)
def reset_kernel(
    lanes: np.ndarray,
    pose: np.ndarray,
    n_points: np.ndarray,
    n_people: np.ndarray,
    n_walls: np.ndarray,
    params: np.ndarray,
    fstate: np.ndarray,
    istate: np.ndarray,
    pstate: np.ndarray,
    paths: np.ndarray,
    walls: np.ndarray,
    keys: np.ndarray,
) -> None:
    """Start a new episode on ``lanes`` (paths, walls, keys and params already written)."""
    for j in range(lanes.shape[0]):
        i = lanes[j]
        fs, ist = fstate[i], istate[i]
        fs[:] = 0.0
        ist[:] = 0
        fs[S_X], fs[S_Y], fs[S_TH] = pose[j, 0], pose[j, 1], pose[j, 2]
        fs[S_WALK_END_T] = -1.0
        fs[S_TRK_APP] = -1.0  # the target's look is not known yet
        ist[I_N_PEOPLE], ist[I_N_WALLS] = n_people[j], n_walls[j]
        for p in range(n_people[j]):
            person_reset(pstate[i, p], paths[i, p], n_points[j, p])
        _frame(i, params[i], fs, ist, pstate[i], walls[i], keys[i], 0)
        _contacts(params[i], fs, ist, pstate[i], walls[i])


def _step_lanes(
    params: np.ndarray,
    fstate: np.ndarray,
    istate: np.ndarray,
    pstate: np.ndarray,
    paths: np.ndarray,
    walls: np.ndarray,
    keys: np.ndarray,
    actions: np.ndarray,
    active: np.ndarray,
) -> None:
    """Advance every active lane by one control step under ``actions`` (N, 2): ``v`` m/s,
    ``w`` rad/s. Lanes whose ``active`` flag is False are left untouched.

    Results land in the state arrays: observation ``S_OBS_D``/``S_OBS_O``, ``S_REWARD``,
    ``S_TERM``/``S_TRUNC`` and ``I_REASON``, plus the ground truth for ``info``. Lanes share
    nothing, so disjoint blocks of lanes may be stepped on different threads.
    """
    for i in range(fstate.shape[0]):
        if not active[i]:
            continue
        prm, fs, ist, ps = params[i], fstate[i], istate[i], pstate[i]
        dt = prm[P_DT]
        ist[I_STEP] += 1
        fs[S_T] += dt
        # 1. Action -> wheel targets by inverse kinematics (SPEC §1.1), as linear wheel speeds.
        v_cmd = min(max(actions[i, 0], -prm[P_V_MAX]), prm[P_V_MAX])
        w_cmd = min(max(actions[i, 1], -prm[P_W_MAX]), prm[P_W_MAX])
        r, L = prm[P_WHEEL_R], prm[P_TRACK]
        w_r, w_l = diff_drive_ik(v_cmd, w_cmd, r, L)
        fs[S_VTGT_R], fs[S_VTGT_L] = w_r * r, w_l * r
        # 2. Inner drive loop (SPEC §1.1, §1.2), on local copies of the wheel state.
        dt_in = prm[P_DT_IN]
        cpr, diam, quantum = prm[P_COUNTS_PER_REV], 2.0 * r, prm[P_SPEED_Q]
        kp, ki, kd, tau, max_duty = prm[P_KP], prm[P_KI], prm[P_KD], prm[P_TAU_D], prm[P_MAX_DUTY]
        aw = prm[P_ANTI_WINDUP] > 0.0
        w_max, alpha = prm[P_MOTOR_WMAX], prm[P_MOTOR_ALPHA]
        fric, stall = prm[P_FRIC_DUTY], prm[P_STALL_DUTY]
        # The constants of every wheel tick, in drive.wheel_tick's order.
        drive = (
            kp,
            ki,
            kd,
            tau,
            dt_in,
            max_duty,
            aw,
            w_max,
            alpha,
            fric,
            stall,
            cpr,
            diam,
            quantum,
        )
        g_r, g_l = prm[P_GAIN_R], prm[P_GAIN_L]
        t_r, t_l = fs[S_VTGT_R], fs[S_VTGT_L]
        m_r, m_l = fs[S_VMEAS_R], fs[S_VMEAS_L]
        e_r, e_l = fs[S_EPREV_R], fs[S_EPREV_L]
        i_r, i_l = fs[S_INT_R], fs[S_INT_L]
        d_r, d_l = fs[S_D_R], fs[S_D_L]
        u_r, u_l = fs[S_DUTY_R], fs[S_DUTY_L]
        o_r, o_l = fs[S_OMEGA_R], fs[S_OMEGA_L]
        a_r, a_l = fs[S_ANG_R], fs[S_ANG_L]
        c_r, c_l = ist[I_ENC_R], ist[I_ENC_L]
        x, y, th, v, w = fs[S_X], fs[S_Y], fs[S_TH], fs[S_V], fs[S_W]
        # Real wheels and track may differ from what the controller assumes (randomisation).
        r_true, L_true = prm[P_WHEEL_R_TRUE], prm[P_TRACK_TRUE]
        enc_noise = prm[P_ENC_NOISE]
        krand = keys[i, STREAM_RANDOMIZE]
        step_no = ist[I_STEP]
        # A push (randomisation): the robot is shoved at push speed for this control step.
        push_x, push_y = 0.0, 0.0
        if prm[P_PUSH_P] > 0.0 and uniform_at(krand, step_no * _SLOTS_PER_STEP) < prm[P_PUSH_P]:
            ang = 2.0 * np.pi * uniform_at(krand, step_no * _SLOTS_PER_STEP + 1)
            push_x, push_y = prm[P_PUSH_V] * np.cos(ang), prm[P_PUSH_V] * np.sin(ang)
        fs[S_PUSH_VX], fs[S_PUSH_VY] = push_x, push_y
        n_sub = int(prm[P_SUBSTEPS])
        for tick in range(n_sub):
            n_r, n_l = 0, 0
            if enc_noise > 0.0:  # extra counts read this tick, per wheel
                z_r, z_l = normal_pair_at(krand ^ _ENC_DOMAIN, step_no * _MAX_SUBSTEPS + tick)
                n_r, n_l = int(np.round(z_r * enc_noise)), int(np.round(z_l * enc_noise))
            u_r, i_r, d_r, e_r, o_r, a_r, c_r, m_r = wheel_tick(
                t_r, m_r, e_r, i_r, d_r, o_r, a_r, c_r, n_r, g_r, drive
            )
            u_l, i_l, d_l, e_l, o_l, a_l, c_l, m_l = wheel_tick(
                t_l, m_l, e_l, i_l, d_l, o_l, a_l, c_l, n_l, g_l, drive
            )
            v, w = diff_drive_fk(o_r, o_l, r_true, L_true)
            x, y, th = euler_pose_step(x, y, th, v, w, dt_in)
            x += push_x * dt_in
            y += push_y * dt_in
        fs[S_VMEAS_R], fs[S_VMEAS_L] = m_r, m_l
        fs[S_EPREV_R], fs[S_EPREV_L] = e_r, e_l
        fs[S_INT_R], fs[S_INT_L] = i_r, i_l
        fs[S_D_R], fs[S_D_L] = d_r, d_l
        fs[S_DUTY_R], fs[S_DUTY_L] = u_r, u_l
        fs[S_OMEGA_R], fs[S_OMEGA_L] = o_r, o_l
        fs[S_ANG_R], fs[S_ANG_L] = a_r, a_l
        ist[I_ENC_R], ist[I_ENC_L] = c_r, c_l
        fs[S_X], fs[S_Y], fs[S_TH], fs[S_V], fs[S_W] = x, y, th, v, w
        # Robot acceleration as the robot computes it: finite difference of encoder speed.
        fs[S_VROBOT_PREV] = fs[S_VROBOT_MEAS]
        fs[S_VROBOT_MEAS] = 0.5 * (fs[S_VMEAS_R] + fs[S_VMEAS_L])
        fs[S_ACCEL] = (fs[S_VROBOT_MEAS] - fs[S_VROBOT_PREV]) / dt
        # 3. People walk, keeping out of each other's way.
        if ist[I_N_PEOPLE] > 1:
            social_forces(ps, ist[I_N_PEOPLE], prm[P_SOCIAL_R], prm[P_SOCIAL_K])
        for p in range(ist[I_N_PEOPLE]):
            person_step(ps[p], paths[i, p], prm[P_PERSON_ACC], prm[P_PERSON_DEC], dt)
        if fs[S_WALK_END_T] < 0.0 and ps[0, PS_DONE] > 0.0:
            fs[S_WALK_END_T] = fs[S_T]
        # 4. Camera frame and perception (SPEC §1.4).
        _frame(i, prm, fs, ist, ps, walls[i], keys[i], ist[I_STEP])
        # 5. Contacts, reward, episode end.
        reason = _contacts(prm, fs, ist, ps, walls[i])
        half_w = 0.5 * prm[P_IMG_W]
        reward = (
            prm[P_R_ALIVE]
            # Capped at 1 m: a person far away costs no more than a lost one, so that losing
            # them on purpose (ending the episode) never beats following badly.
            - prm[P_R_DIST] * min(abs(fs[S_TRUE_D] - prm[P_TARGET_D]), 1.0)
            - prm[P_R_OFF] * min(abs(fs[S_TRUE_O]) / half_w, 1.0)
            - prm[P_R_ACC] * abs(fs[S_ACCEL])
            - prm[P_R_LOST] * (1.0 - fs[S_IN_FRAME])
        )
        term, trunc = 0.0, 0.0
        if reason != REASON_NONE:
            reward -= prm[P_R_COLL]
            term = 1.0
        elif fs[S_LOST_T] > prm[P_LOST_TIMEOUT] + 1e-9:
            reason, term = REASON_LOST, 1.0
        elif fs[S_WALK_END_T] >= 0.0 and fs[S_T] >= fs[S_WALK_END_T] + prm[P_SETTLE] - 1e-9:
            reason, trunc = REASON_WALK_OVER, 1.0
        elif ist[I_STEP] >= prm[P_MAX_STEPS]:
            reason, trunc = REASON_STEP_LIMIT, 1.0
        fs[S_REWARD], fs[S_TERM], fs[S_TRUNC] = reward, term, trunc
        ist[I_REASON] = reason


# Compiled without the GIL so that BatchedSim can run disjoint blocks of lanes on several
# threads. (numba's own parallel=True loop was tried and loses: every per-lane array view
# touches the shared array's reference count atomically, and the threads fight over it.)
step_kernel = njit(cache=True, nogil=True)(_step_lanes)

PARALLEL_MIN_LANES = 256
"""From this many lanes on, BatchedSim steps blocks of lanes on one thread per core."""


class BatchedSim:
    """N lanes of the simulation, each running its own episode.

    :param cfg: the configuration shared by all lanes.
    :param num_lanes: N.
    """

    def __init__(self, cfg: EnvConfig, num_lanes: int) -> None:
        if not isinstance(num_lanes, int) or num_lanes < 1:
            raise ValueError(f"num_lanes={num_lanes!r} is out of range: must be an integer >= 1")
        self.cfg = cfg
        self.n = num_lanes
        self.spec: ScenarioSpec = SCENARIOS[cfg.scenario.name]
        if self.spec.max_people > PEOPLE_MAX:
            raise ValueError(
                f"scenario {self.spec.name!r} declares {self.spec.max_people} people; the core "
                f"holds at most {PEOPLE_MAX}"
            )
        self.base_params = params_from_config(cfg)
        self.params = np.tile(self.base_params, (num_lanes, 1))
        self.fstate = np.zeros((num_lanes, N_FSTATE))
        self.istate = np.zeros((num_lanes, N_ISTATE), dtype=np.int64)
        self.pstate = np.zeros((num_lanes, self.spec.max_people, N_PSTATE))
        self.max_points = self.spec.points_for(cfg)
        self.paths = np.zeros((num_lanes, self.spec.max_people, self.max_points, N_PW))
        self.walls = np.zeros((num_lanes, self.spec.max_walls, WALL_FIELDS))
        self.keys = np.zeros((num_lanes, N_STREAMS), dtype=np.uint64)
        self.seeds = LaneSeeds(num_lanes)
        self._all = np.ones(num_lanes, dtype=np.bool_)
        workers = min(os.cpu_count() or 1, max(1, num_lanes // (PARALLEL_MIN_LANES // 2)))
        self._pool: ThreadPoolExecutor | None = None
        self._blocks: list[tuple[int, int]] = []
        if num_lanes >= PARALLEL_MIN_LANES and workers > 1:
            edges = np.linspace(0, num_lanes, workers + 1).astype(int)
            self._blocks = list(zip(edges[:-1].tolist(), edges[1:].tolist(), strict=True))
            self._pool = ThreadPoolExecutor(workers - 1, thread_name_prefix="personfollow")

    def reset_lanes(self, lanes: np.ndarray, seeds: list[int | None] | None = None) -> None:
        """Start the next episode of each of ``lanes``.

        :param lanes: lane indices.
        :param seeds: new root seeds for these lanes (an int, or ``None`` for OS entropy,
            each); without it every lane goes on to its next episode (see
            :class:`~follow_env.rng.LaneSeeds`).
        """
        lanes = np.asarray(lanes, dtype=np.int64)
        if seeds is not None:
            self.seeds.seed(lanes, list(seeds))
        keys = self.seeds.next_keys(lanes)
        self.keys[lanes] = keys
        batch = self.spec.fn(LaneRandom(keys[:, STREAM_PERSON]), self.cfg)
        n_people_max = batch.paths.shape[1]
        n_pts = batch.paths.shape[2]
        n_w = batch.walls.shape[1]
        if (
            n_people_max > self.spec.max_people
            or n_pts > self.max_points
            or (n_w > self.spec.max_walls)
        ):
            raise ValueError(
                f"scenario {self.spec.name!r} returned {n_people_max} people x {n_pts} points "
                f"and {n_w} walls, more than it registered"
            )
        self.paths[lanes] = 0.0
        self.paths[lanes, :n_people_max, :n_pts] = batch.paths
        self.walls[lanes] = 0.0
        self.walls[lanes, :n_w] = batch.walls
        self.params[lanes] = self.base_params
        spread = self.cfg.motor.gain_spread
        if spread > 0.0:
            gains = 1.0 + LaneRandom(keys[:, STREAM_MOTOR]).normal(2, scale=spread)
            self.params[lanes, P_GAIN_R] = np.clip(gains[:, 0], 0.5, 1.5)
            self.params[lanes, P_GAIN_L] = np.clip(gains[:, 1], 0.5, 1.5)
        self._randomize(lanes, LaneRandom(keys[:, STREAM_RANDOMIZE]))
        reset_kernel(
            lanes,
            np.ascontiguousarray(batch.robot_pose, dtype=np.float64),
            np.ascontiguousarray(batch.n_points, dtype=np.int64),
            np.ascontiguousarray(batch.n_people, dtype=np.int64),
            np.ascontiguousarray(batch.n_walls, dtype=np.int64),
            self.params,
            self.fstate,
            self.istate,
            self.pstate,
            self.paths,
            self.walls,
            self.keys,
        )

    def _randomize(self, lanes: np.ndarray, rng: LaneRandom) -> None:
        """Per-episode domain randomisation of ``lanes`` (RandomizationConfig): every draw is
        made whether or not its effect is on, so switching one on never shifts the others."""
        rc, prm = self.cfg.randomization, self.params
        base = self.base_params
        err = rng.normal(2)  # wheel radius, track width
        prm[lanes, P_WHEEL_R_TRUE] = base[P_WHEEL_R] * np.clip(
            1.0 + rc.wheel_radius_error * err[:, 0], 0.5, 1.5
        )
        prm[lanes, P_TRACK_TRUE] = base[P_TRACK] * np.clip(
            1.0 + rc.track_width_error * err[:, 1], 0.5, 1.5
        )
        tilt = rc.camera_tilt_deg * rng.normal()
        if rc.camera_tilt_deg > 0.0:
            cam = self.cfg.camera
            for j, lane in enumerate(lanes):
                rot = Camera.from_config(
                    dataclasses.replace(cam, pitch_deg=cam.pitch_deg + float(tilt[j]))
                ).R
                prm[lane, P_R00 : P_R22 + 1] = rot.ravel()
        level = 1.0 + rc.detector_level_spread * rng.uniform(3, low=-1.0, high=1.0)
        prm[lanes, P_JIT_C] = base[P_JIT_C] * level[:, 0]
        prm[lanes, P_JIT_S] = base[P_JIT_S] * level[:, 0]
        prm[lanes, P_MISS_P] = np.clip(base[P_MISS_P] * level[:, 1], 0.0, 1.0)
        prm[lanes, P_BURST_START] = np.clip(base[P_BURST_START] * level[:, 2], 0.0, 1.0)
        lat_lo = int(base[P_LATENCY])
        lat_hi = max(lat_lo, rc.latency_frames_max)
        u = rng.uniform()
        prm[lanes, P_LATENCY] = np.minimum(lat_lo + np.floor(u * (lat_hi - lat_lo + 1)), lat_hi)
        prm[lanes, P_DEPTH_K] = base[P_DEPTH_K] * (
            1.0 + (rc.depth_noise_scale_max - 1.0) * rng.uniform()
        )
        fric = 1.0 + rc.friction_spread * rng.uniform(low=-1.0, high=1.0)
        prm[lanes, P_FRIC_DUTY] = base[P_FRIC_DUTY] * fric
        prm[lanes, P_STALL_DUTY] = base[P_STALL_DUTY] * fric

    def step(self, actions: np.ndarray, active: np.ndarray | None = None) -> None:
        """Advance the lanes by one control step; ``actions`` is (N, 2) float64 ``v, w``;
        ``active`` (N,) bool selects the lanes to step (default: all)."""
        arrays = (
            self.params,
            self.fstate,
            self.istate,
            self.pstate,
            self.paths,
            self.walls,
            self.keys,
            actions,
            self._all if active is None else active,
        )
        if self._pool is None:
            step_kernel(*arrays)
            return
        # One block of lanes per core; the kernel releases the GIL, and this thread takes the
        # first block itself rather than wait idle.
        jobs = [
            self._pool.submit(step_kernel, *(a[lo:hi] for a in arrays))
            for lo, hi in self._blocks[1:]
        ]
        lo, hi = self._blocks[0]
        step_kernel(*(a[lo:hi] for a in arrays))
        for job in jobs:
            job.result()

    def close(self) -> None:
        """Stop the worker threads (if any)."""
        if self._pool is not None:
            self._pool.shutdown()
            self._pool = None

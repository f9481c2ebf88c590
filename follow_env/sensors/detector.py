"""The person detector as the robot meets it (reference §1.3, §1.4): misses, bursts, jitter, the
detector's list order, the association rule (first detection, or a tracker with re-ID), and the
delay line of its latency.

The section :class:`PerceptionConfig`, the detector's per-lane parameters (:data:`PARAMS`) and
state (:data:`STATE`), and compiled helpers a task's camera frame calls (see
``follow_env.tasks.person_follow.perception``). Every random draw comes from the detector stream
at counters declared in :mod:`follow_env.sim.streams`: person ``p`` of step ``k`` reads
``k * 256 + 8 p + slot`` (slot 0 the burst chain, 1 the miss, 2 and 3 the box jitter, 4 the
appearance noise).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from follow_env.sensors.tracker import TRACK_ALPHA_APP, box_iou, track_update
from follow_env.sim import streams
from follow_env.sim.config import Validated, param
from follow_env.sim.jit import njit
from follow_env.sim.rng import LaneRandom, normal_pair_at, uniform_at
from follow_env.sim.schema import Block, f8, i8

__all__ = [
    "DELAY_SLOTS",
    "PARAMS",
    "PEOPLE_MAX",
    "STATE",
    "PerceptionConfig",
    "clip_box",
    "first_detection",
    "jitter_box",
    "listed_before",
]

PEOPLE_MAX = 16
"""Most people a detector tracks bursts for (one Markov chain each)."""
DELAY_SLOTS = 9
"""Delay-line slots: ``latency_frames`` <= 8."""
SLOTS_PER_PERSON = 8


@dataclass(frozen=True)
class PerceptionConfig(Validated):
    """Detector model, first-detection rule and distance filter (reference §1.3, §1.4)."""

    latency_frames: int = param(
        1, 0, 8, "frames", "choice: the detector result arrives one 0.1 s frame late", integer=True
    )
    miss_prob: float = param(0.03, 0.0, 1.0, "", "choice: independent misses per frame")
    burst_start_prob: float = param(
        0.01, 0.0, 1.0, "", "choice, in reference §1.3's model of bursts: chance a frame starts one"
    )
    burst_mean_frames: float = param(
        5.0, 1.0, 1000.0, "frames", "choice: mean length of a burst (geometric)"
    )
    center_jitter_frac: float = param(
        0.05, 0.0, 1.0, "of box height", "reference §1.3: centre jitter std ~ 1/20 of box height"
    )
    size_jitter_frac: float = param(
        0.05, 0.0, 1.0, "of box size", "choice: width/height jitter std"
    )
    min_visible_fraction: float = param(
        0.3,
        0.0,
        1.0,
        "",
        "choice: a body less visible than this is not detected (the share of the whole body's "
        "box in sight: one cut off by the image's edge counts as hidden, so on the reference "
        "robot nobody centred nearer than about 0.66 m is detected)",
    )
    min_box_height_px: float = param(
        10.0, 0.0, 1000.0, "px", "choice: smaller boxes are below the detector's resolution"
    )
    filter_history: int = param(
        5, 1, 32, "samples", "choice: reference §1.4 leaves the history length open", integer=True
    )
    association: str = param(
        "first",
        doc="reference §1.4: the robot follows the first detection ('first'); 'tracker' keeps the "
        "detection that looks like the target and best overlaps its predicted box (appearance "
        "and IoU gates, constant-velocity prediction), the fix for bystanders who steal it",
        choices=("first", "tracker"),
    )
    tracker_iou_gate: float = param(
        0.1, 0.0, 1.0, "", "choice: least IoU with the predicted box for a detection to match"
    )
    tracker_appearance_gate: float = param(
        0.15,
        0.0,
        1.0,
        "",
        "choice: the tracker takes a detection as the target's only if its "
        "appearance is this close to what it learnt (re-identification)",
    )
    appearance_noise: float = param(
        0.05,
        0.0,
        1.0,
        "",
        "choice: std of the appearance value a detection carries; people "
        "look like uniform draws on [0, 1], so two of them look alike now and then",
    )
    tracker_coast_frames: int = param(
        10, 0, 1000, "frames", "choice: frames the tracker waits for its target (1 s)", integer=True
    )
    detection_order: str = param(
        "area",
        doc="choice: the detector lists boxes by confidence, modelled as box area (largest first)",
        choices=("area",),
    )
    ahead_rays: int = param(
        0,
        0,
        16,
        "columns",
        "choice: 0 publishes the reference robot's two entries; n > 0 adds a third, ahead_m, "
        "the nearest valid depth at n columns of the image's middle row (the depth image the "
        "distance comes from, reference §1.3), so a controller can see what is in its way",
        integer=True,
    )
    ahead_half_angle_deg: float = param(
        14.0,
        0.0,
        45.0,
        "deg",
        "choice: the columns span +- this about the optical axis, evenly (14 deg: +-0.25 m at "
        "1 m, about a robot's half-width)",
    )
    ahead_target: str = param(
        "include",
        doc="choice: 'include' reads every column; 'exclude' skips the columns inside the box "
        "of the detection published this frame, so that the reading is of what else is ahead "
        "(a bystander, a wall), not a second distance to the person followed",
        choices=("include", "exclude"),
    )


@njit(inline="always")
def clip_box(
    u1: float, v1: float, u2: float, v2: float, width: float, height: float
) -> tuple[float, float, float, float]:
    """Clip a box to the image ``[0, width] x [0, height]`` (px). An empty result has
    ``u2 <= u1`` or ``v2 <= v1``."""
    return max(u1, 0.0), max(v1, 0.0), min(u2, width), min(v2, height)


@njit(inline="always")
def jitter_box(
    u1: float,
    v1: float,
    u2: float,
    v2: float,
    z_cu: float,
    z_cv: float,
    z_w: float,
    z_h: float,
    center_frac: float,
    size_frac: float,
) -> tuple[float, float, float, float]:
    """Detector box noise: the centre moves by ``center_frac * box height`` standard deviations
    (reference §1.3: about 1/20 of the box height), width and height scale by ``1 + size_frac z``.
    ``z_*`` are standard normal draws."""
    w, h = u2 - u1, v2 - v1
    cu = 0.5 * (u1 + u2) + center_frac * h * z_cu
    cv = 0.5 * (v1 + v2) + center_frac * h * z_cv
    w = max(w * (1.0 + size_frac * z_w), 1.0)
    h = max(h * (1.0 + size_frac * z_h), 1.0)
    return cu - 0.5 * w, cv - 0.5 * h, cu + 0.5 * w, cv + 0.5 * h


@njit(inline="always")
def listed_before(area: float, best_area: float) -> bool:
    """The detector's order: does a box of ``area`` (px^2) come before the best so far?

    Detectors list boxes by confidence; it is modelled as box area, largest first, and a tie
    keeps the box seen first.
    """
    return area > best_area


@njit
def first_detection(boxes: np.ndarray, detected: np.ndarray) -> int:
    """The detection the robot follows: the first of the detector's list (reference §1.4 step 2).

    The detector lists boxes by confidence, modelled as box area, largest first; ties keep the
    lower index. ``boxes`` is (n, 4) ``u1, v1, u2, v2``; returns the index into ``boxes`` of the
    first listed detection, or -1 when nothing is detected.
    """
    best = -1
    best_area = -1.0
    for i in range(boxes.shape[0]):
        if not detected[i]:
            continue
        area = (boxes[i, 2] - boxes[i, 0]) * (boxes[i, 3] - boxes[i, 1])
        if listed_before(area, best_area):
            best, best_area = i, area
    return best


# --- per-lane parameters, state and draws -----------------------------------------------------

PARAMS = Block(
    "detector_params",
    "the detector model and the association rule",
    [
        f8("latency", "frames", "detector latency", source="perception.latency_frames"),
        f8("miss_p", "", "independent miss chance per frame", source="perception.miss_prob"),
        f8(
            "burst_start",
            "",
            "chance per frame that a burst starts",
            source="perception.burst_start_prob",
        ),
        f8(
            "burst_end",
            "",
            "chance per frame that a burst ends",
            source=lambda c: 1.0 / c.perception.burst_mean_frames,
        ),
        f8(
            "jit_c",
            "of box height",
            "box centre jitter std",
            source="perception.center_jitter_frac",
        ),
        f8("jit_s", "of box size", "box size jitter std", source="perception.size_jitter_frac"),
        f8("min_vis", "", "least visible share detected", source="perception.min_visible_fraction"),
        f8("min_box_h", "px", "least box height detected", source="perception.min_box_height_px"),
        f8(
            "assoc",
            "",
            "0: first detection, 1: tracker",
            source=lambda c: 1.0 if c.perception.association == "tracker" else 0.0,
        ),
        f8(
            "trk_iou",
            "",
            "tracker gate: least IoU with the predicted box",
            source="perception.tracker_iou_gate",
        ),
        f8(
            "trk_coast",
            "frames",
            "tracker: frames kept without a match",
            source="perception.tracker_coast_frames",
        ),
        f8(
            "trk_app_gate",
            "",
            "tracker: largest appearance difference of the same person",
            source="perception.tracker_appearance_gate",
        ),
        f8(
            "app_noise",
            "",
            "std of the appearance a detection carries",
            source="perception.appearance_noise",
        ),
        f8(
            "look_of",
            "",
            "whose appearance person p's detections carry (p, unless the scenario makes p "
            "a look-alike; set at every reset)",
            shape=(PEOPLE_MAX,),
            source=lambda c: np.arange(PEOPLE_MAX, dtype=np.float64),
        ),
    ],
)

STATE = Block(
    "detector_state",
    "burst chains, the tracker and the delay line",
    [
        i8("burst", "", "1 while a person's occlusion burst lasts", shape=(PEOPLE_MAX,)),
        f8("trk_cx", "px", "track centre column"),
        f8("trk_cy", "px", "track centre row"),
        f8("trk_w", "px", "track box width"),
        f8("trk_h", "px", "track box height"),
        f8("trk_vx", "px/frame", "track centre velocity, column"),
        f8("trk_vy", "px/frame", "track centre velocity, row"),
        f8("trk_lost", "frames", "frames the track has coasted"),
        f8("trk_on", "", "1 while a track exists"),
        f8("trk_app", "", "the target's appearance as the tracker learnt it (-1: not yet)"),
        i8("dl_head", "", "delay line: the slot written last"),
        f8("dl_det", "", "delay line: 1 if the frame had a detection", shape=(DELAY_SLOTS,)),
        f8("dl_cu", "px", "delay line: box centre column", shape=(DELAY_SLOTS,)),
        f8("dl_cv", "px", "delay line: box centre row", shape=(DELAY_SLOTS,)),
        f8("dl_raw", "m", "delay line: raw depth at the centre", shape=(DELAY_SLOTS,)),
        f8("dl_box", "px", "delay line: box u1, v1, u2, v2", shape=(DELAY_SLOTS, 4)),
        f8("dl_owner", "", "delay line: whose detection (-1: none)", shape=(DELAY_SLOTS,)),
    ],
)

PER_PERSON = streams.per_step(
    "detector.person",
    streams.DETECTOR,
    0,
    SLOTS_PER_PERSON * PEOPLE_MAX,
    doc="person p: burst (8p), miss (8p + 1), centre and size jitter (8p + 2, 8p + 3), "
    "appearance noise (8p + 4)",
)
APPEARANCE_KEY = streams.domain(
    "appearance", streams.DETECTOR, 0xE7037ED1A0B428DB, "each person's look for the re-ID gate"
)
APPEARANCE = streams.per_episode(
    "detector.appearance",
    APPEARANCE_KEY,
    0,
    PEOPLE_MAX,
    space="uniform",
    absolute=True,
    doc="person p's appearance value at counter p",
)
LEVEL = streams.per_episode(
    "detector.level",
    streams.RANDOMIZE,
    3,
    3,
    space="uniform",
    doc="jitter, miss and burst levels (randomisation)",
)
LATENCY = streams.per_episode(
    "detector.latency", streams.RANDOMIZE, 6, 1, space="uniform", doc="latency (randomisation)"
)
_DETECTOR = streams.DETECTOR.index
_STRIDE = PER_PERSON.stride
_APP_CONST = np.uint64(APPEARANCE_KEY.constant)


def randomize(
    params: np.ndarray, base: np.void, lanes: np.ndarray, cfg: Any, keys: np.ndarray
) -> None:
    """Per-episode detector levels (jitter, misses, bursts) and latency (randomisation)."""
    rc = cfg.randomization
    rng = LaneRandom(keys[:, streams.RANDOMIZE.index])
    level = 1.0 + rc.detector_level_spread * rng.uniform(3, low=-1.0, high=1.0, at=LEVEL)
    params["jit_c"][lanes] = base["jit_c"] * level[:, 0]
    params["jit_s"][lanes] = base["jit_s"] * level[:, 0]
    params["miss_p"][lanes] = np.clip(base["miss_p"] * level[:, 1], 0.0, 1.0)
    params["burst_start"][lanes] = np.clip(base["burst_start"] * level[:, 2], 0.0, 1.0)
    lat_lo = int(base["latency"])
    lat_hi = max(lat_lo, rc.latency_frames_max)
    u = rng.uniform(at=LATENCY)
    params["latency"][lanes] = np.minimum(lat_lo + np.floor(u * (lat_hi - lat_lo + 1)), lat_hi)


@njit(inline="always")
def reset(st: np.void) -> None:
    """A new episode: no track, the target's look not known yet (state zeroed already)."""
    st.trk_app = -1.0


# --- the detector's view of one person --------------------------------------------------------


@njit(inline="always")
def detection(
    prm: np.void,
    st: np.void,
    keys: np.ndarray,
    step: int,
    p: int,
    visible: bool,
    clipped: tuple[float, float, float, float],
    width: float,
    height: float,
) -> tuple[bool, float, float, float, float, float, float]:
    """Does the detector report person ``p`` this frame, and with which box?

    The burst chain (a two-state Markov chain per person) steps every frame; a visible person
    outside a burst is detected unless missed; the box jitters (centre by ``jit_c`` box
    heights, size by ``jit_s``) and is clipped to the image (``width`` x ``height`` px). With
    the tracker on, the detection also carries an appearance value (the person's own look,
    drawn once per episode, plus noise), standing in for a re-identification embedding.

    :return: ``(detected, u1, v1, u2, v2, area px^2, appearance)``.
    """
    kdet = keys[_DETECTOR]
    slot = step * _STRIDE + p * SLOTS_PER_PERSON
    u_burst = uniform_at(kdet, slot)
    if st.burst[p] != 0:
        if u_burst < prm.burst_end:
            st.burst[p] = 0
    elif u_burst < prm.burst_start:
        st.burst[p] = 1
    if visible and st.burst[p] == 0 and uniform_at(kdet, slot + 1) >= prm.miss_p:
        c1, c2, c3, c4 = clipped
        z_cu, z_cv = normal_pair_at(kdet, slot + 2)
        z_w, z_h = normal_pair_at(kdet, slot + 3)
        j1, j2, j3, j4 = jitter_box(c1, c2, c3, c4, z_cu, z_cv, z_w, z_h, prm.jit_c, prm.jit_s)
        j1, j2, j3, j4 = clip_box(j1, j2, j3, j4, width, height)
        if j3 > j1 and j4 > j2:
            area = (j3 - j1) * (j4 - j2)
            app = 0.0
            if prm.assoc > 0.0:
                z_app = normal_pair_at(kdet, slot + 4)[0]
                look = int(prm.look_of[p])  # a look-alike carries the target's look
                app = uniform_at(kdet ^ _APP_CONST, look) + prm.app_noise * z_app
            return True, j1, j2, j3, j4, area, app
    return False, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0


# A candidate detection: (person, u1, v1, u2, v2, score, appearance); person -1 for none.
Candidate = tuple[int, float, float, float, float, float, float]


@njit(inline="always")
def no_candidate(score: float) -> tuple[int, float, float, float, float, float, float]:
    """An empty candidate whose score any real one must beat."""
    return -1, 0.0, 0.0, 0.0, 0.0, score, 0.0


@njit(inline="always")
def tracking(prm: np.void, st: np.void) -> bool:
    """Is the tracker on and following a track?"""
    return prm.assoc > 0.0 and st.trk_on > 0.0


@njit(inline="always")
def consider(
    prm: np.void,
    st: np.void,
    p: int,
    u1: float,
    v1: float,
    u2: float,
    v2: float,
    area: float,
    app: float,
    first: Candidate,
    reid: Candidate,
    match: Candidate,
) -> tuple[Candidate, Candidate, Candidate]:
    """Walk the detector's list as it is produced: keep the first listed detection (reference §1.4
    step 2, order as in :func:`first_detection`), the first listed one that looks like the
    target (re-ID; every one before the target's look is known), and the one that looks like it
    and best overlaps the tracker's predicted box."""
    if listed_before(area, first[5]):
        first = (p, u1, v1, u2, v2, area, app)
    known = prm.assoc > 0.0 and st.trk_app >= 0.0
    alike = not known or abs(app - st.trk_app) < prm.trk_app_gate
    if alike and listed_before(area, reid[5]):
        reid = (p, u1, v1, u2, v2, area, app)
    if tracking(prm, st) and alike:
        t_cx, t_cy = st.trk_cx + st.trk_vx, st.trk_cy + st.trk_vy
        t_hw, t_hh = 0.5 * st.trk_w, 0.5 * st.trk_h
        iou = box_iou(u1, v1, u2, v2, t_cx - t_hw, t_cy - t_hh, t_cx + t_hw, t_cy + t_hh)
        if iou >= match[5]:
            match = (p, u1, v1, u2, v2, iou, app)
    return first, reid, match


@njit(inline="always")
def associate(
    prm: np.void,
    st: np.void,
    was_tracking: bool,
    first: Candidate,
    reid: Candidate,
    match: Candidate,
) -> Candidate:
    """The detection the robot takes this frame (person -1: none).

    First detection (the reference rule): the first listed. Tracker: the matched detection;
    without one, coast on the prediction for a while and publish nothing; with no track, take
    the best-listed detection that looks like the target (the first detection before the
    target's look is known). The tracker learns from what it takes.
    """
    if prm.assoc <= 0.0:
        return first
    chosen = first
    if was_tracking and match[0] >= 0:
        chosen = match
    elif was_tracking and st.trk_lost < prm.trk_coast:
        chosen = no_candidate(0.0)
    else:
        chosen = reid
    if chosen[0] >= 0:
        track_update(st, chosen[1], chosen[2], chosen[3], chosen[4], was_tracking and match[0] >= 0)
        # The target's look: learnt from the first track, refined while matched.
        if st.trk_app < 0.0:
            st.trk_app = chosen[6]
        else:
            st.trk_app += TRACK_ALPHA_APP * (chosen[6] - st.trk_app)
    elif st.trk_on > 0.0:
        st.trk_lost += 1.0
        st.trk_cx += st.trk_vx
        st.trk_cy += st.trk_vy
        if st.trk_lost > prm.trk_coast:
            st.trk_on = 0.0
    return chosen


# --- the delay line ---------------------------------------------------------------------------


@njit(inline="always")
def _write_slot(
    st: np.void, k: int, det: float, cu: float, cv: float, raw: float, box: Candidate
) -> None:
    st.dl_det[k], st.dl_cu[k], st.dl_cv[k], st.dl_raw[k] = det, cu, cv, raw
    st.dl_box[k, 0], st.dl_box[k, 1] = box[1], box[2]
    st.dl_box[k, 2], st.dl_box[k, 3] = box[3], box[4]
    st.dl_owner[k] = box[0]


@njit(inline="always")
def delay(
    prm: np.void,
    st: np.void,
    step: int,
    det: float,
    cu: float,
    cv: float,
    raw: float,
    box: Candidate,
) -> int:
    """Write this frame's measurement into the delay line of ``latency`` frames and return
    the slot to publish: the one ``latency`` frames old. At reset (step 0) every slot gets the
    first frame, as if the robot had stood still for the whole delay."""
    size = int(prm.latency) + 1
    head = (st.dl_head + 1) % size
    if step == 0:
        for k in range(size):
            _write_slot(st, k, det, cu, cv, raw, box)
        head = 0
    else:
        _write_slot(st, head, det, cu, cv, raw, box)
    st.dl_head = head
    return (head + 1) % size

"""A box tracker for the detector's association rule: an alpha-beta filter on the box centre.

With ``perception.association = "tracker"`` the robot follows the detection that best overlaps
the track's predicted box (an IoU gate) and looks like the target (an appearance gate standing
in for re-identification), instead of the first detection (reference §1.4), which a nearer bystander
steals. The state lives in the detector's record (:data:`follow_env.sensors.detector.STATE`).
"""

from __future__ import annotations

import numpy as np

from follow_env.sim.jit import njit

__all__ = ["TRACK_ALPHA", "TRACK_ALPHA_APP", "TRACK_BETA", "box_iou", "track_update"]

TRACK_ALPHA = 0.6
"""Alpha-beta filter: share of the innovation taken into the centre (and the size)."""
TRACK_BETA = 0.2
"""Alpha-beta filter: share of the innovation taken into the velocity (px/frame)."""
TRACK_ALPHA_APP = 0.05
"""How fast the learnt look follows new views (slowly: no drift onto a bystander)."""


@njit(inline="always")
def box_iou(
    a1: float, a2: float, a3: float, a4: float, b1: float, b2: float, b3: float, b4: float
) -> float:
    """Intersection over union of boxes ``(u1, v1, u2, v2)`` a and b (0 when disjoint)."""
    iw = min(a3, b3) - max(a1, b1)
    ih = min(a4, b4) - max(a2, b2)
    if iw <= 0.0 or ih <= 0.0:
        return 0.0
    inter = iw * ih
    union = (a3 - a1) * (a4 - a2) + (b3 - b1) * (b4 - b2) - inter
    return inter / union if union > 0.0 else 0.0


@njit(inline="always")
def track_update(st: np.void, b1: float, b2: float, b3: float, b4: float, matched: bool) -> None:
    """The tracker takes a detection: an alpha-beta (constant-velocity) filter on the box
    centre (px/frame) and a smoothed size when it matched its track; a fresh track else."""
    cu, cv, w, h = 0.5 * (b1 + b3), 0.5 * (b2 + b4), b3 - b1, b4 - b2
    if matched:
        pu, pv = st.trk_cx + st.trk_vx, st.trk_cy + st.trk_vy
        ru, rv = cu - pu, cv - pv
        st.trk_cx, st.trk_cy = pu + TRACK_ALPHA * ru, pv + TRACK_ALPHA * rv
        st.trk_vx += TRACK_BETA * ru
        st.trk_vy += TRACK_BETA * rv
        st.trk_w += TRACK_ALPHA * (w - st.trk_w)
        st.trk_h += TRACK_ALPHA * (h - st.trk_h)
    else:
        st.trk_cx, st.trk_cy, st.trk_w, st.trk_h = cu, cv, w, h
        st.trk_vx = st.trk_vy = 0.0
    st.trk_lost = 0.0
    st.trk_on = 1.0

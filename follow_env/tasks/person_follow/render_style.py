"""What both panels of PersonFollow's frame share: the layout, the colours, the target's sight
state, the camera's wedge and horizon, and :class:`Lane`, the typed view of a lane they draw."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, NamedTuple

import numpy as np

from follow_env.world.geometry import WALL

if TYPE_CHECKING:
    from follow_env.sim.runner import LaneView

__all__ = [
    "C_STOLEN",
    "FRAME_HEIGHT_PX",
    "FRAME_WIDTH_PX",
    "PANEL_W_PX",
    "SIGHT_CLEAR",
    "SIGHT_HIDDEN",
    "SIGHT_OUT_OF_VIEW",
    "SIGHT_PARTLY",
    "Lane",
    "Seen",
    "camera_edge_azimuths",
    "horizon_row",
    "sight_state",
]

# Frame layout (px). 1280 x 480 keeps both sides multiples of 16, which video encoders want.
PANEL_W_PX = 640
FRAME_HEIGHT_PX = 480
FRAME_WIDTH_PX = 2 * PANEL_W_PX
HEADER_PX = 40  # text strip above the map
MAP_MARGIN_PX = 10
HEADER_MID_PX = 236  # column of the header's middle block (who is followed, visible share)

# Drawing constants.
FRUSTUM_LENGTH_M = 4.0  # how far the field-of-view wedge reaches on the map
FRUSTUM_ALPHA = 0.35
VIEW_PAD_M = 2.0  # room around people and trails when there are no walls to fit
MIN_VIEW_M = 8.0
RING_RADIUS_M = 0.45  # the "followed" ring round a person on the map


# Colours (RGB).
C_BG = (40, 42, 48)
C_FLOOR = (236, 234, 226)
C_GRID = (214, 212, 204)
C_WALL = (60, 60, 66)  # walls and pillars: hide a whole person
C_LOW = (190, 170, 138)  # furniture lower than a person: hides legs only
C_LOW_EDGE = (125, 105, 78)
C_TEXT = (240, 240, 240)
C_ROBOT = (45, 110, 215)
C_ROBOT_EDGE = (20, 50, 110)
C_TARGET = (240, 135, 30)
C_OTHER = (150, 150, 150)
C_PERSON_EDGE = (70, 60, 50)
C_FRUSTUM = (255, 220, 90)
C_SKY = (196, 202, 212)
C_TRUE_BOX = (120, 120, 120)
C_BODY = (205, 205, 205)
C_DET = (40, 200, 60)  # published detection of the target; the followed ring on the target
C_STOLEN = (220, 0, 0)  # a bystander's detection is followed: the stolen target
C_TRACK = (0, 200, 235)
C_CENTRE = (250, 250, 250)
C_WARN = (235, 60, 50)
C_AHEAD = (200, 40, 200)  # the reading ahead: what the depth row sees nearest
# Line of sight to the target, by sight state (index = SIGHT_*).
C_SIGHT = ((40, 170, 60), (245, 150, 0), (235, 60, 50), (140, 140, 140))


# How much of the target the camera sees (see sight_state).
SIGHT_CLEAR = 0
SIGHT_PARTLY = 1
SIGHT_HIDDEN = 2
SIGHT_OUT_OF_VIEW = 3
SIGHT_WORDS = ("in sight", "partly hidden", "hidden", "out of view")

# A wall segment ready to draw: fixed-point end points, colour, thickness (px).
WallLine = tuple[tuple[int, int], tuple[int, int], tuple[int, int, int], int]


class Seen(NamedTuple):
    """One person as the camera would see them with nothing in the way."""

    dist_m: float  # from the robot's centre, for drawing far to near
    box: tuple[float, float, float, float]  # body box clipped to the image (px)
    image_share: float  # share of the body's box inside the image (0 when not in view)


def camera_edge_azimuths(cam: np.void) -> tuple[float, float]:
    """Azimuths (rad, robot frame, CCW from forward) of the image's left and right edge
    columns at the principal row: the horizontal field of view, with the camera's yaw and the
    principal point taken into account (the pitch only shifts where the wedge is seen)."""
    R = np.asarray(cam["R"]).reshape(3, 3)
    fx, cx, width = float(cam["fx"]), float(cam["cx"]), float(cam["img_w"])
    out = []
    for u in (0.0, width):
        d = R @ np.array([(u - cx) / fx, 0.0, 1.0])
        out.append(math.atan2(d[1], d[0]))
    return out[0], out[1]


def horizon_row(cam: np.void) -> float:
    """Image row (px, may lie outside the image) where the level floor meets the sky: the
    projection of a horizontal direction along the optical axis's heading."""
    R = np.asarray(cam["R"]).reshape(3, 3)
    ax, ay = R[0, 2], R[1, 2]
    n = math.hypot(ax, ay)
    if n < 1e-9:  # looking straight up or down: no horizon in view
        return -1e9 if R[2, 2] < 0.0 else 1e9
    d_cam = R.T @ np.array([ax / n, ay / n, 0.0])
    if d_cam[2] <= 1e-9:
        return -1e9
    return float(cam["fy"] * d_cam[1] / d_cam[2] + cam["cy"])


def sight_state(vis_frac: float, image_share: float, min_visible: float) -> int:
    """How much of the target the camera sees, for the line of sight's colour.

    :param vis_frac: the target's visible share the core computed (``vis_frac``): the share
        of the body's box inside the image times the share of it not blocked by obstacles or
        people (line of sight).
    :param image_share: the share of the body's box inside the image with nothing in the way
        (0 when the body is outside the field of view).
    :param min_visible: the detector's threshold, ``perception.min_visible_fraction``.
    :return: ``SIGHT_OUT_OF_VIEW`` when no part of the body is in the image;
        ``SIGHT_HIDDEN`` when it is in the image but fully blocked (``vis_frac == 0``);
        ``SIGHT_PARTLY`` when something blocks part of it, or less than ``min_visible`` is in
        sight (too little to detect); ``SIGHT_CLEAR`` otherwise.
    """
    if image_share <= 0.0:
        return SIGHT_OUT_OF_VIEW
    if vis_frac <= 0.0:
        return SIGHT_HIDDEN
    # The core leaves the share unchanged when every sampled point is in sight, so any drop
    # below the image share means something stands in the way (the margin absorbs rounding).
    if vis_frac < min_visible or vis_frac < image_share * (1.0 - 1e-6):
        return SIGHT_PARTLY
    return SIGHT_CLEAR


W = WALL.columns()
"""Column of each wall field in :attr:`Lane.walls`."""


class Lane:
    """One lane as the renderer reads it: a typed view of the runner's live records
    (:class:`~follow_env.sim.runner.LaneView`), read once per frame."""

    def __init__(self, view: LaneView) -> None:
        prm, st = view.params, view.state
        tp, ts = prm["task"], st["task"]
        det = ts["detector"]
        body = st["body"]
        self.camera = tp["camera"]
        self.t = float(st["episode"]["t"])
        self.reason = int(st["episode"]["reason"])
        self.x, self.y, self.th = float(body["x"]), float(body["y"]), float(body["th"])
        self.obs_d, self.obs_o = float(ts["obs_d"]), float(ts["obs_o"])
        # The reading ahead (m) and the tangent of its half-angle, when it is configured.
        self.ahead_rays = int(tp["depth"]["ahead_rays"])
        self.ahead = float(ts["obs_ahead"]) if self.ahead_rays > 0 else None
        self.ahead_tan = float(tp["depth"]["ahead_tan"])
        self.true_d, self.true_o = float(ts["true_d"]), float(ts["true_o"])
        self.vis_frac = float(ts["vis_frac"])
        self.in_frame = bool(ts["in_frame"] > 0.0)
        self.detected = bool(ts["detected"] > 0.0)
        self.followed = int(ts["detected_id"])  # whose detection the perception published
        self.box = tuple(float(v) for v in ts["box"])
        self.track_on = bool(det["trk_on"] > 0.0)
        self.track = tuple(float(det[k]) for k in ("trk_cx", "trk_cy", "trk_w", "trk_h"))
        self.track_lost = int(det["trk_lost"])
        self.latency = int(tp["detector"]["latency"])
        self.min_visible = float(tp["detector"]["min_vis"])  # perception.min_visible_fraction
        self.person_w, self.person_d, self.person_h = (
            float(tp["person_w"]),
            float(tp["person_d"]),
            float(tp["person_h"]),
        )
        self.people = view.world[0][: int(ts["n_people"])]
        n_walls = int(ts["n_walls"])
        # The walls as plain rows x1, y1, x2, y2, h (their records' fields, in order).
        self.walls = view.world[2][:n_walls].view(np.float64).reshape(n_walls, len(W))

    @property
    def n_people(self) -> int:
        """People in the lane (the target first)."""
        return len(self.people)

    def person(self, p: int) -> tuple[float, float, float]:
        """Person ``p``'s position (m) and heading (rad)."""
        q = self.people[p]
        return float(q["x"]), float(q["y"]), float(q["th"])

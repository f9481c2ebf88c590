"""``rgb_array`` frames of PersonFollow-v0: a top-down map beside the robot's camera view,
drawn with OpenCV (headless: no window is ever opened; ``render_mode="human"`` shows the frames
in a window of :mod:`follow_env.sim.window`).

Left panel (map): the room's walls and obstacles fitted to the panel, shaded by height (walls
and pillars at least as tall as a person dark: they hide a whole body; lower furniture light:
it hides legs only), a metre grid, the camera's horizontal field of view, the robot's footprint
with a heading arrow, every person as a rotated rectangle (the target, person 0, in orange,
bystanders grey), the trails of the robot and the target, the line of sight from the camera to
the target coloured by how much of the target is in sight (see :func:`sight_state`), a ring
round the person whose detection the perception took this frame (green on the target, red with
"followed: bystander N" when a bystander has stolen it), and a header with time, the
observation, the ground truth, who is followed, the target's visible share and the episode end
reason.

Right panel (camera): the image frame scaled to fit, floor below the horizon, each person's true
projected body box in grey (labelled), the box the perception published in green when it is the
target's and red when it is a bystander's (with its centre and its offset from the image's
centre column), the tracker's box dashed in cyan when a track exists, and warnings ("no
detection", "target hidden", ...). Obstacles are not drawn in the camera view: the line of sight
on the map and the target's visible share say what they hide.

Everything is read from a lane's live records through :class:`Lane`, a typed view; nothing here
changes the simulation. Colours are
written as RGB because the frame is returned as RGB and OpenCV's drawing does not care about the
channel order.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, NamedTuple

import cv2
import numpy as np

from follow_env.sensors.camera import Camera, body_box
from follow_env.sim.drawing import (
    FONT,
    FONT_SCALE,
    ONE,
    SHIFT,
    MapView,
    Trail,
    blend_poly,
    dashed_polyline,
    fit_view,
    grid_step_m,
    put_text,
    rect_corners,
)
from follow_env.tasks.person_follow.spec import REASON_NONE, SPEC
from follow_env.world.geometry import WALL, wall_loops

if TYPE_CHECKING:
    from follow_env.sim.runner import LaneView
    from follow_env.tasks.person_follow.config import EnvConfig

__all__ = [
    "C_STOLEN",
    "FRAME_HEIGHT_PX",
    "FRAME_WIDTH_PX",
    "SIGHT_CLEAR",
    "SIGHT_HIDDEN",
    "SIGHT_OUT_OF_VIEW",
    "SIGHT_PARTLY",
    "Renderer",
    "sight_state",
    "wall_loops",
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
# Line of sight to the target, by sight state (index = SIGHT_*).
C_SIGHT = ((40, 170, 60), (245, 150, 0), (235, 60, 50), (140, 140, 140))


# How much of the target the camera sees (see sight_state).
SIGHT_CLEAR = 0
SIGHT_PARTLY = 1
SIGHT_HIDDEN = 2
SIGHT_OUT_OF_VIEW = 3
_SIGHT_WORDS = ("in sight", "partly hidden", "hidden", "out of view")

# A wall segment ready to draw: fixed-point end points, colour, thickness (px).
_WallLine = tuple[tuple[int, int], tuple[int, int], tuple[int, int, int], int]


class _Seen(NamedTuple):
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


# ----------------------------------------------------------------------------------------------
# Renderer
# ----------------------------------------------------------------------------------------------


_W = WALL.columns()


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
        self.walls = view.world[2][:n_walls].view(np.float64).reshape(n_walls, len(_W))

    @property
    def n_people(self) -> int:
        """People in the lane (the target first)."""
        return len(self.people)

    def person(self, p: int) -> tuple[float, float, float]:
        """Person ``p``'s position (m) and heading (rad)."""
        q = self.people[p]
        return float(q["x"]), float(q["y"]), float(q["th"])


class Renderer:
    """Draws ``rgb_array`` frames of a :class:`~follow_env.tasks.person_follow.env.PersonFollowEnv`.

    The frame is always ``FRAME_HEIGHT_PX x FRAME_WIDTH_PX x 3`` (480 x 1280) uint8 RGB, so a
    video of an episode has one size whatever happens in it.

    :param config: the environment's configuration (camera image size and robot footprint).
    """

    def __init__(self, config: EnvConfig) -> None:
        self.config = config
        self.camera = Camera.from_config(config.camera)
        self._scratch = np.zeros(24)  # body_box works in caller-owned memory
        self.foot_l = config.platform.footprint_length_m
        self.foot_w = config.platform.footprint_width_m
        self.robot_trail = Trail()
        self.target_trail = Trail()
        # The map background (floor, grid, walls) only changes with the walls or the view;
        # it is drawn once per key and copied each frame.
        self._map_key: tuple[object, ...] | None = None
        self._map_bg: np.ndarray | None = None
        self._map_view: MapView | None = None
        self._wall_polys: list[tuple[np.ndarray, tuple[int, int, int]]] = []
        self._wall_lines: list[_WallLine] = []
        self._grid_m = 1.0
        # The camera panel: image scaled to fit the panel, letterboxed.
        W, H = self.camera.width_px, self.camera.height_px
        self.cam_scale = min(PANEL_W_PX / W, FRAME_HEIGHT_PX / H)
        self.cam_w = round(W * self.cam_scale)
        self.cam_h = round(H * self.cam_scale)
        self.cam_x0 = (PANEL_W_PX - self.cam_w) // 2
        self.cam_y0 = (FRAME_HEIGHT_PX - self.cam_h) // 2
        self._cam_bg: np.ndarray | None = None  # needs the sim's params: built on first draw

    # -- the interface PersonFollowEnv calls ---------------------------------------------------

    def reset(self) -> None:
        """Forget the trails and who was followed (a new episode starts)."""
        self.robot_trail.clear()
        self.target_trail.clear()

    def record(self, view: LaneView) -> None:
        """Append the robot's and the target's current positions (m) to the trails (the env
        calls this every step whether or not a frame is drawn)."""
        body, target = view.state["body"], view.world[0][0]
        self.robot_trail.append(float(body["x"]), float(body["y"]))
        self.target_trail.append(float(target["x"]), float(target["y"]))

    def draw(self, view: LaneView) -> np.ndarray:
        """The current frame: an RGB uint8 array (480, 1280, 3), C-contiguous, newly allocated
        (callers such as ``RecordVideo`` keep every frame)."""
        if self.robot_trail.n == 0:
            self.record(view)
        lane = Lane(view)
        seen = self._project_people(lane)
        frame = np.empty((FRAME_HEIGHT_PX, FRAME_WIDTH_PX, 3), dtype=np.uint8)
        self._draw_map(lane, seen, frame[:, :PANEL_W_PX])
        self._draw_camera(lane, seen, frame[:, PANEL_W_PX:])
        cv2.line(frame, (PANEL_W_PX, 0), (PANEL_W_PX, FRAME_HEIGHT_PX - 1), (0, 0, 0), 2)
        return frame

    # -- shared by both panels -----------------------------------------------------------------

    def _project_people(self, lane: Lane) -> list[_Seen | None]:
        """Every person's true body box in the image (clipped, px) and the share of it inside
        the image, as the core computes them before the line of sight; None when no part of
        the body is in the image."""
        cam = lane.camera
        W, H = float(cam["img_w"]), float(cam["img_h"])
        rx, ry, rth = lane.x, lane.y, lane.th
        R, T = np.asarray(cam["R"]), np.asarray(cam["T"])
        out: list[_Seen | None] = []
        for p in range(lane.n_people):
            px, py, pth = lane.person(p)
            u1, v1, u2, v2, found = body_box(
                px,
                py,
                pth,
                lane.person_w,
                lane.person_d,
                lane.person_h,
                rx,
                ry,
                rth,
                R,
                T,
                float(cam["fx"]),
                float(cam["fy"]),
                float(cam["cx"]),
                float(cam["cy"]),
                self._scratch,
            )
            c1, c2, c3, c4 = max(u1, 0.0), max(v1, 0.0), min(u2, W), min(v2, H)
            if found and c3 > c1 and c4 > c2:
                share = (c3 - c1) * (c4 - c2) / ((u2 - u1) * (v2 - v1))
                out.append(_Seen(math.hypot(px - rx, py - ry), (c1, c2, c3, c4), share))
            else:
                out.append(None)
        return out

    @staticmethod
    def _target_sight(lane: Lane, seen: list[_Seen | None]) -> int:
        """The target's sight state (``SIGHT_*``), see :func:`sight_state`."""
        target = seen[0] if seen else None
        return sight_state(
            lane.vis_frac, 0.0 if target is None else target.image_share, lane.min_visible
        )

    # -- map panel -----------------------------------------------------------------------------

    def _world_bounds(self, lane: Lane) -> tuple[float, float, float, float]:
        """Extent (m) the map shows: the walls when there are any; otherwise the people and
        trails, padded and snapped to whole metres so the view (and its cached background)
        changes only now and then."""
        if len(lane.walls) > 0:
            w = lane.walls
            xs = np.concatenate([w[:, _W.x1], w[:, _W.x2]])
            ys = np.concatenate([w[:, _W.y1], w[:, _W.y2]])
            pad = 0.3
        else:
            people = np.column_stack([lane.people["x"], lane.people["y"]])
            pts = np.concatenate([self.robot_trail.points, self.target_trail.points, people])
            xs, ys = pts[:, 0], pts[:, 1]
            pad = VIEW_PAD_M
        xmin, xmax = math.floor(xs.min() - pad), math.ceil(xs.max() + pad)
        ymin, ymax = math.floor(ys.min() - pad), math.ceil(ys.max() + pad)
        if xmax - xmin < MIN_VIEW_M:
            c = 0.5 * (xmin + xmax)
            xmin, xmax = c - 0.5 * MIN_VIEW_M, c + 0.5 * MIN_VIEW_M
        if ymax - ymin < MIN_VIEW_M:
            c = 0.5 * (ymin + ymax)
            ymin, ymax = c - 0.5 * MIN_VIEW_M, c + 0.5 * MIN_VIEW_M
        return float(xmin), float(ymin), float(xmax), float(ymax)

    def _map_background(self, lane: Lane) -> tuple[np.ndarray, MapView]:
        """The cached floor and grid for the current walls and extent (the walls' shapes in
        pixels are cached with it, see :meth:`_wall_shapes`)."""
        walls, person_h = lane.walls, lane.person_h
        bounds = self._world_bounds(lane)
        key = (bounds, walls.tobytes(), person_h)
        if key == self._map_key and self._map_bg is not None and self._map_view is not None:
            return self._map_bg, self._map_view
        xmin, ymin, xmax, ymax = bounds
        view = fit_view(
            xmin,
            ymin,
            xmax,
            ymax,
            MAP_MARGIN_PX,
            HEADER_PX + MAP_MARGIN_PX,
            PANEL_W_PX - 2 * MAP_MARGIN_PX,
            FRAME_HEIGHT_PX - HEADER_PX - 2 * MAP_MARGIN_PX,
        )
        bg = np.empty((FRAME_HEIGHT_PX, PANEL_W_PX, 3), dtype=np.uint8)
        bg[:] = C_FLOOR
        step = grid_step_m(view.scale)
        # Grid lines over the whole panel, at multiples of the step (world-aligned).
        gx0 = math.floor((0.0 - view.ox) / view.scale / step) * step
        gx1 = (PANEL_W_PX - view.ox) / view.scale
        gy0 = math.floor((view.oy - FRAME_HEIGHT_PX) / view.scale / step) * step
        gy1 = view.oy / view.scale
        for gx in np.arange(gx0, gx1 + step, step):
            cv2.line(bg, view.pt(gx, gy0), view.pt(gx, gy1), C_GRID, 1, cv2.LINE_8, SHIFT)
        for gy in np.arange(gy0, gy1 + step, step):
            cv2.line(bg, view.pt(gx0, gy), view.pt(gx1, gy), C_GRID, 1, cv2.LINE_8, SHIFT)
        bg[:HEADER_PX] = C_BG
        self._wall_polys, self._wall_lines = self._wall_shapes(view, walls, person_h)
        self._map_key, self._map_bg, self._map_view, self._grid_m = key, bg, view, step
        return bg, view

    @staticmethod
    def _wall_shapes(
        view: MapView, walls: np.ndarray, person_h: float
    ) -> tuple[list[tuple[np.ndarray, tuple[int, int, int]]], list[_WallLine]]:
        """Walls and obstacles as drawing commands in map pixels: filled outlines and thick
        segments, shaded by height: at least a person's height (``person_h``, m) dark, since it
        hides a whole body; lower (furniture) light, since it hides legs only. Closed outlines
        are filled, except one enclosing all the others (the room: its floor stays clear)."""
        polys: list[tuple[np.ndarray, tuple[int, int, int]]] = []
        lines: list[_WallLine] = []
        if len(walls) == 0:
            return polys, lines
        tall = walls[:, _W.h] >= person_h
        lo = np.minimum(walls[:, [_W.x1, _W.y1]], walls[:, [_W.x2, _W.y2]]).min(axis=0)
        hi = np.maximum(walls[:, [_W.x1, _W.y1]], walls[:, [_W.x2, _W.y2]]).max(axis=0)
        for k0, k1 in wall_loops(walls):
            loop = walls[k0:k1][:, [_W.x1, _W.y1]]
            encloses_all = np.allclose(loop.min(axis=0), lo, atol=1e-3) and np.allclose(
                loop.max(axis=0), hi, atol=1e-3
            )
            if not encloses_all:
                polys.append((view.px(loop), C_WALL if tall[k0] else C_LOW))
        wall_px = max(2, round(0.1 * view.scale))  # walls are 0.1 m thick in the contacts
        ends = walls[:, [_W.x1, _W.y1, _W.x2, _W.y2]]
        for (x1, y1, x2, y2), is_tall in zip(ends, tall, strict=True):
            color, width = (C_WALL, wall_px) if is_tall else (C_LOW_EDGE, max(1, wall_px // 2))
            lines.append((view.pt(x1, y1), view.pt(x2, y2), color, width))
        return polys, lines

    def _draw_walls(self, img: np.ndarray) -> None:
        """The cached wall shapes; drawn every frame, over the field-of-view wedge, so that
        obstacles keep their shade wherever the camera looks."""
        for poly, color in self._wall_polys:
            cv2.fillPoly(img, [poly], color, cv2.LINE_AA, SHIFT)
        for a, b, color, width in self._wall_lines:
            cv2.line(img, a, b, color, width, cv2.LINE_AA, SHIFT)

    def _draw_map(self, lane: Lane, seen: list[_Seen | None], panel: np.ndarray) -> None:
        bg, view = self._map_background(lane)
        # Drawing goes into a contiguous buffer: some OpenCV calls reject strided views.
        img = bg.copy()
        rx, ry, rth = lane.x, lane.y, lane.th
        c, s = math.cos(rth), math.sin(rth)

        # Field of view: a wedge from the camera's position on the robot.
        tx_cam, ty_cam = float(lane.camera["T"][0]), float(lane.camera["T"][1])
        camx = rx + c * tx_cam - s * ty_cam
        camy = ry + s * tx_cam + c * ty_cam
        az_l, az_r = camera_edge_azimuths(lane.camera)
        sweep = (az_r - az_l + math.pi) % (2.0 * math.pi) - math.pi
        angles = rth + az_l + sweep * np.linspace(0.0, 1.0, 16)
        wedge = np.empty((len(angles) + 1, 2))
        wedge[0] = camx, camy
        wedge[1:, 0] = camx + FRUSTUM_LENGTH_M * np.cos(angles)
        wedge[1:, 1] = camy + FRUSTUM_LENGTH_M * np.sin(angles)
        wedge_px = view.px(wedge)
        blend_poly(img, wedge_px, C_FRUSTUM, FRUSTUM_ALPHA)
        cv2.polylines(img, [wedge_px], True, (200, 160, 40), 1, cv2.LINE_AA, SHIFT)
        self._draw_walls(img)

        # Trails under the bodies.
        for trail, color in ((self.target_trail, C_TARGET), (self.robot_trail, C_ROBOT)):
            if trail.n >= 2:
                cv2.polylines(img, [view.px(trail.points)], False, color, 1, cv2.LINE_AA, SHIFT)

        # Line of sight from the camera to the target's centre, under the bodies, coloured by
        # how much of the target is in sight; dashed when it is outside the field of view,
        # where there is no sight line to speak of.
        n_people = lane.n_people
        sight = self._target_sight(lane, seen)
        if n_people > 0:
            tx, ty, _ = lane.person(0)
            a, b = view.pt(camx, camy), view.pt(tx, ty)
            if sight == SIGHT_OUT_OF_VIEW:
                dashed_polyline(img, np.array([a, b]), False, C_SIGHT[sight], 1)
            else:
                cv2.line(img, a, b, C_SIGHT[sight], 2, cv2.LINE_AA, SHIFT)

        # People: rotated rectangles, ``depth`` along their heading, with a heading tick.
        pw, pd = lane.person_w, lane.person_d
        followed = lane.followed
        labels: list[tuple[str, tuple[int, int], tuple[int, int, int], float]] = []
        for p in range(n_people - 1, -1, -1):  # target last, on top
            px, py, pth = lane.person(p)
            color = C_TARGET if p == 0 else C_OTHER
            poly = view.px(rect_corners(px, py, pth, pd, pw))
            cv2.fillPoly(img, [poly], color, cv2.LINE_AA, SHIFT)
            cv2.polylines(img, [poly], True, C_PERSON_EDGE, 1, cv2.LINE_AA, SHIFT)
            tip = (px + (0.5 * pd + 0.15) * math.cos(pth), py + (0.5 * pd + 0.15) * math.sin(pth))
            cv2.line(img, view.pt(px, py), view.pt(*tip), C_PERSON_EDGE, 1, cv2.LINE_AA, SHIFT)
            u, v = (q >> SHIFT for q in view.pt(px, py))
            # The target's name above, a bystander's below, so the two rarely overlap when
            # one crosses near the other; a followed bystander is named by its ring's label.
            if p == 0:
                labels.append(("target", (u + 8, v - 8), C_TARGET, 0.4))
            elif p != followed:
                labels.append((f"bystander {p}", (u + 8, v + 16), (215, 215, 215), 0.35))

        # The person whose detection the perception took this frame: a ring, green on the
        # target, red with a label on a bystander (a stolen target).
        if 0 <= followed < n_people:
            px, py, _ = lane.person(followed)
            color = C_DET if followed == 0 else C_STOLEN
            radius = max(RING_RADIUS_M * view.scale, 9.0)
            centre = view.pt(px, py)
            cv2.circle(img, centre, round(radius * ONE), color, 2, cv2.LINE_AA, SHIFT)
            org = ((centre[0] >> SHIFT) + 8, (centre[1] >> SHIFT) + round(radius) + 14)
            if followed == 0:
                put_text(img, "followed", org, C_DET, 0.4)
            else:
                put_text(img, f"followed: bystander {followed}", org, C_TEXT, 0.4, True, C_STOLEN)
        for text, org, color, scale in labels:  # over the ring, so they stay legible
            put_text(img, text, org, color, scale)

        # Robot: footprint (centred on the wheel axle) and an arrow along its heading.
        poly = view.px(rect_corners(rx, ry, rth, self.foot_l, self.foot_w))
        cv2.fillPoly(img, [poly], C_ROBOT, cv2.LINE_AA, SHIFT)
        cv2.polylines(img, [poly], True, C_ROBOT_EDGE, 1, cv2.LINE_AA, SHIFT)
        reach = 0.5 * self.foot_l + 0.3
        cv2.arrowedLine(
            img,
            view.pt(rx, ry),
            view.pt(rx + reach * c, ry + reach * s),
            C_ROBOT_EDGE,
            2,
            cv2.LINE_AA,
            SHIFT,
            0.3,
        )
        cv2.circle(img, view.pt(camx, camy), 3 * ONE, (250, 250, 250), -1, cv2.LINE_AA, SHIFT)

        # Header: time, observation, truth (left); who is followed, the target's visible share
        # (middle); the end reason (right).
        line1 = f"t {lane.t:5.1f} s   obs d {lane.obs_d:5.2f} m  offset {lane.obs_o:+5.0f} px"
        line2 = (
            f"true d {lane.true_d:5.2f} m  offset {lane.true_o:+5.0f} px   grid {self._grid_m:g} m"
        )
        put_text(img, line1, (8, 16), box=False)
        put_text(img, line2, (8, 34), (200, 200, 200), box=False)
        if followed == 0:
            put_text(img, "followed: target", (HEADER_MID_PX, 16), C_DET, box=False)
        elif followed > 0:
            text = f"followed: bystander {followed}"
            put_text(img, text, (HEADER_MID_PX, 16), C_TEXT, box=True, box_color=C_STOLEN)
        else:
            put_text(img, "followed: nobody", (HEADER_MID_PX, 16), C_WARN, box=False)
        vis = f"target visible {100.0 * lane.vis_frac:3.0f} %  ({_SIGHT_WORDS[sight]})"
        put_text(img, vis, (HEADER_MID_PX, 34), C_SIGHT[sight], box=False)
        if lane.reason != REASON_NONE:
            text = f"end: {SPEC.terminations[lane.reason]}"
            (tw, _), _ = cv2.getTextSize(text, FONT, FONT_SCALE, 1)
            put_text(img, text, (PANEL_W_PX - tw - 10, 16), C_WARN, box=False)
        panel[:] = img

    # -- camera panel --------------------------------------------------------------------------

    def _camera_background(self, cam: np.void) -> np.ndarray:
        """Letterbox, sky and a floor darkening towards the robot (a depth cue), drawn once:
        the camera is fixed on the robot, so the horizon never moves in the image."""
        bg = np.empty((FRAME_HEIGHT_PX, PANEL_W_PX, 3), dtype=np.uint8)
        bg[:] = C_BG
        h_row = horizon_row(cam) * self.cam_scale  # in the scaled image
        rows = np.arange(self.cam_h, dtype=float)
        below = np.clip((rows - h_row) / max(self.cam_h - h_row, 1.0), 0.0, 1.0)
        far, near = np.array([185.0, 175.0, 160.0]), np.array([130.0, 118.0, 100.0])
        col = far + below[:, None] * (near - far)
        col[rows < h_row] = C_SKY
        img = bg[self.cam_y0 : self.cam_y0 + self.cam_h, self.cam_x0 : self.cam_x0 + self.cam_w]
        img[:] = col[:, None, :].astype(np.uint8)
        if 0.0 <= h_row < self.cam_h:
            y = self.cam_y0 + round(h_row)
            cv2.line(bg, (self.cam_x0, y), (self.cam_x0 + self.cam_w - 1, y), (150, 150, 150), 1)
        return bg

    def _img_pt(self, u: float, v: float) -> tuple[int, int]:
        """Image pixel (px) -> fixed-point panel coordinates."""
        return (
            round((self.cam_x0 + self.cam_scale * u) * ONE),
            round((self.cam_y0 + self.cam_scale * v) * ONE),
        )

    def _below_box(self, a: tuple[int, int], b: tuple[int, int]) -> tuple[int, int]:
        """Where a label under the fixed-point box ``a``-``b`` goes (px): just below it, kept
        inside the image and above the legend."""
        x = min(max(a[0] >> SHIFT, self.cam_x0 + 4), self.cam_x0 + self.cam_w - 190)
        y = (b[1] >> SHIFT) + 16
        return x, min(max(y, self.cam_y0 + 44), self.cam_y0 + self.cam_h - 30)

    def _draw_camera(self, lane: Lane, seen: list[_Seen | None], panel: np.ndarray) -> None:
        if self._cam_bg is None:
            self._cam_bg = self._camera_background(lane.camera)
        img = self._cam_bg.copy()
        W, H = float(lane.camera["img_w"]), float(lane.camera["img_h"])
        sight = self._target_sight(lane, seen)

        # True body boxes, far to near so nearer bodies cover farther ones; labels after all
        # bodies, so a nearer body does not cover a farther one's label.
        order = sorted(((s.dist_m, p) for p, s in enumerate(seen) if s is not None), reverse=True)
        corners_of: dict[int, tuple[int, int]] = {}
        for _, p in order:
            u1, v1, u2, v2 = seen[p].box  # type: ignore[union-attr]
            a, b = self._img_pt(u1, v1), self._img_pt(u2, v2)
            corners_of[p] = a
            if p == 0 and sight == SIGHT_HIDDEN:
                # Nothing of it reaches the camera: only a dashed outline of where it stands.
                corners = np.array([a, (b[0], a[1]), b, (a[0], b[1])], dtype=np.int32)
                dashed_polyline(img, corners, True, C_WARN, 2)
            else:
                cv2.rectangle(img, a, b, C_BODY, -1, cv2.LINE_8, SHIFT)
                cv2.rectangle(img, a, b, C_TRUE_BOX, 1, cv2.LINE_AA, SHIFT)
        for _, p in order:
            a = corners_of[p]
            if p == 0:
                label = f"target (true box, {100.0 * lane.vis_frac:.0f} % visible)"
            else:
                label = f"bystander {p}"
            # Inside the box's top, but below the header line when the box reaches the top;
            # bystanders one row lower than the target, so a crossing does not hide its label.
            y_label = max((a[1] >> SHIFT) + 16, self.cam_y0 + 44) + (0 if p == 0 else 20)
            put_text(img, label, ((a[0] >> SHIFT) + 5, y_label), (225, 225, 225), 0.4)

        # The image's centre column, against which the observation's offset is measured.
        u_mid = float(int(W) // 2)
        top, bottom = self._img_pt(u_mid, 0.0), self._img_pt(u_mid, H)
        cv2.line(img, top, bottom, C_CENTRE, 1, cv2.LINE_AA, SHIFT)

        # The tracker's box (this frame's estimate; the published box lags it by the
        # latency), dashed so the published box stays readable on top of it.
        if lane.track_on:
            cu, cvv, tw, th = lane.track
            hw, hh = 0.5 * tw, 0.5 * th
            a, b = self._img_pt(cu - hw, cvv - hh), self._img_pt(cu + hw, cvv + hh)
            corners = np.array([a, (b[0], a[1]), b, (a[0], b[1])], dtype=np.int32)
            dashed_polyline(img, corners, True, C_TRACK, 2)
            lost = lane.track_lost
            label = "track" if lost == 0 else f"track (coasting {lost})"
            put_text(img, label, self._below_box(a, b), C_TRACK, 0.4)

        # The published detection (already delayed by the perception's latency, as the
        # observation is): box, centre pixel, and the offset as a bar from the centre column;
        # green when it is the target's, red when a bystander's (a stolen target).
        if lane.detected:
            owner = lane.followed
            color = C_STOLEN if owner > 0 else C_DET
            x1, y1, x2, y2 = lane.box
            a, b = self._img_pt(x1, y1), self._img_pt(x2, y2)
            cv2.rectangle(img, a, b, color, 2, cv2.LINE_AA, SHIFT)
            # Centre pixel as the perception takes it (integer column and row).
            cu, cvv = float(int((x1 + x2) / 2.0)), float(int((y1 + y2) / 2.0))
            centre = self._img_pt(cu, cvv)
            cv2.line(img, self._img_pt(u_mid, cvv), centre, color, 2, cv2.LINE_AA, SHIFT)
            cv2.drawMarker(
                img,
                (centre[0] >> SHIFT, centre[1] >> SHIFT),
                color,
                cv2.MARKER_CROSS,
                14,
                2,
                cv2.LINE_AA,
            )
            if owner > 0:
                # Beside the centre marker, mid-height: clear of the boxes' labels at the top.
                org = (
                    min((centre[0] >> SHIFT) + 12, self.cam_x0 + self.cam_w - 190),
                    (centre[1] >> SHIFT) - 10,
                )
                put_text(img, f"published: bystander {owner}", org, C_TEXT, 0.45, True, C_STOLEN)

        # Warnings bottom right, away from the header and the legend.
        x_warn = self.cam_x0 + self.cam_w - 175
        if not lane.detected:
            put_text(img, "no detection", (x_warn, self.cam_y0 + self.cam_h - 10), C_WARN, 0.6)
        if sight == SIGHT_HIDDEN:
            warning = "target hidden"
        elif sight == SIGHT_OUT_OF_VIEW:
            warning = "target out of view"
        elif not lane.in_frame:
            warning = "target too little in sight"  # below the detector's visible share
        else:
            warning = ""
        if warning:
            put_text(img, warning, (x_warn, self.cam_y0 + self.cam_h - 36), C_WARN)

        put_text(
            img,
            f"camera {int(W)}x{int(H)}   obs d {lane.obs_d:5.2f} m   "
            f"offset {lane.obs_o:+5.0f} px   published {lane.latency} frame(s) late",
            (self.cam_x0 + 8, self.cam_y0 + 18),
        )
        put_text(
            img,
            "grey: true boxes   green/red: published (target/bystander)   cyan: track",
            (self.cam_x0 + 8, self.cam_y0 + self.cam_h - 8),
            (220, 220, 220),
            0.4,
        )
        panel[:] = img

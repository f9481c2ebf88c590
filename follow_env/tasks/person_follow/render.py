"""``rgb_array`` frames of PersonFollow-v0: a top-down map beside the robot's camera view,
drawn with OpenCV (headless: no window is ever opened; ``render_mode="human"`` shows the frames
in a window of :mod:`follow_env.sim.window`).

Left panel (map): the room's walls and obstacles fitted to the panel, shaded by height (walls
and pillars at least as tall as a person dark: they hide a whole body; lower furniture light:
it hides legs only), a metre grid, the camera's horizontal field of view, the robot's footprint
with its wheels and a heading arrow, every person as a rotated rectangle (the target, person 0,
in orange, bystanders grey), the trails of the robot and the target, the line of sight from the
camera to the target coloured by how much of the target is in sight (see :func:`sight_state`),
a ring round the person whose detection the perception took this frame (green on the target,
red with "followed: bystander N" when a bystander has stolen it), and a header with time, the
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
from typing import TYPE_CHECKING

import cv2
import numpy as np

from follow_env.platforms import get_platform
from follow_env.sensors.camera import Camera, body_box
from follow_env.sim.drawing import MapView, Trail
from follow_env.tasks.person_follow.render_camera import CameraPanel
from follow_env.tasks.person_follow.render_map import MapPanel
from follow_env.tasks.person_follow.render_style import (
    C_STOLEN,
    FRAME_HEIGHT_PX,
    FRAME_WIDTH_PX,
    PANEL_W_PX,
    SIGHT_CLEAR,
    SIGHT_HIDDEN,
    SIGHT_OUT_OF_VIEW,
    SIGHT_PARTLY,
    Lane,
    Seen,
    WallLine,
    sight_state,
)

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
    "Lane",
    "Renderer",
    "sight_state",
]


class Renderer(MapPanel, CameraPanel):
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
        wheels = get_platform(config.platform.NAME).wheels
        self.wheels = np.zeros((0, 5)) if wheels is None else np.asarray(wheels(config))
        self.robot_trail = Trail()
        self.target_trail = Trail()
        # The map background (floor, grid, walls) only changes with the walls or the view;
        # it is drawn once per key and copied each frame.
        self._map_key: tuple[object, ...] | None = None
        self._map_bg: np.ndarray | None = None
        self._map_view: MapView | None = None
        self._wall_polys: list[tuple[np.ndarray, tuple[int, int, int]]] = []
        self._wall_lines: list[WallLine] = []
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

    def _project_people(self, lane: Lane) -> list[Seen | None]:
        """Every person's true body box in the image (clipped, px) and the share of it inside
        the image, as the core computes them before the line of sight; None when no part of
        the body is in the image."""
        cam = lane.camera
        W, H = float(cam["img_w"]), float(cam["img_h"])
        rx, ry, rth = lane.x, lane.y, lane.th
        R, T = np.asarray(cam["R"]), np.asarray(cam["T"])
        out: list[Seen | None] = []
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
                out.append(Seen(math.hypot(px - rx, py - ry), (c1, c2, c3, c4), share))
            else:
                out.append(None)
        return out

    @staticmethod
    def _target_sight(lane: Lane, seen: list[Seen | None]) -> int:
        """The target's sight state (``SIGHT_*``), see :func:`sight_state`."""
        target = seen[0] if seen else None
        return sight_state(
            lane.vis_frac, 0.0 if target is None else target.image_share, lane.min_visible
        )

    # -- map panel -----------------------------------------------------------------------------

"""``rgb_array`` frames of LineTrace-v0: the field beside a close-up of the sensor grid, drawn
with OpenCV (headless; ``render_mode="human"`` shows them in a window of
:mod:`follow_env.sim.window`).

Left panel (field): the tiles with their seams, the line in black (gaps as a dashed grey
centreline), the robot's footprint with its wheels, its trail, and a header with time,
progress, cross-track error, active cells and the episode end reason. Right panel (close-up,
world axes, 24 cm across, centred on the grid): the floor and the line, the robot's outline,
the 25 sensor spots filled by their reading (white floor dark, the line bright; an active cell,
above the threshold, ringed in green), and below the grid of readings as numbers.

Everything is read from a lane's live records; nothing here changes the simulation.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import cv2
import numpy as np

from follow_env.platforms import get_platform
from follow_env.sim.drawing import (
    ONE,
    SHIFT,
    MapView,
    Trail,
    dashed_polyline,
    draw_robot,
    fit_view,
    put_text,
)
from follow_env.tasks.line_trace.spec import SPEC

if TYPE_CHECKING:
    from follow_env.sim.runner import LaneView
    from follow_env.tasks.line_trace.config import LineTraceConfig

__all__ = ["FRAME_HEIGHT_PX", "FRAME_WIDTH_PX", "Renderer"]

FRAME_HEIGHT_PX = 480
FRAME_WIDTH_PX = 1280
PANEL_W_PX = 640
CLOSE_UP_M = 0.24
C_FLOOR = (236, 236, 228)
C_SEAM = (200, 200, 192)
C_OFF = (90, 90, 96)
C_LINE = (20, 20, 20)
C_GAP = (150, 150, 150)
C_ROBOT = (70, 110, 190)
C_ROBOT_EDGE = (30, 50, 100)
C_TRAIL = (230, 120, 40)
C_ACTIVE = (40, 200, 60)
C_SPOT_EDGE = (120, 120, 120)


class Renderer:
    """Draws ``rgb_array`` frames of a :class:`~follow_env.tasks.line_trace.env.LineTraceEnv`
    (always 480 x 1280 x 3 uint8 RGB).

    :param config: the environment's configuration (the robot's footprint and wheels, the
        line's width, the grid).
    """

    def __init__(self, config: LineTraceConfig) -> None:
        self.config = config
        self.footprint = (config.platform.footprint_length_m, config.platform.footprint_width_m)
        wheels = get_platform(config.platform.NAME).wheels
        self.wheels = np.zeros((0, 5)) if wheels is None else np.asarray(wheels(config))
        self.trail = Trail()
        self._key: tuple[object, ...] | None = None
        self._bg: np.ndarray | None = None
        self._view: MapView | None = None

    def reset(self) -> None:
        """Forget the trail (a new episode starts)."""
        self.trail.clear()

    def record(self, view: LaneView) -> None:
        """Append the robot's position (m) to the trail (called every step)."""
        body = view.state["body"]
        self.trail.append(float(body["x"]), float(body["y"]))

    def draw(self, view: LaneView) -> np.ndarray:
        """The current frame: RGB uint8 (480, 1280, 3), newly allocated."""
        if self.trail.n == 0:
            self.record(view)
        ts = view.state["task"]
        segs = view.world[0][: int(ts["n_seg"])]
        frame = np.empty((FRAME_HEIGHT_PX, FRAME_WIDTH_PX, 3), dtype=np.uint8)
        self._draw_field(view, segs, frame[:, :PANEL_W_PX])
        self._draw_close_up(view, segs, frame[:, PANEL_W_PX:])
        cv2.line(frame, (PANEL_W_PX, 0), (PANEL_W_PX, FRAME_HEIGHT_PX - 1), (0, 0, 0), 2)
        return frame

    # -- panels --------------------------------------------------------------------------------

    def _line(self, img: np.ndarray, view: MapView, segs: np.ndarray, gap_dashes: bool) -> None:
        width = max(1, round(self.config.track.line_width_m * view.scale))
        for seg in segs:
            a = view.pt(float(seg["x1"]), float(seg["y1"]))
            b = view.pt(float(seg["x2"]), float(seg["y2"]))
            if seg["ink"] > 0.0:
                cv2.line(img, a, b, C_LINE, width, cv2.LINE_AA, SHIFT)
            elif gap_dashes:
                dashed_polyline(img, np.array([a, b], dtype=np.int32), False, C_GAP, 1)

    def _background(self, view: LaneView, segs: np.ndarray) -> tuple[np.ndarray, MapView]:
        ts = view.state["task"]
        field = tuple(float(ts[k]) for k in ("x0", "y0", "x1", "y1"))
        key = (field, segs.tobytes())
        if self._key != key or self._bg is None or self._view is None:
            img = np.empty((FRAME_HEIGHT_PX, PANEL_W_PX, 3), dtype=np.uint8)
            img[:] = C_OFF
            x0, y0, x1, y1 = field
            mv = fit_view(x0, y0, x1, y1, 10, 40, PANEL_W_PX - 20, FRAME_HEIGHT_PX - 50)
            corners = mv.px(np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]]))
            cv2.fillPoly(img, [corners], C_FLOOR, cv2.LINE_AA, SHIFT)
            tile = self.config.track.tile_m
            for x in np.arange(x0, x1 + 1e-9, tile):
                cv2.line(img, mv.pt(x, y0), mv.pt(x, y1), C_SEAM, 1, cv2.LINE_AA, SHIFT)
            for y in np.arange(y0, y1 + 1e-9, tile):
                cv2.line(img, mv.pt(x0, y), mv.pt(x1, y), C_SEAM, 1, cv2.LINE_AA, SHIFT)
            self._line(img, mv, segs, gap_dashes=True)
            self._key, self._bg, self._view = key, img, mv
        return self._bg.copy(), self._view

    def _draw_field(self, view: LaneView, segs: np.ndarray, panel: np.ndarray) -> None:
        img, mv = self._background(view, segs)
        body, ts, ep = view.state["body"], view.state["task"], view.state["episode"]
        pose = (float(body["x"]), float(body["y"]), float(body["th"]))
        if self.trail.n > 1:
            cv2.polylines(img, [mv.px(self.trail.points)], False, C_TRAIL, 1, cv2.LINE_AA, SHIFT)
        draw_robot(img, mv, pose, self.footprint, self.wheels, C_ROBOT, C_ROBOT_EDGE)
        reason = SPEC.terminations[int(ep["reason"])]
        header = (
            f"t {float(ep['t']):5.2f} s  progress {float(ts['s']):.2f}/{float(ts['length']):.2f} m"
            f"  cross-track {100 * float(ts['cte']):+.1f} cm  active {int(ts['grid']['active'])}"
        )
        put_text(img, header, (10, 20))
        if reason:
            put_text(img, f"end: {reason}", (10, 40), (255, 220, 120))
        panel[:] = img

    def _draw_close_up(self, view: LaneView, segs: np.ndarray, panel: np.ndarray) -> None:
        grid, body = view.state["task"]["grid"], view.state["body"]
        cx, cy = float(np.mean(grid["cx"])), float(np.mean(grid["cy"]))
        half = 0.5 * CLOSE_UP_M
        mv = fit_view(cx - half, cy - half, cx + half, cy + half, 20, 10, 600, 340)
        panel[:] = C_OFF
        panel[10:350, 20:620] = C_FLOOR
        self._line(panel, mv, segs, gap_dashes=True)
        panel[350:] = C_OFF  # the line may run beyond the floor's window
        pose = (float(body["x"]), float(body["y"]), float(body["th"]))
        layer = panel.copy()
        draw_robot(layer, mv, pose, self.footprint, self.wheels, C_ROBOT, C_ROBOT_EDGE)
        cv2.addWeighted(layer, 0.25, panel, 0.75, 0.0, dst=panel)
        prm = view.params["task"]["sensor"]
        radius = round(float(prm["r_spot"]) * mv.scale * ONE)
        threshold = float(prm["threshold"])
        for j in range(25):
            r = float(grid["reading"][j])
            centre = mv.pt(float(grid["cx"][j]), float(grid["cy"][j]))
            level = int(40 + 215 * r)
            cv2.circle(panel, centre, radius, (level, level, 40), -1, cv2.LINE_AA, SHIFT)
            edge = C_ACTIVE if r > threshold else C_SPOT_EDGE
            cv2.circle(panel, centre, radius, edge, 2 if r > threshold else 1, cv2.LINE_AA, SHIFT)
        readings = np.asarray(grid["reading"]).reshape(5, 5)
        put_text(panel, "readings (row 0 = front, col 0 = left)", (20, 372))
        for i in range(5):
            text = "  ".join(f"{v:4.2f}" for v in readings[i])
            put_text(panel, text, (20, 394 + 18 * i), (255, 255, 255) if i % 2 else (220, 220, 220))
        put_text(panel, f"close-up {100 * CLOSE_UP_M:.0f} cm, world axes", (380, 372))

"""The map panel of PersonFollow's frame: walls shaded by height, the metre grid, the camera's
field of view, the robot and every person, trails, the line of sight to the target, who is
followed, and a header with the time, the observation and the truth."""

from __future__ import annotations

import math

import cv2
import numpy as np

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
from follow_env.tasks.person_follow.render_style import (
    C_AHEAD,
    C_BG,
    C_DET,
    C_FLOOR,
    C_FRUSTUM,
    C_GRID,
    C_LOW,
    C_LOW_EDGE,
    C_OTHER,
    C_PERSON_EDGE,
    C_ROBOT,
    C_ROBOT_EDGE,
    C_SIGHT,
    C_STOLEN,
    C_TARGET,
    C_TEXT,
    C_WALL,
    C_WARN,
    FRAME_HEIGHT_PX,
    FRUSTUM_ALPHA,
    FRUSTUM_LENGTH_M,
    HEADER_MID_PX,
    HEADER_PX,
    MAP_MARGIN_PX,
    MIN_VIEW_M,
    PANEL_W_PX,
    RING_RADIUS_M,
    SIGHT_OUT_OF_VIEW,
    SIGHT_WORDS,
    VIEW_PAD_M,
    Lane,
    Seen,
    W,
    WallLine,
    camera_edge_azimuths,
)
from follow_env.tasks.person_follow.spec import REASON_NONE, SPEC
from follow_env.world.geometry import wall_loops

__all__ = ["MapPanel"]


class MapPanel:
    """The left panel (a mixin of :class:`~follow_env.tasks.person_follow.render.Renderer`,
    which owns the trails, the footprint and the caches these methods use)."""

    robot_trail: Trail
    target_trail: Trail
    foot_l: float
    foot_w: float
    wheels: np.ndarray  # (x, y, length, width, roller slope) per wheel, body frame (m)

    def _world_bounds(self, lane: Lane) -> tuple[float, float, float, float]:
        """Extent (m) the map shows: the walls when there are any; otherwise the people and
        trails, padded and snapped to whole metres so the view (and its cached background)
        changes only now and then."""
        if len(lane.walls) > 0:
            w = lane.walls
            xs = np.concatenate([w[:, W.x1], w[:, W.x2]])
            ys = np.concatenate([w[:, W.y1], w[:, W.y2]])
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
    ) -> tuple[list[tuple[np.ndarray, tuple[int, int, int]]], list[WallLine]]:
        """Walls and obstacles as drawing commands in map pixels: filled outlines and thick
        segments, shaded by height: at least a person's height (``person_h``, m) dark, since it
        hides a whole body; lower (furniture) light, since it hides legs only. Closed outlines
        are filled, except one enclosing all the others (the room: its floor stays clear)."""
        polys: list[tuple[np.ndarray, tuple[int, int, int]]] = []
        lines: list[WallLine] = []
        if len(walls) == 0:
            return polys, lines
        tall = walls[:, W.h] >= person_h
        lo = np.minimum(walls[:, [W.x1, W.y1]], walls[:, [W.x2, W.y2]]).min(axis=0)
        hi = np.maximum(walls[:, [W.x1, W.y1]], walls[:, [W.x2, W.y2]]).max(axis=0)
        for k0, k1 in wall_loops(walls):
            loop = walls[k0:k1][:, [W.x1, W.y1]]
            encloses_all = np.allclose(loop.min(axis=0), lo, atol=1e-3) and np.allclose(
                loop.max(axis=0), hi, atol=1e-3
            )
            if not encloses_all:
                polys.append((view.px(loop), C_WALL if tall[k0] else C_LOW))
        wall_px = max(2, round(0.1 * view.scale))  # walls are 0.1 m thick in the contacts
        ends = walls[:, [W.x1, W.y1, W.x2, W.y2]]
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

    def _draw_map(self, lane: Lane, seen: list[Seen | None], panel: np.ndarray) -> None:
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

        if lane.ahead is not None:
            # The reading ahead, over the bodies: the line across its columns at the depth it
            # read (a depth is measured along the optical axis, so the line is square to it).
            axis = rth + az_l + 0.5 * sweep
            ax, ay = math.cos(axis), math.sin(axis)
            d, half = lane.ahead, lane.ahead * lane.ahead_tan
            mx, my = camx + d * ax, camy + d * ay
            ends = np.array([[mx - half * ay, my + half * ax], [mx + half * ay, my - half * ax]])
            cv2.line(img, *map(tuple, view.px(ends)), C_AHEAD, 2, cv2.LINE_AA, SHIFT)

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
        # The platform's wheels, with a stroke along a mecanum wheel's rollers.
        for wx, wy, wl, ww, slope in self.wheels:
            cx, cy = rx + wx * c - wy * s, ry + wx * s + wy * c
            wheel = view.px(rect_corners(cx, cy, rth, wl, ww))
            cv2.fillPoly(img, [wheel], C_ROBOT_EDGE, cv2.LINE_AA, SHIFT)
            if slope:
                half = 0.35 * wl / math.hypot(1.0, slope)
                dx, dy = half * (c - slope * s), half * (s + slope * c)
                end1, end2 = view.pt(cx - dx, cy - dy), view.pt(cx + dx, cy + dy)
                cv2.line(img, end1, end2, C_ROBOT, 1, cv2.LINE_AA, SHIFT)
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
        vis = f"target visible {100.0 * lane.vis_frac:3.0f} %  ({SIGHT_WORDS[sight]})"
        put_text(img, vis, (HEADER_MID_PX, 34), C_SIGHT[sight], box=False)
        if lane.reason != REASON_NONE:
            text = f"end: {SPEC.terminations[lane.reason]}"
            (tw, _), _ = cv2.getTextSize(text, FONT, FONT_SCALE, 1)
            put_text(img, text, (PANEL_W_PX - tw - 10, 16), C_WARN, box=False)
        panel[:] = img

    # -- camera panel --------------------------------------------------------------------------

"""The camera panel of PersonFollow's frame: the image with the true body boxes, the published
detection (green on the target, red on a bystander) and its offset from the centre column, the
tracker's box, and warnings."""

from __future__ import annotations

import cv2
import numpy as np

from follow_env.sensors.depth import ahead_column
from follow_env.sim.drawing import ONE, SHIFT, dashed_polyline, put_text
from follow_env.tasks.person_follow.render_style import (
    C_AHEAD,
    C_BG,
    C_BODY,
    C_CENTRE,
    C_DET,
    C_SKY,
    C_STOLEN,
    C_TEXT,
    C_TRACK,
    C_TRUE_BOX,
    C_WARN,
    FRAME_HEIGHT_PX,
    PANEL_W_PX,
    SIGHT_HIDDEN,
    SIGHT_OUT_OF_VIEW,
    Lane,
    Seen,
    horizon_row,
)

__all__ = ["CameraPanel"]

_column = ahead_column.py_func  # where the perception reads ahead, as plain Python


class CameraPanel:
    """The right panel (a mixin of :class:`~follow_env.tasks.person_follow.render.Renderer`,
    which sets the letterbox geometry ``cam_*`` in its constructor)."""

    cam_scale: float
    cam_w: int
    cam_h: int
    cam_x0: int
    cam_y0: int

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

    def _draw_camera(self, lane: Lane, seen: list[Seen | None], panel: np.ndarray) -> None:
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

        # The reading ahead: its columns on the middle row, and what it read.
        if lane.ahead is not None:
            cam = lane.camera
            cx, cy, fx = float(cam["cx"]), float(cam["cy"]), float(cam["fx"])
            for k in range(lane.ahead_rays):
                u = _column(k, lane.ahead_rays, cx, fx, lane.ahead_tan)
                cv2.drawMarker(
                    img,
                    tuple(q >> SHIFT for q in self._img_pt(u, cy)),
                    C_AHEAD,
                    cv2.MARKER_DIAMOND,
                    8,
                    2,
                    cv2.LINE_AA,
                )
            org = (self.cam_x0 + 8, self.cam_y0 + 40)
            put_text(img, f"ahead {lane.ahead:5.2f} m", org, C_AHEAD)

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

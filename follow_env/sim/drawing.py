"""Drawing helpers shared by the tasks' renderers (OpenCV, headless: no window is opened).

Coordinates on screen are OpenCV fixed-point pixels with :data:`SHIFT` fractional bits, so that
thin lines and small shapes are drawn with sub-pixel precision. :class:`MapView` maps world
metres (x right, y up) to map pixels; :class:`Trail` grows a list of positions cheaply.
"""

from __future__ import annotations

import itertools
import math

import cv2
import numpy as np

__all__ = [
    "DASH_PX",
    "FONT",
    "FONT_SCALE",
    "MIN_GRID_PX",
    "ONE",
    "SHIFT",
    "MapView",
    "Trail",
    "blend_poly",
    "dashed_polyline",
    "draw_robot",
    "fit_view",
    "grid_step_m",
    "put_text",
    "rect_corners",
]

# Sub-pixel drawing: OpenCV takes fixed-point coordinates with this many fractional bits.
SHIFT = 4
ONE = 1 << SHIFT
FONT = cv2.FONT_HERSHEY_SIMPLEX
FONT_SCALE = 0.45
DASH_PX = 6.0  # dash and gap length of dashed lines
MIN_GRID_PX = 8.0  # coarser grid when 1 m would be closer than this on screen
TEXT = (240, 240, 240)
TEXT_BOX = (40, 42, 48)


class Trail:
    """A growing (n, 2) float array of positions (m); appends are amortised O(1)."""

    def __init__(self, capacity: int = 256) -> None:
        self._buf = np.empty((capacity, 2))
        self.n = 0

    def clear(self) -> None:
        self.n = 0

    def append(self, x: float, y: float) -> None:
        if self.n == len(self._buf):
            self._buf = np.concatenate([self._buf, np.empty_like(self._buf)])
        self._buf[self.n] = x, y
        self.n += 1

    @property
    def points(self) -> np.ndarray:
        """The recorded positions, oldest first (a view, m)."""
        return self._buf[: self.n]


class MapView:
    """World metres -> map pixels: x to the right, y up (the image's rows grow downwards)."""

    def __init__(self, scale: float, ox: float, oy: float) -> None:
        self.scale = scale  # px per m
        self.ox, self.oy = ox, oy  # px of the world origin

    def px(self, xy: np.ndarray) -> np.ndarray:
        """Fixed-point int32 pixel coordinates (``SHIFT`` fractional bits) of (..., 2) m."""
        xy = np.asarray(xy, dtype=float)
        out = np.empty(xy.shape, dtype=np.int32)
        out[..., 0] = np.round((self.ox + self.scale * xy[..., 0]) * ONE)
        out[..., 1] = np.round((self.oy - self.scale * xy[..., 1]) * ONE)
        return out

    def pt(self, x: float, y: float) -> tuple[int, int]:
        """One point as a fixed-point tuple (for ``cv2.line`` / ``cv2.circle``)."""
        return (round((self.ox + self.scale * x) * ONE), round((self.oy - self.scale * y) * ONE))


def fit_view(
    xmin: float, ymin: float, xmax: float, ymax: float, x0: int, y0: int, w: int, h: int
) -> MapView:
    """The largest uniform scale showing ``[xmin, xmax] x [ymin, ymax]`` (m) centred in the
    pixel rectangle at ``(x0, y0)`` of size ``w x h`` (px)."""
    span_x, span_y = max(xmax - xmin, 1e-6), max(ymax - ymin, 1e-6)
    scale = min(w / span_x, h / span_y)
    ox = x0 + 0.5 * w - scale * 0.5 * (xmin + xmax)
    oy = y0 + 0.5 * h + scale * 0.5 * (ymin + ymax)
    return MapView(scale, ox, oy)


def grid_step_m(scale_px_per_m: float) -> float:
    """The metre grid's spacing (m): 1 m unless that is too dense to read on screen."""
    for step in (1.0, 2.0, 5.0, 10.0, 20.0, 50.0, 100.0):
        if step * scale_px_per_m >= MIN_GRID_PX:
            return step
    return 200.0


def rect_corners(x: float, y: float, th: float, length: float, width: float) -> np.ndarray:
    """Corners (4, 2) (m) of a rectangle centred at ``(x, y)``, ``length`` along heading ``th``
    (rad) and ``width`` across it, in drawing order."""
    c, s = math.cos(th), math.sin(th)
    hl, hw = 0.5 * length, 0.5 * width
    local = np.array([[hl, hw], [-hl, hw], [-hl, -hw], [hl, -hw]])
    rot = np.array([[c, -s], [s, c]])
    return local @ rot.T + (x, y)


def put_text(
    img: np.ndarray,
    text: str,
    org: tuple[int, int],
    color: tuple[int, int, int] = TEXT,
    scale: float = FONT_SCALE,
    box: bool = True,
    box_color: tuple[int, int, int] = TEXT_BOX,
) -> None:
    """Text whose baseline starts at ``org`` (px), on a filled box (``box_color``, dark unless
    told) so it reads on any background.

    A box rather than a thick dark outline: OpenCV 5's fonts widen with thickness, so an
    outline drawn thicker does not line up with the text."""
    if box:
        (tw, th), base = cv2.getTextSize(text, FONT, scale, 1)
        x, y = org
        cv2.rectangle(img, (x - 3, y - th - 3), (x + tw + 3, y + base), box_color, -1)
    cv2.putText(img, text, org, FONT, scale, color, 1, cv2.LINE_AA)


def blend_poly(
    img: np.ndarray, poly_fx: np.ndarray, color: tuple[int, int, int], alpha: float
) -> None:
    """Fill a fixed-point polygon (n, 2) translucently; blends only its bounding box, which
    keeps this cheap whatever the panel size."""
    h, w = img.shape[:2]
    x1, y1 = (poly_fx.min(axis=0) >> SHIFT) - 1
    x2, y2 = (poly_fx.max(axis=0) >> SHIFT) + 2
    x1, y1, x2, y2 = max(int(x1), 0), max(int(y1), 0), min(int(x2), w), min(int(y2), h)
    if x2 <= x1 or y2 <= y1:
        return
    roi = img[y1:y2, x1:x2]
    layer = roi.copy()
    shifted = poly_fx - np.array([x1 * ONE, y1 * ONE], dtype=np.int32)
    cv2.fillPoly(layer, [shifted], color, cv2.LINE_AA, SHIFT)
    cv2.addWeighted(layer, alpha, roi, 1.0 - alpha, 0.0, dst=roi)


def dashed_polyline(
    img: np.ndarray,
    pts_fx: np.ndarray,
    closed: bool,
    color: tuple[int, int, int],
    thickness: int = 1,
    dash_px: float = DASH_PX,
) -> None:
    """A dashed polyline through fixed-point points (n, 2): dashes and gaps of ``dash_px``
    (px) along each edge, drawn in one OpenCV call."""
    pts = pts_fx.astype(float)
    if closed:
        pts = np.vstack([pts, pts[:1]])
    dashes = []
    period = 2.0 * dash_px * ONE
    for a, b in itertools.pairwise(pts):
        length = float(np.hypot(*(b - a)))
        if length <= 0.0:
            continue
        starts = np.arange(0.0, length, period)
        ends = np.minimum(starts + 0.5 * period, length)
        d = (b - a) / length
        seg = np.stack([a + starts[:, None] * d, a + ends[:, None] * d], axis=1)
        dashes.append(np.round(seg).astype(np.int32))
    if dashes:
        cv2.polylines(
            img, list(np.concatenate(dashes)), False, color, thickness, cv2.LINE_AA, SHIFT
        )


def draw_robot(
    img: np.ndarray,
    view: MapView,
    pose: tuple[float, float, float],
    footprint: tuple[float, float],
    wheels: np.ndarray,
    body_color: tuple[int, int, int],
    edge_color: tuple[int, int, int],
) -> None:
    """A robot seen from above: its footprint ``(length, width)`` (m) centred on ``pose``
    ``(x m, y m, heading rad)``, and its wheels (rows ``(x, y, length, width, roller slope)``
    in the body frame, as platforms describe them), with a stroke along a mecanum wheel's
    rollers."""
    rx, ry, rth = pose
    c, s = math.cos(rth), math.sin(rth)
    poly = view.px(rect_corners(rx, ry, rth, footprint[0], footprint[1]))
    cv2.fillPoly(img, [poly], body_color, cv2.LINE_AA, SHIFT)
    cv2.polylines(img, [poly], True, edge_color, 1, cv2.LINE_AA, SHIFT)
    for wx, wy, wl, ww, slope in wheels:
        cx, cy = rx + wx * c - wy * s, ry + wx * s + wy * c
        wheel = view.px(rect_corners(cx, cy, rth, wl, ww))
        cv2.fillPoly(img, [wheel], edge_color, cv2.LINE_AA, SHIFT)
        if slope:
            half = 0.35 * wl / math.hypot(1.0, slope)
            dx, dy = half * (c - slope * s), half * (s + slope * c)
            cv2.line(img, view.pt(cx - dx, cy - dy), view.pt(cx + dx, cy + dy), body_color, 1,
                     cv2.LINE_AA, SHIFT)  # fmt: skip

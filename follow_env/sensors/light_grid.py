"""The mecanum paper's 5 x 5 grid of phototransistors under the robot (reference §2).

Each cell is an LED and a phototransistor looking down at a round spot of the floor. What a cell
reads, every control step (:func:`read`):

1. ``c``, the share of its spot covered by the drawn line, from :data:`SPOT_SAMPLES` points
   spread evenly over the spot (a sunflower pattern; 1 / 24 resolution), each on the line when
   it is within half the line's width of a drawn segment (:mod:`follow_env.world.floor_line`).
2. The light coming back: ``b = g_i (h0 / h)^2 (rho_w (1 - c) + rho_b c) + A``, the LED's light
   reflected by white (``rho_w``) and black (``rho_b``) floor in proportion, falling with the
   square of the height ``h`` above the floor (calibrated at ``h0``), times the cell's gain
   ``g_i`` (per episode, manufacturing spread), plus ambient light ``A`` (a per-episode level
   that flickers from step to step: lamps, shadows), all in units of the LED's light off white
   floor at ``h0``.
3. The reading, calibrated so that at ``h0`` without ambient light it is ``c``:
   ``r = clip((rho_w - b) / (rho_w - rho_b) + noise, 0, 1)``: 0 white, 1 black. Ambient light
   makes the line look paler; a sensor mounted higher sees everything darker.

A cell is *active* when its reading exceeds the threshold. Cell ``(i, j)`` sits
``(2 - i) pitch`` ahead of the grid's centre and ``(2 - j) pitch`` to its left; the grid's
centre is ``offset_x_m`` ahead of the robot's reference point. Every draw is counter-based
(:data:`follow_env.sim.streams.LIGHT`): the noise of step k is the same whatever the robot did.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from follow_env.sim import streams
from follow_env.sim.config import Validated, param
from follow_env.sim.jit import njit
from follow_env.sim.rng import LaneRandom, normal_at
from follow_env.sim.schema import Block, f8
from follow_env.world.floor_line import segment_distance

__all__ = [
    "CELLS",
    "GAINS",
    "NEAR_MAX",
    "NOISE",
    "PARAMS",
    "SPOT_SAMPLES",
    "STATE",
    "LightGridConfig",
    "cell_positions",
    "randomize",
    "read",
]

ROWS = COLS = 5
CELLS = ROWS * COLS
NEAR_MAX = 48
"""Line segments near the grid the scratch list holds (far more than the default grid meets on
the built-in tracks). With more near (small tiles under a wide grid), :func:`read` scans every
segment of the line instead: slower, and as exact."""
SPOT_SAMPLES = 24
_GOLDEN_ANGLE = math.pi * (3.0 - math.sqrt(5.0))
# Equal-area points of the unit disc (Vogel's sunflower): point k at radius sqrt((k + 0.5) / n).
_SPOT = np.array(
    [
        (
            math.sqrt((k + 0.5) / SPOT_SAMPLES) * math.cos(k * _GOLDEN_ANGLE),
            math.sqrt((k + 0.5) / SPOT_SAMPLES) * math.sin(k * _GOLDEN_ANGLE),
        )
        for k in range(SPOT_SAMPLES)
    ]
)
# Cell offsets from the grid's centre in pitches, observation order (row 0 front, col 0 left).
_CELL_XY = np.array([(2.0 - i, 2.0 - j) for i in range(ROWS) for j in range(COLS)])


@dataclass(frozen=True)
class LightGridConfig(Validated):
    """The 5 x 5 phototransistor grid (reference §2 gives the grid; every number is a choice)."""

    pitch_m: float = param(
        0.012,
        0.003,
        0.1,
        "m",
        "choice: 12 mm between cells, a 4.8 cm grid: a 1.9 cm line covers 1-2 cells a row",
    )
    spot_diameter_m: float = param(
        0.008,
        0.001,
        0.05,
        "m",
        "choice: the floor a phototransistor sees from about 5 mm with a 40 deg cone",
    )
    height_m: float = param(
        0.005, 0.001, 0.05, "m", "choice: sensors 5 mm above the floor, as line tracers mount them"
    )
    calibrated_height_m: float = param(
        0.005, 0.001, 0.05, "m", "choice: the height the readings were calibrated at"
    )
    offset_x_m: float = param(
        0.0,
        -0.5,
        0.5,
        "m",
        "reference §2: the grid's centre is the robot's centre (the circle is 'around the "
        "robot centre')",
    )
    white_reflectance: float = param(0.8, 0.05, 1.0, "", "choice: white paper or vinyl tiles")
    black_reflectance: float = param(0.05, 0.0, 0.5, "", "choice: black electrical tape")
    noise_std: float = param(
        0.03, 0.0, 0.5, "", "choice: reading noise, share of the white-black span, per step"
    )
    ambient_max: float = param(
        0.1,
        0.0,
        1.0,
        "",
        "choice: ambient light level per episode, U(0, this), in LED light off white floor",
    )
    ambient_flicker: float = param(
        0.2, 0.0, 1.0, "", "choice: relative std of the ambient light's step-to-step variation"
    )
    gain_spread: float = param(
        0.05, 0.0, 0.5, "", "choice: std of each cell's sensitivity per episode"
    )
    threshold: float = param(
        0.5, 0.0, 1.0, "", "choice: a reading above this is an active cell (half covered)"
    )

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.black_reflectance >= self.white_reflectance:
            raise ValueError(
                f"LightGridConfig.black_reflectance={self.black_reflectance!r} is out of "
                f"range: must be < white_reflectance ({self.white_reflectance})"
            )


def _s(name: str) -> str:
    return f"sensor.{name}"


PARAMS = Block(
    "light_grid_params",
    "the light-sensor grid: geometry, optics, noise (per episode: gains, ambient level)",
    [
        f8("pitch", "m", "distance between cells", source=_s("pitch_m")),
        f8(
            "r_spot",
            "m",
            "radius of a cell's spot",
            source=lambda c: 0.5 * c.sensor.spot_diameter_m,
        ),
        f8("offset_x", "m", "grid centre ahead of the reference point", source=_s("offset_x_m")),
        f8(
            "optics",
            "",
            "(h0 / h)^2: light back from the floor relative to the calibration",
            source=lambda c: (c.sensor.calibrated_height_m / c.sensor.height_m) ** 2,
        ),
        f8("rho_w", "", "white reflectance", source=_s("white_reflectance")),
        f8("rho_b", "", "black reflectance", source=_s("black_reflectance")),
        f8("noise", "", "reading noise std", source=_s("noise_std")),
        f8("flicker", "", "ambient light's relative std per step", source=_s("ambient_flicker")),
        f8("threshold", "", "active above this", source=_s("threshold")),
        f8("ambient", "", "this episode's ambient light level (drawn)"),
        f8(
            "gain",
            "",
            "each cell's sensitivity this episode (drawn)",
            shape=(CELLS,),
            source=lambda c: 1.0,
        ),
    ],
)

STATE = Block(
    "light_grid_state",
    "what the grid reads this step, and where its cells are",
    [
        f8("reading", "", "each cell's reading, observation order", shape=(CELLS,)),
        f8("cover", "", "each cell's spot share on the drawn line (truth)", shape=(CELLS,)),
        f8("cx", "m", "each cell's centre, x (world)", shape=(CELLS,)),
        f8("cy", "m", "each cell's centre, y (world)", shape=(CELLS,)),
        f8("seen", "", "1: some spot overlaps the line, gaps counted as line"),
        f8("ink_seen", "", "1: some spot overlaps the drawn line"),
        f8("active", "", "cells above the threshold"),
        f8("ambient_now", "", "ambient light this step"),
        f8("near", "", "scratch: indices of the segments near the grid", shape=(NEAR_MAX,)),
    ],
)

GAINS = streams.per_episode(
    "light_grid.gains", streams.LIGHT, 0, CELLS, space="normal", doc="each cell's sensitivity"
)
AMBIENT = streams.per_episode(
    "light_grid.ambient", streams.LIGHT, CELLS, 1, space="uniform", doc="ambient light level"
)
NOISE = streams.per_step(
    "light_grid.noise",
    streams.LIGHT,
    0,
    CELLS + 1,
    stride=32,
    space="normal",
    doc="each cell's reading noise (offset j), then the ambient light's flicker (offset 25)",
)
_LIGHT = streams.LIGHT.index
_STRIDE = NOISE.stride


def cell_positions(x: float, y: float, th: float, pitch_m: float, offset_x_m: float) -> np.ndarray:
    """World positions (25, 2) (m) of the cells of a grid on a robot at ``(x, y, th)``."""
    c, s = math.cos(th), math.sin(th)
    bx = offset_x_m + pitch_m * _CELL_XY[:, 0]
    by = pitch_m * _CELL_XY[:, 1]
    return np.stack([x + c * bx - s * by, y + s * bx + c * by], axis=1)


@njit(inline="always")
def read(
    prm: np.void,
    st: np.void,
    x: float,
    y: float,
    th: float,
    segs: np.ndarray,
    n_seg: int,
    half_w: float,
    keys: np.ndarray,
    step: int,
) -> None:
    """Every cell's reading for a robot at ``(x, y, th)`` over the line ``segs[:n_seg]`` of half
    width ``half_w`` (m), at control step ``step`` (module docstring); results in ``st``."""
    c, s = math.cos(th), math.sin(th)
    gx, gy = x + c * prm.offset_x, y + s * prm.offset_x
    r_spot = prm.r_spot
    see = half_w + r_spot
    # Every piece that could touch a spot: its midpoint within half its length plus the
    # grid's reach (corner cell, spot and line) of the grid's centre.
    reach = 2.0 * math.sqrt(2.0) * prm.pitch + see
    n_near = 0
    for k in range(n_seg):
        seg = segs[k]
        dx, dy = seg.mx - gx, seg.my - gy
        lim = 0.5 * seg.length + reach
        if dx * dx + dy * dy <= lim * lim:
            if n_near < NEAR_MAX:
                st.near[n_near] = k
            n_near += 1
    # More pieces near than the scratch list holds: scan the whole line (NEAR_MAX's note).
    every = n_near > NEAR_MAX
    n_scan = n_seg if every else n_near
    key = keys[_LIGHT]
    base = step * _STRIDE
    amb = prm.ambient * (1.0 + prm.flicker * normal_at(key, base + CELLS))
    amb = max(amb, 0.0)
    st.ambient_now = amb
    seen, ink_seen, active = 0.0, 0.0, 0.0
    span = prm.rho_w - prm.rho_b
    for j in range(CELLS):
        bx = prm.offset_x + prm.pitch * _CELL_XY[j, 0]
        by = prm.pitch * _CELL_XY[j, 1]
        px, py = x + c * bx - s * by, y + s * bx + c * by
        st.cx[j], st.cy[j] = px, py
        d_all, d_ink = np.inf, np.inf
        for m in range(n_scan):
            seg = segs[m if every else int(st.near[m])]
            d = segment_distance(seg, px, py)
            d_all = min(d_all, d)
            if seg.ink > 0.0:
                d_ink = min(d_ink, d)
        if d_all < see:
            seen = 1.0
        if d_ink >= see:
            cover = 0.0
        elif d_ink + r_spot <= half_w:
            cover = 1.0
        else:
            hits = 0
            for q in range(SPOT_SAMPLES):
                qx = px + r_spot * _SPOT[q, 0]
                qy = py + r_spot * _SPOT[q, 1]
                for m in range(n_scan):
                    seg = segs[m if every else int(st.near[m])]
                    if seg.ink > 0.0 and segment_distance(seg, qx, qy) <= half_w:
                        hits += 1
                        break
            cover = hits / SPOT_SAMPLES
        if cover > 0.0:
            ink_seen = 1.0
        st.cover[j] = cover
        light = prm.gain[j] * prm.optics * (prm.rho_w * (1.0 - cover) + prm.rho_b * cover) + amb
        r = (prm.rho_w - light) / span + prm.noise * normal_at(key, base + j)
        r = min(max(r, 0.0), 1.0)
        st.reading[j] = r
        if r > prm.threshold:
            active += 1.0
    st.seen, st.ink_seen, st.active = seen, ink_seen, active


def randomize(params: np.ndarray, lanes: np.ndarray, cfg: Any, keys: np.ndarray) -> None:
    """Per-episode draws of ``lanes``: each cell's gain ``1 + gain_spread z`` (clipped to
    [0.5, 1.5]) and the ambient level ``U(0, ambient_max)``.

    :param params: the grid's parameter records of all lanes (written in place).
    :param lanes: lane indices. :param cfg: the configuration (its ``sensor`` section).
    :param keys: the lanes' stream keys ``(len(lanes), N_STREAMS)``.
    """
    sc = cfg.sensor
    rng = LaneRandom(keys[:, _LIGHT])
    params["gain"][lanes] = np.clip(1.0 + sc.gain_spread * rng.normal(CELLS, at=GAINS), 0.5, 1.5)
    params["ambient"][lanes] = rng.uniform(high=sc.ambient_max, at=AMBIENT)

"""Perception: detector model, first-detection rule, depth sampling, distance filter (SPEC §1.4).

Compiled helpers called by the core's kernel for one lane; each is also usable on its own.
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["clip_box", "depth_noise_std", "distance_filter", "first_detection", "jitter_box"]


@njit(cache=True, inline="always")
def clip_box(
    u1: float, v1: float, u2: float, v2: float, width: float, height: float
) -> tuple[float, float, float, float]:
    """Clip a box to the image ``[0, width] x [0, height]`` (px). An empty result has
    ``u2 <= u1`` or ``v2 <= v1``."""
    return max(u1, 0.0), max(v1, 0.0), min(u2, width), min(v2, height)


@njit(cache=True, inline="always")
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
    (SPEC §1.3: about 1/20 of the box height), width and height scale by ``1 + size_frac z``.
    ``z_*`` are standard normal draws."""
    w, h = u2 - u1, v2 - v1
    cu = 0.5 * (u1 + u2) + center_frac * h * z_cu
    cv = 0.5 * (v1 + v2) + center_frac * h * z_cv
    w = max(w * (1.0 + size_frac * z_w), 1.0)
    h = max(h * (1.0 + size_frac * z_h), 1.0)
    return cu - 0.5 * w, cv - 0.5 * h, cu + 0.5 * w, cv + 0.5 * h


@njit(cache=True, inline="always")
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


@njit(cache=True, inline="always")
def listed_before(area: float, best_area: float) -> bool:
    """The detector's order: does a box of ``area`` (px^2) come before the best so far?

    Detectors list boxes by confidence; it is modelled as box area, largest first, and a tie
    keeps the box seen first.
    """
    return area > best_area


@njit(cache=True)
def first_detection(boxes: np.ndarray, detected: np.ndarray) -> int:
    """The detection the robot follows: the first of the detector's list (SPEC §1.4 step 2).

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


@njit(cache=True, inline="always")
def depth_noise_std(z_m: float, subpixel: float, focal_px: float, baseline_m: float) -> float:
    """D435i depth RMS error (m) at depth ``z_m`` (SPEC §1.3): ``Z^2 subpixel / (f B)``."""
    return z_m * z_m * subpixel / (focal_px * baseline_m)


@njit(cache=True, inline="always")
def distance_filter(
    raw_m: float, prev_m: float, history: np.ndarray, count: int, head: int, length: int
) -> tuple[float, int, int]:
    """The asymmetric distance filter of SPEC §1.4 step 4.

    * ``raw == 0`` (invalid depth): keep the previous value;
    * ``raw < prev`` (approaching): reset the history to ``[raw]`` and return ``raw``;
    * otherwise (receding): append ``raw`` to a history of fixed ``length`` (oldest dropped)
      and return the history's mean.

    ``history`` is a ring buffer of at least ``length`` slots holding ``count`` values, the
    newest at ``head``; it is updated in place.

    :return: ``(distance m, new count, new head)``.
    """
    if raw_m == 0.0:
        return prev_m, count, head
    if raw_m < prev_m:
        history[0] = raw_m
        return raw_m, 1, 0
    head = (head + 1) % length if count > 0 else 0
    history[head] = raw_m
    count = min(count + 1, length)
    total = 0.0
    for k in range(count):
        total += history[(head - k) % length]
    return total / count, count, head

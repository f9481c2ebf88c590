"""Detector model, first-detection rule, depth noise and the distance filter (SPEC §1.4)."""

from __future__ import annotations

import numpy as np
import pytest

from follow_env.perception import (
    clip_box,
    depth_noise_std,
    distance_filter,
    first_detection,
    jitter_box,
)


def _filter(values: list[float], length: int = 3) -> list[float]:
    hist = np.zeros(32)
    prev, count, head, out = 0.0, 0, 0, []
    for raw in values:
        prev, count, head = distance_filter(raw, prev, hist, count, head, length)
        out.append(prev)
    return out


def test_filter_invalid_depth_keeps_the_previous_value() -> None:
    assert _filter([2.0, 0.0]) == [2.0, 2.0]


def test_filter_approaching_resets_history_and_returns_raw() -> None:
    # 2.0, 3.0 -> mean 2.5; then 1.0 < 2.5: history = [1.0], returns 1.0; then 2.0 -> (1+2)/2
    assert _filter([2.0, 3.0, 1.0, 2.0]) == [2.0, 2.5, 1.0, 1.5]


def test_filter_receding_returns_the_mean_of_a_fixed_length_history() -> None:
    out = _filter([1.0, 2.0, 3.0, 4.0, 5.0], length=3)
    assert out == pytest.approx([1.0, 1.5, 2.0, 3.0, 4.0])  # last: mean(3, 4, 5)


def test_filter_equal_reading_counts_as_receding() -> None:
    assert _filter([2.0, 2.0, 2.0]) == [2.0, 2.0, 2.0]


def test_filter_first_reading_starts_the_history() -> None:
    assert _filter([1.7]) == [1.7]


def test_first_detection_takes_the_detector_first_box_by_area() -> None:
    boxes = np.array([[0, 0, 10, 10], [0, 0, 30, 30], [0, 0, 20, 20]], dtype=float)
    assert first_detection(boxes, np.array([True, True, True])) == 1
    assert first_detection(boxes, np.array([True, False, True])) == 2
    assert first_detection(boxes, np.array([False, False, False])) == -1


def test_first_detection_can_pick_a_bystander_over_the_target() -> None:
    # The target (index 0) is smaller than a nearer bystander: the bystander wins (no tracking).
    boxes = np.array([[100, 100, 150, 300], [300, 50, 420, 470]], dtype=float)
    assert first_detection(boxes, np.array([True, True])) == 1


def test_depth_noise_grows_with_the_square_of_depth() -> None:
    s1 = depth_noise_std(1.0, 0.08, 424.0, 0.05)
    s2 = depth_noise_std(2.0, 0.08, 424.0, 0.05)
    s4 = depth_noise_std(4.0, 0.08, 424.0, 0.05)
    assert s1 == pytest.approx(0.08 / (424 * 0.05))  # ~3.8 mm at 1 m (SPEC §1.3)
    assert s2 == pytest.approx(4 * s1)
    assert s4 == pytest.approx(16 * s1)
    assert 0.05 < s4 < 0.07  # SPEC: roughly 60 mm at 4 m


def test_jitter_moves_the_centre_by_a_fraction_of_the_box_height() -> None:
    u1, v1, u2, v2 = jitter_box(100, 100, 200, 300, 1.0, -1.0, 0.0, 0.0, 0.05, 0.05)
    assert (u1 + u2) / 2 == pytest.approx(150 + 0.05 * 200)
    assert (v1 + v2) / 2 == pytest.approx(200 - 0.05 * 200)
    assert (u2 - u1, v2 - v1) == pytest.approx((100, 200))


def test_clip_box_keeps_the_part_inside_the_image() -> None:
    assert clip_box(-10, 20, 700, 500, 640, 480) == (0, 20, 640, 480)

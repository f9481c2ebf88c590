"""The detector model: the first-detection rule, box jitter, clipping (reference §1.3, §1.4)."""

from __future__ import annotations

import numpy as np
import pytest

from follow_env.sensors.detector import clip_box, first_detection, jitter_box


def test_first_detection_takes_the_detector_first_box_by_area() -> None:
    boxes = np.array([[0, 0, 10, 10], [0, 0, 30, 30], [0, 0, 20, 20]], dtype=float)
    assert first_detection(boxes, np.array([True, True, True])) == 1
    assert first_detection(boxes, np.array([True, False, True])) == 2
    assert first_detection(boxes, np.array([False, False, False])) == -1


def test_first_detection_can_pick_a_bystander_over_the_target() -> None:
    # The target (index 0) is smaller than a nearer bystander: the bystander wins (no tracking).
    boxes = np.array([[100, 100, 150, 300], [300, 50, 420, 470]], dtype=float)
    assert first_detection(boxes, np.array([True, True])) == 1


def test_jitter_moves_the_centre_by_a_fraction_of_the_box_height() -> None:
    u1, v1, u2, v2 = jitter_box(100, 100, 200, 300, 1.0, -1.0, 0.0, 0.0, 0.05, 0.05)
    assert (u1 + u2) / 2 == pytest.approx(150 + 0.05 * 200)
    assert (v1 + v2) / 2 == pytest.approx(200 - 0.05 * 200)
    assert (u2 - u1, v2 - v1) == pytest.approx((100, 200))


def test_clip_box_keeps_the_part_inside_the_image() -> None:
    assert clip_box(-10, 20, 700, 500, 640, 480) == (0, 20, 640, 480)

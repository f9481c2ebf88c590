"""Depth: the D435i noise model and the robot's distance filter (reference §1.3, §1.4)."""

from __future__ import annotations

import numpy as np
import pytest

from follow_env.sensors.depth import depth_noise_std, distance_filter


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


def test_depth_noise_grows_with_the_square_of_depth() -> None:
    s1 = depth_noise_std(1.0, 0.08, 424.0, 0.05)
    s2 = depth_noise_std(2.0, 0.08, 424.0, 0.05)
    s4 = depth_noise_std(4.0, 0.08, 424.0, 0.05)
    assert s1 == pytest.approx(0.08 / (424 * 0.05))  # ~3.8 mm at 1 m (reference §1.3)
    assert s2 == pytest.approx(4 * s1)
    assert s4 == pytest.approx(16 * s1)
    assert 0.05 < s4 < 0.07  # reference: roughly 60 mm at 4 m

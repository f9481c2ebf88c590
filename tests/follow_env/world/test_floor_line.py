"""Floor lines: segments from a polyline, distances, the nearest point in a window."""

from __future__ import annotations

import numpy as np
import pytest

from follow_env.world.floor_line import (
    LINE_SEGMENT,
    SEG,
    arc_points,
    line_segments,
    nearest_on_line,
)


def _records(flat: np.ndarray) -> np.ndarray:
    return flat.view(LINE_SEGMENT.dtype)[:, 0]


def test_segments_carry_arc_length_and_drop_zero_length_pieces() -> None:
    flat = line_segments(np.array([[0, 0], [1, 0], [1, 0], [1, 2]], float), np.array([1, 1, 0]))
    assert len(flat) == 2
    assert flat[:, SEG.s].tolist() == [0.0, 1.0]
    assert flat[:, SEG.ink].tolist() == [1.0, 0.0]


def test_the_nearest_point_is_signed_left_positive() -> None:
    segs = _records(line_segments(np.array([[0.0, 0.0], [1.0, 0.0]]), np.ones(1)))
    j, s, d = nearest_on_line(segs, 1, 0.3, 0.1, -1.0, 2.0)
    assert (j, s, d) == (0, pytest.approx(0.3), pytest.approx(0.1))
    assert nearest_on_line(segs, 1, 0.3, -0.2, -1.0, 2.0)[2] == pytest.approx(-0.2)


def test_the_window_keeps_progress_from_jumping_to_a_later_pass() -> None:
    # A hairpin: the way back passes 2 cm from the way out.
    pts = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 0.02], [0.0, 0.02]])
    segs = _records(line_segments(pts, np.ones(3)))
    j_all, _s_all, _ = nearest_on_line(segs, 3, 0.5, 0.015, -1.0, 10.0)
    j_win, s_win, _ = nearest_on_line(segs, 3, 0.5, 0.015, 0.3, 0.7)
    assert j_all == 2
    assert s_win == pytest.approx(0.5)
    assert j_win == 0


def test_arc_points_span_the_arc_in_5_degree_chords() -> None:
    pts = arc_points(0.0, 0.0, 1.0, 0.0, np.pi / 2)
    assert len(pts) == 19
    assert np.allclose(np.hypot(pts[:, 0], pts[:, 1]), 1.0)
    assert pts[-1].tolist() == pytest.approx([0.0, 1.0])

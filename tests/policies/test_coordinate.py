"""The mecanum paper's coordinate control: the fitted line, the circle, the command."""

from __future__ import annotations

import math

import numpy as np
import pytest

from policies import for_platform, make_policy
from policies.coordinate import Coordinate, CoordinateParams, fit_line, intersection
from policies.line_base import CELL_XY


def _cells(*cells: tuple[int, int]) -> np.ndarray:
    obs = np.zeros(25, dtype=np.float32)
    for i, j in cells:
        obs[5 * i + j] = 1.0
    return obs


STRAIGHT = _cells(*((i, 2) for i in range(5)))


def test_a_line_straight_ahead_drives_straight_ahead() -> None:
    v, vy, w = make_policy("coordinate:signed").act(STRAIGHT)
    assert v == pytest.approx(0.3)
    assert vy == pytest.approx(0.0)
    assert w == pytest.approx(0.0)


def test_the_literal_preset_turns_at_pi_over_4_on_a_straight_line() -> None:
    _, _, w = make_policy("coordinate:literal").act(STRAIGHT)
    assert w == pytest.approx(math.pi / 4)


def test_a_line_to_the_left_strafes_left() -> None:
    v, vy, w = make_policy("coordinate:signed").act(_cells(*((i, 1) for i in range(5))))
    assert vy > 0.0
    assert v > 0.0
    assert w == pytest.approx(0.0, abs=1e-6)
    # Towards the circle's point: 1 cell left at 3 cells out.
    assert math.atan2(vy, v) == pytest.approx(math.asin(1 / 3))


def test_a_line_bending_right_turns_clockwise() -> None:
    obs = _cells((4, 2), (3, 2), (2, 2), (1, 3), (0, 4))
    _v, vy, w = make_policy("coordinate:signed").act(obs)
    assert w < 0.0
    assert vy < 0.0


def test_without_active_cells_the_last_command_is_kept() -> None:
    law = make_policy("coordinate:signed")
    law.reset()
    first = law.act(_cells(*((i, 1) for i in range(5))))
    assert np.array_equal(law.act(np.zeros(25, np.float32)), first)
    law.reset()
    assert law.act(np.zeros(25, np.float32)).tolist() == pytest.approx([0.3, 0.0, 0.0])


def test_the_rear_row_alone_is_taken_as_a_line_along_the_heading() -> None:
    v, vy, _ = make_policy("coordinate:signed").act(_cells((4, 2)))
    assert v > 0.29
    assert abs(vy) < 1e-6


def test_fit_and_intersection() -> None:
    _, u = fit_line(CELL_XY[[2, 7, 12, 17, 22]], 0.0)
    assert u.tolist() == pytest.approx([1.0, 0.0])
    _p0, u = fit_line(CELL_XY[[10, 11, 12, 13, 14]], -1.0)  # the middle row: across
    assert u.tolist() == pytest.approx([0.0, -1.0])  # towards the last side (right)
    assert intersection(np.zeros(2), np.array([1.0, 0.0]), 3.0).tolist() == [3.0, 0.0]


def test_it_commands_vy_so_it_does_not_run_on_the_differential_drive() -> None:
    with pytest.raises(ValueError, match="commands vy_mps"):
        for_platform(make_policy("coordinate:signed"), ("v_mps", "w_radps"))


def test_batched_acting_equals_one_by_one() -> None:
    rng = np.random.default_rng(0)
    obs = (rng.uniform(size=(40, 6, 25)) > 0.7).astype(np.float32)
    law = Coordinate()
    law.reset_batch(6)
    batched = np.stack([law.act_batch(o) for o in obs])
    for lane in range(6):
        single = Coordinate()
        expected = np.stack([single.act(o[lane]) for o in obs])
        assert np.array_equal(batched[:, lane], expected)


def test_bad_parameters_name_the_field() -> None:
    with pytest.raises(ValueError, match=r"CoordinateParams\.turn='both' is out of range"):
        CoordinateParams(turn="both")
    with pytest.raises(ValueError, match=r"CoordinateParams\.speed_mps=0"):
        CoordinateParams(speed_mps=0)


def test_a_wrong_observation_is_refused() -> None:
    with pytest.raises(ValueError, match=r"shape \(25,\)"):
        make_policy("coordinate:signed").act(np.zeros(2))

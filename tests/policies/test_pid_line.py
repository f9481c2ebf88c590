"""The three-sensor PID line follower."""

from __future__ import annotations

import numpy as np
import pytest

from policies import make_policy
from policies.pid_line import PID_SENSORS, PIDLineParams


def _front(left: float, centre: float, right: float) -> np.ndarray:
    obs = np.zeros(25, dtype=np.float32)
    obs[list(PID_SENSORS)] = left, centre, right
    return obs


def test_it_reads_the_front_rows_three_middle_cells() -> None:
    assert PID_SENSORS == (1, 2, 3)


def test_a_centred_line_drives_straight() -> None:
    v, w = make_policy("pid:hand").act(_front(0.1, 1.0, 0.1))
    assert v == pytest.approx(0.3)
    assert w == pytest.approx(0.0)


def test_a_line_to_the_left_turns_left() -> None:
    law = make_policy("pid:hand")
    law.reset()
    _, w = law.act(_front(0.8, 0.6, 0.0))
    assert w == pytest.approx(PIDLineParams().kp * 0.8 / 1.4)


def test_the_derivative_acts_on_the_error_change() -> None:
    law = make_policy("pid:hand")
    law.reset()
    law.act(_front(0.0, 1.0, 0.0))
    _, w = law.act(_front(0.5, 0.5, 0.0))
    p = PIDLineParams()
    assert w == pytest.approx(p.kp * 0.5 + p.kd * 0.5 / p.dt_s)


def test_losing_the_line_searches_towards_the_side_it_was_last_seen() -> None:
    law = make_policy("pid:hand")
    law.reset()
    law.act(_front(0.0, 0.4, 0.9))  # line to the right
    v, w = law.act(np.zeros(25, np.float32))
    assert v == 0.0
    assert w == pytest.approx(-PIDLineParams().search_w_radps)


def test_a_gap_after_a_centred_line_is_crossed_straight_on() -> None:
    law = make_policy("pid:hand")
    law.reset()
    law.act(_front(0.1, 1.0, 0.1))
    assert law.act(np.zeros(25, np.float32)).tolist() == pytest.approx([0.3, 0.0])


def test_bad_parameters_name_the_field() -> None:
    with pytest.raises(ValueError, match=r"PIDLineParams\.kp=-1"):
        PIDLineParams(kp=-1)

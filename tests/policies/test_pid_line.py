"""The three-sensor PID line follower."""

from __future__ import annotations

import numpy as np
import pytest

from policies import make_policy
from policies.pid_line import PID_SENSORS, PIDLine, PIDLineParams


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


def test_with_lost_sum_0_only_a_blank_row_is_lost() -> None:
    # the error divides by the readings' sum: a blank row used to divide by zero
    law = PIDLine(PIDLineParams(lost_sum=0.0))
    law.reset()
    law.act(_front(0.0, 0.4, 0.9))
    v, w = law.act(np.zeros(25, np.float32))  # searches, as with the default lost_sum
    assert (v, w) == pytest.approx((0.0, -PIDLineParams().search_w_radps))
    _, w = law.act(_front(0.0, 0.0, 0.01))  # any reading at all is the line
    assert w == pytest.approx(-PIDLineParams().kp)


def test_bad_parameters_name_the_field() -> None:
    with pytest.raises(ValueError, match=r"PIDLineParams\.kp=-1"):
        PIDLineParams(kp=-1)


@pytest.mark.parametrize("name", ["pid:hand", "coordinate"])
def test_a_refused_batch_moves_no_lane_and_batches_leave_the_episode_alone(name: str) -> None:
    law = make_policy(name, task="line_trace")
    left, centre = _front(1.0, 0.0, 0.0), _front(0.0, 1.0, 0.0)
    alone = make_policy(name, task="line_trace")
    expected = [alone.act(obs) for obs in (left, centre, centre)]
    law.reset()
    got = [law.act(left)]
    law.reset_batch(2)
    bad = np.stack([left, left])
    bad[1, 0] = np.nan
    with pytest.raises(ValueError, match=r"obs of lanes \[1\] must be finite"):
        law.act_batch(bad)  # lane 0 moved on before lane 1 was refused, once
    law.act_batch(np.stack([centre, left]))  # the lanes' memory, not the episode's
    law.peek(left, 1)
    got += [law.act(centre), law.act(centre)]
    np.testing.assert_array_equal(np.array(got), np.array(expected))
    # lane 0 had one step (centre), lane 1 one (left): a second batch goes on from there
    batch = law.act_batch(np.stack([centre, centre]))
    for lane, first in enumerate((centre, left)):
        fresh = make_policy(name, task="line_trace")
        fresh.act(first)
        np.testing.assert_array_equal(batch[lane], fresh.act(centre))


def test_readings_that_are_not_real_numbers_are_rejected() -> None:
    law = make_policy("pid", task="line_trace")
    with pytest.raises(ValueError, match="obs must be real numbers"):
        law.act(np.array(["0"] * 25))

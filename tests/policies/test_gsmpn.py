"""policies/gsmpn.py: gain-scheduled MPN and its three variants, reference §1.5."""

import math
from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from policies import GSMPN, GSMPN_THESIS, GSMPN_VARIANTS, GSMPNParams
from policies.gsmpn import scheduled_gain

THESIS_LISTING = replace(GSMPN_THESIS, variant="listing")
THESIS_EQUATION = replace(GSMPN_THESIS, variant="equation")


def obs(distance_m: float, offset_px: float) -> np.ndarray:
    return np.array([distance_m, offset_px], dtype=np.float32)


def second_step(params: GSMPNParams, first: np.ndarray, second: np.ndarray) -> np.ndarray:
    law = GSMPN(params)
    law.act(first)
    return law.act(second)


@pytest.mark.parametrize("listing", [False, True])
def test_scheduled_gain_is_zero_at_zero_signal(listing: bool) -> None:
    assert scheduled_gain(0.0, lambda_d=0.3, a=2.0, listing=listing) == 0.0


@given(
    x=st.floats(min_value=-1e9, max_value=1e9),
    lambda_d=st.floats(min_value=0.0, max_value=1e3),
    a=st.floats(min_value=1e-6, max_value=1e3),
    listing=st.booleans(),
)
def test_scheduled_gain_stays_between_zero_and_lambda_d(
    x: float, lambda_d: float, a: float, listing: bool
) -> None:
    assert 0.0 <= scheduled_gain(x, lambda_d, a, listing=listing) <= lambda_d


@given(x=st.floats(min_value=-1e3, max_value=1e3))
def test_scheduled_gain_is_lambda_d_tanh_of_half_a_abs_x(x: float) -> None:
    # reference §1.5: (1 - e) / (1 + e) with e = exp(-a|x|) equals tanh(a|x| / 2).
    expected = 0.5 * math.tanh(0.2 * abs(x) / 2)
    assert scheduled_gain(x, lambda_d=0.5, a=0.2) == pytest.approx(expected, abs=1e-15)


def test_listing_gain_is_the_default_gain_divided_by_one_plus_e() -> None:
    # x = 10, a = 0.1: e = exp(-1); listing = default / (1 + e)
    e = math.exp(-1.0)
    assert scheduled_gain(10.0, 1e-4, 0.1, listing=True) == pytest.approx(
        scheduled_gain(10.0, 1e-4, 0.1) / (1 + e)
    )


def test_gsmpn_default_thesis_matches_hand_computed_values() -> None:
    # rate = (21 - 20) / 0.1 = 10 px/s; e = exp(-0.1 * 10) = 0.367879
    # kd = 1e-4 (1 - e) / (1 + e) = 4.621172e-5
    # w = -(0.1 * 0.05 * 21 / 2 + kd * 10) = -(0.0525 + 4.621172e-4) = -0.05296212; v = 5 (2 - 1)
    e = math.exp(-1.0)
    kd = 1e-4 * (1 - e) / (1 + e)
    action = second_step(GSMPN_THESIS, obs(2.0, 20.0), obs(2.0, 21.0))
    np.testing.assert_allclose(action, [5.0, -(0.0525 + kd * 10)], rtol=1e-6)
    assert action[1] == pytest.approx(-0.05296212, rel=1e-6)


def test_gsmpn_listing_thesis_matches_hand_computed_values() -> None:
    # As the default, but kd = 1e-4 (1 - e) / (1 + e) / (1 + e) = 3.378373e-5
    # w = -(0.0525 + 3.378373e-4) = -0.05283783
    e = math.exp(-1.0)
    kd = 1e-4 * (1 - e) / (1 + e) / (1 + e)
    action = second_step(THESIS_LISTING, obs(2.0, 20.0), obs(2.0, 21.0))
    np.testing.assert_allclose(action, [5.0, -(0.0525 + kd * 10)], rtol=1e-6)
    assert action[1] == pytest.approx(-0.05283783, rel=1e-6)


def test_gsmpn_equation_thesis_matches_hand_computed_values() -> None:
    # Scheduled on |o| = 21: e = exp(-0.1 * 21) = 0.122456
    # kd = 1e-4 (1 - e) / (1 + e) = 7.818064e-5
    # w = -(0.05 * 21 / max(2, 1) + kd * 21) = -(0.525 + 1.641793e-3) = -0.5266418 (no N)
    e = math.exp(-2.1)
    kd = 1e-4 * (1 - e) / (1 + e)
    action = second_step(THESIS_EQUATION, obs(2.0, 20.0), obs(2.0, 21.0))
    np.testing.assert_allclose(action, [5.0, -(0.525 + kd * 21)], rtol=1e-6)
    assert action[1] == pytest.approx(-0.5266418, rel=1e-6)


def test_gsmpn_equation_ignores_the_offset_rate() -> None:
    fresh = GSMPN(THESIS_EQUATION).act(obs(2.0, 21.0))
    after_a_jump = second_step(THESIS_EQUATION, obs(2.0, -300.0), obs(2.0, 21.0))
    np.testing.assert_array_equal(after_a_jump, fresh)


def test_gsmpn_equation_divides_by_at_least_one_metre() -> None:
    # The thesis equation's max(d, 1): at d = 0.5 and d = 1, w = -(0.05 * 10 / 1 + kd * 10)
    at_half = GSMPN(THESIS_EQUATION).act(obs(0.5, 10.0))
    at_one = GSMPN(THESIS_EQUATION).act(obs(1.0, 10.0))
    assert at_half[1] == at_one[1]


@pytest.mark.parametrize("variant", ["default", "listing"])
def test_gsmpn_at_zero_rate_is_the_proportional_term_alone(variant: str) -> None:
    # Offset held at 40 px: rate = 0, kd = 0, w = -(0.1 * 0.05 * 40 / 2) = -0.1
    params = replace(GSMPN_THESIS, variant=variant)
    assert second_step(params, obs(2.0, 40.0), obs(2.0, 40.0))[1] == pytest.approx(-0.1)


def test_gsmpn_first_step_after_reset_has_zero_rate() -> None:
    law = GSMPN(GSMPN_THESIS)
    law.act(obs(2.0, -300.0))
    law.reset()
    np.testing.assert_array_equal(law.act(obs(2.0, 40.0)), GSMPN(GSMPN_THESIS).act(obs(2.0, 40.0)))


def test_gsmpn_divides_by_at_least_the_distance_floor() -> None:
    # max(d, 0.1) on the first step (rate 0): w = -(0.1 * 0.05 * 2 / 0.1) = -0.1 at d = 0.05
    assert GSMPN(GSMPN_THESIS).act(obs(0.05, 2.0))[1] == pytest.approx(-0.1, rel=1e-6)


def test_gsmpn_three_variants_give_three_different_turn_rates() -> None:
    turn_rates = {
        second_step(replace(GSMPN_THESIS, variant=v), obs(2.0, 20.0), obs(2.0, 21.0))[1]
        for v in GSMPN_VARIANTS
    }
    assert len(turn_rates) == 3


def test_gsmpn_default_gain_exceeds_listing_gain_on_a_moving_offset() -> None:
    # Same proportional term; the listing's kd is the default's / (1 + e) < the default's.
    default = second_step(GSMPN_THESIS, obs(2.0, 20.0), obs(2.0, 21.0))[1]
    listing = second_step(THESIS_LISTING, obs(2.0, 20.0), obs(2.0, 21.0))[1]
    assert default < listing < 0


def test_gsmpn_thesis_preset_is_the_thesis_values_in_si() -> None:
    # lambda_d = 0.1 mrad/s per px/s = 1e-4 rad/px; a = 0.1 s/px has no unit to convert.
    assert GSMPN_THESIS.lambda_d == 1e-4
    assert GSMPN_THESIS.a == 0.1
    assert GSMPN_THESIS.kv_per_s == 5.0
    assert GSMPN_THESIS.nav_n * GSMPN_THESIS.kw_rad_per_s_px == pytest.approx(0.005)
    assert GSMPN_THESIS.dt_s == 0.1
    assert GSMPN_THESIS.variant == "default"


def test_gsmpn_unknown_variant_is_rejected_listing_the_variants() -> None:
    with pytest.raises(ValueError, match=r"GSMPNParams\.variant='tanh'.*'default', 'listing'"):
        replace(GSMPN_THESIS, variant="tanh")


@pytest.mark.parametrize(
    ("field", "value", "rule"),
    [("a", 0.0, "> 0"), ("lambda_d", -0.1, ">= 0"), ("kv_per_s", float("nan"), "> 0")],
)
def test_gsmpn_params_reject_out_of_range_value_naming_field(
    field: str, value: float, rule: str
) -> None:
    with pytest.raises(
        ValueError, match=rf"GSMPNParams\.{field}=.* is out of range: must be {rule}"
    ):
        replace(GSMPN_THESIS, **{field: value})

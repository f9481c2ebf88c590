"""policies/mpn.py: modified proportional navigation, reference §1.5."""

import numpy as np
import pytest

from policies import MPN, MPN_THESIS, MPNParams


def obs(distance_m: float, offset_px: float) -> np.ndarray:
    return np.array([distance_m, offset_px], dtype=np.float32)


def test_mpn_first_step_has_zero_rate() -> None:
    # rate = 0, so w = -(0.1 * 0.05 * 20 / 2) = -0.05; v = 5 (2 - 1) = 5
    np.testing.assert_allclose(MPN(MPN_THESIS).act(obs(2.0, 20.0)), [5.0, -0.05])


def test_mpn_thesis_matches_hand_computed_values() -> None:
    law = MPN(MPN_THESIS)
    law.act(obs(2.0, 20.0))
    # rate = (50 - 20) / 0.1 = 300 px/s
    # w = -(0.1 * 0.05 * 50 / 2 + 1e-4 * 300) = -(0.125 + 0.03) = -0.155; v = 5 (2 - 1) = 5
    np.testing.assert_allclose(law.act(obs(2.0, 50.0)), [5.0, -0.155], rtol=1e-6)


def test_mpn_rate_uses_the_previous_offset() -> None:
    law = MPN(MPN_THESIS)
    for offset_px in (0.0, 10.0):
        law.act(obs(1.0, offset_px))
    # rate = (40 - 10) / 0.1 = 300 px/s (the offset before last, 0, plays no part)
    # w = -(0.1 * 0.05 * 40 / 1 + 1e-4 * 300) = -(0.2 + 0.03) = -0.23
    assert law.act(obs(1.0, 40.0))[1] == pytest.approx(-0.23, rel=1e-6)


def test_mpn_reset_clears_the_previous_offset() -> None:
    law = MPN(MPN_THESIS)
    law.act(obs(2.0, -300.0))
    law.reset()
    np.testing.assert_array_equal(law.act(obs(2.0, 20.0)), MPN(MPN_THESIS).act(obs(2.0, 20.0)))


def test_mpn_rate_uses_dt() -> None:
    params = MPNParams(
        kv_per_s=5.0, nav_n=0.1, kw_rad_per_s_px=0.05, lambda_rad_per_px=1e-3, dt_s=0.5
    )
    law = MPN(params)
    law.act(obs(1.0, 0.0))
    # rate = (10 - 0) / 0.5 = 20 px/s; w = -(0.1 * 0.05 * 10 / 1 + 1e-3 * 20) = -(0.05 + 0.02)
    assert law.act(obs(1.0, 10.0))[1] == pytest.approx(-0.07, rel=1e-6)


@pytest.mark.parametrize("distance_m", [0.01, 0.05, 0.1])
def test_mpn_divides_by_at_least_the_distance_floor(distance_m: float) -> None:
    # max(d, 0.1): w = -(0.1 * 0.05 * 2 / 0.1) = -0.1 for any 0 < d <= 0.1 m
    assert MPN(MPN_THESIS).act(obs(distance_m, 2.0))[1] == pytest.approx(-0.1, rel=1e-6)


def test_mpn_below_one_metre_divides_by_d_unlike_pn() -> None:
    # w = -(0.1 * 0.05 * 10 / 0.5) = -0.1 (PN would use max(0.5, 1) and give -0.05)
    assert MPN(MPN_THESIS).act(obs(0.5, 10.0))[1] == pytest.approx(-0.1, rel=1e-6)


def test_mpn_thesis_preset_takes_lambda_equal_to_gsmpn_lambda_d() -> None:
    # The thesis does not state MPN's lambda; the preset uses lambda_d = 0.1 mrad/px = 1e-4 rad/px.
    assert MPN_THESIS.lambda_rad_per_px == 1e-4
    assert MPN_THESIS.kv_per_s == 5.0
    assert MPN_THESIS.nav_n * MPN_THESIS.kw_rad_per_s_px == pytest.approx(0.005)
    assert MPN_THESIS.dt_s == 0.1


@pytest.mark.parametrize(
    ("field", "value", "rule"),
    [
        ("dt_s", 0.0, "> 0"),
        ("kw_rad_per_s_px", -0.05, "> 0"),
        ("lambda_rad_per_px", -1e-4, ">= 0"),
        ("lambda_rad_per_px", float("nan"), ">= 0"),
    ],
)
def test_mpn_params_reject_out_of_range_value_naming_field(
    field: str, value: float, rule: str
) -> None:
    kwargs = {"kv_per_s": 5.0, "nav_n": 0.1, "kw_rad_per_s_px": 0.05, "lambda_rad_per_px": 1e-4}
    with pytest.raises(ValueError, match=rf"MPNParams\.{field}=.* is out of range: must be {rule}"):
        MPNParams(**{**kwargs, field: value})

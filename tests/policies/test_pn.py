"""policies/pn.py: proportional navigation, reference §1.5."""

import numpy as np
import pytest

from policies import PN, PN_THESIS, PN_TUNED, PNParams


def obs(distance_m: float, offset_px: float) -> np.ndarray:
    return np.array([distance_m, offset_px], dtype=np.float32)


@pytest.mark.parametrize(
    ("distance_m", "offset_px", "v_mps", "w_radps"),
    [
        # v = 5 (2 - 1) = 5;     w = -(0.1 * 0.05 * 100 / max(2, 1)) = -0.25
        (2.0, 100.0, 5.0, -0.25),
        # v = 5 (4 - 1) = 15;    w = -(0.1 * 0.05 * -200 / max(4, 1)) = 0.25
        (4.0, -200.0, 15.0, 0.25),
        # v = 5 (0.5 - 1) = -2.5; w = -(0.1 * 0.05 * -40 / max(0.5, 1)) = 0.2
        (0.5, -40.0, -2.5, 0.2),
    ],
)
def test_pn_thesis_matches_hand_computed_values(
    distance_m: float, offset_px: float, v_mps: float, w_radps: float
) -> None:
    np.testing.assert_allclose(PN(PN_THESIS).act(obs(distance_m, offset_px)), [v_mps, w_radps])


@pytest.mark.parametrize("distance_m", [0.05, 0.3, 1.0])
def test_pn_divides_by_at_least_one_metre(distance_m: float) -> None:
    # reference §1.5: max(d, 1.0), so any 0 < d <= 1 m turns like d = 1 m:
    # w = -(0.1 * 0.05 * 60 / 1) = -0.3
    assert PN(PN_THESIS).act(obs(distance_m, 60.0))[1] == pytest.approx(-0.3)


def test_pn_speed_is_zero_at_the_reference_distance() -> None:
    assert PN(PN_THESIS).act(obs(1.0, 0.0))[0] == 0.0


def test_pn_is_memoryless() -> None:
    law = PN(PN_THESIS)
    first = law.act(obs(2.0, 100.0))
    law.act(obs(3.0, -50.0))
    law.reset()
    np.testing.assert_array_equal(law.act(obs(2.0, 100.0)), first)


def test_pn_thesis_preset_is_the_thesis_values_in_si() -> None:
    # kv = 5000 mm/s per m = 5 1/s; N kw = 0.1 * 50 mrad/s/px = 5 mrad/s/px = 0.005 rad/s/px.
    assert PN_THESIS.kv_per_s == 5.0
    assert PN_THESIS.d_ref_m == 1.0
    assert PN_THESIS.nav_n == 0.1
    assert PN_THESIS.nav_n * PN_THESIS.kw_rad_per_s_px == pytest.approx(0.005)


def test_pn_default_params_are_the_tuned_preset() -> None:
    assert PN().params is PN_TUNED


@pytest.mark.parametrize("field", ["kv_per_s", "d_ref_m", "nav_n", "kw_rad_per_s_px"])
@pytest.mark.parametrize("value", [0.0, -1.0, float("inf")])
def test_pn_params_reject_out_of_range_value_naming_field_and_value(
    field: str, value: float
) -> None:
    kwargs = {"kv_per_s": 5.0, "nav_n": 0.1, "kw_rad_per_s_px": 0.05, field: value}
    with pytest.raises(
        ValueError, match=rf"PNParams\.{field}={value!r} is out of range: must be > 0"
    ):
        PNParams(**kwargs)

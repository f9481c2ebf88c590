"""policies/holonomic.py: the strafing law, and policies/adapt.py: actions fitted by name."""

from __future__ import annotations

import numpy as np
import pytest

from policies import Holonomic, HolonomicParams, for_platform, make_policy

MECANUM = ("v_mps", "vy_mps", "w_radps")


def obs(distance_m: float, offset_px: float) -> np.ndarray:
    return np.array([distance_m, offset_px], dtype=np.float32)


def test_a_person_right_of_centre_makes_it_strafe_right_and_turn_clockwise() -> None:
    v, vy, w = make_policy("holonomic").act(obs(2.0, 100.0))
    assert v == pytest.approx(5.0)
    assert vy == pytest.approx(-0.0012 * 2.0 * 100.0)
    assert w == pytest.approx(-0.1 * 0.05 * 100.0 / 2.0)


def test_without_strafing_it_is_pn() -> None:
    pn = make_policy("pn")
    v, vy, w = Holonomic(HolonomicParams(ks_per_s_px=0.0)).act(obs(3.0, -70.0))
    assert vy == 0.0
    assert np.array_equal([v, w], pn.act(obs(3.0, -70.0)))


def test_it_stands_still_before_the_first_reading() -> None:
    assert np.array_equal(make_policy("holonomic").act(obs(0.0, 50.0)), np.zeros(3))


def test_the_bare_name_is_the_default_preset() -> None:
    law = make_policy("holonomic")
    assert law.name == "holonomic:default"
    assert isinstance(law, Holonomic)
    assert law.action_names == MECANUM


def test_bad_gains_name_the_field() -> None:
    with pytest.raises(ValueError, match=r"HolonomicParams\.ks_per_s_px=-1\.0 is out of range"):
        HolonomicParams(ks_per_s_px=-1.0)


def test_batched_actions_equal_one_by_one() -> None:
    law = make_policy("holonomic")
    rows = np.array([[2.0, 30.0], [1.5, -80.0], [0.0, 5.0]], dtype=np.float32)
    law.reset_batch(3)
    assert np.array_equal(law.act_batch(rows), np.stack([law.act(r) for r in rows]))


def test_a_law_on_the_mecanum_base_drives_with_vy_zero() -> None:
    pn = make_policy("pn")
    fitted = for_platform(pn, MECANUM)
    v, w = pn.act(obs(2.0, 100.0))
    assert np.array_equal(fitted.act(obs(2.0, 100.0)), [v, 0.0, w])
    assert fitted.name == pn.name
    fitted.reset_batch(2)
    assert fitted.act_batch(np.stack([obs(2.0, 100.0), obs(1.0, 0.0)])).shape == (2, 3)


def test_a_policy_on_its_own_action_is_not_wrapped() -> None:
    pn = make_policy("pn")
    assert for_platform(pn, ("v_mps", "w_radps")) is pn


def test_a_strafing_law_on_the_differential_drive_is_refused() -> None:
    with pytest.raises(ValueError, match="commands vy_mps"):
        for_platform(make_policy("holonomic"), ("v_mps", "w_radps"))

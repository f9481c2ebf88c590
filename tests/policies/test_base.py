"""policies/base.py: the observation/action contract shared by every policy."""

from dataclasses import FrozenInstanceError

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from policies import MPN, MPN_THESIS, PN, PN_THESIS, Policy, available_policies, make_policy
from policies.adapt import action_names
from policies.base import clip_to, validate_obs
from policies.pn import PNParams


def obs(distance_m: float, offset_px: float, policy: object = None) -> np.ndarray:
    """An observation; for an agent that reads the reading ahead, with nothing near ahead."""
    ahead = [10.0] if getattr(policy, "reads_ahead", None) else []
    return np.array([distance_m, offset_px, *ahead], dtype=np.float32)


# The sign rule of reference §1.5 is a property of the guidance laws' equations. A learned agent is
# held to what it does over an episode instead (tests/policies/test_ppo.py): on its first step
# from rest, far from its 1 m training start, it may turn the wrong way for one step.
LAWS = [name for name in available_policies("person_follow") if not name.startswith("ppo")]


@pytest.mark.parametrize("name", available_policies("person_follow"))
def test_every_registered_policy_satisfies_the_protocol(name: str) -> None:
    assert isinstance(make_policy(name), Policy)


@pytest.mark.parametrize("name", available_policies("person_follow"))
def test_action_is_float32_with_one_entry_per_action_name(name: str) -> None:
    policy = make_policy(name)
    action = policy.act(obs(2.0, 30.0, policy))
    names = action_names(policy)
    assert action.shape == (len(names),)
    assert action.dtype == np.float32
    # Forward speed first, turn rate last, whatever lies between (a strafing law's vy).
    assert (names[0], names[-1]) == ("v_mps", "w_radps")


@pytest.mark.parametrize("name", LAWS)
@given(
    distance_m=st.floats(min_value=1.01, max_value=10.0),
    offset_px=st.floats(min_value=1.0, max_value=500.0),
)
def test_person_right_and_beyond_reference_gives_forward_clockwise_action(
    name: str, distance_m: float, offset_px: float
) -> None:
    # reference §1.5 "Sign": o > 0 (right of centre) needs w < 0; d > d_ref = 1 m needs v > 0.
    action = make_policy(name).act(obs(distance_m, offset_px))
    assert action[0] > 0  # v
    assert action[-1] < 0  # w


@pytest.mark.parametrize("name", LAWS)
def test_person_left_of_centre_gives_counter_clockwise_turn(name: str) -> None:
    assert make_policy(name).act(obs(2.0, -50.0))[-1] > 0  # w


@pytest.mark.parametrize(
    "bad", [[1.0], [1.0, 2.0, 3.0, 4.0], [[1.0, 2.0]], 1.0], ids=["1", "4", "1x2", "scalar"]
)
def test_obs_of_wrong_shape_is_rejected(bad: object) -> None:
    with pytest.raises(ValueError, match=r"shape \(2,\) = \[distance_m, offset_px\] or \(3,\)"):
        PN().act(bad)  # type: ignore[arg-type]


@pytest.mark.parametrize("name", LAWS)
def test_a_law_ignores_the_reading_ahead(name: str) -> None:
    for distance, offset in ((2.0, 50.0), (0.0, 10.0), (0.8, -30.0)):
        plain, given = make_policy(name), make_policy(name)
        np.testing.assert_array_equal(
            plain.act(obs(distance, offset)),
            given.act(np.array([distance, offset, 0.4], dtype=np.float32)),
        )


@pytest.mark.parametrize("bad", [[np.nan, 0.0], [1.0, np.inf], [-np.inf, 3.0]])
def test_obs_with_nan_or_inf_is_rejected(bad: list[float]) -> None:
    with pytest.raises(ValueError, match="finite"):
        PN().act(np.array(bad, dtype=np.float32))


def test_rejected_obs_leaves_law_memory_untouched() -> None:
    law = MPN(MPN_THESIS)
    law.act(obs(1.0, 10.0))
    with pytest.raises(ValueError, match="finite"):
        law.act(obs(1.0, np.nan))
    # rate = (40 - 10) / 0.1 = 300 px/s, as if the bad obs never came;
    # w = -(0.1 * 0.05 * 40 / 1 + 1e-4 * 300) = -(0.2 + 0.03) = -0.23
    assert law.act(obs(1.0, 40.0))[1] == pytest.approx(-0.23, rel=1e-6)


@pytest.mark.parametrize("name", available_policies("person_follow"))
@pytest.mark.parametrize("distance_m", [0.0, -0.5])
def test_no_distance_reading_yet_gives_zero_action(name: str, distance_m: float) -> None:
    # The reference robot did not move before its first reading; V = kv (0 - 1) would reverse.
    policy = make_policy(name)
    action = policy.act(obs(distance_m, 120.0, policy))
    np.testing.assert_array_equal(action, np.zeros_like(action))


def test_no_distance_reading_leaves_law_memory_untouched() -> None:
    law = MPN(MPN_THESIS)
    law.act(obs(1.0, 10.0))
    law.act(obs(0.0, -300.0))  # no reading: ignored
    # rate = (40 - 10) / 0.1 = 300 px/s; w = -(0.1 * 0.05 * 40 / 1 + 1e-4 * 300) = -0.23
    assert law.act(obs(1.0, 40.0))[1] == pytest.approx(-0.23, rel=1e-6)


def test_first_reading_after_no_reading_has_zero_rate() -> None:
    law = MPN(MPN_THESIS)
    law.act(obs(0.0, 80.0))
    # No previous reading, so rate = 0: w = -(0.1 * 0.05 * 40 / 2) = -0.1; v = 5 (2 - 1)
    np.testing.assert_allclose(law.act(obs(2.0, 40.0)), [5.0, -0.1], rtol=1e-6)


def test_validate_obs_returns_distance_and_offset_as_floats() -> None:
    assert validate_obs(obs(1.5, -20.0)) == (1.5, -20.0)


def test_clip_to_clips_to_a_symmetric_limit_or_passes_through() -> None:
    values = np.array([3.0, -4.0, 0.5])
    np.testing.assert_array_equal(clip_to(values, 1.5), [1.5, -1.5, 0.5])
    np.testing.assert_array_equal(clip_to(values, None), values)


def test_law_clips_its_output_to_its_limits() -> None:
    params = PNParams(kv_per_s=5.0, nav_n=0.1, kw_rad_per_s_px=0.05, v_max_mps=1.2, w_max_radps=0.1)
    # Unclipped: v = 5 (3 - 1) = 10 m/s, w = -(0.005 * 300 / 3) = -0.5 rad/s.
    v_mps, w_radps = PN(params).act(obs(3.0, 300.0))
    assert v_mps == pytest.approx(1.2)
    assert w_radps == pytest.approx(-0.1)


@pytest.mark.parametrize("field", ["v_max_mps", "w_max_radps"])
@pytest.mark.parametrize("value", [0.0, -1.0, float("nan")])
def test_non_positive_output_limit_is_rejected_naming_the_field(field: str, value: float) -> None:
    kwargs = {"kv_per_s": 5.0, "nav_n": 0.1, "kw_rad_per_s_px": 0.05, field: value}
    with pytest.raises(ValueError, match=rf"PNParams\.{field}=.* must be None or > 0"):
        PNParams(**kwargs)


def test_params_are_frozen() -> None:
    with pytest.raises(FrozenInstanceError):
        PN_THESIS.kv_per_s = 1.0  # type: ignore[misc]


def _law_obs(steps: int, lanes: int, seed: int) -> np.ndarray:
    """Observations ``(steps, lanes, 2)`` with readings, misses (d = 0) and clipped extremes."""
    rng = np.random.default_rng(seed)
    distance = rng.uniform(0.05, 6.0, (steps, lanes))
    distance[rng.random((steps, lanes)) < 0.2] = 0.0
    offset = rng.normal(0.0, 150.0, (steps, lanes)) * rng.choice([1.0, 1.0, 20.0], (steps, lanes))
    return np.stack([distance, offset], axis=-1).astype(np.float32)


@pytest.mark.parametrize("name", LAWS)
def test_act_batch_equals_each_lanes_episode_alone_bit_for_bit(name: str) -> None:
    # Lanes run the same arithmetic on arrays that act runs on one row, so a lane's actions are
    # bit-identical to its episode alone, through misses and restarts of other lanes.
    steps, lanes = 60, 7
    rows = _law_obs(steps, lanes, seed=3)
    restart = np.zeros((steps, lanes), dtype=bool)
    restart[20, [1, 4]] = restart[41, 4] = True
    batch = make_policy(name)
    batch.reset_batch(lanes)
    got = np.empty((steps, lanes, len(action_names(batch))), dtype=np.float32)
    for t in range(steps):
        batch.reset_lanes(restart[t])
        got[t] = batch.act_batch(rows[t])
    for lane in range(lanes):
        alone = make_policy(name)
        for t in range(steps):
            if restart[t, lane]:
                alone.reset()
            np.testing.assert_array_equal(got[t, lane], alone.act(rows[t, lane]))


@pytest.mark.parametrize("name", LAWS)
def test_peek_leaves_the_lanes_memory_and_act_leaves_the_lanes_alone(name: str) -> None:
    rows = _law_obs(3, 2, seed=5)
    rows[:, :, 0] = 2.0  # every step a reading
    law, twin = make_policy(name), make_policy(name)
    law.reset_batch(2)
    twin.reset_batch(2)
    law.act_batch(rows[0])
    twin.act_batch(rows[0])
    law.peek(rows[1, 1], 1)
    law.act(rows[2, 0])  # the single episode's memory is its own
    np.testing.assert_array_equal(law.act_batch(rows[1]), twin.act_batch(rows[1]))


def test_act_batch_needs_reset_batch_for_its_lane_count() -> None:
    law = MPN(MPN_THESIS)
    with pytest.raises(ValueError, match=r"call reset_batch\(2\) first"):
        law.act_batch(np.ones((2, 2)))
    law.reset_batch(3)
    with pytest.raises(ValueError, match=r"call reset_batch\(2\) first"):
        law.act_batch(np.ones((2, 2)))


@pytest.mark.parametrize(
    "bad",
    [np.array(["2", "100"]), np.array([2 + 0j, 100]), [2.0, 1j], np.array([b"2", b"1"])],
    ids=["str", "complex", "list-with-complex", "bytes"],
)
@pytest.mark.parametrize("name", LAWS)
def test_obs_that_are_not_real_numbers_are_rejected(name: str, bad: object) -> None:
    # strings were parsed and complex numbers cut to their real part, silently
    law = make_policy(name)
    with pytest.raises(ValueError, match="obs must be real numbers"):
        law.act(bad)
    law.reset_batch(2)
    with pytest.raises(ValueError, match="obs must be real numbers"):
        law.act_batch(np.stack([np.asarray(bad)] * 2))

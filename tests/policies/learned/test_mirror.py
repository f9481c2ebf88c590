"""policies/learned/mirror.py: the mirror-symmetric actor-critic."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from gymnasium import spaces

from policies.learned.mirror import MirrorMlpPolicy, check_mirror_action

OBS_SIGN = [1.0, -1.0, 1.0]
ACT_SIGN = [1.0, -1.0]


def make_policy(n_stack: int = 2) -> MirrorMlpPolicy:
    torch.manual_seed(0)
    obs_space = spaces.Box(-5, 5, shape=(3 * n_stack,), dtype=np.float32)
    act_space = spaces.Box(-1, 1, shape=(2,), dtype=np.float32)
    return MirrorMlpPolicy(
        obs_space, act_space, lambda _: 3e-4, mirror_obs=OBS_SIGN, mirror_action=ACT_SIGN
    )


def test_mirrored_observation_gives_mirrored_mean_action_and_equal_value() -> None:
    policy = make_policy()
    x = torch.randn(16, 6)
    mx = x * torch.tensor(OBS_SIGN * 2)
    with torch.no_grad():
        mean = policy.get_distribution(x).distribution.mean
        mirrored_mean = policy.get_distribution(mx).distribution.mean
        torch.testing.assert_close(mirrored_mean, mean * torch.tensor(ACT_SIGN))
        torch.testing.assert_close(policy.predict_values(mx), policy.predict_values(x))


def test_symmetric_observation_gives_no_turn() -> None:
    policy = make_policy()
    x = torch.tensor([[1.2, 0.0, 0.3, 0.8, 0.0, 0.1]])
    with torch.no_grad():
        assert policy.get_distribution(x).distribution.mean[0, 1].item() == 0.0


def test_every_parameter_is_trained() -> None:
    policy = make_policy()
    trained = {id(p) for group in policy.optimizer.param_groups for p in group["params"]}
    assert {id(p) for p in policy.parameters()} <= trained


def test_signs_that_do_not_fit_the_spaces_are_rejected() -> None:
    with pytest.raises(ValueError, match="mirror_obs"):
        MirrorMlpPolicy(
            spaces.Box(-1, 1, shape=(4,), dtype=np.float32),
            spaces.Box(-1, 1, shape=(2,), dtype=np.float32),
            lambda _: 3e-4,
            mirror_obs=OBS_SIGN,
            mirror_action=ACT_SIGN,
        )


# The mecanum base: [v_mps, vy_mps, w_radps]; vy changes sign in a mirror, like w.
MECANUM_OBS_SIGN = [1.0, -1.0, 1.0, 1.0, -1.0, -1.0]  # distance, offset, age, vx, vy, w
MECANUM_ACT_SIGN = [1.0, -1.0, -1.0]


def test_a_three_entry_action_mirrors_vy_and_w_but_not_vx() -> None:
    torch.manual_seed(0)
    policy = MirrorMlpPolicy(
        spaces.Box(-5, 5, shape=(12,), dtype=np.float32),
        spaces.Box(-1, 1, shape=(3,), dtype=np.float32),
        lambda _: 3e-4,
        mirror_obs=MECANUM_OBS_SIGN,
        mirror_action=MECANUM_ACT_SIGN,
    )
    x = torch.randn(16, 12)
    mx = x * torch.tensor(MECANUM_OBS_SIGN * 2)
    with torch.no_grad():
        mean = policy.get_distribution(x).distribution.mean
        mirrored = policy.get_distribution(mx).distribution.mean
    torch.testing.assert_close(mirrored, mean * torch.tensor(MECANUM_ACT_SIGN))
    centred = torch.zeros(1, 12)
    with torch.no_grad():  # a centred person, at rest: no strafe and no turn
        action = policy.get_distribution(centred).distribution.mean[0]
    assert action[1].item() == 0.0
    assert action[2].item() == 0.0


def test_mirror_action_signs_are_checked_against_the_action_names() -> None:
    check_mirror_action([1, -1, -1], ("v_mps", "vy_mps", "w_radps"), "mirror_action")
    check_mirror_action([1, -1], ("v_mps", "w_radps"), "mirror_action")
    with pytest.raises(
        ValueError,
        match=r"mirror_action=\[1, 1, -1\] is out of range: vy_mps "
        r"changes its sign in a left-right mirror, so its sign must be -1",
    ):
        check_mirror_action([1, 1, -1], ("v_mps", "vy_mps", "w_radps"), "mirror_action")
    with pytest.raises(ValueError, match=r"must be 3 signs, one per action entry"):
        check_mirror_action([1, -1], ("v_mps", "vy_mps", "w_radps"), "mirror_action")


# An asymmetric actor-critic: two frames of the actor's view, then three privileged entries
# for the critic (a distance, an offset that changes sign in a mirror, a flag).
PRIVILEGED = [1.0, -1.0, 1.0]


def make_asymmetric() -> MirrorMlpPolicy:
    torch.manual_seed(0)
    return MirrorMlpPolicy(
        spaces.Box(-5, 5, shape=(6 + 3,), dtype=np.float32),
        spaces.Box(-1, 1, shape=(2,), dtype=np.float32),
        lambda _: 3e-4,
        mirror_obs=OBS_SIGN,
        mirror_action=ACT_SIGN,
        privileged_signs=PRIVILEGED,
    )


def test_the_actor_reads_its_own_view_and_the_critic_the_truth_too() -> None:
    policy = make_asymmetric()
    assert policy.actor_entries == 6
    x = torch.randn(16, 9)
    other = x.clone()
    other[:, 6:] = torch.randn(16, 3)  # other truth, the same view
    with torch.no_grad():
        mean = policy.get_distribution(x).distribution.mean
        torch.testing.assert_close(policy.get_distribution(other).distribution.mean, mean)
        # the view alone (inference, where the pipeline does not make the truth) acts the same
        torch.testing.assert_close(policy.get_distribution(x[:, :6]).distribution.mean, mean)
        values, other_values = policy.predict_values(x), policy.predict_values(other)
    assert not torch.allclose(values, other_values)  # the critic reads the truth
    first = policy.mlp_extractor.inner.policy_net[0]
    assert first.in_features == 6
    assert policy.mlp_extractor.inner.value_net[0].in_features == 9


def test_the_asymmetric_policy_is_mirror_symmetric_and_trains_every_parameter() -> None:
    policy = make_asymmetric()
    x = torch.randn(16, 9)
    mx = x * torch.tensor(OBS_SIGN * 2 + PRIVILEGED)
    with torch.no_grad():
        mean = policy.get_distribution(x).distribution.mean
        torch.testing.assert_close(
            policy.get_distribution(mx).distribution.mean, mean * torch.tensor(ACT_SIGN)
        )
        torch.testing.assert_close(policy.predict_values(mx), policy.predict_values(x))
    trained = {id(p) for group in policy.optimizer.param_groups for p in group["params"]}
    assert {id(p) for p in policy.parameters()} <= trained
    saved = policy._get_constructor_parameters()
    assert saved["privileged_signs"] == PRIVILEGED
    assert "privileged_signs" not in make_policy()._get_constructor_parameters()


def test_privileged_signs_must_leave_the_actor_a_view_that_fits_its_frames() -> None:
    for n_obs, signs, match in (
        (9, [1.0, 2.0], "privileged_signs=.* must be a list of \\+1/-1"),
        (3, [1.0, 1.0, -1.0], "leave no entry of the observation"),
        (8, [1.0, -1.0, 1.0], "mirror_obs \\(3 signs\\) must divide the actor's observation"),
    ):
        with pytest.raises(ValueError, match=match):
            MirrorMlpPolicy(
                spaces.Box(-1, 1, shape=(n_obs,), dtype=np.float32),
                spaces.Box(-1, 1, shape=(2,), dtype=np.float32),
                lambda _: 3e-4,
                mirror_obs=OBS_SIGN,
                mirror_action=ACT_SIGN,
                privileged_signs=signs,
            )

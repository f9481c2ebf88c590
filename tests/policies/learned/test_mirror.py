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

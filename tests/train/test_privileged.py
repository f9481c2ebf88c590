"""train/privileged.py: the simulation's truth appended for an asymmetric critic."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml

import follow_env
from policies.learned.features import Pipeline
from train.privileged import PRIVILEGED, PRIVILEGED_SIGNS, VecPrivilegedCritic
from train.wrappers import VecStackFrames


def _expected(info: dict[str, Any]) -> np.ndarray:
    who = info["detected_person"]
    return np.array(
        [
            info["true_distance_m"],
            np.clip(info["true_offset_px"] / 320.0, -2.0, 2.0),
            float(info["in_frame"]),
            float(who > 0),
            float(who < 0),
            min(info["wall_clearance_m"], 2.0),
            min(info["bystander_clearance_m"], 2.0),
        ],
        dtype=np.float32,
    )


def test_each_step_carries_the_truth_of_the_state_it_reached() -> None:
    """Beside a full-info twin on the same seeds and actions: the view is the env's own, the
    appended entries are the twin's infos (an ended lane's terminal observation gets its
    final state's, the new episode's first observation the shared start)."""
    kwargs: dict[str, Any] = {"scenario": "crossing", "episode": {"max_steps": 25}}
    wrapped = VecPrivilegedCritic(follow_env.make_sb3_vec_env(3, **kwargs))
    twin = follow_env.make_sb3_vec_env(3, full_info=True, **kwargs)
    for env in (wrapped, twin):
        env.seed(11)
    first, twin_first = wrapped.reset(), twin.reset()
    n = twin_first.shape[1]
    assert wrapped.observation_space.shape == (n + len(PRIVILEGED),)
    np.testing.assert_array_equal(first[:, :n], twin_first)
    np.testing.assert_array_equal(first[:, n:], np.tile(wrapped._start, (3, 1)))
    rng = np.random.default_rng(0)
    ended, stolen = 0, 0
    for _ in range(60):
        action = rng.uniform(-1.0, 1.0, (3, 2)).astype(np.float32)
        action[:, 0] = np.abs(action[:, 0])  # drive on: episodes end, strangers cross
        obs, _, dones, infos = wrapped.step(action)
        twin_obs, _, twin_dones, twin_infos = twin.step(action)
        np.testing.assert_array_equal(dones, twin_dones)
        np.testing.assert_array_equal(obs[:, :n], twin_obs)
        for i, info in enumerate(twin_infos):
            truth = _expected(info)
            if dones[i]:
                ended += 1
                final = infos[i]["terminal_observation"]
                np.testing.assert_array_equal(final[:n], info["terminal_observation"])
                np.testing.assert_allclose(final[n:], truth, rtol=1e-6)
                np.testing.assert_array_equal(obs[i, n:], wrapped._start)
            else:
                np.testing.assert_allclose(obs[i, n:], truth, rtol=1e-6)
            stolen += info["detected_person"] > 0
        assert all(wrapped.observation_space.contains(row) for row in obs)
    assert ended >= 3  # episodes ended on the way,
    assert stolen >= 1  # and the crossing stranger was taken for the person at least once


def test_the_agent_pipeline_leaves_it_out() -> None:
    """Training-only: the actor's view at inference is the entries below it."""
    entries = [
        ("train.wrappers.VecStackFrames", {"n_stack": 2}),
        ("train.privileged.VecPrivilegedCritic", {}),
    ]
    assert [short for _, short, _ in Pipeline.view_entries(entries)] == ["StackFrames"]
    wrapped = VecPrivilegedCritic(VecStackFrames(follow_env.make_sb3_vec_env(2), n_stack=2))
    assert wrapped.observation_space.shape == (2 * 2 + len(PRIVILEGED),)
    assert VecPrivilegedCritic.training_only
    assert len(PRIVILEGED_SIGNS) == len(PRIVILEGED)
    assert PRIVILEGED_SIGNS[1] == -1.0  # the offset changes sign in a mirror
    assert PRIVILEGED_SIGNS.count(-1.0) == 1


def test_bad_arguments_and_envs_are_refused() -> None:
    with pytest.raises(ValueError, match=r"VecPrivilegedCritic\.clip_m=0\.0 is out of range"):
        VecPrivilegedCritic(follow_env.make_sb3_vec_env(1), clip_m=0.0)
    with pytest.raises(ValueError, match=r"half_width_px=-1\.0 is out of range"):
        VecPrivilegedCritic(follow_env.make_sb3_vec_env(1), half_width_px=-1.0)
    from stable_baselines3.common.env_util import make_vec_env

    with pytest.raises(ValueError, match="needs an env whose infos can carry true_distance_m"):
        VecPrivilegedCritic(make_vec_env("CartPole-v1", n_envs=1))


CRITIC = "train.privileged.VecPrivilegedCritic"


def _asymmetric(**changes: Any) -> dict[str, Any]:
    """ppo_fast.yaml's learner with the critic's truth listed last."""
    section: dict[str, Any] = {
        "policy": "train.mirror.MirrorMlpPolicy",
        "n_envs": 12,
        "n_timesteps": 1000,
        "normalize": {"norm_obs": False, "norm_reward": True},
        "vec_env_wrapper": [
            {"train.wrappers.VecStackFrames": {"n_stack": 2, "pad": "first"}},
            CRITIC,
        ],
        "policy_kwargs": {
            "mirror_obs": [1, -1],
            "mirror_action": [1, -1],
            "privileged_signs": PRIVILEGED_SIGNS,
        },
    }
    section.update(changes)
    return section


@pytest.mark.parametrize(
    ("changes", "message"),
    [
        ({"vec_env_wrapper": [CRITIC, "train.wrappers.VecStackFrames"]}, "listed once, last"),
        ({"frame_stack": 2, "vec_env_wrapper": [CRITIC]}, "frame_stack=2 must be 1"),
        ({"normalize": True}, r"normalize must leave observations alone \(norm_obs: false\)"),
        (
            {"policy_kwargs": {"mirror_obs": [1, -1], "mirror_action": [1, -1]}},
            "privileged_signs=None must give 7 signs",
        ),
        (
            {"vec_env_wrapper": ["train.wrappers.VecStackFrames"]},
            "privileged_signs needs the wrapper train.privileged.VecPrivilegedCritic",
        ),
    ],
)  # fmt: skip
def test_a_file_must_give_the_truth_last_and_say_so_to_the_policy(
    changes: dict[str, Any], message: str
) -> None:
    from train.config import ConfigError, parse_hyperparams

    parse_hyperparams(_asymmetric(), where="f.yaml")  # the sound file passes
    with pytest.raises(ConfigError, match=f"^f.yaml: .*{message}"):
        parse_hyperparams(_asymmetric(**changes), where="f.yaml")


@pytest.mark.slow
def test_an_asymmetric_run_trains_and_acts_on_its_own_view(tmp_path: Path, acts_as_trained) -> None:
    """follow-train with the truth for the critic: the run loads as a policy whose actions, in
    the single env without any truth, are SB3's ``predict`` on the training stack (truth
    appended), step by step; so the actor reads its own view only."""
    from stable_baselines3 import PPO

    from policies import make_policy
    from train.cli import main

    section = _asymmetric(n_envs=4, n_steps=64, batch_size=128, n_epochs=2, n_timesteps=2000)
    section["vec_env_wrapper"] = [
        {"train.wrappers.VecRescaleAction": {"w_max_radps": 2.0}},
        {"train.wrappers.VecScaleObservation": {"scale": [1.0, 0.01]}},
        {"train.wrappers.VecStackFrames": {"n_stack": 2, "pad": "first"}},
        CRITIC,
    ]
    path = tmp_path / "asym.yaml"
    path.write_text(yaml.safe_dump({"PersonFollow-v0": section}))
    run = tmp_path / "run"
    args = ["--hyperparams", str(path), "--scenarios", "straight,curve", "--final-episodes", "0"]
    assert main([*args, "--no-progress", "--eval-freq", "1000", "--out", str(run)]) == 0
    model = PPO.load(run / "model.zip", device="cpu")
    assert model.observation_space.shape == (2 * 2 + len(PRIVILEGED),)
    acts_as_trained(run, make_policy(str(run)), 40)

"""train/config.py: hyperparameters in rl-zoo3's YAML format."""

from __future__ import annotations

from pathlib import Path

import pytest

from train.config import ConfigError, load_hyperparams, parse_hyperparams, policy_class, schedule
from train.ppo import DEFAULT_HYPERPARAMS, ENV_ID

MINIMAL = {"n_envs": 4, "n_timesteps": 1000}


def test_the_shipped_file_loads_and_keeps_rl_zoo3_keys() -> None:
    hp = load_hyperparams(DEFAULT_HYPERPARAMS, ENV_ID)
    assert isinstance(hp["n_timesteps"], int)  # YAML's !!float 4e6 becomes an int
    for key in ("n_envs", "normalize", "frame_stack", "vec_env_wrapper", "policy_kwargs"):
        assert key in hp


def test_missing_defaults_are_filled_in() -> None:
    hp = parse_hyperparams(MINIMAL)
    assert hp["policy"] == "MlpPolicy"
    assert hp["normalize"] is False
    assert hp["frame_stack"] == 1
    assert hp["vec_env_wrapper"] == []


def test_unknown_key_is_named_with_the_file(tmp_path: Path) -> None:
    path = tmp_path / "ppo.yaml"
    path.write_text(f"{ENV_ID}:\n  n_envs: 4\n  n_timesteps: 100\n  n_stepz: 64\n")
    with pytest.raises(
        ConfigError, match=r"ppo.yaml \[PersonFollow-v0\]: unknown key\(s\) n_stepz"
    ):
        load_hyperparams(path, ENV_ID)


def test_missing_env_section_lists_the_sections(tmp_path: Path) -> None:
    path = tmp_path / "ppo.yaml"
    path.write_text("CartPole-v1:\n  n_envs: 4\n")
    with pytest.raises(ConfigError, match="no section 'PersonFollow-v0' \\(found: CartPole-v1\\)"):
        load_hyperparams(path, ENV_ID)


def test_missing_file_is_named(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match=r"nope\.yaml: cannot read"):
        load_hyperparams(tmp_path / "nope.yaml", ENV_ID)


@pytest.mark.parametrize(
    ("override", "message"),
    [
        ({"n_envs": 0}, "n_envs=0 is out of range"),
        ({"normalize": "dict(norm_obs=True)"}, "strings are not evaluated"),
        ({"frame_stack": 0}, "frame_stack=0 is out of range"),
        ({"vec_env_wrapper": ["train.wrappers.NoSuchWrapper"]}, "does not import"),
        ({"policy": "CnnPolicy"}, "does not import"),
        ({"policy": "train.wrappers.VecRescaleAction"}, "not an SB3 ActorCriticPolicy"),
        ({"learning_rate": "cos_3e-4"}, "must be a number or 'lin_<number>'"),
    ],
)
def test_bad_values_are_rejected_naming_the_key(override: dict, message: str) -> None:
    with pytest.raises(ConfigError, match=message):
        parse_hyperparams(MINIMAL | override)


def test_lin_schedule_decays_linearly_to_zero() -> None:
    lr = schedule("lin_3e-4")
    assert lr(1.0) == pytest.approx(3e-4)
    assert lr(0.5) == pytest.approx(1.5e-4)
    assert schedule(0.2) == 0.2


def test_policy_class_imports_a_dotted_name() -> None:
    from train.mirror import MirrorMlpPolicy

    assert policy_class("train.mirror.MirrorMlpPolicy") is MirrorMlpPolicy
    assert policy_class("MlpPolicy") == "MlpPolicy"

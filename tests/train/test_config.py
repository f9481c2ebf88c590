"""train/config.py: hyperparameters in rl-zoo3's YAML format."""

from __future__ import annotations

from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from stable_baselines3.common.vec_env import VecEnvWrapper

from follow_env.tasks.person_follow import ENV_ID
from train.config import (
    ConfigError,
    check_action_fit,
    load_hyperparams,
    parse_hyperparams,
    platform_label,
    policy_class,
    schedule,
    wrapper_specs,
)
from train.ppo import DEFAULT_HYPERPARAMS

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
    with pytest.raises(ConfigError, match=r"nope\.yaml: cannot read") as caught:
        load_hyperparams(tmp_path / "nope.yaml", ENV_ID)
    assert "shipped" not in str(caught.value)


def test_a_shipped_file_named_from_outside_the_clone_is_pointed_to(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # the README's `--hyperparams train/configs/ppo_fast.yaml`, run from another folder
    monkeypatch.chdir(tmp_path)
    shipped = Path(__file__).parents[2] / "train" / "configs" / "ppo_fast.yaml"
    with pytest.raises(ConfigError) as caught:
        load_hyperparams("train/configs/ppo_fast.yaml", ENV_ID)
    assert str(caught.value) == (
        "train/configs/ppo_fast.yaml: cannot read hyperparameters: No such file or directory "
        f"(looked for in {tmp_path}; the shipped ppo_fast.yaml is {shipped})"
    )
    # a file of the user's own that shares a shipped file's name is not pointed elsewhere, and
    # an error other than a missing file (a name too long) stays one line
    for given in ("mine/ppo.yaml", "x" * 300 + "/train/configs/ppo.yaml"):
        with pytest.raises(ConfigError, match="cannot read hyperparameters") as caught:
            load_hyperparams(given, ENV_ID)
        assert "shipped" not in str(caught.value)


@pytest.mark.parametrize(
    ("override", "message"),
    [
        ({"n_envs": 0}, "n_envs=0 is out of range"),
        ({"normalize": "dict(norm_obs=True)"}, "strings are not evaluated"),
        ({"frame_stack": 0}, "frame_stack=0 is out of range"),
        # 10**9 frames once filled the memory building the env
        ({"frame_stack": 10**9}, "frame_stack=1000000000 is out of range"),
        # math.isfinite raised OverflowError on an int past float's range
        ({"ent_coef": 10**400}, "ent_coef=1000"),
        ({"vec_env_wrapper": ["train.wrappers.NoSuchWrapper"]}, "does not import"),
        ({"policy": "CnnPolicy"}, "does not import"),
        ({"policy": "train.wrappers.VecRescaleAction"}, "not an SB3 ActorCriticPolicy"),
        ({"learning_rate": "cos_3e-4"}, "learning_rate='cos_3e-4' is out of range: must be a"),
        (
            {"frame_stack": 4, "vec_env_wrapper": [{"train.wrappers.VecStackFrames": {}}]},
            "frame_stack=4 is out of range beside the wrapper train.wrappers.VecStackFrames, "
            "which stacks frames itself: must be 1",
        ),
        (
            {
                "frame_stack": 2,
                "vec_env_wrapper": [{"train.wrappers.VecStackFrames": {"n_stack": 4}}],
            },
            "frame_stack=2 is out of range beside the wrapper train.wrappers.VecStackFrames",
        ),
        # An SB3 wrapper the agent's view cannot be rebuilt with: it trained for its whole
        # budget, and then the agent could not be loaded
        (
            {"vec_env_wrapper": [{"stable_baselines3.common.vec_env.VecCheckNan": None}]},
            "'stable_baselines3.common.vec_env.VecCheckNan' is not a step a trained agent can",
        ),
        (
            {
                "vec_env_wrapper": [
                    {"stable_baselines3.common.vec_env.VecFrameStack": {"n_stack": 4}}
                ]
            },
            "'stable_baselines3.common.vec_env.VecFrameStack' is not a step a trained agent",
        ),
    ],
)
def test_bad_values_are_rejected_naming_the_key(override: dict, message: str) -> None:
    with pytest.raises(ConfigError, match=message):
        parse_hyperparams(MINIMAL | override)


@pytest.mark.parametrize(
    ("override", "message"),
    [
        (
            {"policy_kwargs": "dict(net_arch=[64])"},
            r"policy_kwargs='dict\(net_arch=\[64\]\)' is out of range: must be a mapping",
        ),
        ({"policy_kwargs": [64, 64]}, r"policy_kwargs=\[64, 64\] is out of range"),
        # rl-zoo3's own keys are named as such, with what to do instead
        (
            {"env_wrapper": "gymnasium.wrappers.TimeLimit"},
            r"env_wrapper='gymnasium.wrappers.TimeLimit' is an rl-zoo3 key follow-train does "
            r"not take: .* vec_env_wrapper",
        ),
        ({"callback": "my.Callback"}, r"callback='my.Callback' is an rl-zoo3 key"),
        ({"monitor_kwargs": {}}, r"monitor_kwargs=\{\} is an rl-zoo3 key"),
    ],
)
def test_rl_zoo3_forms_are_refused_naming_the_value(override: dict, message: str) -> None:
    with pytest.raises(ConfigError, match=message):
        parse_hyperparams(MINIMAL | override)


def test_policy_kwargs_null_is_none_given_as_for_sb3_and_rl_zoo3() -> None:
    assert parse_hyperparams(MINIMAL | {"policy_kwargs": None})["policy_kwargs"] == {}


def test_one_frame_history_is_accepted() -> None:
    """The stacking wrapper with frame_stack 1 (ppo_fast.yaml's way), or frame_stack alone."""
    wrapper = [{"train.wrappers.VecStackFrames": {"n_stack": 4}}]
    assert parse_hyperparams(MINIMAL | {"vec_env_wrapper": wrapper})["frame_stack"] == 1
    assert parse_hyperparams(MINIMAL | {"frame_stack": 4})["frame_stack"] == 4


W = "train.wrappers.VecRescaleAction"


# Each case: a bad value, and the start of its message (key=value, then the allowed range).
@pytest.mark.parametrize(
    ("override", "message"),
    [
        ({"n_steps": "sixty"}, "n_steps='sixty' is out of range: must be an integer >= 1"),
        ({"n_steps": 0}, "n_steps=0 is out of range: must be an integer >= 1"),
        ({"n_steps": 64.5}, "n_steps=64.5 is out of range: must be an integer >= 1"),
        ({"n_steps": True}, "n_steps=True is out of range: must be an integer >= 1"),
        ({"n_epochs": 0}, "n_epochs=0 is out of range: must be an integer >= 1"),
        ({"gamma": 7.5}, r"gamma=7.5 is out of range: must be a number in \[0, 1\]"),
        ({"gamma": -0.1}, r"gamma=-0.1 is out of range: must be a number in \[0, 1\]"),
        ({"gamma": float("nan")}, r"gamma=nan is out of range: must be a number in \[0, 1\]"),
        ({"gamma": "0.99"}, r"gamma='0.99' is out of range: must be a number in \[0, 1\]"),
        ({"gae_lambda": 1.5}, r"gae_lambda=1.5 is out of range: must be a number in \[0, 1\]"),
        ({"learning_rate": 0}, "learning_rate=0 is out of range: must be a number > 0"),
        ({"learning_rate": -3e-4}, "learning_rate=-0.0003 is out of range: must be a number > 0"),
        ({"learning_rate": "lin_-1"}, "learning_rate='lin_-1' is out of range"),
        ({"learning_rate": float("inf")}, "learning_rate=inf is out of range"),
        ({"clip_range": 0}, "clip_range=0 is out of range: must be a number > 0"),
        ({"clip_range": "lin_abc"}, "clip_range='lin_abc' is out of range"),
        ({"clip_range_vf": -0.2}, "clip_range_vf=-0.2 is out of range: must be a number > 0"),
        ({"ent_coef": -0.01}, "ent_coef=-0.01 is out of range: must be a number >= 0"),
        ({"vf_coef": float("inf")}, "vf_coef=inf is out of range: must be a number >= 0"),
        ({"max_grad_norm": 0}, "max_grad_norm=0 is out of range: must be a number > 0"),
        ({"target_kl": 0}, "target_kl=0 is out of range: must be a number > 0"),
        ({"sde_sample_freq": -2}, "sde_sample_freq=-2 is out of range: must be an integer >= -1"),
        ({"stats_window_size": 0}, "stats_window_size=0 is out of range: must be an integer >= 1"),
        ({"use_sde": "no"}, "use_sde='no' is out of range: must be true or false"),
        ({"normalize_advantage": 1}, "normalize_advantage=1 is out of range: must be true or"),
        ({"rollout_buffer_class": "x.Buffer"}, "rollout_buffer_class='x.Buffer' is not supported"),
        ({"_init_setup_model": False}, r"unknown key\(s\) _init_setup_model"),
        ({"frame_stack": "4"}, r"frame_stack='4' is out of range: must be an integer in \[1, 1,0"),
        ({"n_timesteps": -5}, "n_timesteps=-5 is out of range: must be an integer >= 1"),
        ({"normalize": {"norm_obs": "yes"}}, "normalize.norm_obs='yes' is out of range: must be"),
        ({"normalize": {"clip_obs": 0}}, "normalize.clip_obs=0 is out of range: must be a number"),
        ({"normalize": {"gamma": 2}}, r"normalize.gamma=2 is out of range: must be a number in"),
        ({"normalize": {"clipobs": 1}}, "normalize.clipobs is not a VecNormalize argument"),
        ({"policy_kwargs": {"net_arch": [64, -1]}}, r"net_arch=\[64, -1\] is out of range"),
        ({"policy_kwargs": {"net_arch": "64,64"}}, "net_arch='64,64' is out of range"),
        ({"policy_kwargs": {"net_arch": {"pi": [8], "q": [8]}}}, "net_arch=.* is out of range"),
        ({"policy_kwargs": {"net_arch": [64.0]}}, r"net_arch=\[64.0\] is out of range"),
        ({"policy_kwargs": {"log_std_init": "a"}}, "log_std_init='a' is out of range: must be a"),
        ({"policy_kwargs": {"ortho_init": "no"}}, "ortho_init='no' is out of range: must be true"),
        ({"policy_kwargs": {"activation_fn": "nn.ReLU"}}, "activation_fn='nn.ReLU' is not suppo"),
        ({"policy_kwargs": {"netarch": [64]}}, "policy_kwargs.netarch is not an argument of"),
        ({"policy_kwargs": {"use_sde": True}}, "policy_kwargs.use_sde is not an argument of"),
        ({"vec_env_wrapper": [{W: {"w_max": 2.0}}]}, "'w_max' is not one of its arguments"),
        ({"vec_env_wrapper": [{W: {"venv": None}}]}, "'venv' is not one of its arguments"),
        ({"vec_env_wrapper": ["train.config.ConfigError"]}, "is not an SB3 VecEnvWrapper"),
        ({"vec_env_wrapper": [{W: [2.0]}]}, "entry .* is malformed"),
    ],
)
def test_every_field_is_checked_naming_key_value_and_range(override: dict, message: str) -> None:
    with pytest.raises(ConfigError, match=message) as error:
        parse_hyperparams(MINIMAL | override)
    assert str(error.value).startswith("hyperparameters: ")  # the source, then the key


def test_wrapper_arguments_are_checked_against_its_signature_listing_them() -> None:
    with pytest.raises(
        ConfigError, match=r"\(accepted: in_training, reverse_max_mps, v_max_mps, w_max_radps\)"
    ):
        parse_hyperparams(MINIMAL | {"vec_env_wrapper": [{W: {"w_max": 2.0}}]})


def test_policy_kwargs_of_a_custom_policy_include_its_own_arguments() -> None:
    hp = MINIMAL | {"policy": "train.mirror.MirrorMlpPolicy"}
    parse_hyperparams(hp | {"policy_kwargs": {"mirror_obs": [1, -1], "net_arch": [8]}})
    with pytest.raises(ConfigError, match=r"policy_kwargs\.mirror_ob is not an argument"):
        parse_hyperparams(hp | {"policy_kwargs": {"mirror_ob": [1, -1]}})


@pytest.mark.parametrize(
    ("override", "message"),
    [
        ({"n_steps": 64, "batch_size": 512}, r"batch_size=512 .* in \[2, .* = 64 \* 4 = 256\]"),
        ({"n_steps": 64, "batch_size": 1}, r"batch_size=1 is out of range: must be in \[2, "),
        ({"n_envs": 1, "n_steps": 1, "batch_size": 1}, r"n_steps \* n_envs = 1 \* 1 is out of"),
    ],
)
def test_batch_size_must_fit_the_rollout_buffer(override: dict, message: str) -> None:
    with pytest.raises(ConfigError, match=message):
        parse_hyperparams(MINIMAL | override)


def test_a_batch_of_one_is_allowed_without_advantage_normalisation() -> None:
    hp = MINIMAL | {"n_steps": 64, "batch_size": 1, "normalize_advantage": False}
    assert parse_hyperparams(hp)["batch_size"] == 1


def test_a_command_line_override_is_named_as_the_option() -> None:
    with pytest.raises(ConfigError, match=r"= 64 \* 2 = 128\] \(n_envs from --n-envs\)"):
        parse_hyperparams(MINIMAL | {"n_steps": 64, "batch_size": 256}, overrides={"n_envs": 2})
    with pytest.raises(ConfigError, match="--n-timesteps=0 is out of range"):
        parse_hyperparams(MINIMAL, overrides={"n_timesteps": 0})


def test_integral_floats_become_ints_as_yaml_writes_them() -> None:
    hp = parse_hyperparams(MINIMAL | {"n_steps": 64.0, "batch_size": 256.0})
    assert (hp["n_steps"], hp["batch_size"]) == (64, 256)
    assert isinstance(hp["n_steps"], int)


@pytest.mark.parametrize("value", [0, -1.0, "lin_0", "lin_-3e-4", "cos_1", float("nan"), True])
def test_schedule_rejects_anything_but_a_positive_number_or_lin(value: object) -> None:
    with pytest.raises(ConfigError, match="is out of range: must be a number > 0"):
        schedule(value)


# Python's float() reads "1_0" as 10 and " 3e-4" as 3e-4; rl-zoo3 refuses the first, and a
# file that means 1.0 or has a stray character must not train at another rate.
@pytest.mark.parametrize("value", ["lin_1_0", "lin_ 3e-4", "lin_3e-4 ", "lin_1e400", "lin_+1"])
def test_lin_takes_a_plain_decimal_number_only(value: str) -> None:
    with pytest.raises(ConfigError, match="'lin_<number>' with the number > 0"):
        schedule(value)


@pytest.mark.parametrize("value", ["lin_3e-4", "lin_0.0003", "lin_.0003", "lin_3E-4"])
def test_lin_reads_every_way_of_writing_a_decimal(value: str) -> None:
    assert schedule(value)(1.0) == pytest.approx(3e-4)


def test_lin_schedule_decays_linearly_to_zero() -> None:
    lr = schedule("lin_3e-4")
    assert lr(1.0) == pytest.approx(3e-4)
    assert lr(0.5) == pytest.approx(1.5e-4)
    assert schedule(0.2) == 0.2


def test_policy_class_imports_a_dotted_name() -> None:
    from train.mirror import MirrorMlpPolicy

    assert policy_class("train.mirror.MirrorMlpPolicy") is MirrorMlpPolicy
    assert policy_class("MlpPolicy") == "MlpPolicy"


MECANUM_HYPERPARAMS = DEFAULT_HYPERPARAMS.with_name("ppo_mecanum.yaml")


def test_the_mecanum_file_names_its_platform_and_three_entry_settings() -> None:
    hp = load_hyperparams(MECANUM_HYPERPARAMS, ENV_ID)
    assert hp["env_kwargs"] == {"platform": "mecanum"}
    assert hp["policy_kwargs"]["mirror_action"] == [1, -1, -1]
    check_action_fit(hp, ("v_mps", "vy_mps", "w_radps"))


def test_env_kwargs_platform_must_be_a_registered_platform() -> None:
    with pytest.raises(
        ConfigError,
        match=r"env_kwargs\.platform='mecanum4' is out of range: must be a "
        r"platform's name \(diff_drive, mecanum, unicycle\) or a mapping with its 'name'",
    ):
        parse_hyperparams(MINIMAL | {"env_kwargs": {"platform": "mecanum4"}})


def test_env_kwargs_platform_may_carry_section_overrides() -> None:
    platform = {"name": "mecanum", "drive": {"mode": "pid"}}
    hp = parse_hyperparams(MINIMAL | {"env_kwargs": {"platform": platform}})
    assert hp["env_kwargs"]["platform"] == platform
    assert platform_label(platform) == "mecanum (drive.mode=pid)"
    assert platform_label("mecanum") == "mecanum"
    with pytest.raises(ConfigError, match=r"env_kwargs\.platform: .*drive\.gear"):
        parse_hyperparams(
            MINIMAL | {"env_kwargs": {"platform": {"name": "mecanum", "drive": {"gear": 2}}}}
        )
    with pytest.raises(ConfigError, match=r"env_kwargs\.platform=\{'drive'"):
        parse_hyperparams(MINIMAL | {"env_kwargs": {"platform": {"drive": {"mode": "pid"}}}})


@pytest.mark.parametrize(
    ("env_kwargs", "message"),
    [
        ("mecanum", r"env_kwargs='mecanum' must be a mapping of gym\.make keyword arguments"),
        (
            {"scenario": "curve"},
            r"env_kwargs\.scenario is set by follow-train \(give --scenarios\)",
        ),
        ({"config": "noisy"}, r"env_kwargs\.config is set by follow-train \(give --env-config\)"),
    ],
)
def test_env_kwargs_are_checked_naming_the_key(env_kwargs: object, message: str) -> None:
    with pytest.raises(ConfigError, match=message):
        parse_hyperparams(MINIMAL | {"env_kwargs": env_kwargs})


def test_a_file_without_env_kwargs_stays_as_it_was() -> None:
    assert "env_kwargs" not in load_hyperparams(DEFAULT_HYPERPARAMS, ENV_ID)


def test_mirror_action_must_fit_the_platforms_action() -> None:
    hp = load_hyperparams(DEFAULT_HYPERPARAMS, ENV_ID)  # mirror_action [1, -1]: two entries
    hp["env_kwargs"] = {"platform": "mecanum"}
    with pytest.raises(
        ConfigError,
        match=r"policy_kwargs\.mirror_action=\[1, -1\] is out of range: must be 3 "
        r"signs, one per action entry \[v_mps, vy_mps, w_radps\] \(env_kwargs\.platform: mecanum\)",
    ):
        check_action_fit(hp, ("v_mps", "vy_mps", "w_radps"))
    hp["policy_kwargs"]["mirror_action"] = [1, 1, -1]
    with pytest.raises(ConfigError, match="vy_mps changes its sign in a left-right mirror"):
        check_action_fit(hp, ("v_mps", "vy_mps", "w_radps"))


def test_the_fast_file_is_ppo_yaml_with_more_lanes_larger_minibatches_fewer_epochs() -> None:
    fast = load_hyperparams(DEFAULT_HYPERPARAMS.with_name("ppo_fast.yaml"), ENV_ID)
    default = load_hyperparams(DEFAULT_HYPERPARAMS, ENV_ID)
    changed = {k for k in fast if fast[k] != default[k]}
    changed_keys = {"n_envs", "n_timesteps", "batch_size", "n_epochs", "frame_stack"}
    assert changed == {*changed_keys, "vec_env_wrapper"}
    # the agent's view is the same, its 4 frames stacked by VecStackFrames from the episode's
    # first observation (not frame_stack's zeros); the reward and the speed command's steps
    # are its own
    fast_wrappers, default_wrappers = (
        dict(wrapper_specs(h["vec_env_wrapper"])) for h in (fast, default)
    )
    stack = "train.wrappers.VecStackFrames"
    assert (default["frame_stack"], fast["frame_stack"]) == (4, 1)
    assert list(fast_wrappers) == [*default_wrappers, stack]
    assert fast_wrappers.pop(stack) == {"n_stack": 4, "pad": "first"}
    differ = {
        (name, key)
        for name, kwargs in fast_wrappers.items()
        for key in {*kwargs, *default_wrappers[name]}
        if kwargs.get(key) != default_wrappers[name].get(key)
    }
    reward, action = "train.wrappers.VecShapedReward", "train.wrappers.VecIncrementalAction"
    assert differ == {
        (reward, "v_rate_weight"),
        (reward, "far_weight"),
        (reward, "far_from_m"),
        (action, "max_change"),
    }
    assert fast["n_steps"] * fast["n_envs"] % fast["batch_size"] == 0  # whole minibatches


CONFIGS = sorted((Path(__file__).parents[2] / "train" / "configs").glob("*.yaml"))


def _learner_of(path: Path) -> str:
    """The ``--algo`` a shipped file is for: the longest learner name its name starts with
    (``sac_fast.yaml``: ``sac``; ``recurrent_ppo.yaml``: ``recurrent_ppo``)."""
    from train.algos import ALGOS

    return max((name for name in ALGOS if path.stem.startswith(name)), key=len)


@pytest.mark.parametrize("path", CONFIGS, ids=lambda p: p.name)
def test_every_shipped_file_builds_the_env_its_agent_sees(path: Path) -> None:
    """Each file in train/configs loads as its learner's arguments, and its env (with its
    ``env_kwargs``) under its wrappers gives observations of the space the agent is built for."""
    from follow_env.tasks import task_for_env
    from train.config import sole_section
    from train.envs import agent_env, base_env

    env_id = sole_section(path)
    hp = load_hyperparams(path, env_id, algo=_learner_of(path))
    task = task_for_env(env_id)
    preset = "thesis" if "thesis" in task.presets else next(iter(task.presets))
    base = base_env(task.variants()[:1], 2, preset, env_id, hp.get("env_kwargs"))
    venv = agent_env(base, hp, "eval")
    try:
        obs = venv.reset()
        assert obs.shape == (2, *venv.observation_space.shape)
        # finite rather than inside the space: SB3's VecFrameStack repeats each entry's bounds
        # n_stack times (entry by entry) while it stacks the frames one after another
        assert np.isfinite(obs).all()
        actions = [venv.action_space.sample() for _ in range(2)]
        obs, _, _, _ = venv.step(np.stack(actions))
        assert obs.shape == (2, *venv.observation_space.shape)
        assert np.isfinite(obs).all()
    finally:
        venv.close()


def test_the_bursts_file_is_ppo_ahead_yaml_with_its_detector_harsher_in_training() -> None:
    configs = DEFAULT_HYPERPARAMS.parent
    bursts = load_hyperparams(configs / "ppo_ahead_bursts.yaml", ENV_ID)
    ahead = load_hyperparams(configs / "ppo_ahead.yaml", ENV_ID)
    assert {k for k in bursts if bursts[k] != ahead[k]} == {"env_kwargs"}
    harsher, plain = bursts["env_kwargs"]["perception"], ahead["env_kwargs"]["perception"]
    assert {k: v for k, v in harsher.items() if k not in plain} == {
        "burst_start_prob": 0.02,
        "burst_mean_frames": 10.0,
    }
    assert {k: harsher[k] for k in plain} == plain


def test_the_held_file_is_the_bursts_file_with_no_backing_up_blind() -> None:
    configs = DEFAULT_HYPERPARAMS.parent
    held = load_hyperparams(configs / "ppo_ahead_held.yaml", ENV_ID)
    bursts = load_hyperparams(configs / "ppo_ahead_bursts.yaml", ENV_ID)
    assert {k for k in held if held[k] != bursts[k]} == {"vec_env_wrapper"}
    changed = [
        (a, b)
        for a, b in zip(held["vec_env_wrapper"], bursts["vec_env_wrapper"], strict=True)
        if a != b
    ]
    ((mine, theirs),) = changed
    (name, kwargs), (name_b, kwargs_b) = next(iter(mine.items())), next(iter(theirs.items()))
    assert name == name_b == "train.wrappers.VecIncrementalAction"
    assert kwargs == {**kwargs_b, "held_index": 3, "held_floor": [0.0, None]}
    # entry 3 of the view at that step is the age (distance, offset, ahead, age)
    names = [next(iter(entry)) for entry in held["vec_env_wrapper"]]
    assert names.index("train.wrappers.VecObservationAge") < names.index(name)


def test_the_gated_file_is_ppo_ahead_yaml_with_the_gate_left_out_of_training() -> None:
    """ppo_ahead_gated.yaml trains as ppo_ahead.yaml does (the gate passes observations through
    there), and its agent's view holds the gate before the age that reads its held detection."""
    configs = DEFAULT_HYPERPARAMS.parent
    gated = load_hyperparams(configs / "ppo_ahead_gated.yaml", ENV_ID)
    ahead = load_hyperparams(configs / "ppo_ahead.yaml", ENV_ID)
    assert {k for k in gated if gated[k] != ahead[k]} == {"vec_env_wrapper"}
    gate = {
        "train.wrappers.VecJumpGate": {"max_jump_m": 0.5, "accept_after": 10, "in_training": False}
    }
    entries = gated["vec_env_wrapper"]
    assert [e for e in entries if e != gate] == ahead["vec_env_wrapper"]
    names = [next(iter(entry)) for entry in entries]
    assert names.index("train.wrappers.VecJumpGate") + 1 == names.index(
        "train.wrappers.VecObservationAge"
    )
    assert [kw.get("in_training", True) for _, kw in wrapper_specs(entries)].count(False) == 1


def test_the_headway_file_is_the_far_file_with_a_distance_that_grows_with_speed() -> None:
    """ppo_ahead_law_headway.yaml trains as ppo_ahead_law_far.yaml does but for the following
    distance: the env's reward keeps the reference's 1 m, and the shaped reward's distance is
    1 m + 0.1 s x the robot's speed (1.1 m at a walk) where the far file's is 1.1 m always."""
    configs = DEFAULT_HYPERPARAMS.parent
    moving = load_hyperparams(configs / "ppo_ahead_law_headway.yaml", ENV_ID)
    far = load_hyperparams(configs / "ppo_ahead_law_far.yaml", ENV_ID)
    assert {k for k in moving if moving[k] != far[k]} == {"env_kwargs", "vec_env_wrapper"}
    assert moving["env_kwargs"] == {k: v for k, v in far["env_kwargs"].items() if k != "reward"}
    assert far["env_kwargs"]["reward"] == {"target_distance_m": 1.1}
    changed = [
        (a, b)
        for a, b in zip(moving["vec_env_wrapper"], far["vec_env_wrapper"], strict=True)
        if a != b
    ]
    ((mine, theirs),) = changed
    name, kwargs = next(iter(mine.items()))
    assert name == "train.wrappers.VecShapedReward"
    assert kwargs == {**theirs[name], "target_distance_m": 1.0, "headway_s": 0.1}


def test_the_tracker_file_is_the_headway_file_on_the_tracker() -> None:
    """ppo_ahead_law_tracker.yaml trains as ppo_ahead_law_headway.yaml does, on a perception that
    tracks the person (association "tracker") instead of taking the first detection; nothing
    else changes, so the two studies differ by the perception alone."""
    configs = DEFAULT_HYPERPARAMS.parent
    tracked = load_hyperparams(configs / "ppo_ahead_law_tracker.yaml", ENV_ID)
    headway = load_hyperparams(configs / "ppo_ahead_law_headway.yaml", ENV_ID)
    assert {k for k in tracked if tracked[k] != headway[k]} == {"env_kwargs"}
    perception = tracked["env_kwargs"]["perception"]
    assert perception == {**headway["env_kwargs"]["perception"], "association": "tracker"}
    assert {k: v for k, v in tracked["env_kwargs"].items() if k != "perception"} == {
        k: v for k, v in headway["env_kwargs"].items() if k != "perception"
    }
    # the env takes the setting as given (an unknown association would raise here)
    env = gym.make(ENV_ID, **tracked["env_kwargs"])
    assert env.unwrapped.config.perception.association == "tracker"
    env.close()


@pytest.mark.parametrize(
    ("text", "key"),
    [
        (f"{ENV_ID}:\n  n_envs: 4\n  gamma: 0.9\n  gamma: 0.5\n", "'gamma' twice"),
        (f"{ENV_ID}:\n  n_envs: 4\n{ENV_ID}:\n  n_envs: 8\n", f"'{ENV_ID}' twice"),
        (f"{ENV_ID}:\n  policy_kwargs: {{net_arch: [8], net_arch: [64]}}\n", "'net_arch' twice"),
    ],
)
def test_a_key_given_twice_is_refused_naming_it(tmp_path: Path, text: str, key: str) -> None:
    # PyYAML keeps the last of two equal keys without a word: the run would train with a
    # value the reader of the file may not see.
    path = tmp_path / "ppo.yaml"
    path.write_text(text)
    with pytest.raises(
        ConfigError, match=rf"ppo\.yaml: .*line \d+, column \d+: found the key {key}"
    ):
        load_hyperparams(path, ENV_ID)


def test_anchors_and_merge_keys_are_not_duplicates(tmp_path: Path) -> None:
    path = tmp_path / "ppo.yaml"
    path.write_text(
        "base: &base {n_envs: 4, n_timesteps: 100, gamma: 0.9}\n"
        f"{ENV_ID}:\n  <<: *base\n  gamma: 0.5\n"
    )
    hp = load_hyperparams(path, ENV_ID)
    assert (hp["n_envs"], hp["gamma"]) == (4, 0.5)  # the section's own key wins, as YAML says


def test_a_file_that_is_not_utf8_is_named(tmp_path: Path) -> None:
    path = tmp_path / "ppo.yaml"
    path.write_bytes(b"\xff\xfe" + f"{ENV_ID}: {{}}\n".encode())
    with pytest.raises(ConfigError, match=r"ppo\.yaml: not a UTF-8 text file"):
        load_hyperparams(path, ENV_ID)


class VecScaleObservation(VecEnvWrapper):
    """Named as the project's step, but another class (a user's own)."""

    def __init__(self, venv: object, scale: float = 1.0) -> None:
        super().__init__(venv)  # type: ignore[arg-type]

    def reset(self) -> object:
        return self.venv.reset()

    def step_wait(self) -> object:
        return self.venv.step_wait()


def test_a_wrapper_named_as_a_step_but_of_another_class_is_refused() -> None:
    # the agent's view is rebuilt by the step's name: train.wrappers.VecScaleObservation's
    # arithmetic would silently stand in for this class's at inference
    name = f"{__name__}.VecScaleObservation"
    with pytest.raises(ConfigError, match="is named as the step VecScaleObservation but is"):
        parse_hyperparams(MINIMAL | {"vec_env_wrapper": [{name: {"scale": 2.0}}]})


def test_a_normalize_gamma_other_than_the_algorithms_is_refused() -> None:
    """rl-zoo3 replaces normalize.gamma by the algorithm's gamma: the same file must not train
    with another discount here."""
    with pytest.raises(ConfigError, match=r"normalize.gamma=0.9 differs from gamma=0.99"):
        parse_hyperparams(MINIMAL | {"gamma": 0.99, "normalize": {"gamma": 0.9}})
    same = parse_hyperparams(MINIMAL | {"gamma": 0.99, "normalize": {"gamma": 0.99}})
    assert same["normalize"]["gamma"] == 0.99

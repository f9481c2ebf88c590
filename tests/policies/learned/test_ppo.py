"""policies/learned/ppo.py: a trained PPO agent as a Policy, loaded by name or path."""

from __future__ import annotations

import os
import pickle
import re
import shutil
import zipfile
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
import yaml

from eval.rollout import run_episode
from policies import Policy, for_platform, make_policy
from policies.learned.ppo import DEFAULT_AGENT, AgentLoadError, PPOPolicy
from train.envs import agent_env, base_env
from train.run import read_config


@pytest.fixture
def agent_copy(tmp_path: Path) -> Path:
    """The shipped agent's files in a folder of their own, free to damage."""
    folder = tmp_path / "agent"
    folder.mkdir()
    for name in ("model.zip", "vecnormalize.pkl", "config.yaml"):
        shutil.copy(DEFAULT_AGENT / name, folder / name)
    return folder


def obs(distance_m: float, offset_px: float) -> np.ndarray:
    return np.array([distance_m, offset_px], dtype=np.float32)


def test_ppo_name_builds_the_shipped_agent() -> None:
    policy = make_policy("ppo")
    assert isinstance(policy, Policy)
    assert policy.name == "ppo"


def test_a_run_folder_or_its_zip_is_a_policy_name(agent_copy: Path) -> None:
    for name in (str(agent_copy), str(agent_copy / "model.zip")):
        policy = make_policy(name)
        assert policy.name == name
        np.testing.assert_array_equal(
            policy.act(obs(1.4, 30.0)), make_policy("ppo").act(obs(1.4, 30.0))
        )


def test_missing_model_file_is_named(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match=r"nothing\.zip: model file not found"):
        make_policy(str(tmp_path / "nothing.zip"))
    with pytest.raises(ValueError, match="no-such-run: no such agent"):
        make_policy("runs/no-such-run")


def test_corrupt_model_file_fails_clearly_naming_it(agent_copy: Path) -> None:
    (agent_copy / "model.zip").write_bytes(b"not a zip file at all")
    with pytest.raises(AgentLoadError, match=r"model\.zip: not a readable stable-baselines3"):
        make_policy(str(agent_copy))


def test_a_zip_without_the_models_members_is_named(agent_copy: Path) -> None:
    with zipfile.ZipFile(agent_copy / "model.zip", "w") as z:  # a zip, but not SB3's save
        z.writestr("notes.txt", "hello")
    with pytest.raises(AgentLoadError, match=r"model\.zip: not a stable-baselines3 PPO model: "):
        make_policy(str(agent_copy))


def test_a_configuration_that_is_not_yaml_is_named_in_one_line(agent_copy: Path) -> None:
    (agent_copy / "config.yaml").write_text("hyperparams: {n_envs: [4\n")
    with pytest.raises(AgentLoadError, match=r"config\.yaml: not valid YAML: line 2, column 1"):
        make_policy(str(agent_copy))


def test_a_configuration_with_a_key_given_twice_or_not_utf8_is_named(agent_copy: Path) -> None:
    config = agent_copy / "config.yaml"
    text = config.read_text()
    config.write_text(text + "hyperparams: {}\n")
    with pytest.raises(AgentLoadError, match=r"config\.yaml: not valid YAML: line \d+, column 1: "):
        make_policy(str(agent_copy))
    config.write_bytes(b"\xff" + text.encode())
    with pytest.raises(AgentLoadError, match=r"config\.yaml: not a UTF-8 text file \(byte 1 "):
        make_policy(str(agent_copy))


def test_missing_normalisation_statistics_are_named(agent_copy: Path) -> None:
    (agent_copy / "vecnormalize.pkl").unlink()
    with pytest.raises(AgentLoadError, match=r"vecnormalize\.pkl: normalisation statistics"):
        make_policy(str(agent_copy))


def test_model_from_another_configuration_is_rejected(agent_copy: Path) -> None:
    config = yaml.safe_load((agent_copy / "config.yaml").read_text())
    config["hyperparams"]["frame_stack"] += 1
    (agent_copy / "config.yaml").write_text(yaml.safe_dump(config))
    with pytest.raises(AgentLoadError, match=r"model\.zip: expects observations of shape"):
        make_policy(str(agent_copy))


def test_policy_is_deterministic_for_a_seed() -> None:
    first = run_episode("ppo", "curve", 3).log
    second = run_episode("ppo", "curve", 3).log
    columns = ["action_v_mps", "action_w_radps", "obs_offset_px"]
    np.testing.assert_array_equal(first[columns].to_numpy(), second[columns].to_numpy())


def test_an_agent_replaced_under_its_old_times_is_loaded_again(tmp_path: Path) -> None:
    """The loaded-agent cache tells a file's versions apart by more than the modification
    time: an agent copied over with ``cp -p``-like times kept acting as the old model."""
    from policies.learned.ppo import AGENTS

    agent, other = tmp_path / "agent", tmp_path / "other"
    shutil.copytree(AGENTS / "ppo_ensemble" / "seed-0", agent)
    shutil.copytree(AGENTS / "ppo_ensemble" / "seed-1", other)  # same view, other weights
    columns = ["action_v_mps", "action_w_radps"]
    before = run_episode(str(agent), "curve", 3).log[columns].to_numpy()
    for name in ("model.zip", "vecnormalize.pkl", "config.yaml"):
        st = (agent / name).stat()
        shutil.copyfile(other / name, agent / name)
        os.utime(agent / name, ns=(st.st_atime_ns, st.st_mtime_ns))  # the old times
    after = run_episode(str(agent), "curve", 3).log[columns].to_numpy()
    theirs = run_episode(str(other), "curve", 3).log[columns].to_numpy()
    assert not np.array_equal(before, theirs)  # the two models act differently here
    np.testing.assert_array_equal(after, theirs)


def test_reset_forgets_the_previous_episode() -> None:
    used = make_policy("ppo")
    for offset_px in (300.0, -200.0, 150.0):
        used.act(obs(2.5, offset_px))
    used.reset()
    fresh = make_policy("ppo")
    for o in (10.0, 20.0, 25.0):
        np.testing.assert_array_equal(used.act(obs(1.2, o)), fresh.act(obs(1.2, o)))


def test_mirrored_observations_give_mirrored_actions() -> None:
    right, left = make_policy("ppo"), make_policy("ppo")
    for d, o in ((1.0, 5.0), (1.3, 40.0), (1.1, 120.0)):
        v_right, w_right = right.act(obs(d, o))
        v_left, w_left = left.act(obs(d, -o))
        assert v_left == v_right
        assert w_left == -w_right


@pytest.mark.slow
def test_policy_acts_as_the_agent_did_in_its_training_env(acts_as_trained) -> None:
    acts_as_trained(DEFAULT_AGENT, PPOPolicy(DEFAULT_AGENT), 60)


def test_a_stack_of_frames_among_the_wrappers_is_seen_alike_in_training_and_at_inference() -> None:
    # ppo_fast.yaml's view, its history the wrapper VecStackFrames (first frame repeated):
    # the training stack and the policy's pipeline, driven by the same agent actions on the
    # same seed, see the same observations step by step.
    from follow_env.tasks.person_follow import ENV_ID
    from policies.learned.features import Box, Pipeline
    from train.config import load_hyperparams, wrapper_specs
    from train.ppo import DEFAULT_HYPERPARAMS

    hp = load_hyperparams(DEFAULT_HYPERPARAMS.with_name("ppo_fast.yaml"), ENV_ID)
    assert hp["frame_stack"] == 1
    assert wrapper_specs(hp["vec_env_wrapper"])[-1] == (
        "train.wrappers.VecStackFrames",
        {"n_stack": 4, "pad": "first"},
    )
    base = base_env(["curve"], 1)
    venv = agent_env(base, hp, "eval")
    pipeline = Pipeline(
        Pipeline.from_wrappers(wrapper_specs(hp["vec_env_wrapper"])),
        Box(base.observation_space.low, base.observation_space.high),
        Box(base.action_space.low, base.action_space.high, ("v_mps", "w_radps")),
        1,
    )
    single = base_env(["curve"], 1)
    venv.seed(7)
    single.seed(7)
    seen, expected = venv.reset(), pipeline.start(single.reset())
    np.testing.assert_array_equal(seen[0, :5], seen[0, -5:])  # the first frame, four times
    actions = np.random.default_rng(0).uniform(-1, 1, size=(40, 1, 2)).astype(np.float32)
    for action in actions:
        np.testing.assert_array_equal(seen, expected)
        seen, *_ = venv.step(action)
        obs, _, dones, _ = single.step(pipeline.act(action))
        expected = pipeline.observe(obs, dones)
    assert seen.shape == (1, 20)


def test_shipped_agent_keeps_the_person_in_frame_on_straight() -> None:
    episode = run_episode("ppo", "straight", 0)
    assert episode.termination == "walk_over"
    assert episode.log["in_frame"].all()


def test_policy_survives_pickling_by_path() -> None:
    policy = make_policy("ppo")
    copy = pickle.loads(pickle.dumps(policy))
    assert copy.name == "ppo"
    np.testing.assert_array_equal(copy.act(obs(1.3, 50.0)), make_policy("ppo").act(obs(1.3, 50.0)))


def test_a_policy_given_a_relative_path_survives_pickling_in_another_folder(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """It was rebuilt from the path as given: from a worker's folder (another node's, or after a
    chdir) another agent, or none at all."""
    (tmp_path / "link").symlink_to(DEFAULT_AGENT, target_is_directory=True)
    monkeypatch.chdir(tmp_path)
    here = Path.cwd()  # the folder's own path, as a relative path is made absolute
    policy = PPOPolicy("link")
    (tmp_path / "elsewhere").mkdir()
    monkeypatch.chdir(tmp_path / "elsewhere")
    copy = pickle.loads(pickle.dumps(policy))
    assert (policy.name, policy.path) == ("link", "link")  # as given: tables show it
    assert copy.name == "link"
    assert copy.path == str(here / "link")  # absolute, the link kept (not resolved)
    for seen in (obs(1.3, 50.0), obs(2.2, -140.0)):
        np.testing.assert_array_equal(copy.act(seen), policy.act(seen))


@pytest.mark.slow
def test_names_resolve_in_evaluation_worker_processes() -> None:
    from eval.rollout import rollout

    names = ["ppo", str(DEFAULT_AGENT)]
    pooled = rollout(names, ["straight"], [0], workers=2)
    here = rollout(names, ["straight"], [0], workers=1)
    for a, b in zip(pooled, here, strict=True):
        assert a.policy == b.policy
        np.testing.assert_array_equal(a.log["action_w_radps"], b.log["action_w_radps"])


def test_building_the_agent_imports_no_training_code() -> None:
    import subprocess
    import sys

    code = (
        "import sys; from policies import make_policy; p = make_policy('ppo'); "
        "p.act([1.2, 30.0]); print(sorted(m for m in sys.modules if m.split('.')[0] in "
        "('train', 'eval')))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


def test_batched_acting_equals_acting_lane_by_lane() -> None:
    rng = np.random.default_rng(0)
    rows = rng.uniform([0.5, -300.0], [3.0, 300.0], (30, 5, 2)).astype(np.float32)
    batch = make_policy("ppo")
    batch.reset_batch(5)
    lanes = [make_policy("ppo") for _ in range(5)]
    for step in rows:
        together = batch.act_batch(step)
        alone = np.stack([law.act(step[i]) for i, law in enumerate(lanes)])
        np.testing.assert_array_equal(together, alone)


def test_act_batch_needs_reset_batch_for_its_lane_count() -> None:
    policy = make_policy("ppo")
    policy.reset_batch(3)
    with pytest.raises(ValueError, match=r"reset_batch\(2\)"):
        policy.act_batch(np.ones((2, 2), dtype=np.float32))


# -- Platforms: an agent records the platform it was trained on and drives only that one -----

MECANUM = ("v_mps", "vy_mps", "w_radps")


def test_an_agent_saved_without_a_platform_is_a_differential_drive_agent(agent_copy: Path) -> None:
    # agents saved before platforms were named have no platform key
    config = yaml.safe_load((agent_copy / "config.yaml").read_text(encoding="utf-8"))
    assert config.pop("platform") == "diff_drive"
    (agent_copy / "config.yaml").write_text(yaml.safe_dump(config), encoding="utf-8")
    assert "platform" not in read_config(agent_copy)
    policy = make_policy(str(agent_copy))
    assert policy.platform == "diff_drive"  # type: ignore[attr-defined]
    assert policy.action_names == ("v_mps", "w_radps")  # type: ignore[attr-defined]


def test_the_differential_drive_agent_is_refused_on_the_mecanum_base() -> None:
    with pytest.raises(
        ValueError,
        match=r"policy 'ppo' was trained on the diff_drive platform, acting "
        r"\[v_mps, w_radps\]; it cannot drive a platform acting \[v_mps, vy_mps, w_radps\]",
    ):
        for_platform(make_policy("ppo"), MECANUM)


def test_the_mecanum_agent_is_ppo_mecanum_and_follows_on_its_base_only() -> None:
    from eval.rollout import rollout

    policy = make_policy("ppo_mecanum")
    assert policy.platform == "mecanum"
    assert policy.action_names == ("v_mps", "vy_mps", "w_radps")
    (episode,) = rollout(["ppo_mecanum@mecanum"], ["curve"], [0])
    assert episode.termination == "walk_over"
    assert episode.log["in_frame"].all()
    with pytest.raises(ValueError, match="mecanum"):
        rollout(["ppo_mecanum"], ["curve"], [0])  # the differential drive's [v, w]


@pytest.mark.parametrize("name", ["ppo", "ppo_law", "ppo_mecanum"])
def test_a_shipped_agent_acts_on_the_gaussians_mean_as_sb3s_predict(name: str) -> None:
    """The network's fast path (the mean, no distribution object) is the one taken, and gives
    SB3's ``predict`` of the float64 policy, rounded to float32, to the bit, on rows alone and on
    a batch."""
    import torch

    network = make_policy(name)._agent.model
    assert network._gaussian is not None
    assert next(network.policy.parameters()).dtype == torch.float64
    rng = np.random.default_rng(5)
    obs = rng.uniform(-3, 3, (64, *network.observation_space.shape)).astype(np.float32)
    with torch.no_grad():
        theirs = np.concatenate(
            [network.policy.predict(row[None], deterministic=True)[0] for row in obs]
        ).astype(np.float32)
    np.testing.assert_array_equal(network.act(obs), theirs)
    np.testing.assert_array_equal(np.concatenate([network.act(row[None]) for row in obs]), theirs)


@pytest.mark.parametrize(
    "kwargs",
    [
        {},  # SB3's own MlpPolicy
        {"mirror_obs": [1, -1, 1], "mirror_action": [1, -1]},
        {"mirror_obs": [1, -1], "mirror_action": [1, -1], "privileged_signs": [1, -1]},
        {"mirror_obs": [1, -1, 1], "mirror_action": [1, -1], "activation_fn": "relu"},
    ],
    ids=["mlp", "mirror", "mirror-privileged", "mirror-relu"],
)
def test_each_policy_kind_takes_the_mean_path_to_sb3s_predict_bit_for_bit(kwargs: dict) -> None:
    import torch
    from gymnasium import spaces
    from stable_baselines3.common.policies import ActorCriticPolicy

    from policies.learned.mirror import MirrorMlpPolicy
    from policies.learned.networks import Network

    kwargs = dict(kwargs)
    if kwargs.pop("activation_fn", None) == "relu":
        kwargs["activation_fn"] = torch.nn.ReLU
    kind = MirrorMlpPolicy if "mirror_obs" in kwargs else ActorCriticPolicy
    torch.manual_seed(3)
    policy = kind(spaces.Box(-5, 5, (6,)), spaces.Box(-1, 1, (2,)), lambda _: 3e-4, **kwargs)
    rows = np.random.default_rng(7).uniform(-5, 5, (40, 6)).astype(np.float32)
    # In float32, as trained: the same but for float32's rounding (module networks' docstring).
    narrow = np.concatenate([policy.predict(row[None], deterministic=True)[0] for row in rows])
    network = Network(policy)  # acts on a float64 copy of the policy
    assert network._gaussian is not None
    wide = network.policy
    theirs = np.concatenate([wide.predict(row[None], deterministic=True)[0] for row in rows])
    np.testing.assert_array_equal(network.act(rows), theirs.astype(np.float32))
    np.testing.assert_allclose(network.act(rows), narrow, rtol=1e-5, atol=1e-6)
    # The caller's policy is left in float32, acting as before, to the bit.
    assert {p.dtype for p in policy.parameters()} == {torch.float32}
    again = np.concatenate([policy.predict(row[None], deterministic=True)[0] for row in rows])
    np.testing.assert_array_equal(again, narrow)


@pytest.mark.parametrize("algo", ["ppo", "sac"])
def test_a_use_sde_agent_loads_and_acts_as_the_librarys_predict(tmp_path: Path, algo: str) -> None:
    """A policy trained with gSDE holds an exploration matrix computed from its log std, which
    torch will not copy: the loader widens the policy it built in place, and a caller's such
    policy is refused with a clear message rather than changed."""
    import gymnasium as gym
    import torch
    from stable_baselines3 import PPO, SAC

    from policies.learned.networks import Network, load_network

    cls, extra = (PPO, {}) if algo == "ppo" else (SAC, {"buffer_size": 1000})
    model = cls("MlpPolicy", gym.make("Pendulum-v1"), use_sde=True, device="cpu", seed=0, **extra)
    model.save(tmp_path / "model.zip")
    network = load_network(tmp_path / "model.zip", algo, "MlpPolicy", ValueError)
    rows = np.random.default_rng(1).uniform(-1, 1, (16, 3)).astype(np.float32)
    theirs = np.concatenate([model.predict(row[None], deterministic=True)[0] for row in rows])
    np.testing.assert_allclose(network.act(rows), theirs, rtol=1e-5, atol=1e-6)
    with pytest.raises(ValueError, match=r"cannot copy this .*owned=True"):
        Network(model.policy)
    assert {p.dtype for p in model.policy.parameters()} == {torch.float32}  # left as it was


def _normalising(folder: Path, config_norm_obs: bool = True, **fields: object) -> Path:
    """``folder``'s agent with observation statistics ``fields`` (over VecNormalize's saved
    fields: norm_obs, obs_rms's mean and var, epsilon, clip_obs), its config.yaml saying
    ``norm_obs: config_norm_obs``."""
    size = PPOPolicy(DEFAULT_AGENT)._agent.pipeline(1).observation_box.shape[0]
    saved = {"norm_obs": True, "mean": np.zeros(size), "var": np.ones(size)}
    saved |= {"epsilon": 1e-8, "clip_obs": 10.0, **fields}
    rms = SimpleNamespace(mean=saved.pop("mean"), var=saved.pop("var"))
    with (folder / "vecnormalize.pkl").open("wb") as f:
        pickle.dump(SimpleNamespace(obs_rms=rms, **saved), f)
    config = folder / "config.yaml"
    text = config.read_text(encoding="utf-8")
    assert "norm_obs: false" in text
    config.write_text(text.replace("norm_obs: false", f"norm_obs: {config_norm_obs}".lower()))
    return folder


def test_sound_statistics_normalise_the_observation(agent_copy: Path) -> None:
    policy = make_policy(str(_normalising(agent_copy, var=np.full(20, 4.0))))
    action = policy.act(obs(1.4, 30.0))
    assert np.all(np.isfinite(action))


@pytest.mark.parametrize(
    ("fields", "message"),
    [
        ({"var": np.full(20, np.nan)}, "not finite"),
        ({"var": np.full(20, np.inf)}, "not finite"),
        ({"mean": np.full(20, np.nan)}, "not finite"),
        ({"var": np.r_[np.ones(19), -5.0]}, r"negative variances \(entries \[19\]\)"),
        ({"var": "ones"}, "a mean and a variance of the same flat shape"),
        ({"epsilon": 0.0}, "epsilon=0.0 must be a finite number > 0"),
        ({"epsilon": float("nan")}, "epsilon=nan"),
        ({"clip_obs": 0.0}, "clip_obs=0.0 must be > 0"),
        ({"clip_obs": float("nan")}, "clip_obs=nan"),
    ],
)
def test_damaged_statistics_are_refused_naming_them(
    agent_copy: Path, fields: dict, message: str
) -> None:
    """They gave NaN actions, with nothing but numpy's warning."""
    with pytest.raises(AgentLoadError, match=message) as error:
        make_policy(str(_normalising(agent_copy, **fields)))
    assert str(error.value).startswith(f"{agent_copy / 'vecnormalize.pkl'}: ")


@pytest.mark.parametrize("config_norm_obs", [False, True])
def test_statistics_whose_norm_obs_the_config_contradicts_are_refused(
    agent_copy: Path, config_norm_obs: bool
) -> None:
    """Foreign statistics normalised what the agent had seen raw (it drove backwards)."""
    _normalising(agent_copy, config_norm_obs, norm_obs=not config_norm_obs)
    with pytest.raises(AgentLoadError, match=f"norm_obs={not config_norm_obs} but ") as error:
        make_policy(str(agent_copy))
    assert str(error.value).startswith(f"{agent_copy / 'vecnormalize.pkl'}: ")
    assert str(agent_copy / "config.yaml") in str(error.value)


@pytest.mark.parametrize(
    ("old", "new", "message"),
    [
        (
            "\nenv_id: PersonFollow-v0",
            "\nenv_id: CartPole-v1",
            "env_id='CartPole-v1' is out of range",
        ),
        ("\nenv_id: PersonFollow-v0", "\nenv_id: 5", "env_id=5 is out of range"),
        (
            "low: [0.0, -320.0]",
            "low: [20.0, -320.0]",
            r"observation has low > high in entries \[0\]",
        ),
        ("high: [10.0, 319.0]", "high: [.nan, 319.0]", "observation has a NaN bound"),
        ("high: [10.0, 319.0]", "high: ['10', 319.0]", "observation is not a box .* numbers"),
        ("low: [-1.484375, -7.421875]", "low: [2.0, -7.421875]", "action has low > high"),
    ],
)
def test_an_unknown_env_or_a_malformed_box_is_refused_naming_the_config(
    agent_copy: Path, old: str, new: str, message: str
) -> None:
    config = agent_copy / "config.yaml"
    text = config.read_text(encoding="utf-8")
    assert text.count(old) == 1
    config.write_text(text.replace(old, new), encoding="utf-8")
    with pytest.raises(AgentLoadError, match=message) as error:
        make_policy(str(agent_copy))
    assert str(error.value).startswith(f"{config}: ")


@pytest.mark.parametrize(
    ("name", "task", "size"),
    [("ppo", None, 2), ("ppo", "line_trace", 25), ("ppo_ensemble", None, 3)],
)
def test_observations_that_are_not_real_numbers_are_refused_naming_the_dtype(
    name: str, task: str | None, size: int
) -> None:
    """Strings were parsed ("2" read as 2.0) and complex numbers cut to their real part."""
    policy = make_policy(name, task)
    row = np.linspace(0.5, 1.0, size)
    for bad, dtype in (
        (row.astype(str), "dtype <U"),
        (row.astype(complex), "dtype complex128"),
        ([*row.tolist()[:-1], "1"], "dtype <U"),
        (np.array([*row[:-1], "1"], dtype=object), "dtype object holding '1' (str)"),
        (np.array([*row[:-1], None], dtype=object), "dtype object holding None"),
    ):
        policy.reset()
        with pytest.raises(ValueError, match=re.escape(dtype)):
            policy.act(bad)
        policy.reset_batch(2)
        with pytest.raises(ValueError, match=re.escape(dtype)):
            policy.act_batch(np.stack([np.asarray(bad)] * 2))
    # numbers of any real kind act as their float values do
    policy.reset()
    want = policy.act(row.astype(np.float32))
    for same in (row.astype(np.float32).astype(object), row.astype(np.float32).tolist()):
        policy.reset()
        np.testing.assert_array_equal(policy.act(same), want)
    flags = (row > 0.7).astype(bool)
    policy.reset()
    want = policy.act(flags.astype(np.float32))
    policy.reset()
    np.testing.assert_array_equal(policy.act(flags), want)

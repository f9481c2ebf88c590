"""train/algos.py: each learner's rule table, constraints and shipped file; --algo's checks."""

from __future__ import annotations

import inspect
from pathlib import Path

import pytest
import yaml

from follow_env.tasks import task_for_env
from follow_env.tasks.person_follow import ENV_ID
from train.algos import ALGOS, RECURRENT_PPO_RULES, SAC_RULES
from train.cli import main
from train.config import ConfigError, load_hyperparams, parse_hyperparams, wrapper_specs
from train.ppo import Args, check_new_run

MINIMAL = {"n_envs": 4, "n_timesteps": 1000}
# rl-zoo3's keys, which the trainer consumes (the rest go to the algorithm's constructor).
ZOO = ("policy", "n_envs", "n_timesteps", "normalize", "frame_stack", "vec_env_wrapper")
ZOO += ("env_kwargs",)


@pytest.mark.parametrize("name", ["ppo", "recurrent_ppo", "sac"])
def test_the_shipped_files_load_and_check(name: str) -> None:
    algo = ALGOS[name]
    assert algo.hyperparams.name == f"{name}.yaml"
    hp = load_hyperparams(algo.hyperparams, ENV_ID, algo=name)
    scenarios = len(task_for_env(ENV_ID).variants())
    assert hp["n_envs"] % scenarios == 0  # every scenario gets the same lanes
    assert set(hp) - {"policy_kwargs"} <= {*algo.rules, *ZOO}
    args, checked = check_new_run(Args(algo=name, runs=Path("/nonexistent/runs")))
    assert args.hyperparams == algo.hyperparams  # --algo X without --hyperparams: X's file
    assert checked == hp


@pytest.mark.parametrize(
    ("file", "algo", "v_rate_weight", "far_weight", "stack"),
    [
        ("ppo_fast", "ppo", 4.0, 2.0, "first"),
        ("sac_fast", "sac", 4.0, 2.0, "first"),
        # its five-seed study (README) ran with the reward the agent shipped before this one
        # was trained with; the speed command's steps are the shipped agent's; the LSTM
        # carries the history
        ("recurrent_ppo_fast", "recurrent_ppo", 2.0, 1.0, None),
    ],
)
def test_the_budget_files_load_with_the_reward_and_action_of_their_studies(
    file: str, algo: str, v_rate_weight: float, far_weight: float, stack: str | None
) -> None:
    path = ALGOS[algo].hyperparams.with_name(f"{file}.yaml")
    hp = load_hyperparams(path, ENV_ID, algo=algo)
    assert hp["n_envs"] % len(task_for_env(ENV_ID).variants()) == 0
    wrappers = dict(wrapper_specs(hp["vec_env_wrapper"]))
    shaped = wrappers["train.wrappers.VecShapedReward"]
    assert (shaped["v_rate_weight"], shaped["far_weight"], shaped["far_from_m"]) == (
        v_rate_weight,
        far_weight,
        0.0,
    )
    incremental = wrappers["train.wrappers.VecIncrementalAction"]
    assert incremental["max_change"] == [0.2, 0.15]
    assert hp["frame_stack"] == 1  # any history is the stacking wrapper's, from its first frame
    frames = wrappers.get("train.wrappers.VecStackFrames")
    assert (frames or {}).get("pad") == stack
    if stack is not None:  # the outermost wrapper, as the policy runs it
        assert wrapper_specs(hp["vec_env_wrapper"])[-1][0] == "train.wrappers.VecStackFrames"


def test_policies_default_to_the_algorithms_mlp() -> None:
    assert parse_hyperparams(MINIMAL, algo="recurrent_ppo")["policy"] == "MlpLstmPolicy"
    assert parse_hyperparams(MINIMAL, algo="sac")["policy"] == "MlpPolicy"
    assert parse_hyperparams(MINIMAL)["policy"] == "MlpPolicy"


@pytest.mark.parametrize("name", ["recurrent_ppo", "sac"])
def test_the_mirror_policy_is_ppos_only(name: str) -> None:
    hp = MINIMAL | {"policy": "train.mirror.MirrorMlpPolicy"}
    with pytest.raises(ConfigError, match=r"MirrorMlpPolicy' is PPO's only") as e:
        parse_hyperparams(hp, algo=name)
    assert "\n" not in str(e.value)
    with pytest.raises(ConfigError, match="is not an SB3 SACPolicy"):
        parse_hyperparams(MINIMAL | {"policy": "sb3_contrib.common.recurrent.policies."
                                     "RecurrentActorCriticPolicy"}, algo="sac")  # fmt: skip


@pytest.mark.parametrize(
    ("algo", "changes", "message"),
    [
        # SAC's own keys, its ranges
        ("sac", {"tau": 0.0}, r"tau=0\.0 is out of range: must be a number in \(0, 1\]"),
        ("sac", {"tau": 1.5}, r"tau=1\.5 is out of range"),
        ("sac", {"buffer_size": 0}, r"buffer_size=0 is out of range: must be an integer >= 1"),
        ("sac", {"learning_starts": -1}, r"learning_starts=-1 is out of range"),
        ("sac", {"train_freq": 0}, r"train_freq=0 is out of range"),
        ("sac", {"train_freq": [1, "epoch"]}, r"train_freq=\[1, 'epoch'\] is out of range"),
        ("sac", {"gradient_steps": 0}, r"gradient_steps=0 is out of range: .* or -1"),
        ("sac", {"ent_coef": "auto_0"}, r"ent_coef='auto_0' is out of range"),
        # SB3 reads auto_<x> as value.split("_")[1]: "auto_1_0" would start at 1, not 10
        ("sac", {"ent_coef": "auto_1_0"}, r"ent_coef='auto_1_0' is out of range"),
        ("sac", {"ent_coef": "auto_1e400"}, r"ent_coef='auto_1e400' is out of range"),
        ("sac", {"ent_coef": -0.1}, r"ent_coef=-0\.1 is out of range"),
        ("sac", {"target_entropy": "high"}, r"target_entropy='high' is out of range"),
        ("sac", {"learning_rate": 0}, r"learning_rate=0 is out of range"),
        ("sac", {"action_noise": "normal"}, "action_noise='normal' is not supported"),
        ("sac", {"n_epochs": 10}, r"unknown key\(s\) n_epochs \(not SAC arguments\)"),
        ("sac", {"policy_kwargs": {"net_arch": {"pi": [8], "vf": [8]}}}, "net_arch=.* qf"),
        ("sac", {"policy_kwargs": {"n_critics": 0}}, r"policy_kwargs\.n_critics=0 is out"),
        ("sac", {"policy_kwargs": {"ortho_init": False}}, "ortho_init is not an argument"),
        # SAC's buffer constraints, before SB3 meets them
        ("sac", {"buffer_size": 100, "batch_size": 101}, r"batch_size=101 .* buffer_size = 100"),
        ("sac", {"buffer_size": 3}, r"buffer_size=3 is out of range: must be >= n_envs = 4"),
        ("sac", {"train_freq": [1, "episode"]}, r"counting in episodes needs n_envs = 1"),
        ("sac", {"optimize_memory_usage": True}, "optimize_memory_usage=True is out of range"),
        # RecurrentPPO's
        ("recurrent_ppo", {"gae_lambda": 1.1}, r"gae_lambda=1\.1 is out of range"),
        ("recurrent_ppo", {"n_steps": 0}, r"n_steps=0 is out of range"),
        ("recurrent_ppo", {"buffer_size": 10}, r"unknown key\(s\) buffer_size"),
        ("recurrent_ppo", {"rollout_buffer_class": None}, r"unknown key\(s\) rollout_buffer"),
        ("recurrent_ppo", {"n_steps": 8, "batch_size": 64}, r"batch_size=64 .* = 32\]"),
        ("recurrent_ppo", {"n_steps": 8, "batch_size": 31}, "leaves a last mini-batch of 1"),
        ("recurrent_ppo", {"policy_kwargs": {"lstm_hidden_size": 0}}, "lstm_hidden_size=0"),
        ("recurrent_ppo", {"policy_kwargs": {"shared_lstm": True}}, "shared_lstm=True is out"),
        ("recurrent_ppo", {"policy_kwargs": {"lstm_kwargs": 3}}, r"lstm_kwargs=3 is out"),
        ("recurrent_ppo", {"policy": "MlpPolicy"}, "'MlpPolicy' does not import"),
        # and PPO refuses the others' keys
        ("ppo", {"tau": 0.01}, r"unknown key\(s\) tau \(not PPO arguments\)"),
        ("ppo", {"policy": "MlpLstmPolicy"}, "'MlpLstmPolicy' does not import"),
    ],
)
def test_each_rule_table_refuses_bad_values_naming_the_key(
    algo: str, changes: dict, message: str
) -> None:
    with pytest.raises(ConfigError, match=message) as e:
        parse_hyperparams(MINIMAL | changes, where="f.yaml [PersonFollow-v0]", algo=algo)
    assert str(e.value).startswith("f.yaml [PersonFollow-v0]: ")
    assert "\n" not in str(e.value)


def test_good_values_pass_as_sb3_reads_them() -> None:
    hp = parse_hyperparams(
        MINIMAL
        | {"train_freq": [1, "step"], "gradient_steps": -1, "ent_coef": "auto_0.1"}
        | {"batch_size": 4, "buffer_size": 4, "target_entropy": -2.0},
        algo="sac",
    )
    assert hp["train_freq"] == [1, "step"]
    hp = parse_hyperparams(MINIMAL | {"batch_size": None, "n_steps": 8}, algo="recurrent_ppo")
    assert hp["batch_size"] is None  # the whole rollout in one mini-batch
    one_lane = MINIMAL | {"n_envs": 1, "train_freq": [1, "episode"]}
    assert parse_hyperparams(one_lane, algo="sac")["train_freq"] == [1, "episode"]


def test_the_tables_cover_the_constructors() -> None:
    # Every argument of the classes is either in a table or set by follow-train itself.
    own = {"self", "policy", "env", "tensorboard_log", "policy_kwargs", "verbose", "seed"}
    own |= {"device", "_init_setup_model"}
    for name, rules in (("recurrent_ppo", RECURRENT_PPO_RULES), ("sac", SAC_RULES)):
        parameters = set(inspect.signature(ALGOS[name].cls().__init__).parameters)
        assert parameters - own == set(rules), name


def test_a_bad_algo_gives_one_line_status_2_and_writes_nothing(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "run"
    status = main(["--algo", "dqn", "--out", str(out), "--runs", str(tmp_path / "runs")])
    err = capsys.readouterr().err
    assert status == 2
    assert err.count("\n") == 1
    assert "--algo: invalid choice: 'dqn'" in err
    assert "'recurrent_ppo'" in err
    assert list(tmp_path.iterdir()) == []
    with pytest.raises(ValueError, match=r"--algo 'dqn' is not a learner: one of ppo, "):
        check_new_run(Args(algo="dqn", out=out))


def test_a_file_for_another_algorithm_is_refused_in_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    sac = yaml.safe_load(ALGOS["sac"].hyperparams.read_text())
    path = tmp_path / "sac.yaml"
    path.write_text(yaml.safe_dump(sac))
    status = main(["--algo", "ppo", "--hyperparams", str(path), "--out", str(tmp_path / "r")])
    err = capsys.readouterr().err
    assert status == 2
    assert err.count("\n") == 1
    # SAC's own keys are named (batch_size, gamma, ent_coef ... are PPO's too).
    assert "unknown key(s) buffer_size, gradient_steps, learning_starts" in err
    assert "(not PPO arguments)" in err
    assert not (tmp_path / "r").exists()

"""follow-train on LineTrace-v0 (train/configs/ppo_line.yaml), and the agent in the evaluation."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml

from eval.rollout import rollout
from policies import make_policy
from train.cli import main

LINE_YAML = Path(__file__).parents[2] / "train" / "configs" / "ppo_line.yaml"
SMOKE = [
    "--env-config", "paper",
    "--compare-with", "pid",
    "--scenarios", "straight,gaps",
    "--n-envs", "4",
    "--n-timesteps", "1500",
    "--eval-freq", "800",
    "--checkpoint-freq", "800",
    "--final-episodes", "0",
    "--no-progress",
]  # fmt: skip


def small_yaml(folder: Path) -> Path:
    """The shipped LineTrace section with a batch that fits the smoke run's 4 lanes."""
    document = yaml.safe_load(LINE_YAML.read_text())
    document["LineTrace-v0"].update(n_steps=32, batch_size=64)
    path = folder / "ppo_line.yaml"
    path.write_text(yaml.safe_dump(document))
    return path


@pytest.fixture(scope="module")
def line_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("train-line")
    run = root / "ppo-line"
    assert main(["--hyperparams", str(small_yaml(root)), *SMOKE, "--out", str(run)]) == 0
    return run


def test_the_shipped_line_config_is_read_for_its_env_id() -> None:
    from train.config import load_hyperparams

    hp = load_hyperparams(LINE_YAML, "LineTrace-v0")
    assert hp["n_envs"] % 7 == 0  # lanes split evenly over the seven tracks


def test_the_run_saves_the_platforms_action_names_with_the_agent(line_run: Path) -> None:
    config = yaml.safe_load((line_run / "config.yaml").read_text())
    assert config["env_id"] == "LineTrace-v0"
    assert config["env_spaces"]["action"]["names"] == ["v_mps", "vy_mps", "w_radps"]
    assert len(config["env_spaces"]["observation"]["low"]) == 25


def test_the_agent_reads_25_readings_and_commands_the_mecanum_base(line_run: Path) -> None:
    agent = make_policy(str(line_run))
    assert agent.action_names == ("v_mps", "vy_mps", "w_radps")
    agent.reset()
    action = agent.act(np.zeros(25, dtype=np.float32))
    assert action.shape == (3,)
    with pytest.raises(ValueError, match=r"obs must have shape \(25,\)"):
        agent.act(np.zeros(2, dtype=np.float32))


def test_the_agent_runs_in_the_line_evaluation_batched_as_alone(line_run: Path) -> None:
    batched = rollout([str(line_run)], ["gaps"], [0, 1], task="line_trace")
    single = rollout([str(line_run)], ["gaps"], [1], task="line_trace", workers=1)
    assert batched[1].log.equals(single[0].log)


def test_a_card_comparison_is_refused_for_the_line_task(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    argv = ["--hyperparams", str(small_yaml(tmp_path)), *SMOKE[:-3], "--final-episodes", "2"]
    assert main([*argv, "--no-progress", "--runs", str(tmp_path / "r")]) == 2
    err = capsys.readouterr().err
    assert "--final-episodes 2: the model card's comparison with a law is PersonFollow's" in err
    assert not (tmp_path / "r").exists()


def test_the_shipped_line_agent_is_ppo_of_the_line_task_and_takes_corners() -> None:
    from eval.rollout import rollout
    from policies import make_policy

    agent = make_policy("ppo", "line_trace")
    assert agent.name == "ppo"
    assert make_policy("ppo").name == "ppo"  # PersonFollow's agent: another one
    assert type(make_policy("ppo")) is type(agent)
    episodes = rollout(["ppo"], ["corners"], range(3), task="line_trace", workers=1)
    # the 90-degree corners the earlier agents stopped at (README, LineTrace's PPO)
    assert [e.termination for e in episodes] == ["track_end"] * 3

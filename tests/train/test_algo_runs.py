"""follow-train --algo recurrent_ppo / sac: real (tiny) training runs, resumed; and --seeds
with another algorithm."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest
import yaml

from follow_env.tasks.person_follow import ENV_ID
from train.algos import ALGOS
from train.cli import main
from train.run import newest_checkpoint, replay_buffer_file

STEPS = 800
TINY = [
    "--scenarios", "straight,curve",
    "--n-envs", "2",
    "--n-timesteps", str(STEPS),
    "--eval-freq", "400",
    "--checkpoint-freq", "400",
    "--final-episodes", "0",
    "--no-progress",
]  # fmt: skip
# The shipped files with small networks and buffers: a few seconds of training each.
SMALL = {
    "recurrent_ppo": {
        "n_steps": 32,
        "batch_size": 32,
        "n_epochs": 2,
        "policy_kwargs": {"lstm_hidden_size": 8, "net_arch": {"pi": [8], "vf": [8]}},
    },
    "sac": {
        "buffer_size": 2000,
        "learning_starts": 200,
        "batch_size": 32,
        "gradient_steps": 1,
        "policy_kwargs": {"net_arch": [16, 16]},
    },
}


def small_yaml(folder: Path, algo: str) -> Path:
    document = yaml.safe_load(ALGOS[algo].hyperparams.read_text())
    document[ENV_ID].update(SMALL[algo])
    path = folder / f"{algo}.yaml"
    path.write_text(yaml.safe_dump(document))
    return path


@pytest.fixture(scope="module", params=["recurrent_ppo", "sac"])
def run(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory) -> Path:
    algo = request.param
    root = tmp_path_factory.mktemp(algo)
    out = root / "run"
    argv = ["--algo", algo, "--hyperparams", str(small_yaml(root, algo)), *TINY]
    assert main([*argv, "--out", str(out)]) == 0
    return out


def test_a_run_writes_its_folder_with_the_algorithm(run: Path) -> None:
    config = yaml.safe_load((run / "config.yaml").read_text())
    algo = config["algo"]
    assert config["args"]["algo"] == algo
    assert config["hyperparams"]["policy"] == ALGOS[algo].policies[0]
    assert "use_sde" not in config["hyperparams"]["policy_kwargs"]  # SB3's, not the file's
    for name in ("model.zip", "MODEL_CARD.md", "learning_curve.png", "evaluations.npz"):
        assert (run / name).is_file(), name
    steps, model, _ = newest_checkpoint(run, algo)
    assert steps == STEPS
    assert model.name == f"{algo}_{STEPS}_steps.zip"
    assert (run / "vecnormalize.pkl").is_file() == bool(config["hyperparams"]["normalize"])
    card = (run / "MODEL_CARD.md").read_text()
    assert card.startswith(f"# {ALGOS[algo].label} agent for PersonFollow-v0")
    assert f"{ALGOS[algo].library} {ALGOS[algo].label}" in card
    buffers = sorted(p.name for p in (run / "checkpoints").glob("*replay_buffer*"))
    assert buffers == ([f"sac_replay_buffer_{STEPS}_steps.pkl"] if algo == "sac" else [])


def test_resume_continues_with_the_saved_algorithm(
    run: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    copy = tmp_path / "run"
    shutil.copytree(run, copy)
    algo = yaml.safe_load((run / "config.yaml").read_text())["algo"]
    other = "ppo" if algo == "sac" else "sac"
    capsys.readouterr()
    assert main(["--resume", str(copy), "--algo", other, "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1
    assert f"--algo {other}: {copy} is a {algo} run" in err
    assert main(["--resume", str(copy), "--n-timesteps", "1200", "--no-progress"]) == 0
    sessions = json.loads((copy / "sessions.json").read_text())
    assert [s["first_step"] for s in sessions] == [0, STEPS]
    assert newest_checkpoint(copy, algo)[0] == 1200
    if algo == "sac":  # the newest checkpoint only keeps its replay buffer
        buffers = [p.name for p in (copy / "checkpoints").glob("*replay_buffer*")]
        assert buffers == ["sac_replay_buffer_1200_steps.pkl"]


def test_a_sac_resume_reads_the_replay_buffer(
    run: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    if "sac" not in run.parent.name:
        pytest.skip("SAC's only")
    copy = tmp_path / "run"
    shutil.copytree(run, copy)
    replay = replay_buffer_file(newest_checkpoint(copy, "sac")[1])
    replay.write_bytes(b"not a pickle")
    capsys.readouterr()
    assert main(["--resume", str(copy), "--n-timesteps", "1200", "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1
    assert f"{replay}: cannot resume from it" in err


def test_a_study_trains_every_seed_with_the_algorithm(tmp_path: Path) -> None:
    study = tmp_path / "study"
    argv = ["--algo", "sac", "--hyperparams", str(small_yaml(tmp_path, "sac")), *TINY]
    argv[argv.index(str(STEPS))] = "400"
    assert main([*argv, "--seeds", "0-1", "--out", str(study)]) == 0
    for k in (0, 1):
        assert yaml.safe_load((study / f"seed-{k}" / "config.yaml").read_text())["algo"] == "sac"
    assert json.loads((study / "study.json").read_text())["algo"] == "sac"
    assert (study / "seeds.csv").is_file()
    assert main([*argv, "--seeds", "0-1", "--out", str(study)]) == 0  # all done: nothing new

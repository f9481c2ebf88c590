"""train/ppo.py: follow-train writes a complete run folder, resumes, exports, rejects bad input."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
import yaml

from policies import make_policy
from train.ppo import Args, main, train
from train.run import newest_checkpoint

SMOKE_STEPS = 2000
# Two scenarios, 4 lanes, tiny intervals: a few seconds, every part of a run exercised.
SMOKE = [
    "--scenarios", "straight,curve",
    "--n-envs", "4",
    "--n-timesteps", str(SMOKE_STEPS),
    "--eval-freq", "800",
    "--checkpoint-freq", "800",
    "--final-episodes", "2",
    "--no-progress",
]  # fmt: skip


@pytest.fixture(scope="module")
def smoke_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("train")
    run = root / "ppo-smoke"
    assert main([*SMOKE, "--out", str(run), "--export", str(root / "agent")]) == 0
    return run


@pytest.mark.slow
def test_smoke_run_writes_a_complete_run_folder(smoke_run: Path) -> None:
    for name in (
        "config.yaml",
        "model.zip",
        "vecnormalize.pkl",
        "MODEL_CARD.md",
        "learning_curve.png",
        "evaluations.npz",
        "sessions.json",
        "logs/progress-0.csv",
    ):
        assert (smoke_run / name).is_file(), name
    assert list((smoke_run / "logs" / "tb").iterdir()), "TensorBoard events"
    assert (smoke_run / "learning_curve.png").read_bytes()[:4] == b"\x89PNG"
    steps, model, stats = newest_checkpoint(smoke_run)
    assert model.is_file()
    assert stats.is_file()
    assert steps >= 1600
    with np.load(smoke_run / "evaluations.npz") as log:
        assert list(log["timesteps"]) == [800, 1600]
        assert log["results"].shape == (2, 4)  # 2 scenarios x 2 held-out episodes
    config = yaml.safe_load((smoke_run / "config.yaml").read_text())
    assert config["args"]["scenarios"] == ["straight", "curve"]
    assert config["hyperparams"]["n_timesteps"] == SMOKE_STEPS
    card = (smoke_run / "MODEL_CARD.md").read_text()
    for text in ("follow-train --scenarios straight,curve", "seeds", "stable-baselines3", "Scores"):
        assert text in card
    assert not list(smoke_run.glob(".*")), "no temporary files left behind"


@pytest.mark.slow
def test_run_folder_and_export_load_as_policies(smoke_run: Path) -> None:
    exported = smoke_run.parent / "agent"
    assert sorted(p.name for p in exported.iterdir()) == [
        "MODEL_CARD.md",
        "config.yaml",
        "learning_curve.png",
        "model.zip",
        "vecnormalize.pkl",
    ]
    obs = np.array([1.5, 40.0], dtype=np.float32)
    for name in (str(smoke_run), str(smoke_run / "model.zip"), str(exported)):
        assert make_policy(name).act(obs).shape == (2,)


@pytest.mark.slow
def test_resume_continues_the_step_count_from_the_newest_checkpoint(
    smoke_run: Path, tmp_path: Path
) -> None:
    run = tmp_path / "run"
    shutil.copytree(smoke_run, run)
    last_checkpoint, *_ = newest_checkpoint(run)
    assert main(["--resume", str(run), "--n-timesteps", "3000", "--no-progress"]) == 0
    sessions = json.loads((run / "sessions.json").read_text())
    assert len(sessions) == 2
    assert sessions[1]["first_step"] == last_checkpoint
    assert sessions[1]["last_step"] >= 3000
    with np.load(run / "evaluations.npz") as log:
        steps = list(log["timesteps"])
    assert steps[:2] == [800, 1600]
    assert steps[-1] > 1600  # the log continues
    assert (run / "logs" / f"progress-{last_checkpoint}.csv").is_file()
    assert newest_checkpoint(run)[0] > last_checkpoint


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--resume", "runs/x", "--seed", "3"], "--seed: a resumed run keeps its own settings"),
        (["--scenarios", "straight,moon", "--n-envs", "2"], "unknown scenario 'moon'"),
        (["--scenarios", "straight,curve", "--n-envs", "3"], "must be a multiple of the 2"),
        (["--n-timesteps", "0"], "--n-timesteps must be >= 1"),
        (["--hyperparams", "nope.yaml"], "nope.yaml: cannot read"),
    ],
)
def test_bad_arguments_give_one_line_and_status_2(
    argv: list[str], message: str, capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    assert main([*argv, "--runs", str(tmp_path)] if "--resume" not in argv else argv) == 2
    err = capsys.readouterr().err
    assert err.startswith("follow-train: error:")
    assert message in err
    assert not list(tmp_path.iterdir()), "nothing written"


def test_resume_without_checkpoint_names_the_folder(tmp_path: Path, smoke_config: Path) -> None:
    run = tmp_path / "run"
    run.mkdir()
    shutil.copy(smoke_config, run / "config.yaml")
    with pytest.raises(ValueError, match=r"checkpoints: no checkpoint to resume from"):
        train(Args(resume=run, progress=False))


@pytest.fixture
def smoke_config(tmp_path: Path) -> Path:
    path = tmp_path / "config.yaml"
    path.write_text(
        yaml.safe_dump(
            {
                "args": {"scenarios": ["straight"], "n_envs": 1},
                "hyperparams": {"n_envs": 1, "n_timesteps": 100},
            }
        )
    )
    return path

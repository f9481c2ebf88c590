"""train/ppo.py: follow-train writes a complete run folder, resumes, exports, rejects bad input."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
import yaml

from follow_env.tasks.person_follow import ENV_ID
from policies import make_policy
from train.cli import main
from train.ppo import DEFAULT_HYPERPARAMS, Args, train
from train.run import HeldOutEvalCallback, SessionLog, newest_checkpoint

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
        "follow-train-export.json",
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


def test_a_finished_run_resumes_from_its_final_state(smoke_run: Path, tmp_path: Path) -> None:
    # Once, the newest checkpoint of a finished run was older than its model: a resume threw
    # away the last steps and trained them again.
    final = json.loads((smoke_run / "sessions.json").read_text())[-1]["last_step"]
    assert newest_checkpoint(smoke_run)[0] == final
    run = tmp_path / "run"
    shutil.copytree(smoke_run, run)
    assert main(["--resume", str(run), "--n-timesteps", "3000", "--no-progress"]) == 0
    assert json.loads((run / "sessions.json").read_text())[-1]["first_step"] == final


def test_a_run_shorter_than_its_eval_freq_says_it_has_no_held_out_evaluation(
    smoke_run: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from train.cli import _no_held_out

    assert _no_held_out([smoke_run]) == ""  # evaluated every 800 steps: nothing to say
    run = tmp_path / "short"
    argv = [*SMOKE, "--eval-freq", "100000", "--final-episodes", "0", "--out", str(run)]
    assert main(argv) == 0
    assert not (run / "evaluations.npz").exists()  # SB3's EvalCallback never came due
    out = capsys.readouterr().out
    assert "No periodic held-out evaluation ran in the run (trained fewer env steps than" in out
    assert "1 of the 2 runs" in _no_held_out([smoke_run, run])


def test_a_resume_drops_the_evaluations_past_its_checkpoint(
    smoke_run: Path, tmp_path: Path
) -> None:
    # As a kill leaves a run: its log holds evaluations made after its newest checkpoint.
    run = tmp_path / "run"
    shutil.copytree(smoke_run, run)
    for path in (run / "checkpoints").iterdir():
        if int(path.name.split("_")[-2]) > 800:
            path.unlink()
    with np.load(run / "evaluations.npz") as log:
        assert log["timesteps"][-1] > 800
    assert main(["--resume", str(run), "--n-timesteps", "3000", "--no-progress"]) == 0
    with np.load(run / "evaluations.npz") as log:
        steps = log["timesteps"].tolist()
    assert steps == sorted(set(steps)), steps  # each step once, in order
    assert steps[0] == 800


def test_a_run_stopped_while_writing_its_report_resumes_to_write_it(
    smoke_run: Path, tmp_path: Path
) -> None:
    run = tmp_path / "run"
    shutil.copytree(smoke_run, run)
    (run / "MODEL_CARD.md").unlink()
    steps = newest_checkpoint(run)[0]
    assert main(["--resume", str(run), "--no-progress"]) == 0
    assert "## Scores" in (run / "MODEL_CARD.md").read_text()
    last = json.loads((run / "sessions.json").read_text())[-1]
    assert (last["status"], last["first_step"], last["last_step"]) == ("finished", steps, steps)
    # with its report written, the run is complete: nothing left to do
    assert main(["--resume", str(run), "--no-progress"]) == 2


def shipped_yaml(tmp_path: Path, **changes: object) -> Path:
    """The shipped hyperparameter file with ``changes`` applied to its section."""
    document = yaml.safe_load(DEFAULT_HYPERPARAMS.read_text())
    document[ENV_ID].update(changes)
    path = tmp_path / "hp.yaml"
    path.write_text(yaml.safe_dump(document))
    return path


def test_a_run_that_fails_while_learning_is_one_line_and_leaves_no_folder(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # SB3 accepts use_sde with the mirror policy, whose network then fails at the first
    # update with a torch RuntimeError: once a traceback and a run folder stuck "running".
    hp = shipped_yaml(tmp_path, use_sde=True)
    out = tmp_path / "run"
    argv = [*SMOKE, "--hyperparams", str(hp), "--checkpoint-freq", "100000", "--out", str(out)]
    assert main(argv) == 1
    assert_one_line(capsys, "training failed at ")
    assert not out.exists()


@pytest.mark.parametrize(
    "changes", [{"n_steps": 10**12}, {"policy_kwargs": {"net_arch": [1_000_000, 1_000_000]}}]
)
def test_a_model_too_large_for_the_memory_is_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], changes: dict
) -> None:
    # numpy's rollout buffer and torch's layers raise MemoryError / RuntimeError: once tracebacks
    out = tmp_path / "run"
    assert (
        main([*SMOKE, "--hyperparams", str(shipped_yaml(tmp_path, **changes)), "--out", str(out)])
        == 2
    )
    assert_one_line(capsys, "the model does not fit in memory")
    assert not out.exists()


@pytest.mark.parametrize(
    "option", ["--out", "--export", "--runs", "--resume", "--hyperparams", "--add-step"]
)
def test_an_empty_path_is_refused(
    option: str, tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    # Path("") is the current folder, which the user did not name: --out '' once trained
    # into it.
    monkeypatch.chdir(tmp_path)
    assert main([option, ""]) == 2
    assert_one_line(capsys, f"argument {option}: the path is empty")
    assert list(tmp_path.iterdir()) == []


def rescale(**kwargs: object) -> list:
    """The shipped wrapper list with VecRescaleAction's arguments replaced."""
    wrappers = yaml.safe_load(DEFAULT_HYPERPARAMS.read_text())[ENV_ID]["vec_env_wrapper"]
    return [{"train.wrappers.VecRescaleAction": kwargs}, *wrappers[1:]]


# Each case: argv (besides --runs), the message's start. Every one fails before anything is
# built or written (the test checks the runs folder and --out are never made).
BAD_ARGUMENTS = [
    (["--scenarios", "straight,moon", "--n-envs", "2"], "unknown scenario 'moon'"),
    (["--scenarios", "straight,straight"], "--scenarios must name each scenario once"),
    (["--scenarios", ","], "--scenarios must name each scenario once"),
    (["--scenarios", "straight,curve", "--n-envs", "3"], "n_envs=3 is out of range: must be a"),
    (["--n-timesteps", "0"], "--n-timesteps 0 is out of range: must be an integer >= 1"),
    (["--n-envs", "-4"], "--n-envs -4 is out of range: must be an integer >= 1"),
    (["--n-envs", "2", "--scenarios", "straight"], r"batch_size=256 is out of range: must be in"),
    (["--threads", "0"], "--threads 0 is out of range: must be an integer in [1, 256]"),
    (["--threads", "1000"], "--threads 1000 is out of range: must be an integer in [1, 256]"),
    (["--threads", "two"], "argument --threads: invalid int value: 'two'"),
    (["--seed", "-1"], "--seed -1 is out of range: must be an integer in [0, "),
    (["--seed", str(2**32 - 1)], f"--seed {2**32 - 1} is out of range: must be an integer in"),
    (["--n-timesteps", str(2**32)], "--n-timesteps 4294967296 is out of range: must be an"),
    (["--eval-seed", "-5"], "--eval-seed -5 is out of range: must be an integer in [0, "),
    (["--eval-freq", "0"], "--eval-freq 0 is out of range: must be an integer >= 1"),
    (["--checkpoint-freq", "0"], "--checkpoint-freq 0 is out of range: must be an integer >= 1"),
    (["--eval-episodes", "0"], "--eval-episodes 0 is out of range: must be an integer >= 1"),
    (["--final-episodes", "-1"], "--final-episodes -1 is out of range: must be an integer >= 0"),
    (["--compare-with", "nope"], "--compare-with 'nope': unknown policy 'nope'"),
    (["--env-config", "harsh"], "--env-config 'harsh' is not a preset"),
    (["--force"], "--force applies to --export only"),
    (["--export", "{runs}"], "--export {runs}: would contain the run folder {runs}/ppo-<time"),
    (["--hyperparams", "nope.yaml"], "nope.yaml: cannot read"),
    (["--resume", "runs/x", "--seed", "3"], "--seed: a resumed run keeps its own settings"),
    (["--resume", "no/such/run"], "--resume no/such/run: no such run folder"),
    # /proc takes no new file, even from root: refused before training, not after it
    (["--export", "/proc/personfollow-test"], "--export /proc/personfollow-test: cannot write"),
    (["--out", "/proc/personfollow-test"], "--out /proc/personfollow-test: cannot write"),
]


@pytest.mark.parametrize(("argv", "message"), BAD_ARGUMENTS)
def test_bad_arguments_give_one_line_and_status_2(
    argv: list[str], message: str, capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    runs = tmp_path / "runs"
    argv = [arg.format(runs=runs) for arg in argv]
    assert main([*argv, "--runs", str(runs)] if "--resume" not in argv else argv) == 2
    assert_one_line(capsys, message.format(runs=runs))
    assert not runs.exists(), "nothing written"


def assert_one_line(capsys: pytest.CaptureFixture[str], message: str) -> None:
    err = capsys.readouterr().err
    assert err.startswith("follow-train: error: ")
    assert err.count("\n") == 1, err
    assert message in err


# Each case: changes to the shipped YAML section, and the message's start.
BAD_YAML = [
    ({"n_steps": "sixty"}, "n_steps='sixty' is out of range: must be an integer >= 1"),
    ({"gamma": 7.5}, "gamma=7.5 is out of range: must be a number in [0, 1]"),
    ({"learning_rate": -1.0}, "learning_rate=-1.0 is out of range: must be a number > 0"),
    ({"vec_env_wrapper": rescale(w_max=2.0)}, "'w_max' is not one of its arguments"),
    (
        {"vec_env_wrapper": rescale(w_max_radps=99.0)},
        "the agent's env cannot be built: VecRescaleAction.w_max_radps=99.0 is out of range",
    ),
    (
        {"policy_kwargs": {"mirror_obs": [2, 1], "mirror_action": [1, -1]}},
        "MirrorMlpPolicy.mirror_obs=[2, 1] is out of range: must be a list of +1/-1",
    ),
]


@pytest.mark.parametrize(("changes", "message"), BAD_YAML)
def test_bad_yaml_fields_give_one_line_naming_the_field_before_anything_is_written(
    changes: dict, message: str, capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    out = tmp_path / "run"
    argv = ["--hyperparams", str(shipped_yaml(tmp_path, **changes)), "--out", str(out)]
    assert main([*argv, "--scenarios", "straight", "--n-envs", "4", "--no-progress"]) == 2
    assert_one_line(capsys, message)
    assert not out.exists()


def test_yaml_that_does_not_parse_gives_one_line(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    path = tmp_path / "hp.yaml"
    path.write_text("PersonFollow-v0:\n  n_envs: [4\n  gamma: 0.9\n")
    assert main(["--hyperparams", str(path), "--runs", str(tmp_path / "runs")]) == 2
    assert_one_line(capsys, "hp.yaml: not valid YAML")


@pytest.mark.parametrize(
    ("text", "message"),
    [("- a\n- b\n", "holds a list, not rl-zoo3 hyperparameters"), ("", "holds nothing, not")],
)
def test_a_file_that_is_not_a_mapping_of_env_ids_says_so(
    text: str, message: str, capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    path = tmp_path / "hp.yaml"
    path.write_text(text)
    assert main(["--hyperparams", str(path), "--runs", str(tmp_path / "runs")]) == 2
    assert_one_line(capsys, f"hp.yaml: {message}")
    assert not (tmp_path / "runs").exists()


@pytest.mark.parametrize(
    ("make", "message"),
    [
        ("file", "--out {out}: is a file, not a folder"),
        ("below_file", "--out {out}: runs through the file {tmp}/afile, not a folder"),
        ("full_folder", "--out {out} already exists and is not empty; use --resume"),
    ],
)
def test_out_must_be_a_new_or_empty_folder(
    make: str, message: str, capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    (tmp_path / "afile").write_text("x")
    out = {"file": tmp_path / "afile", "below_file": tmp_path / "afile" / "run"}.get(make)
    if make == "full_folder":
        out = tmp_path / "full"
        out.mkdir()
        (out / "notes.txt").write_text("mine")
    assert main(["--out", str(out)]) == 2
    assert_one_line(capsys, message.format(out=out, tmp=tmp_path))
    assert (tmp_path / "afile").read_text() == "x"


def test_runs_pointing_at_a_file_gives_one_line(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    (tmp_path / "afile").write_text("x")
    assert main(["--runs", str(tmp_path / "afile")]) == 2
    assert_one_line(capsys, "--runs {}: is a file, not a folder".format(tmp_path / "afile"))


@pytest.mark.parametrize(
    ("target", "message"),
    [
        ("users_folder", "the folder is not empty and holds no export of follow-train"),
        ("afile", "is a file, not a folder; give a folder (--force never replaces a file)"),
        (".", "--export .: the folder is not empty"),
    ],
)
def test_an_export_that_would_lose_a_file_is_refused_before_training(
    target: str,
    message: str,
    capsys: pytest.CaptureFixture[str],
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.chdir(tmp_path)
    (tmp_path / "users_folder").mkdir()
    (tmp_path / "users_folder" / "thesis.pdf").write_text("mine")
    (tmp_path / "afile").write_text("x")
    before = sorted(str(p.relative_to(tmp_path)) for p in tmp_path.rglob("*"))
    assert main([*SMOKE, "--out", "run", "--export", target]) == 2
    assert_one_line(capsys, message)
    assert sorted(str(p.relative_to(tmp_path)) for p in tmp_path.rglob("*")) == before
    assert (tmp_path / "users_folder" / "thesis.pdf").read_text() == "mine"


def test_resume_with_nothing_left_to_train_is_refused(
    smoke_run: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    run = tmp_path / "run"
    shutil.copytree(smoke_run, run)
    steps = newest_checkpoint(run)[0]
    assert main(["--resume", str(run), "--n-timesteps", str(steps)]) == 2
    assert_one_line(capsys, f"--n-timesteps={steps:,} is out of range: the newest checkpoint is")


def _tree(folder: Path) -> dict[str, bytes]:
    """Every file below ``folder`` with its bytes: what a refused command must not change."""
    return {str(p.relative_to(folder)): p.read_bytes() for p in folder.rglob("*") if p.is_file()}


@pytest.mark.parametrize(
    ("name", "damage", "message"),
    [
        ("evaluations.npz", b"PK\x03\x04", "evaluations.npz: not a readable held-out evaluation"),
        ("sessions.json", b'[{"status":', "sessions.json: cannot read the training sessions"),
    ],
)
def test_resume_of_a_run_with_a_damaged_log_changes_nothing(
    smoke_run: Path,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    name: str,
    damage: bytes,
    message: str,
) -> None:
    # Once, the session wrote config.yaml (the new n_timesteps), an empty progress CSV and a
    # TensorBoard file before it read these logs, then failed: with a traceback for the npz.
    run = tmp_path / "run"
    shutil.copytree(smoke_run, run)
    (run / name).write_bytes(damage)
    before = _tree(run)
    assert main(["--resume", str(run), "--n-timesteps", "3000", "--no-progress"]) == 2
    assert_one_line(capsys, f"{run / message}")
    assert _tree(run) == before


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


class Killed(BaseException):
    """Stands in for SIGKILL: nothing in follow-train handles it."""


def stop_at_checkpoint(monkeypatch: pytest.MonkeyPatch, step: int, error: BaseException) -> None:
    """Raise ``error`` right after the checkpoint at ``step`` is recorded in sessions.json."""
    record = SessionLog.checkpoint

    def checkpoint(self: SessionLog, at: int) -> None:
        record(self, at)
        if at >= step:
            raise error

    monkeypatch.setattr(SessionLog, "checkpoint", checkpoint)


@pytest.mark.slow
def test_killed_and_interrupted_sessions_count_in_the_card(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    run = tmp_path / "run"
    with monkeypatch.context() as m:
        stop_at_checkpoint(m, 800, Killed())
        with pytest.raises(Killed):
            main([*SMOKE, "--out", str(run)])
    [killed] = json.loads((run / "sessions.json").read_text())
    assert (killed["status"], killed["last_step"]) == ("running", 800)
    assert killed["wall_s"] > 0
    stale = run / ".eval-scratch-x1y2"  # what earlier versions left after a kill
    stale.mkdir()
    (stale / "evaluations.npz").write_bytes(b"")

    with monkeypatch.context() as m:
        stop_at_checkpoint(m, 1600, KeyboardInterrupt())
        assert main(["--resume", str(run), "--no-progress"]) == 130
    err = capsys.readouterr().err
    assert err == (
        f"follow-train: interrupted; resume with --resume {run} (continues from the checkpoint "
        "at 1,600 env steps)\n"
    )
    assert not stale.exists()

    assert main(["--resume", str(run), "--no-progress"]) == 0
    sessions = json.loads((run / "sessions.json").read_text())
    assert [s["status"] for s in sessions] == ["killed", "interrupted", "finished"]
    assert [(s["first_step"], s["last_step"]) for s in sessions[:2]] == [(0, 800), (800, 1600)]
    card = (run / "MODEL_CARD.md").read_text()
    assert "killed; counted up to its last checkpoint" in card
    assert "interrupted" in card
    total_min = sum(s["wall_s"] for s in sessions) / 60
    assert f"in {total_min:.1f} min of training" in card
    assert not list(run.glob(".*")), "no hidden or temporary files"


def test_ctrl_c_before_the_first_checkpoint_removes_the_new_run(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    def interrupt(self: HeldOutEvalCallback) -> bool:
        raise KeyboardInterrupt

    monkeypatch.setattr(HeldOutEvalCallback, "_on_step", interrupt)
    run = tmp_path / "run"
    assert main([*SMOKE, "--out", str(run)]) == 130
    assert capsys.readouterr().err == (
        "follow-train: interrupted before the first checkpoint (every 800 env steps): nothing "
        f"to resume, removed {run}\n"
    )
    assert not run.exists()


@pytest.mark.parametrize("where", ["--out", "--runs", "--runs of other runs"])
def test_ctrl_c_before_the_first_checkpoint_removes_the_folders_it_made(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str], where: str
) -> None:
    # The missing parents of --out or --runs went too; a folder that held something stays.
    def interrupt(self: HeldOutEvalCallback) -> bool:
        raise KeyboardInterrupt

    monkeypatch.setattr(HeldOutEvalCallback, "_on_step", interrupt)
    folder = tmp_path / "a" / "b"
    if where.endswith("other runs"):
        (folder / "ppo-old").mkdir(parents=True)
    assert main([*SMOKE, where.split()[0], str(folder)]) == 130
    assert "nothing to resume, removed" in capsys.readouterr().err
    left = sorted(str(p.relative_to(tmp_path)) for p in tmp_path.rglob("*"))
    assert left == (["a", "a/b", "a/b/ppo-old"] if where.endswith("other runs") else [])


def test_divergence_gives_one_line_and_keeps_the_run(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    def diverge(self: HeldOutEvalCallback) -> bool:
        raise ValueError("Expected parameter loc ... but found invalid values:\ntensor([[nan]])")

    monkeypatch.setattr(HeldOutEvalCallback, "_on_step", diverge)
    run = tmp_path / "run"
    assert main([*SMOKE, "--out", str(run)]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1, err
    assert err.startswith("follow-train: error: training diverged at ")
    assert "the policy's outputs became NaN" in err
    assert json.loads((run / "sessions.json").read_text())[0]["status"] == "failed"


def test_the_summary_lists_only_files_that_were_written(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    run = tmp_path / "run"
    short = ["--scenarios", "straight", "--n-envs", "4", "--n-timesteps", "300"]
    never = ["--eval-freq", "100000", "--checkpoint-freq", "100000", "--final-episodes", "0"]
    assert main([*short, *never, "--no-progress", "--out", str(run)]) == 0
    # what was written, then why no held-out evaluation is among it
    printed, why, _ = capsys.readouterr().out.partition(". No periodic held-out evaluation ran")
    assert why
    assert "evaluations.npz" not in printed
    # no checkpoint was due; the final state is one all the same, for a later --resume
    assert "checkpoints/ (1 checkpoint)" in printed
    listed = printed.split(f"Wrote {run}/: ")[1].strip().split(", ")
    assert listed[0] == "model.zip"
    for name in listed:
        assert (run / name.removesuffix(" (1 checkpoint)")).exists(), name

"""train/tune.py: PPO hyperparameters searched with follow-tune's driver."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import yaml

from eval.tuning.driver import SearchConfig, open_study
from eval.tuning.folders import open_search
from eval.tuning.objective import TUNE_SEED0
from train.tune import PPO_SPACE, PPOObjective, hyperparams_for, main


def test_integer_keys_are_rounded_and_the_minibatch_fits_one_rollout() -> None:
    hp = hyperparams_for({"n_steps": 16.4, "batch_size": 900.0, "gamma": 0.99}, n_envs=11)
    assert hp == {"n_steps": 16, "batch_size": 176, "gamma": 0.99}


def test_the_minibatch_divides_the_rollout_nearest_to_the_sampled_size() -> None:
    hp = hyperparams_for({"n_steps": 191.0, "batch_size": 517.0}, n_envs=11)
    assert hp["n_steps"] * 11 % hp["batch_size"] == 0
    assert hp["batch_size"] == 191  # 2101 = 11 x 191: the divisors are 11, 191 and 2101


def test_bad_arguments_give_one_line_and_exit_2(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["--scenarios", "moon", "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("python -m train.tune: error: --scenarios")
    assert not (tmp_path / "out").exists()
    for argv, message in (
        (["--scenarios", ""], "--scenarios is empty"),  # not the default scenarios
        (["--seed", "-1"], "sampler_seed=-1 is out of range"),
    ):
        assert main([*argv, "--out", str(tmp_path / "out")]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1
        assert message in err
        assert not (tmp_path / "out").exists()  # refused before the folder is made


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--n-envs", "5"], "n_envs=5 is out of range"),
        (["--hyperparams", "{tmp}/bad.yaml"], "bad.yaml: not valid YAML: line 2"),
        (["--backend", "ray", "--address", "127.0.0.1:1"], "cannot reach the Ray cluster"),
        (["--backend", "ray", "--address", "127.0.0.1:1", "--workers", "1"], "cannot reach"),
    ],
)
def test_bad_training_options_are_refused_before_out_is_made(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], argv: list[str], message: str
) -> None:
    # Once refused only by the first trial's training: after the journal and the trial's
    # hyperparams.yaml were written into --out.
    (tmp_path / "bad.yaml").write_text("PersonFollow-v0: [1,2\n")
    argv = [a.replace("{tmp}", str(tmp_path)) for a in argv]
    assert main(["--trials", "1", *argv, "--out", str(tmp_path / "pt1")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1
    assert err.startswith("python -m train.tune: error: ")
    assert message in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.yaml"]


@pytest.mark.parametrize(
    ("files", "message"),
    [
        ({"notes.txt": "x"}, "the folder holds notes.txt, which python -m train.tune did not"),
        ({"study.journal": "hi\n"}, "its study.journal is not an Optuna journal"),
        ({"result.json": "{}"}, "its result.json is not python -m train.tune's"),
    ],
)
def test_an_out_folder_of_other_files_is_refused_unchanged(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], files: dict[str, str], message: str
) -> None:
    out = tmp_path / "out"
    out.mkdir()
    for name, text in files.items():
        (out / name).write_text(text)
    assert main(["--trials", "1", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1
    assert f"--out {out}: {message}" in err
    assert {p.name: p.read_text() for p in out.iterdir()} == files


@pytest.mark.slow
def test_a_tiny_search_trains_and_scores_each_trial(tmp_path: Path) -> None:
    out = tmp_path / "out"
    argv = ["--trials", "2", "--n-timesteps", "256", "--n-envs", "12", "--seeds", "1"]
    assert main([*argv, "--scenarios", "straight", "--out", str(out)]) == 0
    result = json.loads((out / "result.json").read_text())
    assert result["trials"] == 2
    best = result["best_hyperparams"]
    assert isinstance(best["n_steps"], int)
    assert best["learning_rate"] in PPO_SPACE["learning_rate"]
    assert best["gamma"] in PPO_SPACE["gamma"]
    files = sorted(out.glob("trials/*/hyperparams.yaml"))
    assert len(files) == 2
    section = yaml.safe_load(files[0].read_text())["PersonFollow-v0"]
    assert isinstance(section["batch_size"], int)
    assert all((f.parent / "run" / "model.zip").exists() for f in files)


def _refused(capsys: pytest.CaptureFixture[str], argv: list[str], message: str) -> None:
    assert main(["--trials", "1", *argv]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1, err
    assert err.startswith("python -m train.tune: error: ")
    assert message in err, err


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--storage", "sqlite:///:memory:"], "an in-memory SQLite database keeps nothing"),
        (["--storage", "sqlite://"], "an in-memory SQLite database keeps nothing"),
        (["--storage", " "], "--storage is empty"),
        (["--study", ""], "--study is empty"),
        (["--backend", "ray", "--address", ""], "--address is empty"),
        (["--scenarios", "curve,straight,curve"], "'curve' is given twice"),
        (["--hyperparams", ""], "--hyperparams"),
        (["--storage", "{tmp}/no/such/j"], "its folder {tmp}/no/such does not exist"),
    ],
)
def test_a_storage_study_or_scenario_list_that_cannot_work_is_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], argv: list[str], message: str
) -> None:
    argv = [a.replace("{tmp}", str(tmp_path)) for a in argv]
    _refused(
        capsys, [*argv, "--out", str(tmp_path / "out")], message.replace("{tmp}", str(tmp_path))
    )
    assert not any(tmp_path.iterdir())


def test_an_out_of_another_study_is_refused_unchanged(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "out"
    out.mkdir()
    result = {"study": "other", "best_hyperparams": {}}
    (out / "result.json").write_text(json.dumps(result))
    _refused(capsys, ["--out", str(out)], "it holds the results of the study other, not ppo")
    assert [p.name for p in out.iterdir()] == ["result.json"]

    (out / "result.json").unlink()
    open_study(out / "study.journal", "other", SearchConfig(1, (TUNE_SEED0,)))
    before = (out / "study.journal").read_bytes()
    _refused(capsys, ["--out", str(out)], "its study.journal holds the study other, not ppo")
    assert (out / "study.journal").read_bytes() == before


def test_a_study_run_with_other_settings_is_not_resumed(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # Its trials were trained for another budget: a resume would rank them with this run's.
    out = tmp_path / "out"
    config = SearchConfig(1, (TUNE_SEED0,))
    open_search(out, str(out / "study.journal"), "ppo", config, {"n_timesteps": 1})
    before = (out / "study.journal").read_bytes()
    _refused(capsys, ["--n-timesteps", "512", "--out", str(out)], "was run with other settings")
    assert (out / "study.journal").read_bytes() == before
    assert [p.name for p in out.iterdir()] == ["study.journal"]


def test_a_trials_folder_is_keyed_by_its_budget_and_lanes(tmp_path: Path) -> None:
    from execution import Backend
    from train.ppo import DEFAULT_HYPERPARAMS, Args

    def folder(**budget: int) -> str:
        base = Args(
            hyperparams=DEFAULT_HYPERPARAMS,
            n_timesteps=budget.get("n", 256),
            n_envs=budget.get("lanes", 12),
        )
        objective = PPOObjective(base, tmp_path, ("straight",), Backend())
        args, _ = objective._unit({"gamma": 0.98})
        return args.out.parent.name

    assert folder() == folder()
    assert len({folder(), folder(n=512), folder(lanes=24)}) == 3


@pytest.mark.parametrize(
    ("where", "message"),
    [
        ("open_study", "interrupted while opening the study ppo in {out}/study.journal; no trial"),
        ("run_search", "interrupted; the study ppo in {out}/study.journal keeps its finished"),
        # after the search, while its result is written: not "before the search began"
        ("_report", "interrupted; the study ppo in {out}/study.journal keeps its finished"),
    ],
)
def test_ctrl_c_is_one_line_saying_what_was_kept(
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
    where: str,
    message: str,
) -> None:
    import eval.tuning.driver
    import train.tune

    def interrupt(*_: object, **__: object) -> None:
        raise KeyboardInterrupt

    monkeypatch.setattr(
        eval.tuning.driver if where == "open_study" else train.tune, where, interrupt
    )
    out = tmp_path / "out"
    tiny = ["--n-timesteps", "256", "--n-envs", "12", "--seeds", "1", "--scenarios", "straight"]
    assert main(["--trials", "1", *tiny, "--out", str(out)]) == 130
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1
    assert err[0].startswith("python -m train.tune: " + message.format(out=out))
    if where == "open_study":
        assert not any(tmp_path.iterdir())  # the folder it made is gone
    elif where == "run_search":
        assert sorted(p.name for p in out.iterdir()) == ["study.journal"]
    else:  # the search ran: its trial's run is kept, no result.json is half-written
        assert sorted(p.name for p in out.iterdir()) == ["study.journal", "trials"]


@pytest.mark.slow
def test_sigterm_stops_a_search_as_ctrl_c_does(tmp_path: Path) -> None:
    """``kill`` (as ``timeout``, Slurm and Kubernetes stop a job) takes Ctrl-C's path: one line
    saying what was kept, exit status 143, no traceback."""
    import os
    import subprocess
    import sys

    from tests.eval.test_tuning_stops import _term_when

    out = tmp_path / "out"
    argv = ["--trials", "50", "--n-timesteps", "256", "--n-envs", "12", "--seeds", "1"]
    argv += ["--scenarios", "straight", "--out", str(out)]
    root = Path(__file__).resolve().parents[2]
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    proc = subprocess.Popen(
        [sys.executable, "-m", "train.tune", *argv],
        cwd=root,
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
    )
    err = _term_when(proc, (out / "trials").exists, 1.0)  # a trial is training
    assert proc.returncode == 143, err
    assert "Traceback" not in err
    last = err.strip().splitlines()[-1]
    assert last.startswith("python -m train.tune: terminated (SIGTERM); the study "), err
    assert last.endswith("run the same command again to resume")

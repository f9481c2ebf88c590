"""``follow-train``'s one-line errors for work units: a ``--seeds`` study whose workers kept
dying, and an error a seed's worker raised."""

from __future__ import annotations

from pathlib import Path

import pytest

import train.cli
from execution import WorkerLostError
from execution.worker import _note_origin, _tag_origin
from train.cli import WORKERS_LOST, main

STUDY = ["--scenarios", "straight", "--n-envs", "4", "--n-timesteps", "600", "--no-progress"]


def test_a_study_whose_workers_kept_dying_says_in_one_line_that_it_resumes(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    def dying(*args: object, **kwargs: object) -> Path:
        raise WorkerLostError(1, "(seed 1)", 4, 3, 2, "killed by SIGKILL")

    monkeypatch.setattr(train.cli, "train_seeds", dying)
    argv = [*STUDY, "--seeds", "0-1", "--workers", "2", "--out", str(tmp_path / "study")]
    assert main(argv) == WORKERS_LOST == 3
    err = capsys.readouterr().err
    assert err.count("\n") == 1, err
    assert err.startswith("follow-train: error: unit 1 (seed 1): its worker process died 4 times")
    assert "the finished seeds are kept" in err
    assert "run the same command again" in err


def test_an_error_a_seeds_worker_raised_names_the_unit_and_host(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    def failing(*args: object, **kwargs: object) -> Path:
        error = ValueError("bad hyperparameter")
        _tag_origin(error)  # as a worker does, then the caller (execution's own, tested there)
        _note_origin(error, 0, "(seed 0)")
        raise error

    monkeypatch.setattr(train.cli, "train_seeds", failing)
    assert main([*STUDY, "--seeds", "0", "--out", str(tmp_path / "study")]) == 2
    err = capsys.readouterr().err
    assert "follow-train: error: bad hyperparameter (in work unit 0 (seed 0) on host " in err

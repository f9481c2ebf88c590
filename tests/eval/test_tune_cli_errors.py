"""The tuning commands' one-line errors for work units: ``follow-tune`` and ``python -m
train.tune`` stopped by workers that kept dying (exit status 3, saying the study resumes), and
an error a trial's worker raised (naming the unit and host)."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from types import ModuleType

import pytest

import eval.tuning.cli
import train.tune
from execution import WORKERS_LOST, WorkerLostError
from execution.worker import _note_origin, _tag_origin

COMMANDS: list[tuple[ModuleType, Callable[[Path], list[str]]]] = [
    (eval.tuning.cli, lambda out: ["pn", "--trials", "2", "--out", str(out)]),
    (train.tune, lambda out: ["--trials", "2", "--out", str(out)]),
]


@pytest.mark.parametrize(("module", "argv"), COMMANDS)
def test_a_search_whose_workers_kept_dying_says_in_one_line_that_it_resumes(
    module: ModuleType,
    argv: Callable[[Path], list[str]],
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    def dying(*args: object, **kwargs: object) -> int:
        raise WorkerLostError(2, "(trial 2)", 4, 3, 5, "killed by SIGKILL")

    monkeypatch.setattr(module, "run", dying)
    assert module.main(argv(tmp_path / "out")) == WORKERS_LOST == 3
    err = capsys.readouterr().err
    assert err.count("\n") == 1, err  # one line, no traceback
    assert err.startswith(f"{module.PROG}: error: unit 2 (trial 2): its worker process died 4")
    assert "the study keeps its finished trials" in err
    assert "run the same command again to resume" in err


@pytest.mark.parametrize(("module", "argv"), COMMANDS)
def test_an_error_a_trials_worker_raised_names_the_unit_and_host(
    module: ModuleType,
    argv: Callable[[Path], list[str]],
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    def failing(*args: object, **kwargs: object) -> int:
        error = ValueError("bad episode")
        _tag_origin(error)  # as a worker does, then the caller (execution's own, tested there)
        _note_origin(error, 0, "(trial 0)")
        raise error

    monkeypatch.setattr(module, "run", failing)
    assert module.main(argv(tmp_path / "out")) == 2
    err = capsys.readouterr().err
    assert f"{module.PROG}: error: bad episode (in work unit 0 (trial 0) on host " in err

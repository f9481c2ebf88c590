"""``follow-train --seeds``' work units: what they carry to their worker, and what it does.

A seed's unit names its folder by absolute path and carries the driver's code digest; its
worker decides whether the folder is a new run or one to resume, so that the unit of a worker
that died is run again from the seed's newest checkpoint; and a study is trained on only by
the code that started it.
"""

from __future__ import annotations

import dataclasses
import json
import shutil
import socket
from pathlib import Path
from typing import Any

import pytest

import train.seeds
from eval.provenance import running_sources_sha256
from train.cli import main
from train.seeds import _train_unit
from train.study_record import TRAINING_PACKAGES

TINY = [
    "--scenarios", "straight",
    "--n-envs", "4",
    "--n-timesteps", "600",
    "--eval-freq", "300",
    "--checkpoint-freq", "300",
    "--eval-episodes", "2",
    "--final-episodes", "0",
    "--no-progress",
]  # fmt: skip
OTHER = "f" * 64  # a digest no code has


def _one_line(capsys: pytest.CaptureFixture[str]) -> str:
    err = capsys.readouterr().err
    assert err.startswith("follow-train: error: "), err
    assert err.count("\n") == 1, err
    return err


@pytest.fixture(scope="module")
def trained(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, list[Any]]:
    """A study of seeds 0 and 1, trained from a relative --out, and the units it sent."""
    root = tmp_path_factory.mktemp("units")
    sent: list[Any] = []
    real = train.seeds.execute

    def kept(fn: Any, units: Any, *args: Any, **kwargs: Any) -> Any:
        sent.extend(units)
        return real(fn, units, *args, **kwargs)

    with pytest.MonkeyPatch.context() as patch:
        patch.chdir(root)
        patch.setattr(train.seeds, "execute", kept)
        assert main([*TINY, "--seeds", "0-1", "--out", "study"]) == 0
    return root / "study", sent


def test_a_seeds_unit_names_its_folder_by_absolute_path(trained: tuple[Path, list[Any]]) -> None:
    """A Ray worker resolves a relative --out from the folder its ``ray start`` ran in."""
    study, units = trained
    assert [unit.args.out for unit in units] == [study / "seed-0", study / "seed-1"]
    assert all(unit.args.out.is_absolute() for unit in units)
    assert json.loads((study / "study.json").read_text())["code"] == running_sources_sha256(
        TRAINING_PACKAGES
    )


def _as_a_killed_worker_left_it(run: Path) -> int:
    """Make ``run`` what a worker killed after its first checkpoint leaves; returns the step."""
    sessions = json.loads((run / "sessions.json").read_text())
    kept = sorted((run / "checkpoints").glob("ppo_*_steps.zip"))
    first = int(kept[0].stem.split("_")[1])
    for late in kept[1:]:
        late.unlink()
    sessions[-1] |= {"status": "running", "last_step": first}
    (run / "sessions.json").write_text(json.dumps(sessions))
    (run / "model.zip").unlink()
    (run / "MODEL_CARD.md").unlink()
    return first


def test_a_seed_whose_worker_died_is_run_again_from_its_checkpoint(
    trained: tuple[Path, list[Any]], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The execution layer runs a lost unit again: once, its new run's options met the folder
    the dead worker had filled ("--out ... already exists and is not empty"), and the command
    stopped with status 2. The worker's folder may not be the driver's: it is another one."""
    study, units = trained
    copy = tmp_path / "study"
    shutil.copytree(study, copy)
    unit = units[1]._replace(args=dataclasses.replace(units[1].args, out=copy / "seed-1"))
    first = _as_a_killed_worker_left_it(copy / "seed-1")
    monkeypatch.chdir(tmp_path)  # a worker's own folder
    row = _train_unit(unit)
    sessions = json.loads((copy / "seed-1" / "sessions.json").read_text())
    assert sessions[-1]["status"] == "finished"
    assert sessions[-1]["first_step"] == first  # resumed, not started again
    assert (row["seed"], row["run"]) == (1, "seed-1")
    assert row["env_steps"] >= 600
    # Its worker died once more, after the run had finished: nothing is trained again.
    before = (copy / "seed-1" / "sessions.json").read_text()
    assert _train_unit(unit) == row
    assert (copy / "seed-1" / "sessions.json").read_text() == before


def test_a_seed_resumed_keeps_the_studys_mkl_intel_paths(
    trained: tuple[Path, list[Any]], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A resumed seed trains with the option as the study's new seeds do (its worker then
    refuses to train without the preload, train.mkl_paths.require_active)."""
    study, units = trained
    copy = tmp_path / "study"
    shutil.copytree(study, copy)
    args = dataclasses.replace(units[1].args, out=copy / "seed-1", mkl_intel_paths=True)
    _as_a_killed_worker_left_it(copy / "seed-1")
    given: list[Any] = []

    def resumed(args: Any, command: str) -> Path:
        given.append(args)
        raise KeyboardInterrupt  # what it was given is all this test needs

    monkeypatch.setattr(train.seeds, "train", resumed)
    with pytest.raises(KeyboardInterrupt):
        _train_unit(units[1]._replace(args=args))
    assert given[0].resume == copy / "seed-1"
    assert given[0].mkl_intel_paths is True


def test_a_new_seed_whose_worker_died_before_its_first_checkpoint_starts_again(
    trained: tuple[Path, list[Any]], tmp_path: Path
) -> None:
    study, units = trained
    folder, unit = _lost_before_a_checkpoint(study, units[0], tmp_path)
    (folder / "logs").mkdir()
    row = _train_unit(unit)
    sessions = json.loads((folder / "sessions.json").read_text())
    assert [s["status"] for s in sessions] == ["finished"]
    assert row["env_steps"] == 768


def test_a_study_is_trained_on_only_by_the_code_that_started_it(
    trained: tuple[Path, list[Any]],
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    study, _ = trained
    copy = tmp_path / "study"
    shutil.copytree(study, copy)
    had = json.loads((copy / "study.json").read_text())["code"]
    argv = [*TINY, "--out", str(copy)]
    with monkeypatch.context() as patch:
        patch.setattr(train.seeds, "running_sources_sha256", lambda packages: OTHER)
        assert main([*argv, "--seeds", "0-2"]) == 2  # seed 2 would train with other code
        err = _one_line(capsys)
        assert "the code changed since the study started" in err
        assert f"was {had[:12]}, is now {OTHER[:12]}" in err
        assert "run it with the code it started with, or give another --out" in err
        assert not (copy / "seed-2").exists()
        # Nothing to train: its seeds are summed up again, whatever the code.
        assert main([*argv, "--seeds", "0-1"]) == 0
    assert json.loads((copy / "study.json").read_text())["code"] == had


def test_a_study_that_records_no_code_says_how_to_go_on(
    trained: tuple[Path, list[Any]], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    study, _ = trained
    copy = tmp_path / "study"
    shutil.copytree(study, copy)
    settings = json.loads((copy / "study.json").read_text())
    code = settings.pop("code")  # as a study made before studies recorded it
    (copy / "study.json").write_text(json.dumps(settings))
    argv = [*TINY, "--out", str(copy), "--seeds", "0-2"]
    assert main(argv) == 2
    err = _one_line(capsys)
    assert f"{copy / 'study.json'} records no code" in err
    assert f'add "code": "{code}"' in err
    assert not (copy / "seed-2").exists()
    (copy / "study.json").write_text(json.dumps(settings | {"code": code}))  # as it says
    assert main(argv) == 0


def test_a_worker_with_other_code_than_the_driver_trains_nothing(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """The driver's digest is another than its worker's (this process reads its own files)."""
    monkeypatch.setattr(train.seeds, "running_sources_sha256", lambda packages: OTHER)
    out = tmp_path / "study"
    assert main([*TINY, "--seeds", "0", "--out", str(out)]) == 2
    err = _one_line(capsys)
    assert f"this worker ({socket.gethostname()}) runs other code than the driver" in err
    assert "train sources" in err
    assert not (out / "seed-0").exists()


def test_a_lost_new_seeds_folder_is_cleared_only_of_what_a_run_writes(
    trained: tuple[Path, list[Any]], tmp_path: Path
) -> None:
    """A file no run writes is never deleted to train a seed again: the seed is refused."""
    study, units = trained
    folder, unit = _lost_before_a_checkpoint(study, units[0], tmp_path)
    (folder / "notes.txt").write_text("mine")
    with pytest.raises(ValueError, match=r"holds notes\.txt, which no run writes"):
        _train_unit(unit)
    assert sorted(p.name for p in folder.iterdir()) == ["config.yaml", "notes.txt"]


def test_a_worker_that_reads_other_hyperparameters_trains_nothing(
    trained: tuple[Path, list[Any]], tmp_path: Path
) -> None:
    """The hyperparameter file is read on the worker: another node's copy may differ."""
    _, units = trained
    folder = tmp_path / "seed-0"
    unit = units[0]._replace(args=dataclasses.replace(units[0].args, out=folder))
    unit = unit._replace(hp={**unit.hp, "gamma": 0.5})  # what the driver read
    with pytest.raises(ValueError, match=r"reads other hyperparameters than the driver"):
        _train_unit(unit)
    assert not folder.exists()


def _lost_before_a_checkpoint(study: Path, unit: Any, tmp_path: Path) -> tuple[Path, Any]:
    """A new seed's folder as its worker left it, dying before the first checkpoint: the
    run's config.yaml and nothing else; and the unit that trains into it."""
    folder = tmp_path / "seed-0"
    folder.mkdir()
    shutil.copy(study / "seed-0" / "config.yaml", folder / "config.yaml")
    return folder, unit._replace(args=dataclasses.replace(unit.args, out=folder))

"""``follow-train --seeds`` run again over what an earlier command left: a ``--compare-with``
agent a seed's worker must find as the driver named it, a seed killed before its first
checkpoint, and an export folder holding an earlier export of other seeds."""

from __future__ import annotations

import json
import shutil
from pathlib import Path
from typing import Any

import pytest
import yaml

import train.seeds
from policies import make_policy
from policies.learned.ensemble import EnsemblePolicy
from policies.learned.ppo import AGENTS
from train.cli import main
from train.options import Args, check_new_run
from train.seeds import _train_unit, seed_args

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


def _files(folder: Path) -> dict[Path, bytes]:
    """Every file below ``folder`` with its bytes: what a refused command must not change."""
    return {p: p.read_bytes() for p in folder.rglob("*") if p.is_file()}


def _error(capsys: pytest.CaptureFixture[str]) -> str:
    err = capsys.readouterr().err
    assert err.startswith("follow-train: error: "), err
    assert err.count("\n") == 1, err
    return err


@pytest.fixture(scope="module")
def study(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A finished study of seeds 0-3 (each test works on a copy)."""
    out = tmp_path_factory.mktemp("leftovers") / "study"
    assert main([*TINY, "--seeds", "0-3", "--out", str(out)]) == 0
    return out


@pytest.fixture
def copy(study: Path, tmp_path: Path) -> Path:
    shutil.copytree(study, tmp_path / "study")
    return tmp_path / "study"


# -- --compare-with: a path is made absolute on the driver --------------------------------------


def _comparison(card: Path) -> list[str]:
    """The model card's comparison: the law it names and its table's rows."""
    lines = card.read_text(encoding="utf-8").splitlines()
    return [line for line in lines if line.startswith(("Against ", "| straight |"))]


def test_a_compare_with_path_names_the_drivers_agent_on_any_worker(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A Ray worker resolves a relative path from the folder its ``ray start`` ran in: once, it
    compared the seed with another agent at the same relative path there (or found none)."""
    driver, worker = tmp_path / "driver", tmp_path / "worker"
    agent = driver / "agents" / "mine"
    shutil.copytree(AGENTS / "ppo", agent)
    shutil.copytree(AGENTS / "ppo_ensemble" / "seed-1", worker / "agents" / "mine")  # another
    sent: list[Any] = []
    real = train.seeds.execute

    labels: list[str] = []

    def kept(fn: Any, units: Any, *args: Any, **kwargs: Any) -> Any:
        sent.extend(units)
        labels.extend(kwargs["describe"](u) for u in units)
        return real(fn, units, *args, **kwargs)

    monkeypatch.setattr(train.seeds, "execute", kept)
    monkeypatch.chdir(driver)
    argv = ["--seeds", "0", "--out", "study", "--compare-with", "agents/mine"]
    assert main([*TINY, "--final-episodes", "1", *argv]) == 0
    (unit,) = sent
    assert unit.args.compare_with == str(agent)
    # messages put the label in parentheses themselves: "unit 0 (seed 0)", not "((seed 0))"
    assert labels == ["seed 0"]
    card = driver / "study" / "seed-0" / "MODEL_CARD.md"
    on_the_driver = _comparison(card)
    assert on_the_driver[0].startswith(f"Against `{agent}` on held-out seeds"), on_the_driver
    assert len(on_the_driver) > 1
    saved = yaml.safe_load((driver / "study" / "seed-0" / "config.yaml").read_text())
    assert saved["args"]["compare_with"] == str(agent)  # a resume compares with it too
    # the study's record keeps the option as given: the same command is the same study
    assert json.loads((driver / "study" / "study.json").read_text())["compare_with"] == (
        "agents/mine"
    )
    # The same unit on a worker started in another folder: the driver's agent, the same table.
    shutil.rmtree(driver / "study" / "seed-0")
    monkeypatch.chdir(worker)
    _train_unit(unit)
    assert _comparison(card) == on_the_driver


@pytest.mark.parametrize(
    ("given", "sent"),
    [
        ("gsmpn:tuned", "gsmpn:tuned"),
        ("pn", "pn"),  # registered: the law, though a folder "pn" is here too (make_policy's rule)
        ("agents/mine", "{here}/agents/mine"),
        ("agents/mine/model.zip", "{here}/agents/mine/model.zip"),
        ("agents/typo", "agents/typo"),  # no such path: left for the check to name
    ],
)
def test_a_compare_with_path_is_made_absolute_and_a_name_left_as_it_is(
    given: str, sent: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    (tmp_path / "pn").mkdir()
    (tmp_path / "agents" / "mine").mkdir(parents=True)
    (tmp_path / "agents" / "mine" / "model.zip").write_bytes(b"")
    monkeypatch.chdir(tmp_path)
    one = seed_args(Args(compare_with=given), 2, tmp_path / "study")
    assert one.compare_with == sent.format(here=tmp_path)


def test_a_single_runs_compare_with_path_is_recorded_absolute(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """One run's ``config.yaml`` is what ``--resume`` reads: from another folder, a relative
    path there named another agent or none."""
    shutil.copytree(AGENTS / "ppo", tmp_path / "agents" / "mine")
    monkeypatch.chdir(tmp_path)
    args, _ = check_new_run(Args(compare_with="agents/mine", out=tmp_path / "run"))
    assert args.compare_with == str(tmp_path / "agents" / "mine")
    assert check_new_run(Args(compare_with="gsmpn:tuned"))[0].compare_with == "gsmpn:tuned"


# -- a seed killed before its first checkpoint ------------------------------------------------


def _killed_before_its_first_checkpoint(run: Path) -> None:
    """Make ``run`` what a kill before its first checkpoint leaves: its config, a session still
    "running", the held-out log, SB3's logs, the statistics of a checkpoint it did not finish
    and the temporary file of the model it was writing."""
    for child in run.iterdir():
        if child.name not in ("config.yaml", "evaluations.npz", "logs", "checkpoints"):
            shutil.rmtree(child) if child.is_dir() else child.unlink()
    for child in (run / "checkpoints").iterdir():
        if child.name != "ppo_vecnormalize_300_steps.pkl":
            child.unlink()
    (run / "checkpoints" / ".ppo_300_steps.a1b2c3d4.tmp.zip").write_bytes(b"PK")
    session = {"command": "follow-train", "status": "running", "first_step": 0, "last_step": 0}
    (run / "sessions.json").write_text(json.dumps([session]))


def _interrupted_after_its_first_checkpoint(run: Path) -> int:
    """Make ``run`` what Ctrl-C after its first checkpoint leaves; returns that step."""
    sessions = json.loads((run / "sessions.json").read_text())
    kept = sorted((run / "checkpoints").glob("ppo_*_steps.zip"))
    first = int(kept[0].stem.split("_")[1])
    for late in kept[1:]:
        late.unlink()
    sessions[-1] |= {"status": "interrupted", "last_step": first}
    (run / "sessions.json").write_text(json.dumps(sessions))
    (run / "model.zip").unlink()
    (run / "MODEL_CARD.md").unlink()
    return first


def test_the_same_command_resumes_a_study_with_a_seed_killed_before_its_first_checkpoint(
    copy: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Once refused ("no checkpoint to resume from"): only the execution layer's retry, within
    the command, started such a seed again."""
    _killed_before_its_first_checkpoint(copy / "seed-1")
    first = _interrupted_after_its_first_checkpoint(copy / "seed-2")
    finished = {k: (copy / f"seed-{k}" / "sessions.json").read_text() for k in (0, 3)}
    assert main([*TINY, "--seeds", "0-3", "--out", str(copy)]) == 0
    err = capsys.readouterr().err
    assert err.startswith(f"follow-train: {copy / 'seed-1'} held no checkpoint, only what its run")
    assert "(checkpoints/, config.yaml, evaluations.npz, logs/, sessions.json)" in err
    assert "seed 1 starts again" in err
    assert err.count("\n") == 1, err
    for k, before in finished.items():  # kept, not trained again
        assert (copy / f"seed-{k}" / "sessions.json").read_text() == before
    resumed = json.loads((copy / "seed-2" / "sessions.json").read_text())
    assert [s["status"] for s in resumed] == ["interrupted", "finished"]
    assert resumed[-1]["first_step"] == first
    again = json.loads((copy / "seed-1" / "sessions.json").read_text())
    assert [(s["status"], s["first_step"]) for s in again] == [("finished", 0)]
    assert not list((copy / "seed-1").rglob(".*"))  # the killed run's temporary file is gone
    rows = (copy / "seeds.csv").read_text().splitlines()
    assert [row.split(",")[0] for row in rows[1:]] == ["0", "1", "2", "3"]


@pytest.mark.parametrize(
    "name", ["notes.txt", "logs/notes.txt", "logs/tb/notes.txt", "checkpoints/mine.pkl"]
)
def test_a_killed_seeds_folder_holding_another_file_is_refused_naming_it(
    name: str, copy: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Nothing but what a run writes is ever deleted to start a seed again."""
    folder = copy / "seed-1"
    _killed_before_its_first_checkpoint(folder)
    (folder / name).write_text("mine")
    before = _files(copy)
    assert main([*TINY, "--seeds", "0-3", "--out", str(copy)]) == 2
    err = _error(capsys)
    assert f"{folder}: its run ended before its first checkpoint, but the folder holds {name}," in (
        err
    )
    assert _files(copy) == before  # refused before any seed trained


# -- an export folder holding an export of other seeds ----------------------------------------


@pytest.fixture
def exported(copy: Path, tmp_path: Path) -> Path:
    """The study's seeds 0 and 1 exported as one agent, with the user's notes beside it."""
    dest = tmp_path / "pair"
    assert main([*TINY, "--seeds", "0-1", "--out", str(copy), "--export", str(dest)]) == 0
    (dest / "notes.txt").write_text("kept")
    return dest


def _export(copy: Path, dest: Path, seeds: str, *extra: str) -> int:
    return main([*TINY, "--seeds", seeds, "--out", str(copy), "--export", str(dest), *extra])


def test_an_export_of_other_seeds_is_refused_before_anything_trains(
    copy: Path, exported: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Once, ``--seeds 2-3 --export DIR`` over an export of seeds 0-1 wrote an ensemble of 2-3
    and left seed-0 and seed-1 in DIR: agents its ensemble.yaml does not name."""
    capsys.readouterr()
    before = _files(exported)
    assert _export(copy, exported, "2-4") == 2  # seed 4 is new: it would train first
    err = _error(capsys)
    assert f"--export {exported}: holds an export of other seeds (seed-0, seed-1)" in err
    assert "give --force to replace that export" in err
    assert _files(exported) == before
    assert not (copy / "seed-4").exists()
    # More seeds than the export has is no stale member: the export grows.
    assert _export(copy, exported, "0-2") == 0
    assert yaml.safe_load((exported / "ensemble.yaml").read_text())["members"] == [
        "seed-0",
        "seed-1",
        "seed-2",
    ]


def test_force_replaces_an_export_of_other_seeds_with_exactly_the_new_ones(
    copy: Path, exported: Path
) -> None:
    assert _export(copy, exported, "2-3", "--force") == 0
    # the new members, the user's notes (nothing else is touched), no temporary left
    names = sorted(p.name for p in exported.iterdir())
    assert names == ["ensemble.yaml", "notes.txt", "seed-2", "seed-3"]
    assert yaml.safe_load((exported / "ensemble.yaml").read_text())["members"] == [
        "seed-2",
        "seed-3",
    ]
    for k in (2, 3):
        model = (exported / f"seed-{k}" / "model.zip").read_bytes()
        assert model == (copy / f"seed-{k}" / "model.zip").read_bytes()
    assert isinstance(make_policy(str(exported)), EnsemblePolicy)


@pytest.mark.parametrize("change", ["mine.txt", "MODEL_CARD.md"])
def test_force_keeps_a_stale_member_holding_a_file_its_export_did_not_write(
    change: str, copy: Path, exported: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """--force deletes only files an export wrote, unchanged since (as one run's export)."""
    with (exported / "seed-1" / change).open("a") as f:
        f.write("mine")
    capsys.readouterr()
    before = _files(exported)
    assert _export(copy, exported, "2-3", "--force") == 2
    err = _error(capsys)
    assert f"cannot remove the stale member seed-1: {change} in it was not written by" in err
    assert _files(exported) == before


def test_a_kill_while_an_export_is_replaced_leaves_one_whole_agent(
    copy: Path, exported: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The new members are written whole before ``ensemble.yaml`` names them, and the stale
    ones removed after: DIR is the old agent or the new one, and the same command finishes."""
    import train.study_export

    old = _files(exported)
    real = train.study_export.export_agent
    calls: list[Path] = []

    def killed_at_the_second(run: Path, dest: Path, **kwargs: Any) -> Path:
        calls.append(dest)
        if len(calls) == 2:
            raise KeyboardInterrupt
        return real(run, dest, **kwargs)

    with monkeypatch.context() as patch:
        patch.setattr(train.study_export, "export_agent", killed_at_the_second)
        assert _export(copy, exported, "2-3", "--force") == 130
    assert {p: b for p, b in _files(exported).items() if p in old} == old  # the old agent
    assert yaml.safe_load((exported / "ensemble.yaml").read_text())["members"] == [
        "seed-0",
        "seed-1",
    ]
    with monkeypatch.context() as patch:  # killed once ensemble.yaml names the new members
        patch.setattr(train.study_export, "_remove", lambda folder: _raise(KeyboardInterrupt))
        assert _export(copy, exported, "2-3", "--force") == 130
    assert yaml.safe_load((exported / "ensemble.yaml").read_text())["members"] == [
        "seed-2",
        "seed-3",
    ]
    assert isinstance(make_policy(str(exported)), EnsemblePolicy)
    # seed-0 and seed-1, left behind, are still found as stale without an ensemble naming them
    assert _export(copy, exported, "2-3") == 2
    assert _export(copy, exported, "2-3", "--force") == 0
    assert sorted(p.name for p in exported.iterdir()) == [
        "ensemble.yaml",
        "notes.txt",
        "seed-2",
        "seed-3",
    ]


def _raise(error: type[BaseException]) -> None:
    raise error

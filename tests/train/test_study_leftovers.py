"""``follow-train --seeds`` run again over what an earlier command left: a ``--compare-with``
agent a seed's worker must find as the driver named it, a seed killed before its first
checkpoint, an export folder holding an earlier export of other seeds; and a second command on
a study another one is training."""

from __future__ import annotations

import contextlib
import fcntl
import json
import os
import shutil
import subprocess
import sys
from collections.abc import Iterator
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
from train.run import not_written_early
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


def _tree(folder: Path) -> dict[Path, bytes | None]:
    """Every file (with its bytes) and folder below ``folder``."""
    return {p: p.read_bytes() if p.is_file() else None for p in folder.rglob("*")}


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
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
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
    # the study's record names the agent as this folder read it
    study_json = driver / "study" / "study.json"
    assert json.loads(study_json.read_text())["compare_with"] == str(agent)
    # The same unit on a worker started in another folder: the driver's agent, the same table.
    shutil.rmtree(driver / "study" / "seed-0")
    monkeypatch.chdir(worker)
    _train_unit(unit)
    assert _comparison(card) == on_the_driver
    # The same command from the worker's folder names another agent: another study (it was
    # taken for the same one, and its new seeds compared with the other agent).
    study = str(driver / "study")
    argv = ["--final-episodes", "1", "--seeds", "0-1", "--out", study]
    assert main([*TINY, *argv, "--compare-with", "agents/mine"]) == 2
    assert "holds another study (its study.json differs in compare_with)" in _error(capsys)
    # From the driver's folder, relative or absolute, it is the same study; so is a study.json
    # that kept the option as typed (before it was recorded absolute).
    monkeypatch.chdir(driver)
    argv = ["--final-episodes", "1", "--seeds", "0", "--out", study]
    assert main([*TINY, *argv, "--compare-with", str(agent)]) == 0
    legacy = json.loads(study_json.read_text()) | {"compare_with": "agents/mine"}
    study_json.write_text(json.dumps(legacy))
    assert main([*TINY, *argv, "--compare-with", "agents/mine"]) == 0
    # The agent moved away since: nothing left to train, the same command is still this study
    # (say, to export it).
    shutil.move(agent, driver / "agents" / "moved")
    assert main([*TINY, *argv, "--compare-with", "agents/mine"]) == 0


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


# -- two commands on one study ------------------------------------------------------------------

#: Another process holding a study folder as a follow-train command does, until it is killed.
_HOLD = (
    "import fcntl, os, sys; fd = os.open(sys.argv[1], os.O_RDONLY); "
    "fcntl.flock(fd, fcntl.LOCK_EX); print('held', flush=True); sys.stdin.read()"
)


@contextlib.contextmanager
def _held(folder: Path) -> Iterator[None]:
    """``folder`` held by another process (:data:`_HOLD`) inside the block, then let go as a
    killed command's hold is: by the kernel."""
    holder = subprocess.Popen(
        [sys.executable, "-c", _HOLD, str(folder)], stdin=subprocess.PIPE, stdout=subprocess.PIPE
    )
    try:
        assert holder.stdout is not None
        assert holder.stdout.readline() == b"held\n"
        yield
    finally:
        holder.kill()
        holder.wait()


def test_a_second_command_on_a_study_in_training_is_refused_and_changes_nothing(
    copy: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Once, the same command run while the first still trained seed 1 before its first
    checkpoint cleared that live run's folder (it looks exactly like a run killed then)."""
    _killed_before_its_first_checkpoint(copy / "seed-1")  # as the live run has it now
    capsys.readouterr()
    with _held(copy):
        before = _tree(copy)
        assert main([*TINY, "--seeds", "0-3", "--out", str(copy)]) == 2
        err = _error(capsys)
        assert f"--out {copy}: another follow-train command is training this study now; " in err
        assert "wait for it to end (or stop it) and run this again" in err
        assert _tree(copy) == before
    assert main([*TINY, "--seeds", "0-3", "--out", str(copy)]) == 0
    assert "seed 1 starts again" in capsys.readouterr().err


def test_a_run_in_training_is_not_trained_again_beside_it(
    copy: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``--resume RUN`` while another command trains RUN (a second resume, or the study
    command training that seed) wrote the same checkpoints and logs as the other."""
    run = copy / "seed-1"
    _interrupted_after_its_first_checkpoint(run)
    capsys.readouterr()
    with _held(run):
        before = _tree(copy)
        assert main(["--resume", str(run), "--no-progress"]) == 2
        err = _error(capsys)
        assert f"--resume {run}: another follow-train command is training this run now" in err
        assert _tree(copy) == before
    assert main(["--resume", str(run), "--no-progress"]) == 0


def test_a_new_study_is_held_from_when_it_is_made_until_the_command_ends(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "study"
    argv = [*TINY, "--seeds", "0", "--out", str(out)]
    real = train.seeds.execute
    meanwhile: list[tuple[int, str]] = []
    calls: list[int] = []

    def and_the_same_command_again(*args: Any, **kwargs: Any) -> Any:
        calls.append(1)
        if len(calls) == 1:  # once: unrefused, the second command would come here too
            capsys.readouterr()
            meanwhile.append((main(argv), capsys.readouterr().err))  # while seed 0 is to train
        return real(*args, **kwargs)

    monkeypatch.setattr(train.seeds, "execute", and_the_same_command_again)
    assert main(argv) == 0
    ((status, err),) = meanwhile
    assert status == 2, err
    assert f"--out {out}: another follow-train command is training this study now" in err
    fd = os.open(out, os.O_RDONLY)  # let go once the command ended
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    finally:
        os.close(fd)


# -- hidden files in a seed killed before its first checkpoint ---------------------------------


@pytest.mark.parametrize(
    ("hidden", "named"),
    [
        ([".git/HEAD"], ".git"),
        ([".analysis.ipynb"], ".analysis.ipynb"),
        (["logs/.ipynb_checkpoints/x.ipynb"], "logs/.ipynb_checkpoints"),
        (["checkpoints/.mine/best_by_hand.zip"], "checkpoints/.mine"),
        # named as a temporary file, but a folder, or a name no atomic write makes
        ([".config.abcdefgh.tmp.yaml/x"], ".config.abcdefgh.tmp.yaml"),
        ([".config.abcdefgh.tmp.yaml.bak"], ".config.abcdefgh.tmp.yaml.bak"),
        (["logs/.progress-0.abcdefg.tmp.csv"], "logs/.progress-0.abcdefg.tmp.csv"),
        (
            [
                ".git/HEAD",
                ".analysis.ipynb",
                "logs/.ipynb_checkpoints/x.ipynb",
                "checkpoints/.mine/best_by_hand.zip",
            ],
            ".analysis.ipynb",
        ),
    ],
)
def test_a_killed_seeds_hidden_file_or_folder_is_refused_naming_it(
    hidden: list[str], named: str, copy: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Once, every hidden entry was taken for an atomic write's temporary file and deleted
    with the folder, and the message listed only the visible ones."""
    folder = copy / "seed-1"
    _killed_before_its_first_checkpoint(folder)
    for name in hidden:
        (folder / name).parent.mkdir(parents=True, exist_ok=True)
        (folder / name).write_text("mine")
    capsys.readouterr()
    before = _tree(copy)
    assert main([*TINY, "--seeds", "0-3", "--out", str(copy)]) == 2
    err = _error(capsys)
    assert (
        f"{folder}: its run ended before its first checkpoint, but the folder holds {named}, "
        in (err)
    )
    assert _tree(copy) == before


def test_a_hidden_link_is_refused(tmp_path: Path) -> None:
    run = tmp_path / "run"
    run.mkdir()
    (run / "config.yaml").write_text("x")
    (tmp_path / "mine.yaml").write_text("mine")
    (run / ".config.abcdefgh.tmp.yaml").symlink_to(tmp_path / "mine.yaml")
    assert not_written_early(run) == ".config.abcdefgh.tmp.yaml"


@pytest.mark.parametrize(
    "target",
    [
        "config.yaml",
        "sessions.json",
        "evaluations.npz",
        "checkpoints/ppo_300_steps.zip",
        "checkpoints/recurrent_ppo_vecnormalize_300_steps.pkl",
        "logs/tb/" + "x" * 60 + ".json",  # the stem cut short
        "logs/notes." + "y" * 20,  # a suffix too long to keep
        "logs/archive.tar.gz",
    ],
)
def test_the_temporary_files_of_atomic_writes_are_what_a_killed_run_may_hold(
    target: str, tmp_path: Path
) -> None:
    """Named by :mod:`follow_env.sim.atomic` itself: what a kill in an atomic write leaves."""
    from follow_env.sim.atomic import atomic_path

    run = tmp_path / "run"
    (run / target).parent.mkdir(parents=True)
    made: list[Path] = []
    with contextlib.suppress(KeyboardInterrupt), atomic_path(run / target) as tmp:
        made.append(tmp)
        raise KeyboardInterrupt  # atomic_path removes its file; a kill would have left it
    (left,) = made
    assert not left.exists()
    left.write_bytes(b"half")
    assert left.name.startswith(".")
    assert not_written_early(run) is None


@pytest.mark.parametrize("name_bytes", [0, 80])
def test_the_probe_of_a_folders_writability_is_what_a_killed_run_may_hold(
    name_bytes: int, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """``check_writable`` makes a file and removes it at once: a kill in between leaves it."""
    import follow_env.sim.atomic as atomic

    run = tmp_path / "run"
    run.mkdir()
    made: list[str] = []
    real = atomic.tempfile.mkstemp

    def kept(*args: Any, **kwargs: Any) -> Any:
        fd, name = real(*args, **kwargs)
        made.append(name)
        return fd, name

    monkeypatch.setattr(atomic.tempfile, "mkstemp", kept)
    monkeypatch.setattr(atomic.os, "unlink", lambda name: None)  # the kill: never removed
    atomic.try_new_file(run, name_bytes=name_bytes)
    (left,) = made
    assert Path(left).name.startswith(".write-check.")
    assert not_written_early(run) is None


# -- exports over a folder an export of other agents holds -------------------------------------


@pytest.mark.parametrize(("seeds", "force"), [("3", True), ("3", False), ("4", True)])
def test_one_seed_is_not_exported_beside_an_ensemble(
    seeds: str, force: bool, copy: Path, exported: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Once, ``--seeds 3 --export DIR --force`` wrote the agent beside DIR's ensemble.yaml, and
    make_policy(DIR) was still the old ensemble."""
    capsys.readouterr()
    before = _tree(exported)
    assert _export(copy, exported, seeds, *(["--force"] if force else [])) == 2
    err = _error(capsys)
    assert f"--export {exported}: holds ensemble.yaml, and an agent is exported into the" in err
    assert f"make_policy({str(exported)!r}) would still be the old ensemble" in err
    assert _tree(exported) == before
    assert not (copy / "seed-4").exists()  # refused before the new seed trained
    assert isinstance(make_policy(str(exported)), EnsemblePolicy)


@pytest.mark.parametrize("force", [True, False])
def test_the_members_of_an_ensemble_assembled_by_hand_are_never_removed(
    force: bool, copy: Path, exported: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Once, --force removed the members ``best`` and ``robust`` as "other seeds": they held
    an export's manifest."""
    hand = tmp_path / "hand"
    hand.mkdir()
    shutil.copytree(exported / "seed-0", hand / "best")
    shutil.copytree(exported / "seed-1", hand / "robust")
    (hand / "ensemble.yaml").write_text("members: [best, robust]\n")
    capsys.readouterr()
    before = _tree(hand)
    assert _export(copy, hand, "2-3", *(["--force"] if force else [])) == 2
    err = _error(capsys)
    assert f"--export {hand}: its ensemble.yaml lists best, robust, which the new " in err
    assert f"(best from the run {(copy / 'seed-0').resolve()}; robust from the run" in err
    assert "move them away, or choose another folder" in err
    assert _tree(hand) == before


def test_another_studys_seeds_in_an_export_are_never_removed(
    copy: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    other, dest = tmp_path / "other-study", tmp_path / "pair"
    # trained from other seeds: other models (a copy of this study's would be its own models)
    argv = ["--seed", "7", "--seeds", "0-1", "--out", str(other), "--export", str(dest)]
    assert main([*TINY, *argv]) == 0
    capsys.readouterr()
    before = _tree(dest)
    assert _export(copy, dest, "2-3", "--force") == 2
    err = _error(capsys)
    assert f"--export {dest}: its ensemble.yaml lists seed-0, seed-1, which the new" in err
    # each named with the run it came from
    assert f"seed-0 from the run {(other / 'seed-0').resolve()}; seed-1 from the run" in err
    assert _tree(dest) == before


def test_a_removal_cut_short_is_finished_by_the_next_export(
    copy: Path, exported: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Once, the hidden folder a stale member was renamed into stayed for good."""
    real = shutil.rmtree

    def killed_while_deleting(path: Any, *args: Any, **kwargs: Any) -> None:
        if str(path).endswith(".removed"):
            raise KeyboardInterrupt
        real(path, *args, **kwargs)

    with monkeypatch.context() as patch:
        patch.setattr(shutil, "rmtree", killed_while_deleting)
        assert _export(copy, exported, "2-3", "--force") == 130
    (left,) = exported.glob(".seed-0.*.removed")
    assert (left / "seed-0" / "model.zip").is_file()
    # names of another shape are the user's, not a removal's: left alone
    for name in (".seed-0.abcdefg.removed", ".best.abcdefgh.removed", ".seed-0.abcdefgh.removed.1"):
        (exported / name).mkdir()
    (exported / ".seed-1.abcdefgh.removed").write_text("a file")
    assert _export(copy, exported, "2-3", "--force") == 0
    assert sorted(p.name for p in exported.iterdir()) == [
        ".best.abcdefgh.removed",
        ".seed-0.abcdefg.removed",
        ".seed-0.abcdefgh.removed.1",
        ".seed-1.abcdefgh.removed",
        "ensemble.yaml",
        "notes.txt",
        "seed-2",
        "seed-3",
    ]


def test_without_flock_a_study_is_unguarded_not_refused(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Windows has no fcntl: every follow-train command imported it, and failed there."""
    import train.study_lock

    monkeypatch.setattr(train.study_lock, "fcntl", None)
    study = tmp_path / "study"
    study.mkdir()
    with train.study_lock.StudyLock(study) as first, train.study_lock.StudyLock(study) as second:
        first.take()
        second.take()  # nothing to hold it with: not refused
        assert not first.held
        assert not second.held


def test_a_moved_study_replaces_its_own_earlier_export(
    copy: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The members' manifests name the study's old folder; their model files are the moved
    study's still. Once, its own seed-2 was refused as "not exported from this study"."""
    dest = tmp_path / "three"
    assert main([*TINY, "--seeds", "0-2", "--out", str(copy), "--export", str(dest)]) == 0
    moved = tmp_path / "moved"
    shutil.copytree(copy, moved, symlinks=True)
    capsys.readouterr()
    assert _export(moved, dest, "0-1", "--force") == 0
    assert sorted(p.name for p in dest.iterdir() if p.name.startswith("seed-")) == [
        "seed-0",
        "seed-1",
    ]

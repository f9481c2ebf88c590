"""follow-tune's refusals: one line, exit status 2, and no file or folder written or changed.

Each case here once went wrong: an unrelated ``--storage`` file got an Optuna record appended,
an ``--out`` folder of other files got the results written among them, ``--seed -1`` left a
journal behind, ``--scenarios ''`` started a full tune, an unwritable ``--out`` gave a bare
``[Errno 2]`` and a YAML error took eight lines. The runs carry the smallest budget, so that a
regression that lets one start ends in seconds rather than hanging the suite.
"""

from __future__ import annotations

import json
from pathlib import Path

import optuna
import pytest
from optuna.storages.journal._storage import JournalOperation

from eval.cli_base import UsageError
from eval.tuning import SearchConfig, open_study
from eval.tuning.cli import _check_out, main
from eval.tuning.driver import _CREATE_STUDY, MAX_SAMPLER_SEED, check_journal, journal_problem
from eval.tuning.objective import TUNE_SEED0

SMALL = ["--trials", "1", "--seeds", "1", "--holdout-seeds", "1", "--scenarios", "straight"]


def _tree(folder: Path) -> dict[str, bytes]:
    """Every file below ``folder`` with its bytes: what must not change."""
    return {
        str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()
    }


def _refused(capsys: pytest.CaptureFixture[str], argv: list[str], *expected: str) -> str:
    """Run follow-tune; assert exit status 2 and one stderr line holding ``expected``."""
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1, err
    assert err.startswith("follow-tune: error: ")
    for text in expected:
        assert text in err, err
    return err


def _journal(path: Path) -> None:
    """A real follow-tune journal: a study with one finished trial."""
    study = open_study(path, "pn-person_follow", SearchConfig(1, (TUNE_SEED0,)))
    trial = study.ask()
    study.tell(trial, 1.0)


# 1. --storage: an existing file that is not a journal is neither changed nor opened.


def test_a_storage_file_that_is_not_a_journal_is_refused_unchanged(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.chdir(tmp_path)
    Path("afile").write_text("hi\n")
    before = _tree(tmp_path)
    argv = ["pn", *SMALL, "--storage", "afile", "--out", "tu3"]
    _refused(capsys, argv, "--storage afile is not an Optuna journal", "line 1")
    assert _tree(tmp_path) == before  # no record appended, no lock, no tu3


@pytest.mark.parametrize(
    ("text", "problem"),
    [
        ("hi", "line 1 is not a journal record"),  # no newline: Optuna would glue onto it
        ('{"a": 1}\n', "line 1 is not a journal record"),
        ('{"op_code": 4, "worker_id": "w"}\n', "first record does not create a study"),
    ],
)
def test_check_journal_names_the_first_line_that_is_not_a_record(
    tmp_path: Path, text: str, problem: str
) -> None:
    path = tmp_path / "j"
    path.write_text(text)
    assert problem in (journal_problem(path) or "")
    with pytest.raises(ValueError, match="is not an Optuna journal"):
        open_study(path, "x", SearchConfig(1, (TUNE_SEED0,)))
    assert path.read_text() == text


def test_a_journal_an_empty_file_and_a_new_path_are_accepted(tmp_path: Path) -> None:
    assert _CREATE_STUDY == JournalOperation.CREATE_STUDY  # the op code read from Optuna's layout
    _journal(tmp_path / "study.journal")
    lines = (tmp_path / "study.journal").read_bytes().splitlines(keepends=True)
    assert json.loads(lines[0])["op_code"] == _CREATE_STUDY
    check_journal(tmp_path / "study.journal")
    (tmp_path / "empty").write_text("")
    check_journal(tmp_path / "empty")
    check_journal(tmp_path / "new")


# 2. --out: a folder of other files is not written into; a study's folder may be resumed.


@pytest.mark.parametrize(
    ("files", "expected"),
    [
        ({"notes.txt": "x"}, "the folder holds notes.txt, which follow-tune did not write"),
        ({"study.journal": "hi\n"}, "its study.journal is not an Optuna journal"),
        ({"result.json": "{}"}, "its result.json is not follow-tune's"),
        ({"preset.txt": "mine\n"}, "its preset.txt is not follow-tune's"),
    ],
)
def test_an_out_folder_follow_tune_did_not_write_is_refused_unchanged(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], files: dict[str, str], expected: str
) -> None:
    out = tmp_path / "exists"
    out.mkdir()
    for name, text in files.items():
        (out / name).write_text(text)
    before = _tree(tmp_path)
    _refused(capsys, ["pn", *SMALL, "--out", str(out)], f"--out {out}: {expected}")
    assert _tree(tmp_path) == before


def test_a_follow_tune_study_folder_is_accepted_for_resuming(tmp_path: Path) -> None:
    _check_out(tmp_path / "new")  # a folder to make
    _check_out(tmp_path)  # an empty one
    _journal(tmp_path / "study.journal")  # an interrupted run left only its journal
    _check_out(tmp_path)
    summary = {"search": {}, "holdout": [], "verdict": "kept"}
    (tmp_path / "result.json").write_text(json.dumps(summary))
    (tmp_path / "preset.txt").write_text("# follow-tune pn --trials 1\n")
    (tmp_path / ".preset.abc123.tmp.txt").write_text("# follow-tune")  # a killed atomic write
    _check_out(tmp_path)
    (tmp_path / "notes.txt").write_text("x")
    with pytest.raises(UsageError, match=r"holds notes\.txt"):
        _check_out(tmp_path)


# 3. --seed: the sampler's range, checked before the journal is made.


@pytest.mark.parametrize("seed", ["-1", str(2**32), "x"])
def test_a_seed_the_sampler_does_not_take_is_an_argument_error(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], seed: str
) -> None:
    out = tmp_path / "tu2"
    err = _refused(capsys, ["pn", "--seed", seed, *SMALL, "--out", str(out)], "argument --seed: ")
    assert "0..2**32-1" in err or "is not an integer" in err
    assert not out.exists()


def test_the_command_line_and_the_sampler_take_the_same_seeds() -> None:
    # The bound is written twice (parsing the command line does not import Optuna): one range.
    from eval.tuning import cli

    assert cli.MAX_SAMPLER_SEED == MAX_SAMPLER_SEED
    assert cli._sampler_seed(str(MAX_SAMPLER_SEED)) == MAX_SAMPLER_SEED
    SearchConfig(1, (TUNE_SEED0,), sampler_seed=cli.MAX_SAMPLER_SEED)


def test_the_top_seed_still_opens_a_resumed_study(tmp_path: Path) -> None:
    # A resumed study seeds its sampler with seed + trials so far: that wraps, never overflows.
    config = SearchConfig(2, (TUNE_SEED0,), sampler_seed=MAX_SAMPLER_SEED)
    study = open_study(tmp_path / "j", "s", config)
    study.tell(study.ask(), 1.0)
    assert len(open_study(tmp_path / "j", "s", config).trials) == 1
    with pytest.raises(ValueError, match="sampler_seed=-1 is out of range"):
        SearchConfig(1, (TUNE_SEED0,), sampler_seed=-1)


def test_a_failed_open_removes_the_journal_and_folders_it_made(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    def refuse(**_: object) -> None:
        raise RuntimeError("no study today")

    monkeypatch.setattr(optuna, "create_study", refuse)
    out = tmp_path / "a" / "b"
    _refused(capsys, ["pn", *SMALL, "--out", str(out)], "cannot open the storage", "no study today")
    assert not (tmp_path / "a").exists()


# 4. Empty values: never the default in disguise.


@pytest.mark.parametrize(
    ("option", "expected"),
    [
        ("--scenarios", "--scenarios is empty"),
        ("--holdout-scenarios", "--holdout-scenarios is empty"),
        ("--task", "--task is empty"),
        ("--study", "--study is empty"),
        ("--storage", "--storage is empty"),
        ("--config", "--config is empty"),
        ("--out", "argument --out: the path is empty"),
        ("--write-preset", "argument --write-preset: the path is empty"),
    ],
)
def test_an_empty_value_is_refused_not_replaced_by_the_default(
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
    option: str,
    expected: str,
) -> None:
    monkeypatch.chdir(tmp_path)
    small = ["--trials", "1", "--seeds", "1", "--holdout-seeds", "1"]
    out = [] if option == "--out" else ["--out", "tu"]
    _refused(capsys, ["pn", *small, *out, option, ""], expected)
    assert not any(tmp_path.iterdir())


# 5. An --out that cannot be made names the option.


@pytest.mark.skipif(not Path("/proc/self").is_dir(), reason="needs Linux's /proc")
def test_an_out_folder_that_cannot_be_made_names_the_option(
    capsys: pytest.CaptureFixture[str],
) -> None:
    _refused(capsys, ["pn", *SMALL, "--out", "/proc/x"], "--out /proc/x: cannot write to /proc")


# 6. --config: a YAML syntax error in one line.


def test_a_config_file_with_a_yaml_error_gives_its_line_and_column(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bad = tmp_path / "bad.yaml"
    bad.write_text("perception: [1,2\n")
    out = tmp_path / "tu4"
    _refused(
        capsys,
        ["pn", *SMALL, "--config", str(bad), "--out", str(out)],
        f"argument --config: {bad} is not valid YAML/JSON: line 2, column 1: expected ','",
    )
    assert not out.exists()


# 3. A damaged database: SQLAlchemy's message spans three lines; follow-tune's error is one.


def test_a_damaged_sqlite_database_is_named_in_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    db = tmp_path / "tuning.db"
    db.write_text("not a database, whatever its name says\n")
    before = _tree(tmp_path)
    url = f"sqlite:///{db}"
    argv = ["pn", *SMALL, "--storage", url, "--out", str(tmp_path / "out")]
    err = _refused(capsys, argv, f"cannot open the storage {url}", "file is not a database")
    assert "[SQL:" not in err
    assert "Background on this error" not in err
    assert _tree(tmp_path) == before  # no --out folder, the file as it was

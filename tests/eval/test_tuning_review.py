"""follow-tune and ``python -m train.tune``: the defects a review found, each pinned.

A refused command changes nothing (not the journal, not ``--out``, not a ``--write-preset``
target), ``--out`` is resumed only by its own study, and Ctrl-C after the study opened ends in
one line saying what was kept. The runs carry the smallest budget.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from eval.tuning import SearchConfig, open_study
from eval.tuning.cli import main
from eval.tuning.objective import TUNE_SEED0
from tests.eval.test_tuning_cli_errors import SMALL, _refused, _tree


def _study(journal: Path, name: str = "pn-person_follow", search: object = None) -> None:
    """A journal holding the study ``name`` with one finished trial and ``search`` settings."""
    study = open_study(journal, name, SearchConfig(1, (TUNE_SEED0,)))
    if search is not None:
        study.set_user_attr("search", search)
    study.tell(study.ask(), 1.0)


# 1. A study started with other settings: refused, and its journal not appended to.


def test_a_refused_resume_leaves_the_journal_unchanged(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "t1"
    out.mkdir()
    _study(out / "study.journal", search={"law": "pn", "seeds": 99})
    before = _tree(tmp_path)
    _refused(capsys, ["pn", *SMALL, "--out", str(out)], "was run with other settings")
    assert _tree(tmp_path) == before


def test_reopening_a_study_adds_no_record(tmp_path: Path) -> None:
    journal = tmp_path / "j"
    _study(journal)
    before = journal.read_bytes()
    assert len(open_study(journal, "pn-person_follow", SearchConfig(1, (TUNE_SEED0,))).trials) == 1
    assert journal.read_bytes() == before


# 2. --write-preset onto a file the study keeps: refused, the study intact.


@pytest.mark.parametrize("target", ["out/study.journal", "out/result.json", "out/preset.txt"])
def test_write_preset_onto_the_studys_own_files_is_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch, target: str
) -> None:
    monkeypatch.chdir(tmp_path)
    Path("out").mkdir()
    _study(Path("out/study.journal"))
    before = _tree(tmp_path)
    # "out/../out/x" resolves to the same file: compared resolved, not as typed
    argv = ["pn", *SMALL, "--out", "out", "--write-preset", f"out/../{target}"]
    _refused(capsys, argv, f"--write-preset out/../{target}: that is --out's", "another file")
    assert _tree(tmp_path) == before


def test_write_preset_onto_the_storage_is_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    journal = tmp_path / "j.journal"
    _study(journal)
    before = _tree(tmp_path)
    for storage in (str(journal), f"sqlite:///{tmp_path / 'x.db'}"):
        target = journal if "://" not in storage else tmp_path / "x.db"
        argv = ["pn", *SMALL, "--storage", storage, "--write-preset", str(target)]
        _refused(capsys, [*argv, "--out", str(tmp_path / "out")], "that is --storage")
    assert _tree(tmp_path) == before


# 3. An --out folder of another law or --study: refused, naming what it holds.


def _results(out: Path, law: str, study: str) -> None:
    """``out`` as a finished follow-tune run of ``study`` (of ``law``) leaves it."""
    out.mkdir()
    _study(out / "study.journal", study)
    summary = {"study": study, "search": {"law": law}, "holdout": [], "verdict": "kept"}
    (out / "result.json").write_text(json.dumps(summary))
    (out / "preset.txt").write_text(f"# follow-tune {law} --trials 1\n")


@pytest.mark.parametrize(
    ("argv", "expected"),
    [
        (["mpn"], "holds the results of the study pn-person_follow of the law pn, not mpn-"),
        (["pn", "--study", "other"], "not other of pn"),
    ],
)
def test_an_out_folder_of_another_study_is_refused_unchanged(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], argv: list[str], expected: str
) -> None:
    out = tmp_path / "t2"
    _results(out, "pn", "pn-person_follow")
    before = _tree(tmp_path)
    _refused(capsys, [*argv, *SMALL, "--out", str(out)], f"--out {out}: it", expected)
    assert _tree(tmp_path) == before


def test_an_out_folder_whose_journal_holds_another_study_is_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "t2"
    out.mkdir()
    _study(out / "study.journal")  # an interrupted pn run: its journal only
    before = _tree(tmp_path)
    expected = "its study.journal holds the study pn-person_follow, not mpn-person_follow"
    _refused(capsys, ["mpn", *SMALL, "--out", str(out)], expected)
    assert _tree(tmp_path) == before


# 4. An unreachable Ray cluster: refused before the journal is made.


@pytest.mark.parametrize("workers", [[], ["--workers", "1"]])
def test_an_unreachable_ray_cluster_leaves_no_journal(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], workers: list[str]
) -> None:
    out = tmp_path / "tz"
    argv = ["pn", *SMALL, "--backend", "ray", "--address", "127.0.0.1:1", *workers]
    _refused(capsys, [*argv, "--out", str(out)], "cannot reach the Ray cluster at 127.0.0.1:1")
    assert not any(tmp_path.iterdir())


# 5. An in-memory database and a variant given twice.


@pytest.mark.parametrize(
    "url",
    ["sqlite://", "sqlite:///", "sqlite:///:memory:", "sqlite:///file:x?mode=memory&uri=true"],
)
def test_an_in_memory_sqlite_database_is_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], url: str
) -> None:
    argv = ["pn", *SMALL, "--storage", url, "--out", str(tmp_path / "out")]
    _refused(capsys, argv, f"--storage {url}: an in-memory SQLite database keeps nothing")
    assert not any(tmp_path.iterdir())


@pytest.mark.parametrize("option", ["--scenarios", "--holdout-scenarios"])
def test_a_variant_given_twice_is_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], option: str
) -> None:
    argv = ["pn", *SMALL, option, "straight, curve,straight", "--out", str(tmp_path / "out")]
    _refused(capsys, argv, f"{option} straight, curve,straight: 'straight' is given twice")
    assert not any(tmp_path.iterdir())


# 6. Ctrl-C after the study opened: one line, status 130, the trials kept.


def test_ctrl_c_in_the_held_out_check_says_what_was_kept(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    import eval.tuning.holdout

    def interrupt(*_: object, **__: object) -> None:
        raise KeyboardInterrupt

    monkeypatch.setattr(eval.tuning.holdout, "reevaluate", interrupt)
    out = tmp_path / "out"
    assert main(["pn", *SMALL, "--out", str(out)]) == 130
    err = capsys.readouterr().err.splitlines()
    assert err[-1] == (
        f"follow-tune: interrupted; the study pn-person_follow in {out}/study.journal keeps its "
        f"finished trials (this run's held-out check is not in {out}): run the same command "
        "again to resume"
    )
    assert not any("Traceback" in line for line in err)
    assert sorted(p.name for p in out.iterdir()) == ["study.journal"]
    study = open_study(out / "study.journal", "pn-person_follow", SearchConfig(1, (TUNE_SEED0,)))
    assert [t.state.name for t in study.trials] == ["COMPLETE"]


def test_ctrl_c_while_the_study_opens_is_one_line_and_leaves_nothing(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    import eval.tuning.driver

    def interrupt(*_: object, **__: object) -> None:
        raise KeyboardInterrupt

    monkeypatch.setattr(eval.tuning.driver, "open_study", interrupt)
    out = tmp_path / "a" / "out"
    assert main(["pn", *SMALL, "--out", str(out)]) == 130
    err = capsys.readouterr().err.splitlines()
    assert err == [
        f"follow-tune: interrupted while opening the study pn-person_follow in "
        f"{out}/study.journal; no trial ran: run the same command again"
    ]
    assert not any(tmp_path.iterdir())  # the folders it made are gone


def test_ctrl_c_before_the_search_is_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    import eval.tuning.cli

    def interrupt(*_: object, **__: object) -> None:
        raise KeyboardInterrupt

    monkeypatch.setattr(eval.tuning.cli, "_check", interrupt)
    assert main(["pn", "--out", str(tmp_path / "out")]) == 130
    assert capsys.readouterr().err.splitlines() == [
        "follow-tune: interrupted before the search began; nothing was written"
    ]
    assert not any(tmp_path.iterdir())

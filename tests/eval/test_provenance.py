"""eval.provenance: the code revision a run records, and the notes pooling makes of it."""

from __future__ import annotations

import json
import shutil
import subprocess
from pathlib import Path

import pytest

from eval import provenance
from eval.cli import main
from eval.provenance import ROLLOUT_PACKAGES, code_notes, code_revision, code_sha256, sources_sha256

needs_git = pytest.mark.skipif(shutil.which("git") is None, reason="git is not installed")


def _package(root: Path, name: str, files: dict[str, str]) -> Path:
    """A package ``name`` under ``root`` holding ``files`` (relative path -> text)."""
    folder = root / name
    for path, text in {"__init__.py": "", **files}.items():
        (folder / path).parent.mkdir(parents=True, exist_ok=True)
        (folder / path).write_text(text)
    return folder


def _git(root: Path, *args: str) -> str:
    done = subprocess.run(
        ["git", "-C", str(root), "-c", "user.name=t", "-c", "user.email=t@t", *args],
        capture_output=True,
        text=True,
        check=True,
    )
    return done.stdout.strip()


def test_the_digest_follows_every_source_file_and_nothing_else(tmp_path: Path) -> None:
    pkg = _package(tmp_path, "pkg", {"a.py": "x = 1\n", "sub/b.py": "y = 2\n"})
    before = sources_sha256([pkg])
    (pkg / "notes.txt").write_text("not code")
    (pkg / "__pycache__").mkdir()
    (pkg / "__pycache__" / "generated.py").write_text("z = 3\n")  # numba's composed kernels
    assert sources_sha256([pkg]) == before
    (pkg / "sub" / "b.py").write_text("y = 3\n")
    changed = sources_sha256([pkg])
    assert changed != before
    (pkg / "sub" / "b.py").rename(pkg / "sub" / "c.py")  # the same bytes under another name
    assert sources_sha256([pkg]) not in (before, changed)


_CODE = '''"""A module."""

LIMIT = 2.0  # m/s


def speed(v: float) -> float:
    """The speed, bounded."""
    return min(v, LIMIT)
'''


@pytest.mark.parametrize(
    ("edited", "same"),
    [
        (_CODE.replace("# m/s", "# metres a second"), True),  # a comment
        (_CODE.replace("The speed, bounded.", "Bounded speed (m/s)."), True),  # a docstring
        (_CODE.replace('"""A module."""\n', ""), True),  # a docstring removed
        (_CODE.replace("min(v, LIMIT)", "min(\n        v,\n        LIMIT,\n    )"), True),
        (_CODE.replace("2.0", "2.5"), False),  # a constant
        (_CODE.replace("min(v, LIMIT)", "max(v, LIMIT)"), False),  # an operation
        (_CODE.replace("def speed(", "def bounded(").replace("speed, b", "b"), False),  # a name
        (_CODE + "\n\nX = 'A string that is not a docstring.'\n", False),
    ],
    ids=["comment", "docstring", "docstring-removed", "layout", "constant", "call", "name", "str"],
)
def test_the_code_digest_ignores_comments_docstrings_and_layout_only(
    tmp_path: Path, edited: str, same: bool
) -> None:
    pkg = _package(tmp_path, "pkg", {"a.py": _CODE})
    before, sources = code_sha256([pkg]), sources_sha256([pkg])
    (pkg / "a.py").write_text(edited)
    assert (code_sha256([pkg]) == before) is same
    assert sources_sha256([pkg]) != sources  # the sources' digest sees every edit


def test_the_code_digest_follows_files_and_takes_one_that_does_not_parse(tmp_path: Path) -> None:
    pkg = _package(tmp_path, "pkg", {"a.py": _CODE})
    before = code_sha256([pkg])
    (pkg / "a.py").rename(pkg / "b.py")
    assert code_sha256([pkg]) != before
    (pkg / "c.py").write_text("def broken(:\n")
    broken = code_sha256([pkg])
    (pkg / "c.py").write_text("def broken(:  # still broken\n")
    assert code_sha256([pkg]) != broken  # compared as its bytes


def _other_pythons() -> list[str]:
    """Pythons 3.12 and 3.13 that run here: on PATH, or pyenv's (whose shims may not run one)."""
    import os

    pyenv = Path(os.environ.get("PYENV_ROOT") or Path.home() / ".pyenv")
    found = [shutil.which(f"python3.{minor}") for minor in (12, 13)]
    found += [str(p) for p in sorted(pyenv.glob("versions/3.1[23]*/bin/python"))]
    runs = {}
    for python in filter(None, found):
        done = subprocess.run(
            [python, "-c", "import sys; print(sys.version_info[:2])"],
            capture_output=True,
            text=True,
        )
        if done.returncode == 0:
            runs.setdefault(done.stdout.strip(), python)  # one per version
    return list(runs.values())


_OTHER_PYTHONS = _other_pythons()


@pytest.mark.skipif(not _OTHER_PYTHONS, reason="no Python 3.12 or 3.13 on this machine")
def test_the_code_digest_is_the_same_under_every_python_that_parses_alike() -> None:
    """``ast.dump`` writes a tree differently from one Python version to the next (3.12 added
    empty ``type_params``; 3.13 leaves empty fields out): the digest must not follow it, or a
    study moved to another interpreter would be refused as scored by other code."""
    import sys

    source = Path(provenance.__file__)
    run = (
        "import importlib.util, sys; "
        f"spec = importlib.util.spec_from_file_location('p', {str(source)!r}); "
        "m = importlib.util.module_from_spec(spec); spec.loader.exec_module(m); "
        "print(m.code_sha256([m.Path(d) for d in sys.argv[1:]]))"
    )
    dirs = [str(Path(provenance.__file__).parents[1] / p) for p in ROLLOUT_PACKAGES]
    digests = {
        python: subprocess.run(
            [python, "-c", run, *dirs], capture_output=True, text=True, check=True
        ).stdout.strip()
        for python in [sys.executable, *_OTHER_PYTHONS]
    }
    assert len(set(digests.values())) == 1, digests


def test_the_digest_is_of_paths_relative_to_the_packages_folder(tmp_path: Path) -> None:
    here = _package(tmp_path / "one", "pkg", {"a.py": "x = 1\n"})
    there = _package(tmp_path / "two" / "deeper", "pkg", {"a.py": "x = 1\n"})
    assert sources_sha256([here]) == sources_sha256([there])


@needs_git
def test_git_names_the_head_commit_and_whether_the_packages_were_edited(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    _package(tmp_path, "prov_pkg_a", {"m.py": "x = 1\n"})
    (tmp_path / "README").write_text("docs\n")
    _git(tmp_path, "init", "-q")
    _git(tmp_path, "add", ".")
    _git(tmp_path, "commit", "-q", "-m", "first")
    monkeypatch.syspath_prepend(str(tmp_path))
    clean = code_revision(["prov_pkg_a"])
    assert clean["git"] == _git(tmp_path, "rev-parse", "HEAD")
    assert clean["git_dirty"] is False
    (tmp_path / "README").write_text("other docs\n")  # outside the packages: not their edit
    assert code_revision(["prov_pkg_a"])["git_dirty"] is False
    (tmp_path / "prov_pkg_a" / "new.py").write_text("y = 2\n")  # untracked, but it is code
    edited = code_revision(["prov_pkg_a"])
    assert edited["git_dirty"] is True
    assert edited["sources_sha256"] != clean["sources_sha256"]


@needs_git
def test_a_package_that_the_checkout_around_it_does_not_track_has_no_git_revision(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """An installed copy in a venv inside some checkout must not take that checkout's commit."""
    (tmp_path / "README").write_text("docs\n")
    _git(tmp_path, "init", "-q")
    _git(tmp_path, "add", ".")
    _git(tmp_path, "commit", "-q", "-m", "first")
    site = tmp_path / "venv" / "site-packages"
    _package(site, "prov_pkg_b", {"m.py": "x = 1\n"})
    monkeypatch.syspath_prepend(str(site))
    code = code_revision(["prov_pkg_b"])
    assert code == {"sources_sha256": code["sources_sha256"], "git": None, "git_dirty": None}


def test_without_git_the_revision_is_null_and_the_digest_stays(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    _package(tmp_path, "prov_pkg_c", {"m.py": "x = 1\n"})
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setenv("PATH", str(tmp_path / "nowhere"))  # no git executable to be found
    code = code_revision(["prov_pkg_c"])
    assert code["git"] is None
    assert code["git_dirty"] is None
    assert code["sources_sha256"] == sources_sha256([tmp_path / "prov_pkg_c"])


def test_this_projects_revision_covers_the_simulation_the_policies_and_the_evaluation() -> None:
    root = Path(provenance.__file__).resolve().parents[1]
    code = code_revision()
    assert set(ROLLOUT_PACKAGES) == {"follow_env", "policies", "eval"}
    assert code["sources_sha256"] == sources_sha256([root / n for n in ROLLOUT_PACKAGES])


def _meta(digest: str | None, git: str | None = "a" * 40, dirty: bool | None = False) -> dict:
    code = {"sources_sha256": digest, "git": git, "git_dirty": dirty}
    return {"task": "person_follow"} if digest is None else {"code": code}


def test_runs_of_the_same_sources_need_no_note_whatever_their_commits() -> None:
    metas = [_meta("d" * 64, git="a" * 40), _meta("d" * 64, git="b" * 40, dirty=True)]
    assert code_notes(["r1", "r2"], metas) == []


def test_runs_of_different_sources_are_named_with_their_revisions_in_one_note() -> None:
    metas = [_meta("d" * 64), _meta("e" * 64, git="b" * 40, dirty=True), _meta("d" * 64)]
    (note,) = code_notes(["r1", "r2", "r3"], metas)
    assert "different simulator, policy or evaluation code" in note
    assert f"r1 (git {'a' * 12}, sources {'d' * 12})" in note
    assert f"r2 (git {'b' * 12} + uncommitted edits, sources {'e' * 12})" in note
    assert "\n" not in note


def test_a_run_without_a_code_entry_is_noted_as_unknown() -> None:
    (note,) = code_notes(["old", "new"], [_meta(None), _meta("d" * 64)])
    assert note.startswith("old: its code revision is unknown")
    both = code_notes(["r1", "r2"], [_meta(None), {"code": "garbled"}])
    assert len(both) == 1
    assert both[0].startswith("r1, r2: their code revision is unknown")


def test_a_run_records_the_code_it_ran(tmp_path: Path) -> None:
    out = tmp_path / "run"
    grid = ["--policies", "pn", "--scenarios", "straight", "--episodes", "1", "--no-logs"]
    assert main(["run", *grid, "--workers", "1", "--out", str(out)]) == 0
    code = json.loads((out / "meta.json").read_text())["code"]
    assert code == code_revision()

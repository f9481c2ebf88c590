"""train/export.py: an export never deletes or replaces a file it did not write."""

from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path

import pytest

from train.export import MANIFEST, ExportError, check_export, export_agent

AGENT = ("model.zip", "vecnormalize.pkl", "config.yaml", "MODEL_CARD.md", "learning_curve.png")


def fake_run(root: Path, tag: str = "a", *, normalized: bool = True) -> Path:
    """A finished run folder: the agent's files, each holding ``tag`` (contents are not read)."""
    run = root / f"run-{tag}"
    run.mkdir()
    for name in AGENT:
        if normalized or name != "vecnormalize.pkl":
            (run / name).write_text(f"{name} of run {tag}")
    (run / "checkpoints").mkdir()  # run-only files are never exported
    return run


def contents(folder: Path) -> dict[str, str]:
    return {p.name: p.read_text() for p in folder.iterdir()}


def test_a_new_folder_gets_the_agent_and_a_manifest(tmp_path: Path) -> None:
    run = fake_run(tmp_path)
    dest = export_agent(run, tmp_path / "deep" / "agent")
    assert sorted(contents(dest)) == sorted([*AGENT, MANIFEST])
    assert contents(dest)["model.zip"] == "model.zip of run a"
    manifest = json.loads((dest / MANIFEST).read_text())
    assert sorted(manifest["files"]) == sorted(AGENT)
    assert manifest["run"] == str(run.resolve())
    assert not [p for p in dest.parent.iterdir() if p.name.startswith(".")], "no temporary left"


def test_an_existing_folder_with_a_users_file_is_refused_and_left_alone(tmp_path: Path) -> None:
    dest = tmp_path / "agent"
    dest.mkdir()
    (dest / "notes.txt").write_text("mine")
    with pytest.raises(ExportError, match=r"is not empty and holds no export .*--force"):
        export_agent(fake_run(tmp_path), dest)
    assert contents(dest) == {"notes.txt": "mine"}


def test_force_writes_the_agent_beside_the_users_files_and_deletes_none(tmp_path: Path) -> None:
    dest = tmp_path / "agent"
    dest.mkdir()
    (dest / "notes.txt").write_text("mine")
    (dest / "MODEL_CARD.md").write_text("my card")  # named like an agent file: replaced
    export_agent(fake_run(tmp_path), dest, force=True)
    files = contents(dest)
    assert files["notes.txt"] == "mine"
    assert files["MODEL_CARD.md"] == "MODEL_CARD.md of run a"
    assert sorted(files) == sorted([*AGENT, MANIFEST, "notes.txt"])


@pytest.mark.parametrize("force", [False, True])
def test_an_agent_is_not_exported_beside_an_ensemble_file(tmp_path: Path, force: bool) -> None:
    """make_policy(DIR) reads ensemble.yaml first: an agent written beside it (--force) was
    never the policy DIR names, without a word."""
    dest = tmp_path / "agent"
    dest.mkdir()
    (dest / "ensemble.yaml").write_text("members: [seed-0, seed-1]\n")
    with pytest.raises(
        ExportError, match=r"holds ensemble\.yaml.* would still be the old ensemble"
    ):
        export_agent(fake_run(tmp_path), dest, force=force)
    assert contents(dest) == {"ensemble.yaml": "members: [seed-0, seed-1]\n"}


@pytest.mark.parametrize("force", [False, True])
def test_a_regular_file_is_refused_even_with_force(tmp_path: Path, force: bool) -> None:
    dest = tmp_path / "agent"
    dest.write_text("a file of mine")
    with pytest.raises(ExportError, match=r"is a file, not a folder.*never replaces a file"):
        export_agent(fake_run(tmp_path), dest, force=force)
    assert dest.read_text() == "a file of mine"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["agent", "run-a"]  # no .agent.old


def test_a_path_through_a_regular_file_names_that_file(tmp_path: Path) -> None:
    (tmp_path / "afile").write_text("x")
    with pytest.raises(ExportError, match=r"afile is a file, not a folder"):
        check_export(tmp_path / "afile" / "agent")


def test_the_current_folder_is_refused_when_it_is_not_empty(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.chdir(tmp_path)
    (tmp_path / "notes.txt").write_text("mine")
    with pytest.raises(ExportError, match=r"--export \.: the folder is not empty"):
        check_export(Path("."))


def test_the_run_folder_itself_is_refused(tmp_path: Path) -> None:
    run = fake_run(tmp_path)
    with pytest.raises(ExportError, match="is the run folder"):
        check_export(run, force=True, run=run)


def test_a_folder_inside_the_run_folder_is_refused(tmp_path: Path) -> None:
    # The agent's files inside the run's own folder: a run holding a second copy of itself.
    run = fake_run(tmp_path)
    with pytest.raises(ExportError, match=r"--export .*/agent: lies in the run folder"):
        check_export(run / "agent", run=run)


def test_a_folder_that_will_contain_the_run_is_refused_before_either_exists(tmp_path: Path) -> None:
    with pytest.raises(ExportError, match=r"--export .*/agent: would contain the run folder"):
        check_export(tmp_path / "agent", run=tmp_path / "agent" / "run")


def test_an_existing_export_may_hold_the_run_folder(tmp_path: Path) -> None:
    dest = export_agent(fake_run(tmp_path, "a"), tmp_path / "agent")
    check_export(dest, run=dest / "run-b")  # the run lands beside the files, touching none


def test_an_empty_folder_is_written_into(tmp_path: Path) -> None:
    dest = tmp_path / "agent"
    dest.mkdir()
    export_agent(fake_run(tmp_path), dest)
    assert sorted(contents(dest)) == sorted([*AGENT, MANIFEST])


def test_a_re_export_replaces_its_own_files_and_keeps_the_users(tmp_path: Path) -> None:
    dest = export_agent(fake_run(tmp_path, "a"), tmp_path / "agent")
    (dest / "notes.txt").write_text("mine")
    export_agent(fake_run(tmp_path, "b"), dest)
    files = contents(dest)
    assert files["model.zip"] == "model.zip of run b"
    assert files["notes.txt"] == "mine"
    assert json.loads(files[MANIFEST])["run"].endswith("run-b")


def test_a_re_export_removes_a_file_only_its_earlier_export_wrote(tmp_path: Path) -> None:
    dest = export_agent(fake_run(tmp_path, "a"), tmp_path / "agent")
    export_agent(fake_run(tmp_path, "b", normalized=False), dest)
    # run a's statistics would pair with run b's model: the export that wrote them removes them
    assert "vecnormalize.pkl" not in contents(dest)


def test_a_re_export_refuses_over_a_file_changed_since(tmp_path: Path) -> None:
    dest = export_agent(fake_run(tmp_path, "a"), tmp_path / "agent")
    (dest / "MODEL_CARD.md").write_text("my edits")
    with pytest.raises(ExportError, match=r"MODEL_CARD\.md changed since the last export"):
        export_agent(fake_run(tmp_path, "b"), dest)
    assert (dest / "MODEL_CARD.md").read_text() == "my edits"
    assert (dest / "model.zip").read_text() == "model.zip of run a", "nothing was replaced"


def test_a_file_the_manifest_does_not_list_is_not_replaced_without_force(tmp_path: Path) -> None:
    dest = export_agent(fake_run(tmp_path, "a", normalized=False), tmp_path / "agent")
    (dest / "vecnormalize.pkl").write_text("my statistics")
    with pytest.raises(ExportError, match=r"vecnormalize\.pkl changed since .* or was not written"):
        export_agent(fake_run(tmp_path, "b"), dest)
    assert (dest / "vecnormalize.pkl").read_text() == "my statistics"


def test_an_edited_file_is_kept_when_the_new_export_does_not_write_it(tmp_path: Path) -> None:
    dest = export_agent(fake_run(tmp_path, "a"), tmp_path / "agent")
    (dest / "vecnormalize.pkl").write_text("my statistics")
    export_agent(fake_run(tmp_path, "b", normalized=False), dest, force=True)
    assert (dest / "vecnormalize.pkl").read_text() == "my statistics", "not ours any more"


def test_a_manifest_naming_other_files_is_not_trusted(tmp_path: Path) -> None:
    dest = tmp_path / "agent"
    dest.mkdir()
    (dest / "thesis.pdf").write_text("mine")
    files = {"thesis.pdf": ["0" * 64]}
    manifest = {"written_by": "follow-train --export", "files": files}
    (dest / MANIFEST).write_text(json.dumps(manifest))
    with pytest.raises(ExportError, match="holds no export"):
        check_export(dest)


def test_a_half_done_re_export_is_still_recognised(tmp_path: Path) -> None:
    # An export killed between two renames leaves files of either run; its interim manifest
    # lists both contents, so the next export still takes the folder for its own.
    dest = export_agent(fake_run(tmp_path, "a"), tmp_path / "agent")
    manifest = json.loads((dest / MANIFEST).read_text())
    (dest / "model.zip").write_text("model.zip of run b")
    new = hashlib.sha256(b"model.zip of run b").hexdigest()
    manifest["files"]["model.zip"].append(new)
    (dest / MANIFEST).write_text(json.dumps(manifest))
    export_agent(fake_run(tmp_path, "c"), dest)
    assert (dest / "model.zip").read_text() == "model.zip of run c"


def test_a_folder_named_like_an_agent_file_is_refused_even_with_force(tmp_path: Path) -> None:
    dest = tmp_path / "agent"
    (dest / "model.zip").mkdir(parents=True)
    with pytest.raises(ExportError, match=r"model\.zip in it is a folder"):
        check_export(dest, force=True)


@pytest.mark.skipif(os.geteuid() == 0, reason="root can write into read-only folders")
def test_an_unwritable_parent_is_refused(tmp_path: Path) -> None:
    locked = tmp_path / "locked"
    locked.mkdir(mode=0o500)
    with pytest.raises(ExportError, match="permission denied"):
        check_export(locked / "agent")


@pytest.mark.skipif(not Path("/proc/self").is_dir(), reason="needs Linux's /proc")
def test_a_folder_that_takes_no_file_is_refused() -> None:
    # /proc refuses new files even to root, for whom a read-only folder is writable
    with pytest.raises(ExportError, match="cannot write to /proc"):
        check_export(Path("/proc/personfollow-test/agent"))


def test_a_missing_agent_file_in_the_run_writes_nothing(tmp_path: Path) -> None:
    run = fake_run(tmp_path)
    (run / "MODEL_CARD.md").unlink()
    with pytest.raises(FileNotFoundError, match=r"MODEL_CARD\.md: missing"):
        export_agent(run, tmp_path / "agent")
    assert not (tmp_path / "agent").exists()

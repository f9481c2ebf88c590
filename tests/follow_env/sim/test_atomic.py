"""follow_env/sim/atomic.py: files and folders appear whole or not at all."""

import errno
import os
import re
import stat
from pathlib import Path

import pytest

from follow_env.sim.atomic import (
    atomic_folder,
    atomic_path,
    atomic_write_text,
    file_on_path,
    longest_name,
    try_new_file,
)


def test_atomic_path_renames_into_place(tmp_path: Path) -> None:
    with atomic_path(tmp_path / "a.txt") as tmp:
        tmp.write_text("hello")
        assert not (tmp_path / "a.txt").exists()
    assert (tmp_path / "a.txt").read_text() == "hello"
    assert [p.name for p in tmp_path.iterdir()] == ["a.txt"]


def test_atomic_path_leaves_nothing_on_failure(tmp_path: Path) -> None:
    def write_half(tmp: Path) -> None:
        tmp.write_text("half")
        raise RuntimeError("writer failed")

    with pytest.raises(RuntimeError), atomic_path(tmp_path / "a.txt") as tmp:
        write_half(tmp)
    assert list(tmp_path.iterdir()) == []


def test_atomic_path_keeps_the_suffix_for_format_sniffing_writers(tmp_path: Path) -> None:
    with atomic_path(tmp_path / "v.mp4") as tmp:
        assert tmp.suffix == ".mp4"


def test_a_fifo_or_a_device_is_never_replaced(tmp_path: Path) -> None:
    # os.replace would put a regular file in its place (/dev/null, for root)
    fifo = tmp_path / "log.csv"
    os.mkfifo(fifo)
    with pytest.raises(OSError, match="is not a regular file"):
        atomic_write_text(fifo, "x")
    assert stat.S_ISFIFO(os.stat(fifo).st_mode)
    assert [p.name for p in tmp_path.iterdir()] == ["log.csv"]  # no temporary file left
    (tmp_path / "link.csv").symlink_to(fifo)  # a link is replaced, not what it points to
    atomic_write_text(tmp_path / "link.csv", "x")
    assert (tmp_path / "link.csv").read_text() == "x"
    assert stat.S_ISFIFO(os.stat(fifo).st_mode)


@pytest.mark.parametrize("name_bytes", [250, 255])
def test_a_name_as_long_as_the_file_system_takes_gets_a_temporary_name(
    tmp_path: Path, name_bytes: int
) -> None:
    target = tmp_path / ("x" * (name_bytes - 4) + ".csv")
    assert longest_name(target) == name_bytes
    try_new_file(tmp_path, longest_name(target))
    atomic_write_text(target, "x")  # its temporary file's name is shorter
    assert [p.name for p in tmp_path.iterdir()] == [target.name]


@pytest.mark.parametrize(
    "name",
    [
        "a." + "b" * 240,  # 242 bytes, nearly all suffix
        "a." + "b" * 253,  # 255 bytes: the longest a name can be
        "a." + "\u00e9" * 126,  # 254 bytes, two for each of the suffix's characters
    ],
)
def test_a_name_with_a_long_suffix_the_file_system_takes_is_written_atomically(
    tmp_path: Path, name: str
) -> None:
    # the temporary name keeps no suffix longer than any format's, so it is never the longer
    target = tmp_path / name
    assert len(os.fsencode(name)) <= 255
    assert longest_name(target) == len(os.fsencode(name))
    try_new_file(tmp_path, longest_name(target))
    atomic_write_text(target, "x")
    assert [p.name for p in tmp_path.iterdir()] == [name]
    assert target.read_text() == "x"


def test_try_new_file_tries_a_name_of_the_length_asked(tmp_path: Path) -> None:
    try_new_file(tmp_path, 255)
    with pytest.raises(OSError, match="too long") as caught:
        try_new_file(tmp_path, 256)  # over the 255 bytes of ext4, tmpfs, xfs, btrfs, overlayfs
    assert caught.value.errno == errno.ENAMETOOLONG
    assert list(tmp_path.iterdir()) == []
    short = tmp_path / "a.csv"
    assert longest_name(short) > len("a.csv")  # the temporary name is the longer here


def test_atomic_write_into_missing_folder_names_it(tmp_path: Path) -> None:
    with pytest.raises(OSError, match=r"cannot write to .*missing"):
        atomic_write_text(tmp_path / "missing" / "a.txt", "x")


def test_atomic_folder_appears_only_when_complete(tmp_path: Path) -> None:
    with atomic_folder(tmp_path / "run") as tmp:
        (tmp / "a.csv").write_text("x")
        assert not (tmp_path / "run").exists()
    assert (tmp_path / "run" / "a.csv").read_text() == "x"


def test_atomic_folder_is_removed_on_failure(tmp_path: Path) -> None:
    def write_and_stop(tmp: Path) -> None:
        (tmp / "a.csv").write_text("x")
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt), atomic_folder(tmp_path / "run") as tmp:
        write_and_stop(tmp)
    assert list(tmp_path.iterdir()) == []


def test_atomic_folder_fills_an_empty_folder(tmp_path: Path) -> None:
    (tmp_path / "run").mkdir()
    with atomic_folder(tmp_path / "run") as tmp:
        (tmp / "a.csv").write_text("x")
    assert (tmp_path / "run" / "a.csv").exists()


def test_atomic_folder_never_overwrites_a_previous_run(tmp_path: Path) -> None:
    (tmp_path / "run").mkdir()
    (tmp_path / "run" / "old.csv").write_text("keep")
    with pytest.raises(FileExistsError, match="already exists and is not an empty folder"):
        atomic_folder(tmp_path / "run").__enter__()
    assert (tmp_path / "run" / "old.csv").read_text() == "keep"


@pytest.mark.parametrize("below", ["run", "sub/run"])
def test_folder_below_a_regular_file_names_that_file(tmp_path: Path, below: str) -> None:
    (tmp_path / "afile").write_text("x")
    target = tmp_path / "afile" / below
    message = re.escape(f"{tmp_path / 'afile'} is a file, not a folder")
    with pytest.raises(NotADirectoryError, match=message), atomic_folder(target):
        pass
    assert (tmp_path / "afile").read_text() == "x"


def test_file_on_path_is_none_where_a_folder_can_be_made(tmp_path: Path) -> None:
    assert file_on_path(tmp_path / "new" / "deeper") is None
    (tmp_path / "f").write_text("x")
    assert file_on_path(tmp_path / "f") == tmp_path / "f"
    assert file_on_path(tmp_path / "f" / "a" / "b") == tmp_path / "f"


def test_a_folder_named_as_long_as_the_file_system_takes_is_made_atomically(tmp_path: Path) -> None:
    from follow_env.sim.atomic import atomic_folder, longest_name

    target = tmp_path / ("d" * 255)
    assert longest_name(target) <= 255
    with atomic_folder(target) as tmp:
        (tmp / "a.txt").write_text("x")
    assert (target / "a.txt").read_text() == "x"
    assert sorted(p.name for p in tmp_path.iterdir()) == [target.name]


# -- durability: the data reaches the disk before the name does --------------------------------


def _record_syncs(monkeypatch: pytest.MonkeyPatch) -> list[tuple[str, str]]:
    """Record, in order, every fsync (of what path) and every rename (to what path)."""
    import follow_env.sim.atomic as atomic

    events: list[tuple[str, str]] = []
    real_fsync, real_replace = os.fsync, os.replace

    def fsync(fd: int) -> None:
        events.append(("fsync", os.readlink(f"/proc/self/fd/{fd}")))
        real_fsync(fd)

    def replace(src: os.PathLike[str], dst: os.PathLike[str]) -> None:
        events.append(("replace", str(dst)))
        real_replace(src, dst)

    monkeypatch.setattr(atomic.os, "fsync", fsync)
    monkeypatch.setattr(atomic.os, "replace", replace)
    return events


@pytest.mark.skipif(not Path("/proc/self/fd").is_dir(), reason="names fds through /proc")
def test_a_file_is_flushed_before_its_rename_and_its_folder_after(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    events = _record_syncs(monkeypatch)
    target = tmp_path / "table.csv"
    atomic_write_text(target, "a,b\n1,2\n")
    at = events.index(("replace", str(target)))
    [synced_before] = [Path(p) for k, p in events[:at] if k == "fsync"]
    assert synced_before.parent == tmp_path  # the temporary file, not yet renamed
    assert synced_before.name.startswith(".table.")
    assert ("fsync", str(tmp_path)) in events[at:]  # the rename, in its folder
    assert target.read_text() == "a,b\n1,2\n"


@pytest.mark.skipif(not Path("/proc/self/fd").is_dir(), reason="names fds through /proc")
def test_a_folders_files_are_flushed_before_its_rename_however_written(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    events = _record_syncs(monkeypatch)
    with atomic_folder(tmp_path / "run") as tmp:
        (tmp / "logs").mkdir()
        (tmp / "logs" / "seed_0.csv").write_text("t\n0\n")  # written directly, not atomically
    at = events.index(("replace", str(tmp_path / "run")))
    before = {Path(p).relative_to(tmp).as_posix() for k, p in events[:at] if k == "fsync"}
    assert before == {"logs/seed_0.csv", "logs", "."}
    assert ("fsync", str(tmp_path)) in events[at:]


def test_a_file_system_that_cannot_fsync_is_let_be_and_a_write_error_is_not(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    import follow_env.sim.atomic as atomic

    def refuse(fd: int) -> None:
        raise OSError(errno.EINVAL, "Invalid argument")

    monkeypatch.setattr(atomic.os, "fsync", refuse)
    assert atomic_write_text(tmp_path / "a.txt", "x").read_text() == "x"

    def fail(fd: int) -> None:
        raise OSError(errno.EIO, "Input/output error")

    monkeypatch.setattr(atomic.os, "fsync", fail)
    with pytest.raises(OSError, match="Input/output"):
        atomic_write_text(tmp_path / "b.txt", "x")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.txt"]  # no b.txt, no temp file

"""Atomic writes: a file or a folder appears whole, or not at all.

Every file the project writes (the evaluation's tables, plots and videos, training's runs and
exports, the robot's step log, the composed kernels) goes to a temporary name beside its target
and is renamed into place when complete (``os.replace`` is atomic on one file system), so an
interrupted run never leaves a half-written file that a later reader would trust. It sits at
the bottom layer, with no import of its own, so that every layer and leaf can use the one
implementation (the robot's side may not import the evaluation).
"""

from __future__ import annotations

import contextlib
import os
import shutil
import tempfile
from collections.abc import Iterator
from pathlib import Path

__all__ = [
    "atomic_folder",
    "atomic_path",
    "atomic_write_text",
    "check_new_folder",
    "check_writable",
    "file_on_path",
    "try_new_file",
]


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


@contextlib.contextmanager
def atomic_path(path: str | Path) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; rename it to ``path`` if the block succeeds.

    The temporary name keeps the target's suffix (writers such as ``cv2.VideoWriter`` and
    ``savefig`` pick the format from it). On an exception the temporary file is removed.

    :raises OSError: if the folder is not writable (the message names it).
    """
    path = Path(path)
    try:
        fd, tmp_name = tempfile.mkstemp(
            prefix=f".{path.stem}.", suffix=f".tmp{path.suffix}", dir=path.parent
        )
    except OSError as e:
        raise OSError(f"cannot write to {path.parent}: {e.strerror or e}") from None
    os.close(fd)
    tmp = Path(tmp_name)
    os.chmod(tmp, 0o666 & ~_umask())  # mkstemp makes 0600; give the file the usual mode
    try:
        yield tmp
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def atomic_write_text(path: str | Path, text: str) -> Path:
    """Write ``text`` (UTF-8) to ``path`` atomically; returns the path."""
    path = Path(path)
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")
    return path


def file_on_path(path: str | Path) -> Path | None:
    """The first existing entry on ``path`` that is not a folder (``path`` itself or one of its
    parents), or None when a folder could be made at ``path``.

    ``Path.mkdir`` below a regular file fails with an error that names the deepest missing
    folder, not the file in the way; this names the file.
    """
    path = Path(path)
    for candidate in (path, *path.parents):
        if candidate.exists() or candidate.is_symlink():
            return None if candidate.is_dir() else candidate
    return None


def check_new_folder(path: str | Path) -> None:
    """Check that ``path`` can become a new folder: it does not exist or is an empty folder,
    no parent of it is a regular file, and its nearest existing parent takes a new file.

    :raises FileExistsError: if ``path`` exists and is not an empty folder.
    :raises NotADirectoryError: if a parent of ``path`` is a regular file (the message names it).
    :raises OSError: if the folder it would be made in takes no file (the message names it).
    """
    path = Path(path)
    blocker = file_on_path(path)
    if blocker is not None and blocker != path:
        raise NotADirectoryError(f"cannot write to {path}: {blocker} is a file, not a folder")
    if path.exists() and not (path.is_dir() and not any(path.iterdir())):
        raise FileExistsError(
            f"{path} already exists and is not an empty folder; choose another output folder"
        )
    check_writable(path)


def check_writable(path: str | Path) -> None:
    """Check that ``path`` could be written: the nearest existing folder on it takes a new file.

    Tried with a real file (made and removed at once), not ``os.access``: a root shell passes
    every permission check, and file systems such as ``/proc`` refuse new files to anyone.
    Called before long work starts, so that a run is not lost to a folder it cannot write.

    :raises NotADirectoryError: if a parent of ``path`` is a regular file (the message names it).
    :raises OSError: if the folder takes no new file (the message names it and says why).
    """
    path = Path(path).absolute()
    blocker = file_on_path(path.parent)
    if blocker is not None:
        raise NotADirectoryError(f"cannot write to {path}: {blocker} is a file, not a folder")
    folder = next(p for p in path.parents if p.exists())
    try:
        try_new_file(folder)
    except OSError as e:
        raise OSError(f"cannot write to {folder}: {e.strerror or e}") from None


def try_new_file(folder: str | Path) -> None:
    """Make a file in ``folder`` and remove it at once: the one test of whether a folder takes
    new files (permissions, read-only mounts, ``/proc``, ACLs), since ``os.access`` passes for
    root. Callers put the failure in their own words.

    :raises OSError: as the file system refused the file (``strerror`` says why).
    """
    fd, name = tempfile.mkstemp(prefix=".write-check.", dir=folder)
    os.close(fd)
    os.unlink(name)


@contextlib.contextmanager
def atomic_folder(path: str | Path) -> Iterator[Path]:
    """Yield a temporary folder beside ``path``; rename it to ``path`` if the block succeeds.

    ``path`` must not exist, or be an empty folder (a run folder is never overwritten).
    On an exception the temporary folder and everything in it is removed.

    :raises FileExistsError: if ``path`` exists and is not an empty folder.
    :raises NotADirectoryError: if a parent of ``path`` is a regular file (the message names it).
    :raises OSError: if the parent folder cannot be created or written (the message names it).
    """
    path = Path(path)
    check_new_folder(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = Path(tempfile.mkdtemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent))
        os.chmod(tmp, 0o777 & ~_umask())  # mkdtemp makes 0700; give the folder the usual mode
    except OSError as e:
        raise OSError(f"cannot write to {path.parent}: {e.strerror or e}") from None
    try:
        yield tmp
        os.replace(tmp, path)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise

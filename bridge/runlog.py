"""The runner's step log on disk: where it may go (checked before a session starts) and how it
is written (a temporary file renamed into place, or, if that fails at the end, a copy saved
elsewhere, so that a session's data is never lost to a bad path).
"""

from __future__ import annotations

import csv
import errno
import os
import stat
import tempfile
import time
from pathlib import Path
from typing import Any

from follow_env.sim.atomic import atomic_path, longest_name, try_new_file
from follow_env.tasks.person_follow.steplog import log_columns

__all__ = ["LOG_COLUMNS", "check_log_path", "save_rows", "write_rows"]

LOG_COLUMNS = log_columns(ahead=True)
"""The robot's step log: the simulator's columns and the reading ahead's place, in order."""


def check_log_path(path: str | Path) -> Path:
    """``path`` as a :class:`~pathlib.Path` if a step log can be written there: not a folder
    nor any other file that is not a regular one (a device, a FIFO: the log would replace it),
    in an existing folder where this process can create a file of the log's name's length.

    :raises ValueError: ``--log PATH: ...`` saying what is wrong, in one line.
    """
    if not str(path).strip():
        raise ValueError("--log '': empty; give a file name, such as run.csv")
    path = Path(path)
    parent = path.parent
    try:
        mode: int | None = os.stat(path).st_mode
    except OSError:  # absent (or a name too long, which creating a file below tells)
        mode = None
    if mode is not None and stat.S_ISDIR(mode):
        raise ValueError(f"--log {path}: is a folder; give a file name, such as {path / 'run.csv'}")
    if mode is not None and not stat.S_ISREG(mode):
        raise ValueError(
            f"--log {path}: is not a regular file (a device, a FIFO or a socket, which a log "
            "must not replace); give a file name, such as run.csv"
        )
    if not parent.exists():
        raise ValueError(f"--log {path}: the folder {parent} does not exist")
    if not parent.is_dir():
        raise ValueError(f"--log {path}: {parent} is not a folder")
    # Only creating a file tells: the log is written exactly so, a temporary file beside it
    # renamed into place. The file tried has the longer of the two names' lengths, which the
    # folder's file system might refuse (255 bytes on most).
    length = longest_name(path)
    try:
        try_new_file(parent, length)
    except OSError as exc:
        why = exc.strerror or str(exc)
        if exc.errno == errno.ENAMETOOLONG:
            why += f": the log's name, or its temporary file's, takes {length} bytes"
        raise ValueError(
            f"--log {path}: cannot create a file in the folder {parent} ({why})"
        ) from None
    return path


def write_rows(rows: list[dict[str, Any]], path: Path, errors: str = "strict") -> Path:
    """Write step-log rows (the columns they use, in the layout's order) atomically.

    :param errors: how text that is not UTF-8 is written (:func:`open`'s ``errors``): refused
        by default (``UnicodeEncodeError``), so that a log is never altered without a word.
    """
    used = {k for row in rows for k, v in row.items() if v is not None}
    header = [c for c in LOG_COLUMNS if c in used]
    with atomic_path(path) as tmp, tmp.open("w", newline="", encoding="utf-8", errors=errors) as f:
        writer = csv.writer(f, lineterminator="\n")
        writer.writerow(header)
        for row in rows:
            writer.writerow(["" if row.get(c) is None else _cell(row[c]) for c in header])
    return path


def save_rows(rows: list[dict[str, Any]], path: Path) -> tuple[Path | None, str]:
    """Write the rows to ``path``; if that fails, whatever the reason (the folder went away
    during the session, the disk filled up, a value is not UTF-8 text), to a file of its own in
    the system's temporary folder instead, where text that is not UTF-8 is written as
    backslash escapes (``\\udcff``) rather than lose the rows. Never raises: it runs at the end
    of a session, whose summary must still be said.

    :returns: ``(where the log is, "")``, or ``(the fallback file, why path failed)``, or
        ``(None, why both failed)``: the reason is one line naming ``--log`` and the path.
    """
    try:
        return write_rows(rows, path), ""
    except Exception as exc:  # any: the rows go to the spare file whatever stopped them here
        why = f"--log {path}: the step log could not be written ({_why(exc)})"
    stamp = time.strftime("%Y%m%d-%H%M%S")
    spare: Path | None = None
    try:
        fd, name = tempfile.mkstemp(prefix=f"follow-robot-{stamp}-", suffix=".csv")
        os.close(fd)  # a name of our own; write_rows renames its own temporary file onto it
        spare = Path(name)
        saved = write_rows(rows, spare, errors="backslashreplace")
        return saved, f"{why}; saved to {spare} instead"
    except Exception as exc:  # any: said in the one line, not a traceback that hides the summary
        if spare is not None:
            spare.unlink(missing_ok=True)  # no empty file left for a log that is not there
        return None, f"{why}, nor in {tempfile.gettempdir()} ({_why(exc)}): lost"


def _why(exc: Exception) -> str:
    """What went wrong, in a few words: an OS error's own, or the exception's type and text."""
    if isinstance(exc, OSError):
        return str(exc.strerror or exc)
    if isinstance(exc, UnicodeEncodeError):  # its position is in a buffer, of no use to anyone
        bad = exc.object[exc.start : exc.end].encode("utf-8", "backslashreplace").decode()
        return f"a value holds {bad}, which is not UTF-8 text"
    return f"{type(exc).__name__}: {exc}"


def _cell(value: Any) -> str:
    if isinstance(value, float):
        return f"{value:.9g}"
    return str(value)

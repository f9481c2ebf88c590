"""The runner's step log on disk: where it may go (checked before a session starts) and how it
is written (a temporary file renamed into place, or, if that fails at the end, a copy saved
elsewhere, so that a session's data is never lost to a bad path).

With the monitor, what drives may change mid-session (a mode chosen in the browser, manual,
stop), and no step is credited to a policy that did not drive it (:func:`label_rows`): the
``policy`` column, which ``follow-eval metrics`` reads as the session's label (from the first
row), names the one policy only when it drove every step, else ``mixed:`` and every name that
drove, in the order they first did (``mixed:gsmpn:tuned,manual,stop``); the robot's own
``driver`` column (:data:`DRIVER_COLUMN`) says which of those names drove each step.
"""

from __future__ import annotations

import contextlib
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

__all__ = [
    "DRIVER_COLUMN",
    "LOG_COLUMNS",
    "check_log_path",
    "label_rows",
    "save_rows",
    "spare_folder",
    "write_rows",
]

DRIVER_COLUMN = "driver"
"""Which name of the ``policy`` column drove the step: 0 for its first (the only one when one
policy drove the whole session), 1 for the next, ... A number, so that every reader of step
logs (``follow-eval metrics``) reads it as any other column it does not score."""
_SIM_COLUMNS = log_columns(ahead=True)
LOG_COLUMNS = (*_SIM_COLUMNS[:3], DRIVER_COLUMN, *_SIM_COLUMNS[3:])
"""The robot's step log: the simulator's columns (the reading ahead's place too) and
:data:`DRIVER_COLUMN` after the policy, scenario and seed, in order."""


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


def label_rows(rows: list[dict[str, Any]], drivers: list[str], named: bool = True) -> None:
    """Set every row's ``policy`` to the label of what drove the session (module docstring).

    :param rows: the rows, each with its :data:`DRIVER_COLUMN`: an index into ``drivers``.
    :param drivers: the names of what drove (a policy, a mode, ``manual``, ``stop``), in the
        order each first drove.
    :param named: the rows already name the policy (the label then replaces it); if not, a
        session one policy drove gets no label, as before.
    """
    if len(drivers) > 1:
        label = "mixed:" + ",".join(drivers)
    elif drivers and named:
        label = drivers[0]
    else:
        return
    for row in rows:
        row["policy"] = label


def spare_folder() -> Path | None:
    """The folder :func:`save_rows` saves a log it could not write where asked: the system's
    temporary folder, found now (finding it creates a file, which a process out of file
    descriptors cannot: decide it before the session); ``None`` if there is none usable."""
    try:
        return Path(tempfile.gettempdir())
    except Exception:  # any: no folder, said by save_rows, is no reason to stop a session
        return None


def save_rows(
    rows: list[dict[str, Any]], path: Path, spare: Path | None = None
) -> tuple[Path | None, str]:
    """Write the rows to ``path``; if that fails, whatever the reason (the folder went away
    during the session, the disk filled up, a value is not UTF-8 text), to a file of its own in
    the ``spare`` folder instead, where text that is not UTF-8 is written as backslash escapes
    (``\\udcff``) rather than lose the rows. Never raises: it runs at the end of a session,
    whose summary must still be said.

    :param spare: the spare file's folder, decided before the session (:func:`spare_folder`);
        ``None``: found now, which fails in a process out of file descriptors.
    :returns: ``(where the log is, "")``, or ``(the fallback file, why path failed)``, or
        ``(None, why both failed)``: the reason is one line naming ``--log`` and the path.
    """
    try:
        return write_rows(rows, path), ""
    except Exception as exc:  # any: the rows go to the spare file whatever stopped them here
        why = f"--log {path}: the step log could not be written ({_why(exc)})"
    folder = spare if spare is not None else spare_folder()
    if folder is None:
        return None, f"{why}, nor could a temporary folder be found to save it in: lost"
    stamp = time.strftime("%Y%m%d-%H%M%S")
    saved: Path | None = None
    try:
        fd, name = tempfile.mkstemp(prefix=f"follow-robot-{stamp}-", suffix=".csv", dir=folder)
        os.close(fd)  # a name of our own; write_rows renames its own temporary file onto it
        saved = Path(name)
        return write_rows(
            rows, saved, errors="backslashreplace"
        ), f"{why}; saved to {saved} instead"
    except Exception as exc:  # any: said in the one line, not a traceback that hides the summary
        if saved is not None:
            with contextlib.suppress(OSError):  # no empty file left for a log that is not there
                saved.unlink(missing_ok=True)
        return None, f"{why}, nor in {folder} ({_why(exc)}): lost"


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

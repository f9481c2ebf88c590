"""Step logs: one CSV per episode, one row per control step, in a layout a real robot can write.

The reference robot logged its camera and encoder data to CSV every 0.1 s (reference §1.6). A step
log here is that file, extended with the simulation's ground truth. Only the first columns are
needed to compute the thesis metrics, so a log recorded on the real robot (time, observation,
encoder speeds) is read and scored by the same code as a simulated one; every other column is
optional and the metrics that need it give NaN without it.

The columns, their units and their order are the task's
(:mod:`follow_env.tasks.person_follow.steplog`, :mod:`follow_env.tasks.line_trace.steplog`);
this module reads, validates and writes them (:data:`LAYOUTS`: what each task's log needs).
"""

from __future__ import annotations

import csv
import math
import re
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from follow_env.sim.atomic import atomic_path
from follow_env.tasks.line_trace import steplog as line_steplog
from follow_env.tasks.person_follow.steplog import (
    ACCEL_SOURCES,
    ACTION_COLUMNS,
    COLUMNS,
    META_COLUMNS,
    REQUIRED_COLUMNS,
    TEXT_COLUMNS,
    WHEEL_COLUMNS,
    log_columns,
)

__all__ = [
    "ACTION_COLUMNS",
    "COLUMNS",
    "LAYOUTS",
    "META_COLUMNS",
    "REQUIRED_COLUMNS",
    "TEXT_COLUMNS",
    "WHEEL_COLUMNS",
    "LogLayout",
    "StepLogError",
    "accel_from_speed",
    "log_columns",
    "read_step_log",
    "step_log_files",
    "validate_step_log",
    "write_step_log",
]

_ACCEL_SOURCES = ACCEL_SOURCES
# Enough digits that float32 observations and float64 ground truth survive the round trip to
# 1e-9 relative, at a third of the size of full repr precision.
FLOAT_FORMAT = "%.9g"


class StepLogError(ValueError):
    """A step log file is missing, unreadable or malformed; the message names file and row."""


@dataclass(frozen=True)
class LogLayout:
    """What a task's step log must hold.

    :param required: columns every log has, with a value in every row.
    :param text: columns holding text (every other one is numeric).
    :param accel: whether a log needs ``accel_mps2`` or ``encoder_speed_mps`` (the thesis's
        acceleration metrics; derived from the speed when only that is logged).
    """

    required: tuple[str, ...]
    text: frozenset[str]
    accel: bool


LAYOUTS: dict[str, LogLayout] = {
    "person_follow": LogLayout(REQUIRED_COLUMNS, TEXT_COLUMNS, True),
    "line_trace": LogLayout(line_steplog.REQUIRED_COLUMNS, line_steplog.TEXT_COLUMNS, False),
}
"""Each task's step-log layout, by task name."""


def write_step_log(log: pd.DataFrame, path: str | Path) -> Path:
    """Write ``log`` as CSV atomically (a temporary file renamed into place).

    :param log: a step log (columns as in :data:`COLUMNS`, any subset in any order is written
        as given).
    :param path: the target file; its folder must exist.
    :returns: the path written.
    """
    path = Path(path)
    with atomic_path(path) as tmp:
        log.to_csv(tmp, index=False, float_format=FLOAT_FORMAT, lineterminator="\n")
    return path


def read_step_log(path: str | Path, task: str = "person_follow") -> pd.DataFrame:
    """Read and validate a step log of ``task`` (its :data:`LAYOUTS` entry).

    Cells may be empty (not recorded) except in the required columns. Text columns come back
    as strings (empty string when blank), every other column as float64.

    :raises StepLogError: naming the file, and the line and column for a malformed row: a
        missing file, no header, a missing required column, a row with the wrong number of
        fields, a cell that is not a number (``nan`` included) or is infinite, a
        non-increasing ``time_s``.
    """
    path = Path(path)
    try:
        with path.open(newline="", encoding="utf-8") as f:
            rows = list(csv.reader(f))
    except FileNotFoundError:
        raise StepLogError(f"{path}: no such file") from None
    except IsADirectoryError:
        raise StepLogError(f"{path}: is a folder, not a step log CSV") from None
    except UnicodeDecodeError as e:
        raise StepLogError(f"{path}: not a text CSV file ({e.reason} at byte {e.start})") from None
    except OSError as e:
        raise StepLogError(f"{path}: cannot read: {e.strerror or e}") from None
    except csv.Error as e:
        raise StepLogError(f"{path}: not a valid CSV file: {e}") from None
    if not rows or not any(cell.strip() for cell in rows[0]):
        raise StepLogError(f"{path}: empty file; expected a header line with the columns")
    header = [cell.strip() for cell in rows[0]]
    return _to_frame(path, header, rows[1:], LAYOUTS[task])


def _to_frame(
    path: Path, header: list[str], rows: list[list[str]], layout: LogLayout
) -> pd.DataFrame:
    dupes = sorted({c for c in header if header.count(c) > 1})
    if dupes:
        raise StepLogError(f"{path}: duplicate column(s) {', '.join(dupes)} in the header")
    missing = [c for c in layout.required if c not in header]
    if layout.accel and not any(c in header for c in _ACCEL_SOURCES):
        missing.append(" or ".join(_ACCEL_SOURCES))
    if missing:
        needs = ", ".join(layout.required)
        if layout.accel:
            needs += " and accel_mps2 or encoder_speed_mps"
        raise StepLogError(
            f"{path}: missing column(s) {', '.join(missing)}; a step log needs {needs}"
        )
    # Skip blank lines (a trailing newline at the end of a hand-written file).
    numbered = [(i + 2, r) for i, r in enumerate(rows) if any(cell.strip() for cell in r)]
    if not numbered:
        raise StepLogError(f"{path}: no data rows after the header")
    for line, row in numbered:
        if len(row) != len(header):
            raise StepLogError(
                f"{path}: line {line}: expected {len(header)} fields as in the header, "
                f"found {len(row)}"
            )
    lines = [line for line, _ in numbered]
    data = {name: [row[j].strip() for _, row in numbered] for j, name in enumerate(header) if name}
    frame = pd.DataFrame(index=pd.RangeIndex(len(numbered)))
    for name, cells in data.items():
        if name in layout.text:
            frame[name] = cells
            continue
        values = pd.to_numeric(pd.Series(cells).replace("", np.nan), errors="coerce")
        bad = values.isna() & (pd.Series(cells) != "")
        if bad.any():
            k = int(np.flatnonzero(bad.to_numpy())[0])
            raise StepLogError(
                f"{path}: line {lines[k]}, column {name}: {cells[k]!r} is not a number"
            )
        # "inf" parses as a number, but every metric drops non-finite values, so a logging
        # fault would vanish from the scores instead of being reported like "nan" is.
        infinite = np.isinf(values.to_numpy(dtype=np.float64))
        if infinite.any():
            k = int(np.flatnonzero(infinite)[0])
            raise StepLogError(
                f"{path}: line {lines[k]}, column {name}: {cells[k]!r} is not a finite number"
            )
        if name in layout.required and values.isna().any():
            k = int(np.flatnonzero(values.isna().to_numpy())[0])
            raise StepLogError(f"{path}: line {lines[k]}, column {name}: value is missing")
        frame[name] = values.astype(np.float64)
    validate_step_log(frame, path, lines)
    if "accel_mps2" not in frame and "encoder_speed_mps" in frame:
        frame["accel_mps2"] = accel_from_speed(frame["time_s"], frame["encoder_speed_mps"])
    return frame


def validate_step_log(
    log: pd.DataFrame, path: str | Path = "<log>", lines: Iterable[int] | None = None
) -> None:
    """Check the invariants every step log keeps: finite, strictly increasing ``time_s``.

    :param log: the step log.
    :param path: the file name used in messages.
    :param lines: file line numbers of the rows (default: row index + 2, after a header).
    :raises StepLogError: naming the first offending line.
    """
    t = log["time_s"].to_numpy(dtype=np.float64)
    line_of = list(lines) if lines is not None else [k + 2 for k in range(len(t))]
    for k, value in enumerate(t):
        if not math.isfinite(value):
            raise StepLogError(f"{path}: line {line_of[k]}, column time_s: {value} is not finite")
        if k > 0 and value <= t[k - 1]:
            raise StepLogError(
                f"{path}: line {line_of[k]}, column time_s: {value:g} s is not after the "
                f"previous row's {t[k - 1]:g} s"
            )


def accel_from_speed(time_s: pd.Series, speed_mps: pd.Series) -> pd.Series:
    """Acceleration as the robot computes it: speed difference over the time between rows.

    The first row has no predecessor and gets 0 (the robot starts at rest, reference §1.6).

    :param time_s: sample times [s].
    :param speed_mps: encoder speed [m/s].
    :returns: acceleration [m/s²].
    """
    accel = speed_mps.diff() / time_s.diff()
    return accel.fillna(0.0) if len(accel) else accel


def _natural_key(path: Path) -> list[str | int]:
    """Sort key that compares runs of digits as numbers: ``seed_2`` before ``seed_10``."""
    # re.split with a group alternates text and digits, so equal positions hold equal types.
    parts = re.split(r"(\d+)", path.as_posix())
    return [int(part) if k % 2 else part for k, part in enumerate(parts)]


def step_log_files(paths: Iterable[str | Path]) -> list[Path]:
    """Expand folders into the ``*.csv`` files below them; keep files as given.

    Files found in a folder are sorted with numbers compared as numbers (``seed_2.csv``
    before ``seed_10.csv``), the order ``follow-eval run`` wrote them in.
    """
    out: list[Path] = []
    for p in map(Path, paths):
        out.extend(sorted(p.rglob("*.csv"), key=_natural_key) if p.is_dir() else [p])
    return out

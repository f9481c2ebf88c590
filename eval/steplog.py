"""Step logs: one CSV per episode, one row per control step, in a layout a real robot can write.

The reference robot logged its camera and encoder data to CSV every 0.1 s (reference §1.6). A step
log here is that file, extended with the simulation's ground truth. Only the first columns are
needed to compute the thesis metrics, so a log recorded on the real robot (time, observation,
encoder speeds) is read and scored by the same code as a simulated one; every other column is
optional and the metrics that need it give NaN without it.

The columns, their units and their order are the task's
(:mod:`follow_env.tasks.person_follow.steplog`, :mod:`follow_env.tasks.line_trace.steplog`);
this module reads them into a DataFrame and writes them (:data:`LAYOUTS`: what each task's log
needs). The checks are :mod:`follow_env.sim.steplog`'s, which the robot's replay source reads
with too, so a log one refuses the other refuses in the same words.
"""

from __future__ import annotations

import csv
import io
import re
from collections.abc import Iterable
from pathlib import Path

import numpy as np
import pandas as pd

from follow_env.sim.atomic import atomic_path
from follow_env.sim.steplog import LogLayout, StepLogError, read_columns, validate_times
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
    "step_log_text",
    "validate_step_log",
    "write_step_log",
]

# Enough digits that float32 observations and float64 ground truth survive the round trip to
# 1e-9 relative, at a third of the size of full repr precision.
FLOAT_FORMAT = "%.9g"

LAYOUTS: dict[str, LogLayout] = {
    "person_follow": LogLayout(REQUIRED_COLUMNS, TEXT_COLUMNS, ACCEL_SOURCES),
    "line_trace": LogLayout(line_steplog.REQUIRED_COLUMNS, line_steplog.TEXT_COLUMNS),
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
        tmp.write_text(step_log_text(log), encoding="utf-8", newline="")
    return path


def step_log_text(log: pd.DataFrame) -> str:
    """The text :func:`write_step_log` writes: what ``log.to_csv(index=False,
    float_format=FLOAT_FORMAT, lineterminator="\n")`` gives (tested), 2-3 times faster. Each row
    is formatted by one ``%`` on a template of the columns' formats, where pandas formats every
    cell through layers of its own. The columns that need more (a missing float, a text cell the
    CSV format must quote) are turned into their cells first; a log of one column, whose empty
    cells the csv module quotes, or with a header of several rows goes to pandas."""
    if len(log.columns) < 2 or isinstance(log.columns, pd.MultiIndex):
        return log.to_csv(index=False, float_format=FLOAT_FORMAT, lineterminator="\n")
    formats, columns = [], []
    # items() yields each column by position (a name may stand twice): 2.5x faster than
    # log.iloc[:, k] on a 39-column log
    for _, column in log.items():
        values = column.to_numpy()
        if values.dtype.kind == "f" and not np.isnan(values).any():
            formats.append(FLOAT_FORMAT)
            columns.append(values.tolist())
        elif values.dtype.kind in "iu":
            formats.append("%d")
            columns.append(values.tolist())
        else:
            formats.append("%s")
            columns.append(_cells(values))
    header = io.StringIO()
    csv.writer(header, lineterminator="\n").writerow([str(name) for name in log.columns])
    template = ",".join(formats)
    rows = [template % row for row in zip(*columns, strict=True)]
    return header.getvalue() + "".join(row + "\n" for row in rows)


def _cells(values: np.ndarray) -> list[str]:
    """A column's cells as text the way ``to_csv`` writes them: floats by
    :data:`FLOAT_FORMAT`, missing values blank, the rest as ``str``, quoted where the CSV format
    needs it (a comma, a quote or a line break in the cell)."""
    if values.dtype.kind == "f":
        return ["" if v != v else FLOAT_FORMAT % v for v in values.tolist()]
    missing = pd.isna(values).tolist()
    cells = ["" if gone else str(v) for v, gone in zip(values.tolist(), missing, strict=True)]
    return [_quoted(c) if _MAY_NEED_QUOTES.search(c) else c for c in cells]


_MAY_NEED_QUOTES = re.compile(r'[,"\r\n]')


def _quoted(cell: str) -> str:
    """``cell`` as the csv module writes it, quoted or not, in a log of several columns."""
    out = io.StringIO()
    csv.writer(out, lineterminator="\n").writerow([cell])
    return out.getvalue()[:-1]


def read_step_log(path: str | Path, task: str = "person_follow") -> pd.DataFrame:
    """Read and validate a step log of ``task`` (its :data:`LAYOUTS` entry), with
    :func:`follow_env.sim.steplog.read_columns`.

    Cells may be empty (not recorded) except in the required columns. Text columns come back
    as strings (empty string when blank), every other column as float64; a log with the
    encoder speed but no ``accel_mps2`` gets it derived (:func:`accel_from_speed`).

    :raises StepLogError: naming the file, and the line and column for a malformed row: a
        missing file, no header, a missing required column, a row with the wrong number of
        fields, a cell that is not a number (``nan`` included) or is infinite, a
        non-increasing ``time_s``.
    """
    columns, _ = read_columns(path, LAYOUTS[task])
    frame = pd.DataFrame(columns)
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
    validate_times(log["time_s"], path, lines)


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

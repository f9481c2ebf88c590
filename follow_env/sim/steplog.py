"""Reading a step-log CSV, checked cell by cell, for every layer that reads one.

A step log is one CSV per episode, one row per control step (the tasks' ``steplog`` modules
name the columns; :mod:`eval.steplog` scores them, and the robot's replay source
(:mod:`bridge.perception`) drives a controller from one). Both read the file through
:func:`read_columns`, so a log refused by one is refused by the other with the same message:
file, line and column of the first problem. numpy only (the robot's side does not load pandas).
"""

from __future__ import annotations

import csv
import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

__all__ = ["LogLayout", "StepLogError", "read_columns", "validate_times"]


class StepLogError(ValueError):
    """A step log file is missing, unreadable or malformed; the message names file and row."""


@dataclass(frozen=True)
class LogLayout:
    """What a step log must hold.

    :param required: columns every log has, with a value in every row (``time_s`` first).
    :param text: columns holding text (every other one is numeric).
    :param any_of: columns of which a log needs at least one (empty: none needed).
    """

    required: tuple[str, ...]
    text: frozenset[str] = field(default_factory=frozenset)
    any_of: tuple[str, ...] = ()


def read_columns(path: str | Path, layout: LogLayout) -> tuple[dict[str, Sequence], list[int]]:
    """Read and check the step log at ``path`` against ``layout``.

    Cells may be empty (not recorded) except in the required columns; blank lines are skipped
    (a hand-written file's trailing newline).

    :returns: each named column (text ones as lists of stripped strings, empty when blank; the
        others as float64 arrays, NaN when blank) and the file line of each row.
    :raises StepLogError: naming the file, and the line and column for a malformed row: a
        missing file, no header, a duplicate or missing column, a row with the wrong number of
        fields, a cell with a NUL byte, a cell that is not a number (``nan`` included) or is
        infinite, a missing required value, a ``time_s`` that does not increase.
    """
    path = Path(path)
    try:
        with path.open(newline="", encoding="utf-8") as f:
            reader = csv.reader(f)
            # line_num: the line a row ends on, right even when a quoted cell spans lines
            table = [(reader.line_num, row) for row in reader]
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
    if not table or not any(cell.strip() for cell in table[0][1]):
        raise StepLogError(f"{path}: empty file; expected a header line with the columns")
    header = [cell.strip() for cell in table[0][1]]
    _check_header(path, header, layout)
    numbered = [(line, row) for line, row in table[1:] if any(cell.strip() for cell in row)]
    if not numbered:
        raise StepLogError(f"{path}: no data rows after the header")
    for line, row in numbered:
        if len(row) != len(header):
            raise StepLogError(
                f"{path}: line {line}: expected {len(header)} fields as in the header, "
                f"found {len(row)}"
            )
        for j, cell in enumerate(row):
            # a NUL is no text (a zero-filled block after a power cut), and numpy's parser
            # would drop a trailing one: "2\x00" would read as 2
            if "\x00" in cell:
                raise StepLogError(
                    f"{path}: line {line}, column {header[j] or f'#{j + 1}'}: {cell!r} holds a "
                    "NUL byte (not text: a damaged file)"
                )
    lines = [line for line, _ in numbered]
    data = list(zip(*(row for _, row in numbered), strict=True))  # the cells column by column
    columns: dict[str, Sequence] = {}
    for j, name in enumerate(header):
        if not name:
            continue
        cells = [cell.strip() for cell in data[j]]
        columns[name] = cells if name in layout.text else _numbers(path, name, cells, lines)
        if name in layout.required and name not in layout.text:
            blank = np.flatnonzero(np.isnan(columns[name]))
            if blank.size:
                raise StepLogError(
                    f"{path}: line {lines[blank[0]]}, column {name}: value is missing"
                )
    validate_times(columns["time_s"], path, lines)
    return columns, lines


def _check_header(path: Path, header: list[str], layout: LogLayout) -> None:
    dupes = sorted({c for c in header if c and header.count(c) > 1})
    if dupes:
        raise StepLogError(f"{path}: duplicate column(s) {', '.join(dupes)} in the header")
    missing = [c for c in layout.required if c not in header]
    if layout.any_of and not any(c in header for c in layout.any_of):
        missing.append(" or ".join(layout.any_of))
    if missing:
        needs = ", ".join(layout.required)
        if layout.any_of:
            needs += " and " + " or ".join(layout.any_of)
        raise StepLogError(
            f"{path}: missing column(s) {', '.join(missing)}; a step log needs {needs}"
        )


def _numbers(path: Path, name: str, cells: list[str], lines: list[int]) -> np.ndarray:
    """One column's cells as float64 (NaN where blank), or the first bad cell named."""
    raw = np.array(cells, dtype=str)
    written = raw != ""
    try:  # numpy parses in C; only a column it refuses is walked cell by cell for the message
        values = np.where(written, raw, "nan").astype(np.float64)
    except ValueError:
        parsed = []
        for k, cell in enumerate(cells):
            try:
                parsed.append(float(cell) if cell else math.nan)
            except ValueError:
                raise StepLogError(
                    f"{path}: line {lines[k]}, column {name}: {cell!r} is not a number"
                ) from None
        values = np.array(parsed, dtype=np.float64)
    # "nan" written in the file is no measurement; "inf" parses, but every metric drops
    # non-finite values, so a logging fault would vanish from the scores instead of being
    # reported like "nan" is.
    bad = np.flatnonzero((np.isnan(values) & written) | np.isinf(values))
    if bad.size:
        k = int(bad[0])
        what = "is not a finite number" if np.isinf(values[k]) else "is not a number"
        raise StepLogError(f"{path}: line {lines[k]}, column {name}: {cells[k]!r} {what}")
    return values


def validate_times(
    time_s: Iterable[float], path: str | Path = "<log>", lines: Iterable[int] | None = None
) -> None:
    """Check that ``time_s`` is finite and strictly increasing.

    :param time_s: the log's times [s], one per row.
    :param path: the file name used in messages.
    :param lines: file line numbers of the rows (default: row index + 2, after a header).
    :raises StepLogError: naming the first offending line.
    """
    t = np.asarray(list(time_s), dtype=np.float64)
    line_of = list(lines) if lines is not None else [k + 2 for k in range(len(t))]
    bad = np.flatnonzero(~np.isfinite(t))
    if bad.size:
        k = int(bad[0])
        raise StepLogError(f"{path}: line {line_of[k]}, column time_s: {t[k]} is not finite")
    back = np.flatnonzero(np.diff(t) <= 0.0)
    if back.size:
        k = int(back[0]) + 1
        raise StepLogError(
            f"{path}: line {line_of[k]}, column time_s: {t[k]:g} s is not after the "
            f"previous row's {t[k - 1]:g} s"
        )

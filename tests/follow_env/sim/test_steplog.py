"""The step-log reader shared by the evaluation and the robot's replay source."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from follow_env.sim.steplog import LogLayout, StepLogError, read_columns, validate_times

LAYOUT = LogLayout(("time_s", "d"), frozenset({"who"}), ("a", "v"))


def _write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "log.csv"
    path.write_text(text, encoding="utf-8")
    return path


def test_columns_come_back_typed_with_their_file_lines(tmp_path: Path) -> None:
    path = _write(tmp_path, 'time_s,d,a,who\n0,1.5,,"Ann"\n\n0.1,1.25,2,"B\nob"\n')
    columns, lines = read_columns(path, LAYOUT)
    np.testing.assert_array_equal(columns["time_s"], [0.0, 0.1])
    np.testing.assert_array_equal(columns["a"], [np.nan, 2.0])
    assert columns["who"] == ["Ann", "B\nob"]
    # a blank line is skipped, and a row ends on the line its quoted cell closes on
    assert lines == [2, 5]


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("time_s,d\n0,1\n", "missing column(s) a or v; a step log needs time_s, d and a or v"),
        ("time_s,d,a,a\n0,1,0,0\n", "duplicate column(s) a in the header"),
        ("time_s,d,a\n", "no data rows after the header"),
        ("time_s,d,a\n0,1,0\n0.1,,0\n", "line 3, column d: value is missing"),
        ("time_s,d,a\n0,1,0\n0.1,1,-inf\n", "line 3, column a: '-inf' is not a finite number"),
        ("time_s,d,a\n0,1,0\n0.1,1,NaN\n", "line 3, column a: 'NaN' is not a number"),
        ("time_s,d,a\n0,1,0\n0.1,1,0x1\n", "line 3, column a: '0x1' is not a number"),
        ("time_s,d,a\n0.2,1,0\n0.1,1,0\n", "line 3, column time_s: 0.1 s is not after"),
    ],
)
def test_each_problem_is_named_by_file_line_and_column(
    tmp_path: Path, text: str, message: str
) -> None:
    with pytest.raises(StepLogError) as info:
        read_columns(_write(tmp_path, text), LAYOUT)
    assert str(info.value).startswith(str(tmp_path / "log.csv"))
    assert message in str(info.value)


def test_validate_times_numbers_rows_after_a_header_by_default() -> None:
    with pytest.raises(StepLogError, match=r"<log>: line 4, column time_s: nan is not finite"):
        validate_times([0.0, 0.1, float("nan")])

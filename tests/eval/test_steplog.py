"""eval/steplog.py: step-log CSVs round-trip, and malformed files give errors naming the row."""

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from eval.steplog import (
    COLUMNS,
    FLOAT_FORMAT,
    StepLogError,
    read_step_log,
    step_log_files,
    write_step_log,
)

HEADER = "time_s,obs_distance_m,obs_offset_px,accel_mps2"


def write(tmp_path: Path, text: str, name: str = "log.csv") -> Path:
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return path


def test_minimal_robot_log_is_read_as_floats(tmp_path: Path) -> None:
    log = read_step_log(write(tmp_path, f"{HEADER}\n0.0,1.0,5,0.0\n0.1,1.1,-3,0.2\n"))
    assert list(log.columns) == HEADER.split(",")
    np.testing.assert_allclose(log["obs_offset_px"], [5.0, -3.0])
    assert all(log.dtypes == np.float64)


def pandas_csv(log: pd.DataFrame) -> str:
    """What ``write_step_log`` wrote before it formatted rows itself: pandas' CSV."""
    return log.to_csv(index=False, float_format=FLOAT_FORMAT, lineterminator="\n")


@pytest.mark.parametrize(
    ("policy", "scenario", "task"),
    [
        ("pn", "straight", "person_follow"),
        ("ppo_law", "crowd", "person_follow"),
        ("gsmpn", "random_world", "person_follow"),
        ("pid", "gaps", "line_trace"),
    ],
)
def test_a_written_log_is_pandas_csv_to_the_byte(
    tmp_path: Path, policy: str, scenario: str, task: str
) -> None:
    from eval.rollout import run_episode

    log = run_episode(policy, scenario, 3, task=task).log
    assert log.isna().any().any()  # the final row's action: missing floats are written too
    written = write_step_log(log, tmp_path / "ep.csv").read_bytes().decode("utf-8")
    assert written == pandas_csv(log)


def test_cells_the_csv_format_quotes_or_blanks_are_written_as_pandas_writes_them(
    tmp_path: Path,
) -> None:
    odd = pd.DataFrame(
        {
            "time_s": [1.5, np.nan, np.inf, -0.0, 1e-20],
            "step": np.array([1, 2, 3, 4, 5], dtype=np.uint8),
            "termination": ["x,y", 'q"t', "", None, "new\nline"],
            "detected": [True, False, True, True, False],
            "obs_offset_px": np.array([1.1, 2.2, np.nan, 4, 5], dtype=np.float32),
            "mixed": [0.1, "s", None, 3, np.nan],
            "accel_mps2": [np.inf, -np.inf, 1.0, 2.0, 1e300],
            "percent": ["%s", "%d", "a\rb", "", ""],
        }
    )
    twice = pd.concat([odd[["time_s"]], odd[["time_s", "termination"]]], axis=1)
    rows_of_names = odd[["time_s", "step"]].set_axis(
        pd.MultiIndex.from_tuples([("t", "s"), ("t", "step")]), axis=1
    )
    frames = [odd, odd[["termination"]], odd[["time_s"]], odd[["termination", "percent"]]]
    frames += [twice, rows_of_names]
    for k, frame in enumerate([*frames, odd.iloc[:0]]):
        written = write_step_log(frame, tmp_path / f"{k}.csv").read_bytes().decode("utf-8")
        assert written == pandas_csv(frame), frame.columns.tolist()


def test_simulated_log_round_trips(tmp_path: Path) -> None:
    from eval.rollout import run_episode

    log = run_episode("pn:thesis", "straight", 0).log
    back = read_step_log(write_step_log(log, tmp_path / "ep.csv"))
    assert list(back.columns) == list(COLUMNS)
    assert list(back["termination"]) == list(log["termination"])
    assert back["policy"].iloc[0] == "pn:thesis"
    numeric = [c for c in COLUMNS if c not in ("policy", "scenario", "termination")]
    np.testing.assert_allclose(
        back[numeric].to_numpy(), log[numeric].to_numpy(dtype=float), rtol=1e-8, equal_nan=True
    )


def test_final_row_has_no_action(tmp_path: Path) -> None:
    from eval.rollout import run_episode

    log = run_episode("pn:thesis", "straight", 0).log
    assert log["action_v_mps"].iloc[:-1].notna().all()
    assert np.isnan(log["action_v_mps"].iloc[-1])
    assert log["termination"].iloc[-1] != ""
    assert (log["termination"].iloc[:-1] == "").all()


def test_acceleration_is_derived_from_encoder_speed_when_not_logged(tmp_path: Path) -> None:
    text = "time_s,obs_distance_m,obs_offset_px,encoder_speed_mps\n"
    text += "0,1,0,0\n0.1,1,0,0.05\n0.2,1,0,0.05\n"
    log = read_step_log(write(tmp_path, text))
    # (0.05 - 0) / 0.1 = 0.5 m/s², then 0; the first row has no predecessor: 0.
    np.testing.assert_allclose(log["accel_mps2"], [0.0, 0.5, 0.0])


def test_row_with_extra_field_names_file_and_line(tmp_path: Path) -> None:
    path = write(tmp_path, f"{HEADER}\n0.0,1.0,5,0.0\n0.1,1.1,-3,0.2,9\n")
    with pytest.raises(StepLogError, match=r"log\.csv: line 3: expected 4 fields .* found 5"):
        read_step_log(path)


def test_row_with_missing_field_names_the_line(tmp_path: Path) -> None:
    with pytest.raises(StepLogError, match=r"line 2: expected 4 fields .* found 3"):
        read_step_log(write(tmp_path, f"{HEADER}\n0.0,1.0,5\n"))


def test_cell_that_is_not_a_number_names_line_column_and_value(tmp_path: Path) -> None:
    path = write(tmp_path, f"{HEADER}\n0.0,1.0,5,0.0\n0.1,1.1,left,0.2\n")
    with pytest.raises(
        StepLogError, match=r"log\.csv: line 3, column obs_offset_px: 'left' is not a number"
    ):
        read_step_log(path)


def test_a_nul_byte_in_a_cell_names_line_and_column(tmp_path: Path) -> None:
    # numpy's parser drops a trailing NUL: "3\x00" would read as 3 (a zero-filled block after a
    # power cut); the robot's replay reads logs through the same reader
    path = write(tmp_path, f"{HEADER}\n0.0,1.0,5,0.0\n0.1,1.1,3\x00,0.2\n")
    with pytest.raises(
        StepLogError, match=r"log\.csv: line 3, column obs_offset_px: '3\\x00' holds a NUL byte"
    ):
        read_step_log(path)


def test_empty_required_cell_names_the_line(tmp_path: Path) -> None:
    with pytest.raises(StepLogError, match=r"line 3, column obs_distance_m: value is missing"):
        read_step_log(write(tmp_path, f"{HEADER}\n0.0,1.0,5,0.0\n0.1,,5,0.0\n"))


def test_time_going_backwards_names_the_line(tmp_path: Path) -> None:
    with pytest.raises(StepLogError, match=r"line 4, column time_s: 0.1 s is not after .* 0.2 s"):
        read_step_log(write(tmp_path, f"{HEADER}\n0.0,1,0,0\n0.2,1,0,0\n0.1,1,0,0\n"))


def test_missing_required_column_is_named(tmp_path: Path) -> None:
    with pytest.raises(StepLogError, match=r"missing column.*obs_offset_px"):
        read_step_log(write(tmp_path, "time_s,obs_distance_m,accel_mps2\n0,1,0\n"))


def test_log_without_acceleration_or_speed_is_rejected(tmp_path: Path) -> None:
    with pytest.raises(StepLogError, match="accel_mps2 or encoder_speed_mps"):
        read_step_log(write(tmp_path, "time_s,obs_distance_m,obs_offset_px\n0,1,0\n"))


@pytest.mark.parametrize(("text", "message"), [("", "empty file"), (f"{HEADER}\n", "no data rows")])
def test_empty_file_or_header_only_is_rejected(tmp_path: Path, text: str, message: str) -> None:
    with pytest.raises(StepLogError, match=message):
        read_step_log(write(tmp_path, text))


def test_missing_file_is_named(tmp_path: Path) -> None:
    with pytest.raises(StepLogError, match=r"nope\.csv: no such file"):
        read_step_log(tmp_path / "nope.csv")


def test_binary_file_is_rejected_as_not_text(tmp_path: Path) -> None:
    path = tmp_path / "log.csv"
    path.write_bytes(b"\xff\xfe\x00binary")
    with pytest.raises(StepLogError, match="not a text CSV"):
        read_step_log(path)


def test_write_leaves_no_temporary_file(tmp_path: Path) -> None:
    write_step_log(pd.DataFrame({"time_s": [0.0], "obs_offset_px": [1.0]}), tmp_path / "a.csv")
    assert [p.name for p in tmp_path.iterdir()] == ["a.csv"]


@pytest.mark.parametrize(("column", "cell"), [("obs_offset_px", "inf"), ("accel_mps2", "-inf")])
def test_infinite_cell_names_file_line_and_column(tmp_path: Path, column: str, cell: str) -> None:
    row = {"time_s": "0.1", "obs_distance_m": "1", "obs_offset_px": "3", "accel_mps2": "0"}
    row[column] = cell
    path = write(tmp_path, f"{HEADER}\n0.0,1.0,5,0.0\n{','.join(row.values())}\n")
    with pytest.raises(
        StepLogError, match=rf"log\.csv: line 3, column {column}: '{cell}' is not a finite number"
    ):
        read_step_log(path)


def test_infinite_optional_cell_is_rejected_too(tmp_path: Path) -> None:
    text = f"{HEADER},raw_depth_m\n0.0,1.0,5,0.0,1.2\n0.1,1.0,5,0.0,Infinity\n"
    with pytest.raises(
        StepLogError, match="line 3, column raw_depth_m: 'Infinity' is not a finite"
    ):
        read_step_log(write(tmp_path, text))


def test_nan_cell_is_rejected_as_not_a_number(tmp_path: Path) -> None:
    with pytest.raises(StepLogError, match="line 3, column obs_offset_px: 'nan' is not a number"):
        read_step_log(write(tmp_path, f"{HEADER}\n0.0,1.0,5,0.0\n0.1,1.0,nan,0.0\n"))


def test_folders_list_logs_with_seeds_in_numeric_order(tmp_path: Path) -> None:
    for policy in ("pn", "mpn"):
        (tmp_path / policy).mkdir()
        for seed in (10, 2, 1, 0, 11):
            write(tmp_path / policy, f"{HEADER}\n0,1,0,0\n", f"seed_{seed}.csv")
    names = [p.relative_to(tmp_path).as_posix() for p in step_log_files([tmp_path])]
    expected = [f"{p}/seed_{k}.csv" for p in ("mpn", "pn") for k in (0, 1, 2, 10, 11)]
    assert names == expected


def test_the_reference_robots_layout_is_columns_and_another_platform_brings_its_own() -> None:
    from eval.steplog import WHEEL_COLUMNS, log_columns

    assert log_columns() == COLUMNS
    assert log_columns(("v_mps", "w_radps"), WHEEL_COLUMNS[::-1]) == COLUMNS
    other = log_columns(("v_mps", "vy_mps", "w_radps"), ("duty_fl", "duty_fr"))
    assert not set(WHEEL_COLUMNS) & set(other)
    at = other.index("action_v_mps")
    assert other[at : at + 3] == ("action_v_mps", "action_vy_mps", "action_w_radps")
    assert other[other.index("duty_fl") : other.index("duty_fl") + 3] == (
        "duty_fl",
        "duty_fr",
        "encoder_speed_mps",
    )

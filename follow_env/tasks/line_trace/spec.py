"""LineTrace's contract in names and units (no simulation import): observation, grid, info, ends.

The observation is the 25 readings of the mecanum paper's 5 x 5 phototransistor grid (reference
§2), in row-major order, row 0 the front row and column 0 the leftmost cell. Cell ``(i, j)``
sits at ``x = (2 - i) * pitch`` ahead of the grid's centre and ``y = (2 - j) * pitch`` to its
left (REP 103 body axes); :func:`cell_offsets` gives these offsets in cells, which is all a
policy needs to know of the grid's geometry. A reading is the share of the cell's spot covered
by the line, after the sensor's optics, ambient light and noise: 0 on white floor, 1 on the
black line. Policies read the observation through :data:`SPEC`; the action is the platform's.
"""

from __future__ import annotations

from follow_env.tasks.spec import Quantity, TaskSpec

__all__ = [
    "GRID_COLS",
    "GRID_ROWS",
    "REASON_LEFT_FIELD",
    "REASON_LOST",
    "REASON_NONE",
    "REASON_TIME_LIMIT",
    "REASON_TRACK_END",
    "SPEC",
    "cell_index",
    "cell_name",
    "cell_offsets",
]

GRID_ROWS = 5
"""Rows of the sensor grid (reference §2: 5 x 5)."""
GRID_COLS = 5
"""Columns of the sensor grid."""
N_CELLS = GRID_ROWS * GRID_COLS

REASON_NONE = 0
REASON_LOST = 1
REASON_LEFT_FIELD = 2
REASON_TRACK_END = 3
REASON_TIME_LIMIT = 4


def cell_name(row: int, col: int) -> str:
    """Observation name of cell ``(row, col)``: ``cell_<row><col>`` (row 0 front, col 0 left)."""
    return f"cell_{row}{col}"


def cell_index(row: int, col: int) -> int:
    """Index of cell ``(row, col)`` in the observation (row-major)."""
    return row * GRID_COLS + col


def cell_offsets() -> list[tuple[float, float]]:
    """Each cell's ``(x, y)`` from the grid's centre in cells, observation order: x forward,
    y to the left (REP 103)."""
    mid_r, mid_c = (GRID_ROWS - 1) / 2, (GRID_COLS - 1) / 2
    return [(mid_r - i, mid_c - j) for i in range(GRID_ROWS) for j in range(GRID_COLS)]


_Q = Quantity

SPEC = TaskSpec(
    name="line_trace",
    env_id="LineTrace-v0",
    doc="trace a black line on white tiles with a 5 x 5 grid of light sensors (reference §2)",
    observation=tuple(
        _Q(
            cell_name(i, j),
            "",
            f"line reading of cell ({i}, {j}): row {i} of 5 from the front, column {j} of 5 "
            "from the left; 0 white floor, 1 fully on the line",
        )
        for i in range(GRID_ROWS)
        for j in range(GRID_COLS)
    ),
    terminations=("", "lost", "left_field", "track_end", "time_limit"),
    info=(
        _Q("time_s", "s", "episode time"),
        _Q("robot_x_m", "m", "robot position x (world)"),
        _Q("robot_y_m", "m", "robot position y"),
        _Q("robot_theta_rad", "rad", "robot heading"),
        _Q("robot_v_mps", "m/s", "robot forward speed (true)"),
        _Q("robot_vy_mps", "m/s", "robot sideways speed, to the left (true)"),
        _Q("robot_w_radps", "rad/s", "robot turn rate (true)"),
        _Q("encoder_speed_mps", "m/s", "robot speed from the encoders, as the robot computes it"),
        _Q("accel_mps2", "m/s^2", "finite difference of encoder_speed_mps over the step"),
        _Q("progress_m", "m", "arc length of the line point nearest the robot"),
        _Q("track_length_m", "m", "arc length of the whole line, start to end"),
        _Q("cross_track_m", "m", "signed distance robot - line (> 0: robot left of the line)"),
        _Q("heading_error_rad", "rad", "robot heading - the line's direction, in (-pi, pi]"),
        _Q("in_gap", "", "the line point nearest the robot lies in a gap"),
        _Q("line_seen", "", "some cell's spot overlaps the line (gaps counted as line)"),
        _Q("active_cells", "", "cells whose reading is above the sensor's threshold"),
        _Q("lost_s", "s", "time the grid has not overlapped the line (gaps counted as line)"),
        _Q("step", "", "control steps taken"),
        _Q("termination", "", "why the episode ended, or ''"),
    ),
    platform_info_after="accel_mps2",
)
"""The line-tracing task (reference §2)."""

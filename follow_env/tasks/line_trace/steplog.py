"""LineTrace's step-log layout: the columns of one CSV row per control step (names only).

One row per control step, as PersonFollow's logs (:mod:`follow_env.tasks.person_follow.steplog`)
are: row k holds the readings published at time k dt, the state at that time and the action the
policy chose from them; the final row holds the state the episode ended in (no action). This
module only names the columns (no simulation import), so the evaluation and the env agree on
one layout.

## Columns
In this order (units in the names):

| column | unit | meaning |
|---|---|---|
| ``policy``, ``track``, ``seed`` | | what ran (text, text, integer); constant per file |
| ``step`` | | control step index, 0 at reset |
| ``time_s`` | s | time since reset |
| ``obs_cell_00`` ... ``obs_cell_44`` | | the 25 readings (row 0 front, column 0 left) |
| ``action_<entry>`` | SI | the command, per entry of the platform's action (final row: none) |
| the platform's info keys | | its wheels (targets, encoder and true speeds, duties) |
| ``encoder_speed_mps``, ``accel_mps2`` | m/s, m/s² | speed from the encoders, its difference |
| ``robot_x_m`` ... ``robot_w_radps`` | m, rad, m/s, rad/s | robot pose and twist (true) |
| ``progress_m``, ``track_length_m`` | m | arc length of the nearest line point, of the line |
| ``cross_track_m`` | m | robot to the line, > 0 left of it |
| ``heading_error_rad`` | rad | heading against the line's direction |
| ``in_gap``, ``line_seen`` | 0/1 | nearest line point in a gap; some spot over the line |
| ``active_cells`` | | cells above the sensor's threshold |
| ``lost_s`` | s | time without any spot over the line (gaps count as line) |
| ``reward`` | | the env's reward for the step that led to this row |
| ``termination`` | | why the episode ended (final row only) |
"""

from __future__ import annotations

from follow_env.tasks.line_trace.spec import SPEC

__all__ = [
    "FLAG_COLUMNS",
    "META_COLUMNS",
    "OBS_COLUMNS",
    "REQUIRED_COLUMNS",
    "TEXT_COLUMNS",
    "log_columns",
]

META_COLUMNS: tuple[str, ...] = ("policy", "track", "seed")
OBS_COLUMNS: tuple[str, ...] = tuple(f"obs_{name}" for name in SPEC.observation_names)
#: info flags written as 0/1.
FLAG_COLUMNS: tuple[str, ...] = ("in_gap", "line_seen")
_TRUTH: tuple[str, ...] = (
    "robot_x_m",
    "robot_y_m",
    "robot_theta_rad",
    "robot_v_mps",
    "robot_vy_mps",
    "robot_w_radps",
    "progress_m",
    "track_length_m",
    "cross_track_m",
    "heading_error_rad",
    "in_gap",
    "line_seen",
    "active_cells",
    "lost_s",
)


def log_columns(
    action_names: tuple[str, ...] = ("v_mps", "vy_mps", "w_radps"),
    platform_keys: tuple[str, ...] = (),
) -> tuple[str, ...]:
    """The step log's columns on a platform with these action entries and info keys (module
    docstring)."""
    return (
        *META_COLUMNS,
        "step",
        "time_s",
        *OBS_COLUMNS,
        *(f"action_{name}" for name in action_names),
        *platform_keys,
        "encoder_speed_mps",
        "accel_mps2",
        *_TRUTH,
        "reward",
        "termination",
    )


#: Columns holding text; every other column is numeric.
TEXT_COLUMNS: frozenset[str] = frozenset({"policy", "track", "termination"})
#: Columns a log must have, with a value in every row.
REQUIRED_COLUMNS: tuple[str, ...] = ("time_s", *OBS_COLUMNS)

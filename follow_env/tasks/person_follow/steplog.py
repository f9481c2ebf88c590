"""PersonFollow's step-log layout: the columns of one CSV row per control step (names only).

The reference robot logged its camera and encoder data to CSV every 0.1 s (reference §1.6). A
step log is that file, extended with the simulation's ground truth. This module only names the
columns (no simulation import), so the evaluation (``eval.steplog`` reads and writes them), the
robot bridge (``follow-robot run`` writes them on a real robot) and the env agree on one layout.

## Columns
In this order (units in the names; a real robot's log may leave out any optional column):

| column | unit | required | meaning |
|---|---|---|---|
| ``policy``, ``scenario``, ``seed`` | | no | what ran (text, text, integer); constant per file |
| ``step`` | | no | control step index, 0 at reset |
| ``time_s`` | s | yes | time since reset; strictly increasing |
| ``obs_distance_m`` | m | yes | published distance (reference §1.4; 0 = no reading yet) |
| ``obs_offset_px`` | px | yes | published offset, > 0 right of centre (held when not detected) |
| ``obs_ahead_m`` | m | no | the reading ahead, when configured (``PerceptionConfig.ahead_rays``) |
| ``detected`` | 0/1 | no | a fresh detection was published at this step |
| ``raw_depth_m`` | m | no | the depth pixel behind the last detection, before the filter |
| ``action_v_mps``, ``action_w_radps`` | m/s, rad/s | no | command sent (final row: none) |
| ``wheel_target_r_mps``, ``wheel_target_l_mps`` | m/s | no | PID set-points |
| ``wheel_measured_r_mps``, ``wheel_measured_l_mps`` | m/s | no | encoder wheel speeds |
| ``duty_r_pct``, ``duty_l_pct`` | % | no | motor duty |
| ``encoder_speed_mps`` | m/s | see below | robot speed from the encoders, (right + left) / 2 |
| ``accel_mps2`` | m/s² | see below | finite difference of ``encoder_speed_mps`` over one step |
| ``true_distance_m``, ``true_offset_px``, ``in_frame`` | m, px, 0/1 | no | the person's truth |
| ``robot_x_m`` ... ``robot_vy_mps`` | m, rad, m/s, rad/s, m/s | no | robot pose and speeds |
| ``person_x_m`` ... ``person_v_mps`` | m, rad, m/s | no | person pose and speed |
| ``wheel_true_r_radps``, ``wheel_true_l_radps`` | rad/s | no | true wheel speeds |
| ``wall_clearance_m``, ``person_clearance_m`` | m | no | clearances |
| ``detected_person`` | | no | index of the person the detector picked first (-1: none) |
| ``reward`` | | no | the env's reward for the step that led to this row |
| ``termination`` | | no | why the episode ended (final row only; see ``follow_env.INFO_KEYS``) |

That is the reference robot's layout (the differential drive). On another platform
(:func:`log_columns`) the action columns are ``action_<entry>`` for each entry of its action
(the mecanum base: ``action_v_mps, action_vy_mps, action_w_radps``) and its own info keys (its
wheels) replace the wheel columns, placed before ``encoder_speed_mps``.
With the reading ahead configured, ``obs_ahead_m`` follows ``obs_offset_px`` (``ahead=True``).

One of ``accel_mps2`` and ``encoder_speed_mps`` is required; when only the speed is logged, the
acceleration is computed from it as the robot does (finite difference per row).

Row k holds the observation published at time k dt, the state at that time and the action the
policy chose from it; the final row holds the state the episode ended in (no action).
"""

from __future__ import annotations

__all__ = [
    "ACCEL_SOURCES",
    "ACTION_COLUMNS",
    "AHEAD_COLUMN",
    "COLUMNS",
    "FLAG_COLUMNS",
    "META_COLUMNS",
    "OBS_COLUMNS",
    "REQUIRED_COLUMNS",
    "TEXT_COLUMNS",
    "WHEEL_COLUMNS",
    "log_columns",
]

META_COLUMNS: tuple[str, ...] = ("policy", "scenario", "seed")
ACTION_COLUMNS: tuple[str, ...] = ("action_v_mps", "action_w_radps")
#: Every column a simulated step log has, in file order (module docstring).
COLUMNS: tuple[str, ...] = (
    *META_COLUMNS,
    "step",
    "time_s",
    "obs_distance_m",
    "obs_offset_px",
    "detected",
    "raw_depth_m",
    *ACTION_COLUMNS,
    "wheel_target_r_mps",
    "wheel_target_l_mps",
    "wheel_measured_r_mps",
    "wheel_measured_l_mps",
    "duty_r_pct",
    "duty_l_pct",
    "encoder_speed_mps",
    "accel_mps2",
    "true_distance_m",
    "true_offset_px",
    "in_frame",
    "robot_x_m",
    "robot_y_m",
    "robot_theta_rad",
    "robot_v_mps",
    "robot_w_radps",
    "robot_vy_mps",
    "person_x_m",
    "person_y_m",
    "person_theta_rad",
    "person_v_mps",
    "wheel_true_r_radps",
    "wheel_true_l_radps",
    "wall_clearance_m",
    "person_clearance_m",
    "detected_person",
    "reward",
    "termination",
)
#: The reference robot's wheel columns (its platform's info keys) in :data:`COLUMNS`.
WHEEL_COLUMNS: tuple[str, ...] = (
    "wheel_target_r_mps",
    "wheel_target_l_mps",
    "wheel_measured_r_mps",
    "wheel_measured_l_mps",
    "duty_r_pct",
    "duty_l_pct",
    "wheel_true_r_radps",
    "wheel_true_l_radps",
)


def log_columns(
    action_names: tuple[str, ...] = ("v_mps", "w_radps"),
    platform_keys: tuple[str, ...] = (),
    ahead: bool = False,
) -> tuple[str, ...]:
    """The step log's columns on a platform with these action entries and info keys: exactly
    :data:`COLUMNS` for the reference robot's (or no platform keys given), otherwise its
    action and wheel columns in their places, and :data:`AHEAD_COLUMN` with the reading
    ahead (module docstring)."""
    actions = tuple(f"action_{name}" for name in action_names)
    out: list[str] = []
    keep_wheels = not platform_keys or set(platform_keys) == set(WHEEL_COLUMNS)
    for column in COLUMNS:
        if column == "obs_offset_px" and ahead:
            out.extend((column, AHEAD_COLUMN))
        elif column == ACTION_COLUMNS[0]:
            out.extend(actions)
        elif column == "encoder_speed_mps" and not keep_wheels:
            out.extend((*platform_keys, column))
        elif column not in ACTION_COLUMNS and (keep_wheels or column not in WHEEL_COLUMNS):
            out.append(column)
    return tuple(out)


#: Columns holding text; every other column is numeric.
TEXT_COLUMNS: frozenset[str] = frozenset({"policy", "scenario", "termination"})
#: Columns a log must have, with a value in every row.
REQUIRED_COLUMNS: tuple[str, ...] = ("time_s", "obs_distance_m", "obs_offset_px")
#: One of these must be present (module docstring).
ACCEL_SOURCES: tuple[str, ...] = ("accel_mps2", "encoder_speed_mps")
#: The observation's columns, in the observation's order.
OBS_COLUMNS: tuple[str, ...] = ("obs_distance_m", "obs_offset_px")
#: The reading ahead's column (optional: only when it is configured).
AHEAD_COLUMN = "obs_ahead_m"
#: info flags written as 0/1.
FLAG_COLUMNS: tuple[str, ...] = ("detected", "in_frame")

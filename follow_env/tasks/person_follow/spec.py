"""PersonFollow's contract in names and units (no simulation import): observation, info, ends.

Policies read the observation through :data:`SPEC`; the robot bridge writes step logs with the
same names. With ``PerceptionConfig.ahead_rays > 0`` the observation has a third entry,
:data:`AHEAD` (``observation_names(ahead=True)``). The action is the platform's (e.g.
``[v_mps, w_radps]`` for the differential drive), and so are the info keys of its wheels,
placed after ``raw_depth_m``.
"""

from __future__ import annotations

from typing import Any

from follow_env.tasks.spec import Quantity, TaskSpec

__all__ = [
    "AHEAD",
    "AHEAD_SETTINGS",
    "REASON_COLLISION_BYSTANDER",
    "REASON_COLLISION_PERSON",
    "REASON_COLLISION_WALL",
    "REASON_LOST",
    "REASON_NONE",
    "REASON_STEP_LIMIT",
    "REASON_WALK_OVER",
    "SPEC",
    "ahead_settings",
    "observation_bounds",
    "observation_names",
    "observation_size",
]

REASON_NONE = 0
REASON_COLLISION_WALL = 1
REASON_COLLISION_PERSON = 2
REASON_LOST = 3
REASON_WALK_OVER = 4
REASON_STEP_LIMIT = 5
REASON_COLLISION_BYSTANDER = 6

_Q = Quantity

SPEC = TaskSpec(
    name="person_follow",
    env_id="PersonFollow-v0",
    doc="follow a walking person at 1 m, centred in the image, using only an RGB-D camera",
    observation=(
        _Q("distance_m", "m", "filtered depth at the box centre (0: no reading yet)"),
        _Q("offset_px", "px", "box centre column - width // 2 (> 0: person right of centre)"),
    ),
    terminations=(
        "",
        "collision_wall",
        "collision_person",
        "lost",
        "walk_over",
        "step_limit",
        "collision_bystander",
    ),
    info=(
        _Q("time_s", "s", "episode time"),
        _Q("robot_x_m", "m", "robot position x (world)"),
        _Q("robot_y_m", "m", "robot position y"),
        _Q("robot_theta_rad", "rad", "robot heading"),
        _Q("robot_v_mps", "m/s", "robot forward speed (true)"),
        _Q("robot_w_radps", "rad/s", "robot turn rate (true)"),
        _Q("robot_vy_mps", "m/s", "robot sideways speed, to the left (true; 0 unless it strafes)"),
        _Q("true_distance_m", "m", "camera to the front of the target's body"),
        _Q("true_offset_px", "px", "image column of the target's axis - width // 2"),
        _Q("raw_depth_m", "m", "unfiltered depth of the published detection"),
        _Q("encoder_speed_mps", "m/s", "robot speed from the encoders, as the robot computes it"),
        _Q("accel_mps2", "m/s^2", "finite difference of encoder_speed_mps over the step"),
        _Q("wall_clearance_m", "m", "footprint to the nearest wall or obstacle"),
        _Q("person_clearance_m", "m", "footprint to the target's body"),
        _Q("bystander_clearance_m", "m", "footprint to the nearest bystander's body (inf: none)"),
        _Q("person_x_m", "m", "target position x"),
        _Q("person_y_m", "m", "target position y"),
        _Q("person_theta_rad", "rad", "target heading"),
        _Q("person_v_mps", "m/s", "target walking speed"),
        _Q("in_frame", "", "enough of the target in the image and in sight to be detected"),
        _Q("detected", "", "this step's observation is a fresh detection"),
        _Q("detected_person", "", "whose detection it is: 0 the target, > 0 a bystander, -1 none"),
        _Q("step", "", "control steps taken"),
        _Q("termination", "", "why the episode ended, or ''"),
    ),
    platform_info_after="raw_depth_m",
)
"""The person-following task (reference §1)."""


AHEAD = _Q(
    "ahead_m",
    "m",
    "nearest valid depth across the image's middle row (depth_max_m: none); only with "
    "PerceptionConfig.ahead_rays > 0",
)
"""The optional third observation entry, the reading ahead."""

AHEAD_SETTINGS: dict[str, Any] = {
    "ahead_rays": 0,
    "ahead_half_angle_deg": 14.0,
    "ahead_target": "include",
}
"""The settings that shape the reading ahead (``PerceptionConfig``'s fields) and their defaults,
for code that sees the task only through this spec (a learned agent names what it reads)."""


def ahead_settings(perception: Any) -> dict[str, Any] | None:
    """The reading ahead's settings of a ``PerceptionConfig`` (every one of
    :data:`AHEAD_SETTINGS`), or None when it publishes no reading."""
    if not perception.ahead_rays:
        return None
    return {k: getattr(perception, k) for k in AHEAD_SETTINGS}


def observation_names(ahead: bool = False) -> tuple[str, ...]:
    """The observation's entries: :data:`SPEC`'s, then ``ahead_m`` with the reading ahead."""
    return (*SPEC.observation_names, *((AHEAD.name,) if ahead else ()))


def observation_size(cfg: Any) -> int:
    """Entries of the observation under ``cfg`` (an ``EnvConfig``): 2, or 3 with the reading
    ahead on."""
    return SPEC.observation_size + (1 if cfg.perception.ahead_rays > 0 else 0)


def observation_bounds(
    width_px: int, depth_max_m: float, ahead: bool = False
) -> tuple[list[float], list[float]]:
    """``(low, high)`` of the observation for a camera of ``width_px`` and a depth range to
    ``depth_max_m`` (``ahead``: with the reading ahead, in ``[0, depth_max_m]``)."""
    half_w = width_px // 2
    low, high = [0.0, float(-half_w)], [float(depth_max_m), float(width_px - 1 - half_w)]
    if ahead:
        low.append(0.0)
        high.append(float(depth_max_m))
    return low, high

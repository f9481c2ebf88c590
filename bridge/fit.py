"""Whether this robot can run a policy: what it commands and what it reads (the runner checks
before it starts, and again for each mode the monitor chooses)."""

from __future__ import annotations

import json
from typing import Any

from bridge.perception import PerceptionError, PerceptionSource
from follow_env.platforms.diff_drive import DiffDriveConfig

__all__ = ["COMMAND", "check_ahead", "check_command", "check_platform"]

COMMAND = ("v_mps", "w_radps")
"""What a policy must command here: the differential drive's forward speed and turn rate."""


def check_command(policy: Any) -> None:
    """Refuse a policy that does not command the differential drive's ``[v_mps, w_radps]``
    (the mecanum base's agent commands ``[v, vy, w]``).

    :raises ValueError: naming the policy and both commands.
    """
    names = tuple(getattr(policy, "action_names", COMMAND))
    if names != COMMAND:
        raise ValueError(
            f"{getattr(policy, 'name', 'the policy')} commands [{', '.join(names)}], but this "
            f"robot takes [{', '.join(COMMAND)}]"
        )


def check_platform(platform: Any) -> None:
    """Refuse a platform other than the differential drive: the robot the runner drives (its
    wheel loop sends two wheel commands; its inverse kinematics are the differential drive's).

    :raises ValueError: naming ``config.platform`` and what it must be, in one line.
    """
    if not isinstance(platform, DiffDriveConfig):
        raise ValueError(
            f"config.platform={type(platform).__name__} is out of range: the robot "
            "follow-robot drives is the differential drive (DiffDriveConfig)"
        )


def check_ahead(policy: Any, perception: PerceptionSource) -> None:
    """Refuse a perception that cannot feed the policy's reading ahead
    (``PPOPolicy.reads_ahead``): one that publishes none, or publishes it with other settings
    than the agent was trained with (the world's or the camera's, once started).

    :raises PerceptionError: naming the policy, the source and what to change.
    """
    wanted = getattr(policy, "reads_ahead", None)
    if not wanted:
        return
    given = getattr(perception, "ahead", None)
    name = getattr(policy, "name", "the policy")
    if given is None:
        raise PerceptionError(
            f"{name} reads the reading ahead ({wanted}), but {perception.name} does not publish "
            f"it: start the emulator with --config '{{\"perception\": {json.dumps(wanted)}}}', "
            "replay a log with an obs_ahead_m column, or use the realsense perception"
        )
    if isinstance(given, dict) and any(given.get(k) != v for k, v in wanted.items()):
        raise PerceptionError(
            f"{name} reads the reading ahead with {wanted}, but {perception.name} publishes it "
            f"with {given}"
        )

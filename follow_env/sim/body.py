"""The robot's body: the one record every platform writes and every sensor and task reads.

Pose in SI (world frame), the twist in the body frame (``v`` forward, ``vy`` to the left,
``w`` counter-clockwise: REP 103), and the speed and acceleration *as the robot measures
them* (encoder-based), which is what the reference robot logged. It is task- and
platform-agnostic, so the runner composes it into every lane's state.
"""

from __future__ import annotations

from follow_env.sim.schema import Block, f8

__all__ = ["BODY"]

BODY = Block(
    "body",
    "the robot's pose and twist (world frame, SI), and its speed as its encoders measure it",
    [
        f8("x", "m", "position of the base's reference point (the axle centre), x"),
        f8("y", "m", "position of the base's reference point, y"),
        f8("th", "rad", "heading, counter-clockwise from +x, in (-pi, pi]"),
        f8("v", "m/s", "forward speed (true)"),
        f8("w", "rad/s", "turn rate, counter-clockwise positive (true)"),
        f8("v_meas", "m/s", "forward speed from the encoders, as the robot computes it"),
        f8("v_meas_prev", "m/s", "v_meas one control step earlier"),
        f8("accel", "m/s^2", "finite difference of v_meas over the control step"),
        f8("push_vx", "m/s", "a push (randomisation) this control step, x"),
        f8("push_vy", "m/s", "a push this control step, y"),
        f8("vy", "m/s", "sideways speed, to the left (true; 0 on a base that cannot strafe)"),
    ],
)

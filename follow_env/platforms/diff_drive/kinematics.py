"""Differential-drive kinematics (reference §1.1): inverse, forward, and the Euler pose step."""

from __future__ import annotations

from typing import ClassVar

import numpy as np

from follow_env.sim.jit import njit

__all__ = ["DiffDrive", "diff_drive_fk", "diff_drive_ik", "euler_pose_step"]


@njit(inline="always")
def diff_drive_ik(v: float, w: float, r: float, L: float) -> tuple[float, float]:
    """Wheel angular speeds (rad/s) for a body twist (reference §1.1).

    ``wR = (v + L w / 2) / r``, ``wL = (v - L w / 2) / r``.

    :param v: forward speed (m/s). :param w: turn rate (rad/s, counter-clockwise positive).
    :param r: wheel radius (m). :param L: distance between the wheels (m).
    :return: ``(wR, wL)`` in rad/s.
    """
    return (v + 0.5 * L * w) / r, (v - 0.5 * L * w) / r


@njit(inline="always")
def diff_drive_fk(wR: float, wL: float, r: float, L: float) -> tuple[float, float]:
    """Body twist for wheel angular speeds (reference §1.1): ``v = r/2 (wR + wL)``,
    ``w = r/L (wR - wL)``. Returns ``(v m/s, w rad/s)``."""
    return 0.5 * r * (wR + wL), r / L * (wR - wL)


@njit(inline="always")
def euler_pose_step(
    x: float, y: float, th: float, v: float, w: float, dt: float
) -> tuple[float, float, float]:
    """One explicit Euler step of the unicycle pose (reference §1.1):
    ``x += v cos(th) dt``, ``y += v sin(th) dt``, ``th += w dt`` (th wrapped to (-pi, pi])."""
    x += v * np.cos(th) * dt
    y += v * np.sin(th) * dt
    th += w * dt
    if th > np.pi:
        th -= 2.0 * np.pi
    elif th <= -np.pi:
        th += 2.0 * np.pi
    return x, y, th


class DiffDrive:
    """Differential drive with wheel radius ``r`` (m) and track width ``L`` (m).

    Wheel order is (right, left), as in the reference robot's serial protocol.
    """

    n_wheels: ClassVar[int] = 2

    def __init__(self, wheel_radius_m: float, track_width_m: float) -> None:
        self.r = float(wheel_radius_m)
        self.L = float(track_width_m)

    def inverse(self, v: np.ndarray, w: np.ndarray) -> np.ndarray:
        """Wheel angular speeds (rad/s), shape (..., 2) ordered (right, left)."""
        v = np.asarray(v, dtype=float)
        w = np.asarray(w, dtype=float)
        return np.stack([(v + 0.5 * self.L * w) / self.r, (v - 0.5 * self.L * w) / self.r], -1)

    def forward(self, wheel_radps: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Body twist ``(v m/s, w rad/s)`` from wheel speeds of shape (..., 2)."""
        wheel_radps = np.asarray(wheel_radps, dtype=float)
        wR, wL = wheel_radps[..., 0], wheel_radps[..., 1]
        return 0.5 * self.r * (wR + wL), self.r / self.L * (wR - wL)

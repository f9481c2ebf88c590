"""The simulated world around an emulated robot: the person, the camera and the walls.

The emulated wheel microcontroller (:mod:`bridge.mcu`) turns the wheels in real time; this
world moves the robot's body by the twist those wheels really produced over each control
period, and runs the task's own person, camera, detector, depth and contact models on it:
``PersonFollow-v0`` on the ideal ``unicycle`` platform, whose action is exactly that twist. So
a hardware-in-the-loop run (emulator + the runner with ``--perception sim``) meets the person
and the detector noise the simulator would give on the same scenario and seed.

Every frame is a plain dict (JSON-ready): the published observation (``ahead_m`` too when the
configuration publishes the reading ahead), whether the episode is over, and the ground truth
the step log records (robot and person poses, ``in_frame``, ...).
"""

from __future__ import annotations

import math
import threading
from typing import Any

import numpy as np

from follow_env.platforms.base import motor_gains
from follow_env.platforms.diff_drive import DiffDriveConfig
from follow_env.platforms.unicycle import UnicycleBody, UnicycleConfig
from follow_env.tasks.person_follow.config import EnvConfig
from follow_env.tasks.person_follow.env import PersonFollowEnv
from follow_env.tasks.person_follow.render_style import Lane, W
from follow_env.tasks.person_follow.spec import ahead_settings

__all__ = ["TRUTH_KEYS", "EmulatedWorld", "scene_walls"]

TRUTH_KEYS: tuple[str, ...] = (
    "true_distance_m",
    "true_offset_px",
    "in_frame",
    "raw_depth_m",
    "robot_x_m",
    "robot_y_m",
    "robot_theta_rad",
    "robot_v_mps",
    "robot_w_radps",
    "person_x_m",
    "person_y_m",
    "person_theta_rad",
    "person_v_mps",
    "wall_clearance_m",
    "person_clearance_m",
    "detected_person",
)
"""The info keys a frame carries as ground truth (names as in the step log)."""


def scene_walls(env: PersonFollowEnv) -> list[list[float]]:
    """The walls of the env's current episode as ``[x1, y1, x2, y2]`` rows, m (for drawing)."""
    walls = Lane(env.sim.lane(0)).walls
    return [[float(w[W.x1]), float(w[W.y1]), float(w[W.x2]), float(w[W.y2])] for w in walls]


class EmulatedWorld:
    """A person-following world moved by measured wheel motion.

    :param config: the environment configuration; its platform must be the differential drive
        (the robot the emulated MCU drives), whose geometry moves the body.
    :param seed: the episode seed (the same person and noise as the simulator's on that seed).
    """

    def __init__(self, config: EnvConfig, seed: int = 0) -> None:
        if not isinstance(config.platform, DiffDriveConfig):
            raise ValueError(
                f"config.platform={type(config.platform).__name__} is out of range: the emulated "
                "robot is the differential drive (DiffDriveConfig)"
            )
        self.config = config
        self.robot: DiffDriveConfig = config.platform
        self.seed = int(seed)
        self.dt = config.episode.control_dt_s
        twin = UnicycleConfig(
            body=UnicycleBody(
                footprint_length_m=self.robot.robot.footprint_length_m,
                footprint_width_m=self.robot.robot.footprint_width_m,
                # the wheels bound the twist; the twin must not clip what they really did
                max_speed_mps=10.0,
                max_turn_rate_radps=50.0,
                integration_steps=self.robot.sub_steps(self.dt),
            )
        )
        self.env = PersonFollowEnv(config=config, platform=twin)
        self.lock = threading.Lock()
        self.episodes = 0
        #: The reading ahead's settings (None: the world publishes none).
        self.ahead: dict[str, Any] | None = ahead_settings(config.perception)
        # Load (or, the first time, compile) the kernels now rather than at the first step.
        self.env.reset(seed=self.seed)
        self.env.step(np.zeros(2))
        self.reset()

    def reset(self, seed: int | None = None) -> dict[str, Any]:
        """Start the episode again (with ``seed``, or the same seed); returns the first frame."""
        with self.lock:
            # kept only once the env took it: a seed it refuses leaves the world as it was
            chosen = self.seed if seed is None else int(seed)
            obs, info = self.env.reset(seed=chosen)
            self.seed = chosen
            self.episodes += 1
            self.done = False
            self.frame = self._frame(obs, info, False, "")
            return dict(self.frame)

    def motor_gains(self) -> tuple[float, float]:
        """The two motors' gain factors the simulator draws for this episode (right, left)."""
        spread = self.robot.motor.gain_spread
        if spread <= 0.0:
            return (1.0, 1.0)
        gains = motor_gains(self.env.sim.keys[:1], 2, spread)[0]
        return float(gains[0]), float(gains[1])

    def step(self, d_angle_r: float, d_angle_l: float, periods: int = 1) -> dict[str, Any]:
        """Advance by ``periods`` control periods in which the wheels turned by ``d_angle_r``
        and ``d_angle_l`` (rad, true angles); returns the newest frame.

        The twist that covers the same wheel travel in the nominal period (forward kinematics
        with the robot's wheel radius and track, reference §1.1) is applied to the body, split
        evenly when the emulator fell behind by more than one period.
        """
        r, L = self.robot.robot.wheel_radius_m, self.robot.robot.track_width_m
        span = self.dt * periods
        v = 0.5 * r * (d_angle_r + d_angle_l) / span
        w = r * (d_angle_r - d_angle_l) / L / span
        action = np.array([v, w], dtype=np.float64)
        with self.lock:
            for _ in range(periods):
                if self.done:
                    break
                obs, _, terminated, truncated, info = self.env.step(action)
                self.done = bool(terminated or truncated)
                self.frame = self._frame(obs, info, self.done, info["termination"])
            return dict(self.frame)

    def walls(self) -> list[list[float]]:
        """The episode's walls, ``[x1, y1, x2, y2]`` rows in m."""
        with self.lock:
            return scene_walls(self.env)

    def latest(self) -> dict[str, Any]:
        """The newest frame (a copy)."""
        with self.lock:
            return dict(self.frame)

    @staticmethod
    def _frame(obs: np.ndarray, info: dict[str, Any], done: bool, why: str) -> dict[str, Any]:
        frame: dict[str, Any] = {
            "time_s": float(info["time_s"]),
            "step": int(info["step"]),
            "distance_m": float(obs[0]),
            "offset_px": float(obs[1]),
            "detected": bool(info["detected"]),
            "done": done,
            "termination": why,
        }
        if len(obs) > 2:
            frame["ahead_m"] = float(obs[2])
        for key in TRUTH_KEYS:
            value = float(info[key])
            frame[key] = value if math.isfinite(value) else None
        return frame

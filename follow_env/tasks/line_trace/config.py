"""Configuration of the line-tracing task: the tree of sections and its presets.

``LineTraceConfig`` holds the platform (the mecanum paper's base,
:class:`~follow_env.platforms.mecanum.MecanumConfig`, by default; its sections are reached at the
top level too: ``floor={...}``), the light-sensor grid (``sensor``, a sensor of
:mod:`follow_env.sensors.light_grid`), and the task's own sections: the track, the start, the
reward, the episode and the randomisation. Every field declares its unit, its allowed range and
where its default comes from (:mod:`follow_env.sim.config`).

Presets: :data:`PAPER` (the mecanum paper's task as closely as the sources allow; the default),
:data:`IDEAL` (noiseless sensing, no motor spread: for debugging and tests; the gear friction
stays, so a straight command under 0.24 m/s does not start the open-loop base) and
:data:`NOISY` (more sensor noise and ambient light, every platform randomisation on).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from follow_env.platforms.base import PlatformConfig, PlatformRandomization
from follow_env.platforms.mecanum import MecanumConfig
from follow_env.sensors.light_grid import LightGridConfig
from follow_env.sim.checks import out_of_range
from follow_env.sim.config import Validated, param
from follow_env.tasks.config import TaskConfig
from follow_env.tasks.config import config_from_text as task_config_from_text

__all__ = [
    "IDEAL",
    "NOISY",
    "PAPER",
    "PRESETS",
    "EpisodeConfig",
    "LineTraceConfig",
    "RandomizationConfig",
    "RewardConfig",
    "StartConfig",
    "TrackConfig",
    "config_from_text",
]


@dataclass(frozen=True)
class TrackConfig(Validated):
    """The course: floor tiles in the style of RoboCup Junior Rescue Line (the mecanum paper's
    robot was built for it, reference §2). Tracks are registered by name
    (:mod:`follow_env.tasks.line_trace.tracks`); the name is checked when an env is built."""

    name: str = param("course", doc="choice: the mixed course (every kind of tile)")
    tile_m: float = param(0.30, 0.1, 1.0, "m", "RoboCup Junior Rescue Line: 30 cm tiles")
    line_width_m: float = param(
        0.019,
        0.005,
        0.05,
        "m",
        "RoboCup Junior Rescue Line: a black line 1-2 cm wide; choice: 19 mm tape",
    )
    gap_m: float = param(
        0.20,
        0.0,
        0.28,
        "m",
        "RoboCup Junior Rescue Line: gaps of up to 20 cm; the gaps of the built-in tracks",
    )
    zigzag_amplitude_m: float = param(
        0.05,
        0.0,
        0.12,
        "m",
        "choice: a zigzag's teeth reach 5 cm to either side of the tile's axis",
    )
    zigzag_teeth: int = param(
        3,
        1,
        8,
        "",
        "choice: teeth of a zigzag tile (3: 45 deg bends at the defaults)",
        integer=True,
    )
    random_tiles: int = param(
        16,
        2,
        60,
        "tiles",
        "choice: tiles of a 'random' track (4.8 m of line and more)",
        integer=True,
    )
    random_cols: int = param(
        8, 2, 20, "tiles", "choice: the field of a 'random' track, tiles along x", integer=True
    )
    random_rows: int = param(
        6, 2, 20, "tiles", "choice: the field of a 'random' track, tiles along y", integer=True
    )
    random_curve_prob: float = param(
        0.5, 0.0, 1.0, "", "choice: a turn of a 'random' track is a curve (else a 90 deg corner)"
    )
    random_gap_prob: float = param(
        0.15, 0.0, 1.0, "", "choice: a straight tile of a 'random' track has a gap"
    )
    random_zigzag_prob: float = param(
        0.15, 0.0, 1.0, "", "choice: a straight tile of a 'random' track is a zigzag"
    )

    def __post_init__(self) -> None:
        super().__post_init__()
        # A self-avoiding walk through a fuller field can take the search minutes, or fail,
        # at reset (a full 8 x 6 field 2-12 s a reset, a full 20 x 3 one no track at all);
        # up to 3/4 of it every field shape tried lays a track in under a second.
        most = max(2, (3 * self.random_cols * self.random_rows) // 4)
        if self.random_tiles > most:
            raise out_of_range(
                "TrackConfig.random_tiles",
                self.random_tiles,
                f"<= 3/4 of random_cols x random_rows ({most})",
            )
        if self.random_gap_prob + self.random_zigzag_prob > 1.0:
            raise out_of_range(
                "TrackConfig.random_zigzag_prob",
                self.random_zigzag_prob,
                f"<= 1 - random_gap_prob ({1.0 - self.random_gap_prob})",
            )
        if self.gap_m > self.tile_m - 0.02:
            raise out_of_range(
                "TrackConfig.gap_m", self.gap_m, f"<= tile_m - 0.02 m ({self.tile_m - 0.02:g} m)"
            )


@dataclass(frozen=True)
class StartConfig(Validated):
    """Where the robot starts: on the line, facing along it, a little off by chance."""

    distance_m: float = param(
        0.15, 0.0, 1.0, "m", "choice: the robot's centre starts this far along the line (mid tile)"
    )
    lateral_spread_m: float = param(
        0.005, 0.0, 0.05, "m", "choice: std of the start's sideways offset from the line"
    )
    heading_spread_deg: float = param(
        5.0, 0.0, 45.0, "deg", "choice: std of the start heading's error from the line's direction"
    )


@dataclass(frozen=True)
class RewardConfig(Validated):
    """Dense reward from ground truth (see ``LineTraceEnv``'s manual)."""

    progress_weight: float = param(
        1.0, 0.0, 100.0, "/cm", "choice: per cm of progress along the line (negative backwards)"
    )
    cross_track_weight: float = param(
        0.2, 0.0, 100.0, "/step", "choice: min(|cross-track error| / cross_track_scale_m, 1)"
    )
    cross_track_scale_m: float = param(
        0.02,
        0.001,
        1.0,
        "m",
        "choice: the cross-track error that costs the full weight",
        lo_open=True,
    )
    accel_weight: float = param(
        0.005, 0.0, 100.0, "/(m/s^2)", "choice: smoothness, |change of (v, vy)| / dt"
    )
    yaw_accel_weight: float = param(
        0.001, 0.0, 100.0, "/(rad/s^2)", "choice: smoothness, |change of w| / dt"
    )
    lost_penalty: float = param(50.0, 0.0, 1e5, "", "choice: once, when the line is lost")
    left_field_penalty: float = param(50.0, 0.0, 1e5, "", "choice: once, on leaving the field")
    finish_bonus: float = param(50.0, 0.0, 1e5, "", "choice: once, on reaching the track's end")


@dataclass(frozen=True)
class EpisodeConfig(Validated):
    """Timing and episode end."""

    control_dt_s: float = param(
        0.02,
        0.002,
        1.0,
        "s",
        "choice: a 50 Hz line-tracing loop (the paper's Arduino Due loop period is not given)",
    )
    max_time_s: float = param(
        60.0, 0.1, 3600.0, "s", "choice: a RoboCup Junior run's time for one course and more"
    )
    lost_timeout_s: float = param(
        1.0,
        0.0,
        60.0,
        "s",
        "choice: the line is lost after 1 s without any spot over it (gaps count as line)",
    )
    finish_margin_m: float = param(
        0.02, 0.0, 0.5, "m", "choice: the track ends this short of its last point"
    )
    field_margin_m: float = param(
        0.0, 0.0, 1.0, "m", "choice: the robot's centre may stray this far beyond the tiles"
    )


@dataclass(frozen=True)
class RandomizationConfig(PlatformRandomization):
    """Domain randomisation: the platform's (all off by default, as in PersonFollow's)."""


@dataclass(frozen=True)
class LineTraceConfig(TaskConfig):
    """Everything one line-tracing robot, its sensor grid and its course need."""

    platform: PlatformConfig = field(default_factory=MecanumConfig)
    sensor: LightGridConfig = field(default_factory=LightGridConfig)
    track: TrackConfig = field(default_factory=TrackConfig)
    start: StartConfig = field(default_factory=StartConfig)
    reward: RewardConfig = field(default_factory=RewardConfig)
    episode: EpisodeConfig = field(default_factory=EpisodeConfig)
    randomization: RandomizationConfig = field(default_factory=RandomizationConfig)

    @property
    def max_steps(self) -> int:
        """Control steps of ``episode.max_time_s``."""
        return max(1, round(self.episode.max_time_s / self.episode.control_dt_s))


PAPER = LineTraceConfig()
"""The mecanum paper's task as closely as the sources allow (reference §2): the default."""

IDEAL = PAPER.replace(
    sensor={"noise_std": 0.0, "ambient_max": 0.0, "gain_spread": 0.0},
    start={"lateral_spread_m": 0.0, "heading_spread_deg": 0.0},
    motor={"gain_spread": 0.0, "start_spread": 0.0},
    floor={"spread": 0.0},
)
"""Noiseless sensing, no motor or floor spread (on any platform), an exact start: for debugging
and tests.

The paper's robot otherwise, its gear friction included (reference §2: motors stall at low
duty): with every motor alike, none starts under ``start_duty`` (41 of 255, 16 %), that is a
straight command under 0.24 m/s on the open-loop mecanum base. The tuned ``pid`` law (0.2 m/s)
stands still here, where under :data:`PAPER` the motors' spread and the sensor noise let it
move in fits; ``drive={"mode": "pid"}`` (wheel PIDs on the encoders) runs it."""

NOISY = PAPER.replace(
    sensor={"noise_std": 0.08, "ambient_max": 0.3, "ambient_flicker": 0.4, "gain_spread": 0.15},
    randomization=RandomizationConfig(
        wheel_radius_error=0.02,
        track_width_error=0.03,
        encoder_noise_counts=1.0,
        friction_spread=0.3,
        push_prob=0.005,
        push_speed_mps=0.1,
    ),
)
"""Harsher light (noise, ambient light, sensor spread) and every platform randomisation."""

PRESETS: dict[str, LineTraceConfig] = {"paper": PAPER, "ideal": IDEAL, "noisy": NOISY}


def config_from_text(text: str) -> str | dict[str, Any]:
    """A command line's ``--config`` for this task (see
    :func:`follow_env.tasks.config.config_from_text`), checked against :data:`PAPER`."""
    return task_config_from_text(text, LineTraceConfig, PRESETS, PAPER)

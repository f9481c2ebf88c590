"""Configuration of the simulated robot, sensors, person, scenario, reward and episode.

Every number of the simulation lives here, in frozen dataclasses validated in ``__post_init__``.
Each field declares its unit, its allowed range and where its default comes from:

* ``SPEC §n``: the reference system (``shared/SPEC.md``);
* ``datasheet``: Intel RealSense D435i public figures;
* ``choice``: the sources are silent; the reason for the value is given.

A wrong value raises ``ValueError`` naming the field, the value and the allowed range, e.g.
``MotorConfig.time_constant_s=-1.0 is out of range: must be in (0, 2] s``.

Presets are named instances: :data:`THESIS` (the reference robot as closely as the sources
allow; the default), :data:`IDEAL` (perfect sensing, for debugging and tests) and :data:`NOISY`
(harsher sensing). ``EnvConfig.from_overrides`` maps ``gym.make`` keyword arguments onto them.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

__all__ = [
    "IDEAL",
    "NOISY",
    "PRESETS",
    "RANDOMIZED",
    "THESIS",
    "CameraConfig",
    "EncoderConfig",
    "EnvConfig",
    "EpisodeConfig",
    "MotorConfig",
    "PIDConfig",
    "PerceptionConfig",
    "PersonConfig",
    "RandomizationConfig",
    "RewardConfig",
    "RobotConfig",
    "ScenarioConfig",
    "field_spec",
]


def param(
    default: float | int | str,
    lo: float | None = None,
    hi: float | None = None,
    unit: str = "",
    doc: str = "",
    *,
    lo_open: bool = False,
    integer: bool = False,
    choices: tuple[str, ...] | None = None,
) -> Any:
    """A dataclass field carrying its range, unit and documentation as metadata.

    :param default: the default value.
    :param lo: lowest allowed value (``None``: unbounded).
    :param hi: highest allowed value, inclusive (``None``: unbounded).
    :param unit: the unit, e.g. ``"m"``, ``"rad/s"``, ``"%"``.
    :param doc: where the default comes from.
    :param lo_open: ``lo`` itself is excluded.
    :param integer: the value must be an ``int``.
    :param choices: for string fields, the allowed values.
    """
    meta = {
        "lo": lo,
        "hi": hi,
        "unit": unit,
        "doc": doc,
        "lo_open": lo_open,
        "integer": integer,
        "choices": choices,
    }
    return field(default=default, metadata=meta)


def field_spec(cls: type, name: str) -> Mapping[str, Any]:
    """The range metadata of field ``name`` of config class ``cls`` (used by tests and docs)."""
    return next(f.metadata for f in dataclasses.fields(cls) if f.name == name)


def _range_text(meta: Mapping[str, Any]) -> str:
    if meta["choices"] is not None:
        return "one of " + ", ".join(repr(c) for c in meta["choices"])
    lo, hi = meta["lo"], meta["hi"]
    left = "(" if meta["lo_open"] else "["
    lo_s = "-inf" if lo is None else f"{lo:g}"
    hi_s = "inf" if hi is None else f"{hi:g}"
    kind = "an integer in " if meta["integer"] else ""
    return f"{kind}{left}{lo_s}, {hi_s}]" + (f" {meta['unit']}" if meta["unit"] else "")


def _fail(obj: object, name: str, value: object, meta: Mapping[str, Any]) -> None:
    raise ValueError(
        f"{type(obj).__name__}.{name}={value!r} is out of range: must be {_range_text(meta)}"
    )


def _validate_fields(obj: object) -> None:
    """Check every field of a config dataclass against its declared range."""
    for f in dataclasses.fields(obj):  # type: ignore[arg-type]
        meta = f.metadata
        if "lo" not in meta:
            continue
        value = getattr(obj, f.name)
        if meta["choices"] is None and isinstance(f.default, str):
            continue  # free-form string (e.g. a registry name): checked by its class
        if meta["choices"] is not None:
            if value not in meta["choices"]:
                _fail(obj, f.name, value, meta)
            continue
        if isinstance(value, bool) or not isinstance(value, int | float):
            _fail(obj, f.name, value, meta)
        if meta["integer"] and not isinstance(value, int):
            _fail(obj, f.name, value, meta)
        if not math.isfinite(value):
            _fail(obj, f.name, value, meta)
        lo, hi = meta["lo"], meta["hi"]
        if lo is not None and (value < lo or (meta["lo_open"] and value == lo)):
            _fail(obj, f.name, value, meta)
        if hi is not None and value > hi:
            _fail(obj, f.name, value, meta)


class _Validated:
    """Mixin: validate all ranged fields after construction."""

    def __post_init__(self) -> None:
        _validate_fields(self)


@dataclass(frozen=True)
class RobotConfig(_Validated):
    """Geometry of the differential-drive base (SPEC §1.1: the thesis gives no r, L or size)."""

    wheel_radius_m: float = param(
        0.075,
        0.01,
        0.5,
        "m",
        "choice: 150 mm wheels, usual for a small indoor transport robot",
        lo_open=True,
    )
    track_width_m: float = param(
        0.40,
        0.05,
        2.0,
        "m",
        "choice: distance between the wheels of a ~0.5 m wide base",
        lo_open=True,
    )
    footprint_length_m: float = param(
        0.50, 0.05, 3.0, "m", "choice: rectangular footprint, centred on the wheel axle"
    )
    footprint_width_m: float = param(
        0.45, 0.05, 3.0, "m", "choice: footprint width, wheels included"
    )

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.footprint_width_m < self.track_width_m:
            raise ValueError(
                f"RobotConfig.footprint_width_m={self.footprint_width_m!r} is out of range: "
                f"must be >= track_width_m ({self.track_width_m} m), the wheels are inside it"
            )


@dataclass(frozen=True)
class MotorConfig(_Validated):
    """DC gear-motor model, one per wheel: first-order lag from duty to speed, with friction.

    Steady-state wheel speed for duty ``u`` (%): ``no_load * sign(u) * (|u| - friction) /
    (100 - friction)`` when ``|u| > friction``, else 0; a stopped wheel stays stopped while
    ``|u| < stall_duty_pct`` (static friction; SPEC §2 reports such stalls on hardware).
    """

    no_load_speed_radps: float = param(
        20.0, 1.0, 200.0, "rad/s", "choice: ~190 rpm at the wheel, i.e. 1.5 m/s with 75 mm wheels"
    )
    time_constant_s: float = param(
        0.08, 0.001, 2.0, "s", "choice: mechanical lag of a loaded gear-motor", lo_open=True
    )
    friction_duty_pct: float = param(
        4.0, 0.0, 50.0, "%", "choice: Coulomb friction expressed as the duty it eats"
    )
    stall_duty_pct: float = param(
        8.0, 0.0, 50.0, "%", "choice: static friction; SPEC §2 observes stalls at low duty"
    )
    max_duty_pct: float = param(
        99.0, 1.0, 100.0, "%", "SPEC §1.1: the gate driver cannot hold 100 %"
    )
    gain_spread: float = param(
        0.02, 0.0, 0.5, "", "choice: std of a per-episode, per-motor gain factor (SPEC §2 P_i)"
    )

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.stall_duty_pct < self.friction_duty_pct:
            raise ValueError(
                f"MotorConfig.stall_duty_pct={self.stall_duty_pct!r} is out of range: must be "
                f">= friction_duty_pct ({self.friction_duty_pct} %)"
            )
        if self.max_duty_pct <= self.friction_duty_pct:
            raise ValueError(
                f"MotorConfig.max_duty_pct={self.max_duty_pct!r} is out of range: must be "
                f"> friction_duty_pct ({self.friction_duty_pct} %)"
            )


@dataclass(frozen=True)
class EncoderConfig(_Validated):
    """Quadrature wheel encoder and the firmware's speed estimate (SPEC §1.1)."""

    ppr: int = param(2048, 1, 1_000_000, "pulses/rev", "SPEC §1.1: AMT102-V", integer=True)
    quadrature: int = param(4, 1, 4, "counts/pulse", "SPEC §1.1: counted in 4x mode", integer=True)
    sample_period_s: float = param(
        0.01, 0.0005, 0.1, "s", "SPEC §1.1: firmware estimates speed every 10 ms"
    )
    speed_quantum_mps: float = param(
        0.001,
        0.0,
        0.1,
        "m/s",
        "SPEC §1.1: speed sent as an int16 in mm/s (truncated); 0 disables the quantisation",
    )

    @property
    def counts_per_rev(self) -> int:
        """Encoder counts per wheel revolution (``ppr * quadrature``)."""
        return self.ppr * self.quadrature


@dataclass(frozen=True)
class PIDConfig(_Validated):
    """Wheel speed PID with the low-pass filtered derivative of SPEC §1.2.

    Input: target minus measured linear wheel speed (m/s); output: duty (%). The thesis gives no
    gains; the defaults are tuned here (``tests/follow_env/test_drive.py`` shows the step
    response settles within 0.3 s without sustained oscillation).
    """

    kp: float = param(120.0, 0.0, 1e4, "%/(m/s)", "choice: tuned, see class docstring")
    ki: float = param(1500.0, 0.0, 1e5, "%/m", "choice: tuned, see class docstring")
    kd: float = param(0.5, 0.0, 1e3, "%·s/(m/s)", "choice: tuned, see class docstring")
    tau_s: float = param(0.01, 0.0, 1.0, "s", "SPEC §1.2: derivative low-pass time constant")
    anti_windup: str = param(
        "clamp",
        doc="choice: stop integrating while the duty is saturated and the error "
        "pushes further into saturation ('none' disables it)",
        choices=("clamp", "none"),
    )


@dataclass(frozen=True)
class CameraConfig(_Validated):
    """Pinhole colour camera with aligned depth (Intel RealSense D435i, SPEC §1.3).

    Intrinsics derive from the field of view: ``fy = (height/2) / tan(vfov/2)``, ``fx = fy``
    (square pixels), principal point at the image centre. The D435i colour sensor has a
    69 x 42 deg field of view at 16:9; the 4:3 stream of 640 x 480 px (the usual detector input;
    the thesis does not give its resolution) crops it to about 55 x 42 deg, fx = fy ~ 615 px.
    Extrinsics: the camera sits at ``mount_*`` in the robot frame (x forward, y left, z up),
    looking forward, tilted by ``pitch_deg`` (positive looks down).
    """

    width_px: int = param(640, 16, 4096, "px", "choice: see class docstring", integer=True)
    height_px: int = param(480, 16, 4096, "px", "choice: see class docstring", integer=True)
    vfov_deg: float = param(
        42.5, 5.0, 150.0, "deg", "datasheet: D435i colour vertical field of view"
    )
    mount_x_m: float = param(0.20, -2.0, 2.0, "m", "choice: at the front of the base")
    mount_y_m: float = param(0.0, -2.0, 2.0, "m", "choice: on the centre line")
    mount_z_m: float = param(0.60, 0.05, 3.0, "m", "choice: on a mast above the cargo deck")
    pitch_deg: float = param(0.0, -60.0, 60.0, "deg", "choice: level")
    yaw_deg: float = param(0.0, -90.0, 90.0, "deg", "choice: straight ahead")
    depth_min_m: float = param(0.1, 0.0, 5.0, "m", "SPEC §1.3: range 0.1 to 10 m")
    depth_max_m: float = param(10.0, 0.5, 100.0, "m", "SPEC §1.3: range 0.1 to 10 m")
    depth_focal_px: float = param(
        424.0, 10.0, 5000.0, "px", "SPEC §1.3: depth focal length at 848 px width"
    )
    depth_baseline_m: float = param(0.05, 0.001, 1.0, "m", "SPEC §1.3: stereo baseline 50 mm")
    depth_subpixel: float = param(
        0.08, 0.0, 1.0, "px", "SPEC §1.3: RMS = Z^2 subpixel / (f B); 0.08 typical, 0.03 tuned"
    )
    depth_unit_m: float = param(
        0.001, 0.0, 0.1, "m", "datasheet: depth is reported in whole millimetres; 0 = exact"
    )
    depth_invalid_prob: float = param(
        0.02, 0.0, 1.0, "", "choice: share of random invalid (0) depth pixels"
    )

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.depth_max_m <= self.depth_min_m:
            raise ValueError(
                f"CameraConfig.depth_max_m={self.depth_max_m!r} is out of range: must be > "
                f"depth_min_m ({self.depth_min_m} m)"
            )

    @property
    def fy(self) -> float:
        """Vertical focal length (px) from the vertical field of view."""
        return (self.height_px / 2.0) / math.tan(math.radians(self.vfov_deg) / 2.0)

    @property
    def fx(self) -> float:
        """Horizontal focal length (px): square pixels, so equal to ``fy``."""
        return self.fy

    @property
    def cx(self) -> float:
        """Principal point column (px): the image centre."""
        return self.width_px / 2.0

    @property
    def cy(self) -> float:
        """Principal point row (px): the image centre."""
        return self.height_px / 2.0

    @property
    def hfov_deg(self) -> float:
        """Horizontal field of view (deg) implied by ``fx`` and the width."""
        return math.degrees(2.0 * math.atan(self.cx / self.fx))


@dataclass(frozen=True)
class PerceptionConfig(_Validated):
    """Detector model, first-detection rule and distance filter (SPEC §1.3, §1.4)."""

    latency_frames: int = param(
        1, 0, 8, "frames", "choice: the detector result arrives one 0.1 s frame late", integer=True
    )
    miss_prob: float = param(0.03, 0.0, 1.0, "", "choice: independent misses per frame")
    burst_start_prob: float = param(
        0.01, 0.0, 1.0, "", "SPEC §1.3: bursts of occlusion; chance per frame that one starts"
    )
    burst_mean_frames: float = param(
        5.0, 1.0, 1000.0, "frames", "choice: mean length of a burst (geometric)"
    )
    center_jitter_frac: float = param(
        0.05, 0.0, 1.0, "of box height", "SPEC §1.3: centre jitter std ~ 1/20 of box height"
    )
    size_jitter_frac: float = param(
        0.05, 0.0, 1.0, "of box size", "choice: width/height jitter std"
    )
    min_visible_fraction: float = param(
        0.3, 0.0, 1.0, "", "choice: a body less visible than this is not detected"
    )
    min_box_height_px: float = param(
        10.0, 0.0, 1000.0, "px", "choice: smaller boxes are below the detector's resolution"
    )
    filter_history: int = param(
        5, 1, 32, "samples", "choice: SPEC §1.4 leaves the history length open", integer=True
    )
    association: str = param(
        "first",
        doc="SPEC §1.4: the robot follows the first detection ('first'); 'tracker' keeps the "
        "detection that looks like the target and best overlaps its predicted box (appearance "
        "and IoU gates, constant-velocity prediction), the fix for bystanders who steal it",
        choices=("first", "tracker"),
    )
    tracker_iou_gate: float = param(
        0.1, 0.0, 1.0, "", "choice: least IoU with the predicted box for a detection to match"
    )
    tracker_appearance_gate: float = param(
        0.15,
        0.0,
        1.0,
        "",
        "choice: the tracker takes a detection as the target's only if its "
        "appearance is this close to what it learnt (re-identification)",
    )
    appearance_noise: float = param(
        0.05,
        0.0,
        1.0,
        "",
        "choice: std of the appearance value a detection carries; people "
        "look like uniform draws on [0, 1], so two of them look alike now and then",
    )
    tracker_coast_frames: int = param(
        10, 0, 1000, "frames", "choice: frames the tracker waits for its target (1 s)", integer=True
    )
    detection_order: str = param(
        "area",
        doc="choice: the detector lists boxes by confidence, modelled as box area (largest first)",
        choices=("area",),
    )


@dataclass(frozen=True)
class PersonConfig(_Validated):
    """The followed person: an upright box body and a human speed profile."""

    height_m: float = param(1.7, 0.5, 2.5, "m", "issue: about 1.7 m tall")
    width_m: float = param(0.45, 0.1, 1.5, "m", "issue: about 0.45 m wide (shoulders)")
    depth_m: float = param(0.25, 0.05, 1.5, "m", "choice: chest depth")
    cruise_speed_mps: float = param(
        1.0, 0.05, 3.0, "m/s", "choice: ~1 m/s walking pace behind a transport robot"
    )
    speed_spread_mps: float = param(
        0.1, 0.0, 1.0, "m/s", "choice: per-episode cruise speed is uniform within +- this"
    )
    accel_mps2: float = param(0.5, 0.05, 5.0, "m/s^2", "choice: gait start from rest")
    decel_mps2: float = param(0.8, 0.05, 5.0, "m/s^2", "choice: gait stop")
    social_radius_m: float = param(
        0.7, 0.0, 5.0, "m", "choice: people step aside from others closer than this"
    )
    social_strength_mps2: float = param(
        1.5, 0.0, 50.0, "m/s^2", "choice: strength of that sideways social force"
    )
    lateral_accel_mps2: float = param(
        0.8, 0.05, 5.0, "m/s^2", "choice: people slow down in turns to keep v^2/R below this"
    )

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.speed_spread_mps >= self.cruise_speed_mps:
            raise ValueError(
                f"PersonConfig.speed_spread_mps={self.speed_spread_mps!r} is out of range: "
                f"must be < cruise_speed_mps ({self.cruise_speed_mps} m/s)"
            )


@dataclass(frozen=True)
class ScenarioConfig(_Validated):
    """Where the person walks. Scenarios are registered by name in ``follow_env.scenarios``."""

    name: str = param("straight", doc="SPEC §1.6 condition 1")
    walk_length_m: float = param(10.0, 0.5, 500.0, "m", "SPEC §1.6: the person walks 10 m")
    start_distance_m: float = param(
        1.0, 0.4, 8.0, "m", "SPEC §1.6: the person starts 1 m in front (camera to body front)"
    )
    curve_turn_deg: float = param(
        90.0,
        -360.0,
        360.0,
        "deg",
        "choice: 'curve' turns this much (left > 0) over its whole walk; 90 deg over 10 m is a "
        "radius of 6.4 m, a corridor corner taken wide",
    )
    room_length_m: float = param(24.0, 4.0, 200.0, "m", "choice: a hall with room to walk")
    room_width_m: float = param(16.0, 4.0, 200.0, "m", "choice: a hall with room to walk")
    random_duration_s: float = param(
        40.0, 2.0, 600.0, "s", "choice: length of a 'random' walk in time"
    )
    stop_prob: float = param(
        0.25, 0.0, 1.0, "", "choice: chance that a 'random' leg ends in a stop"
    )
    settle_s: float = param(
        2.0, 0.0, 60.0, "s", "choice: time the episode runs on after the walk ends"
    )

    def __post_init__(self) -> None:
        super().__post_init__()
        from follow_env.scenarios import SCENARIOS  # registry lives with the scenarios

        if self.name not in SCENARIOS:
            raise ValueError(
                f"ScenarioConfig.name={self.name!r} is out of range: must be one of "
                + ", ".join(repr(n) for n in sorted(SCENARIOS))
            )


@dataclass(frozen=True)
class RandomizationConfig(_Validated):
    """Domain randomisation and disturbances, drawn per episode (and per step for pushes and
    encoder noise) from the episode's own streams, never from the actions. All off by default;
    the ``randomized`` preset switches them on."""

    wheel_radius_error: float = param(
        0.0, 0.0, 0.2, "", "std of the real/assumed wheel radius ratio minus 1"
    )
    track_width_error: float = param(
        0.0, 0.0, 0.2, "", "std of the real/assumed track width ratio minus 1"
    )
    encoder_noise_counts: float = param(
        0.0, 0.0, 100.0, "counts", "std of extra counts read per 10 ms tick"
    )
    camera_tilt_deg: float = param(
        0.0, 0.0, 20.0, "deg", "std of the camera's real pitch around its configured one"
    )
    detector_level_spread: float = param(
        0.0, 0.0, 1.0, "", "jitter, miss and burst rates scale by U(1 - s, 1 + s)"
    )
    latency_frames_max: int = param(
        0, 0, 8, "frames", "latency is drawn from [latency_frames, this] (0: fixed)", integer=True
    )
    depth_noise_scale_max: float = param(1.0, 1.0, 10.0, "", "depth noise scales by U(1, this)")
    friction_spread: float = param(
        0.0, 0.0, 0.9, "", "motor friction and stall duty scale by U(1 - s, 1 + s) (floor)"
    )
    push_prob: float = param(0.0, 0.0, 1.0, "/step", "chance of a push in a control step")
    push_speed_mps: float = param(
        0.3, 0.0, 5.0, "m/s", "a push moves the robot at this speed for one step"
    )


@dataclass(frozen=True)
class RewardConfig(_Validated):
    """Dense following reward, from ground truth (see ``PersonFollowEnv`` docstring)."""

    target_distance_m: float = param(1.0, 0.3, 10.0, "m", "SPEC §1.5: desired distance 1.0 m")
    alive_bonus: float = param(1.0, 0.0, 100.0, "/step", "choice: reward for following at all")
    distance_weight: float = param(
        1.0, 0.0, 100.0, "/m", "choice: min(|d - d_ref|, 1 m) penalty (capped, see the env)"
    )
    offset_weight: float = param(
        1.0, 0.0, 100.0, "/half-width", "choice: |offset| / (width/2) penalty"
    )
    accel_weight: float = param(
        0.02, 0.0, 100.0, "/(m/s^2)", "choice: smoothness, |robot acceleration| penalty"
    )
    lost_penalty: float = param(
        1.0, 0.0, 1000.0, "/step", "choice: person outside the camera frame"
    )
    collision_penalty: float = param(50.0, 0.0, 1e5, "", "choice: once, on a collision")


@dataclass(frozen=True)
class EpisodeConfig(_Validated):
    """Timing and episode end."""

    control_dt_s: float = param(0.1, 0.01, 1.0, "s", "SPEC §1.5/§1.6: 0.1 s sampling")
    max_steps: int = param(
        1000,
        1,
        1_000_000,
        "steps",
        "choice: a hard cap (100 s) beyond every built-in walk",
        integer=True,
    )
    lost_timeout_s: float = param(
        3.0, 0.0, 1000.0, "s", "issue: terminate after 3 s without a detection"
    )
    person_clearance_m: float = param(
        0.3, 0.0, 5.0, "m", "issue: closer than 0.3 m to the person is a collision"
    )


_SECTIONS: dict[str, type] = {
    "robot": RobotConfig,
    "motor": MotorConfig,
    "encoder": EncoderConfig,
    "pid": PIDConfig,
    "camera": CameraConfig,
    "perception": PerceptionConfig,
    "person": PersonConfig,
    "scenario": ScenarioConfig,
    "reward": RewardConfig,
    "episode": EpisodeConfig,
    "randomization": RandomizationConfig,
}


@dataclass(frozen=True)
class EnvConfig:
    """Everything one simulated robot, its sensors and its task need."""

    robot: RobotConfig = field(default_factory=RobotConfig)
    motor: MotorConfig = field(default_factory=MotorConfig)
    encoder: EncoderConfig = field(default_factory=EncoderConfig)
    pid: PIDConfig = field(default_factory=PIDConfig)
    camera: CameraConfig = field(default_factory=CameraConfig)
    perception: PerceptionConfig = field(default_factory=PerceptionConfig)
    person: PersonConfig = field(default_factory=PersonConfig)
    scenario: ScenarioConfig = field(default_factory=ScenarioConfig)
    reward: RewardConfig = field(default_factory=RewardConfig)
    episode: EpisodeConfig = field(default_factory=EpisodeConfig)
    randomization: RandomizationConfig = field(default_factory=RandomizationConfig)

    def __post_init__(self) -> None:
        for name, cls in _SECTIONS.items():
            value = getattr(self, name)
            if not isinstance(value, cls):
                raise ValueError(
                    f"EnvConfig.{name}={value!r} is out of range: must be a {cls.__name__}"
                )
        ratio = self.episode.control_dt_s / self.encoder.sample_period_s
        if abs(ratio - round(ratio)) > 1e-9 or round(ratio) < 1:
            raise ValueError(
                f"EpisodeConfig.control_dt_s={self.episode.control_dt_s!r} is out of range: "
                f"must be a whole multiple of encoder.sample_period_s "
                f"({self.encoder.sample_period_s} s)"
            )

        lat_max = self.randomization.latency_frames_max
        if lat_max and lat_max < self.perception.latency_frames:
            raise ValueError(
                f"RandomizationConfig.latency_frames_max={lat_max!r} is out of range: must be 0 "
                f"or >= perception.latency_frames ({self.perception.latency_frames})"
            )
        if self.sub_steps > 4096:
            raise ValueError(
                f"EpisodeConfig.control_dt_s={self.episode.control_dt_s!r} is out of range: at "
                "most 4096 encoder periods per control step"
            )

    @property
    def sub_steps(self) -> int:
        """Inner drive-loop steps per control step (10 with the defaults)."""
        return round(self.episode.control_dt_s / self.encoder.sample_period_s)

    @property
    def max_wheel_speed_mps(self) -> float:
        """Highest steady linear wheel speed the motors reach at the duty limit (m/s)."""
        m = self.motor
        frac = (m.max_duty_pct - m.friction_duty_pct) / (100.0 - m.friction_duty_pct)
        return m.no_load_speed_radps * self.robot.wheel_radius_m * frac

    @property
    def max_speed_mps(self) -> float:
        """Action bound on forward speed ``v`` (m/s): both wheels at their top speed."""
        return self.max_wheel_speed_mps

    @property
    def max_turn_rate_radps(self) -> float:
        """Action bound on turn rate ``w`` (rad/s): wheels at top speed in opposite senses."""
        return 2.0 * self.max_wheel_speed_mps / self.robot.track_width_m

    def replace(self, **sections: Any) -> EnvConfig:
        """A copy with whole sections replaced or updated from mappings of field values."""
        return self.from_overrides(self, sections)

    @classmethod
    def from_overrides(cls, base: EnvConfig, overrides: Mapping[str, Any]) -> EnvConfig:
        """Apply ``{"section": {"field": value} | SectionConfig}`` (or ``"section.field"``
        keys) to ``base``. Unknown sections or fields raise ``ValueError`` listing the known
        ones; values are validated by the sections themselves."""
        updates: dict[str, dict[str, Any]] = {}
        whole: dict[str, Any] = {}
        for key, value in overrides.items():
            section, _, fname = key.partition(".")
            if section not in _SECTIONS:
                raise ValueError(
                    f"unknown config section {section!r}: known sections are "
                    + ", ".join(_SECTIONS)
                )
            if fname:
                updates.setdefault(section, {})[fname] = value
            elif isinstance(value, _SECTIONS[section]):
                whole[section] = value
            elif isinstance(value, Mapping):
                updates.setdefault(section, {}).update(value)
            else:
                raise ValueError(
                    f"EnvConfig.{section}={value!r} is out of range: must be a "
                    f"{_SECTIONS[section].__name__} or a mapping of its fields"
                )
        new_sections: dict[str, Any] = {}
        for section in _SECTIONS:
            current = whole.get(section, getattr(base, section))
            if section in updates:
                known = {f.name for f in dataclasses.fields(current)}
                for fname in updates[section]:
                    if fname not in known:
                        raise ValueError(
                            f"unknown field {section}.{fname}: {type(current).__name__} has "
                            + ", ".join(sorted(known))
                        )
                current = dataclasses.replace(current, **updates[section])
            new_sections[section] = current
        return cls(**new_sections)

    def to_dict(self) -> dict[str, dict[str, Any]]:
        """Plain nested dict (for run folders and reports)."""
        return dataclasses.asdict(self)


THESIS = EnvConfig()
"""The reference robot as closely as the sources allow (SPEC §1): the default."""

IDEAL = EnvConfig(
    motor=MotorConfig(gain_spread=0.0),
    camera=CameraConfig(depth_subpixel=0.0, depth_unit_m=0.0, depth_invalid_prob=0.0),
    perception=PerceptionConfig(
        latency_frames=0,
        miss_prob=0.0,
        burst_start_prob=0.0,
        center_jitter_frac=0.0,
        size_jitter_frac=0.0,
    ),
)
"""Perfect sensing: no detector noise, no latency, exact depth. For debugging and tests."""

NOISY = EnvConfig(
    motor=MotorConfig(gain_spread=0.05),
    camera=CameraConfig(depth_invalid_prob=0.05),
    perception=PerceptionConfig(
        latency_frames=2,
        miss_prob=0.10,
        burst_start_prob=0.03,
        burst_mean_frames=8.0,
        center_jitter_frac=0.08,
        size_jitter_frac=0.08,
    ),
)
"""Harsher sensing than the thesis robot: a slower detector, more misses and occlusions."""

RANDOMIZED = NOISY.replace(
    randomization=RandomizationConfig(
        wheel_radius_error=0.02,
        track_width_error=0.03,
        encoder_noise_counts=1.0,
        camera_tilt_deg=2.0,
        detector_level_spread=0.5,
        latency_frames_max=3,
        depth_noise_scale_max=2.0,
        friction_spread=0.3,
        push_prob=0.01,
        push_speed_mps=0.3,
    )
)
"""The noisy preset with every domain randomisation and pushes on: for robust training."""

PRESETS: dict[str, EnvConfig] = {
    "thesis": THESIS,
    "ideal": IDEAL,
    "noisy": NOISY,
    "randomized": RANDOMIZED,
}

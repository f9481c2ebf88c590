"""What every platform shares: the body's state, the parameters every base has, the protocol.

A platform is one module (``diff_drive.py``, ``mecanum.py``) that defines its config
sections, its parameter and state blocks, its action, and two compiled functions the kernel of
every task calls for each lane (:mod:`follow_env.sim.compose`):

* ``reset(prm, st, body)``: the lane starts an episode at rest (state already zeroed);
* ``drive(prm, st, body, action, keys, step)``: one control step: the action through the
  platform's inverse kinematics, the inner wheel loop, and the pose (``body``).

``body`` is the record every platform writes and every task and sensor reads (:data:`BODY`):
the pose and twist in SI, and the speed and acceleration *as the robot measures them*
(encoder-based), which is what the reference robot logged.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from follow_env.sim import body, streams
from follow_env.sim.config import Sections, Validated, param
from follow_env.sim.jit import njit
from follow_env.sim.rng import LaneRandom, uniform_at
from follow_env.sim.schema import Block, Field, f8

__all__ = [
    "BASE_PARAMS",
    "BODY",
    "ENCODER_NOISE",
    "FRICTION",
    "GEOMETRY_ERROR",
    "MOTOR_GAINS",
    "PUSH",
    "ActionField",
    "Platform",
    "PlatformConfig",
    "PlatformRandomization",
    "push_velocity",
]

# The body record lives in the sim layer (every robot has one); platforms write it.
BODY = body.BODY


def base_param_fields() -> list[Field]:
    """The parameters every platform has (first in its parameter block)."""
    return [
        f8(
            "foot_l",
            "m",
            "footprint length along the heading",
            source="platform.footprint_length_m",
        ),
        f8("foot_w", "m", "footprint width", source="platform.footprint_width_m"),
        f8("dt", "s", "control period", source="episode.control_dt_s"),
        f8(
            "push_p", "/step", "chance of a push per control step", source="randomization.push_prob"
        ),
        f8(
            "push_v",
            "m/s",
            "push speed for one control step",
            source="randomization.push_speed_mps",
        ),
    ]


BASE_PARAMS = Block("platform_base", "parameters every platform has", base_param_fields())

# Draws every platform may make, in the one randomness table (follow_env.sim.streams).
GEOMETRY_ERROR = streams.per_episode(
    "platform.geometry_error",
    streams.RANDOMIZE,
    0,
    2,
    space="normal",
    doc="real/assumed ratios of the drive geometry (wheel radius, track width)",
)
FRICTION = streams.per_episode(
    "platform.friction",
    streams.RANDOMIZE,
    8,
    1,
    space="uniform",
    doc="motor friction and stall duty scale",
)
MOTOR_GAINS = streams.per_episode(
    "platform.motor_gains",
    streams.MOTOR,
    0,
    8,
    space="normal",
    doc="one gain factor per motor (manufacturing spread), motor i at offset i",
)
PUSH = streams.per_step(
    "platform.push",
    streams.RANDOMIZE,
    0,
    2,
    space="uniform",
    doc="whether the robot is pushed this step, and the push's direction",
)
ENCODER_NOISE_KEY = streams.domain(
    "encoder_noise", streams.RANDOMIZE, 0xA0761D6478BD642F, "extra encoder counts per tick"
)
ENCODER_NOISE = streams.per_step(
    "platform.encoder_noise",
    ENCODER_NOISE_KEY,
    0,
    4096,
    stride=4096,
    space="normal",
    doc="one normal pair per 10 ms tick (counter step * 4096 + tick)",
)
ENCODER_NOISE_CONST = np.uint64(ENCODER_NOISE_KEY.constant)
_RANDOMIZE = streams.RANDOMIZE.index
_PUSH_STRIDE = PUSH.stride


@njit(inline="always")
def push_velocity(push_p: float, push_v: float, keys: np.ndarray, step: int) -> tuple[float, float]:
    """A push (randomisation): with chance ``push_p`` per step the robot is shoved at
    ``push_v`` (m/s) in a random direction for this control step; ``(0, 0)`` otherwise."""
    krand = keys[_RANDOMIZE]
    if push_p > 0.0 and uniform_at(krand, step * _PUSH_STRIDE) < push_p:
        ang = 2.0 * np.pi * uniform_at(krand, step * _PUSH_STRIDE + 1)
        return push_v * np.cos(ang), push_v * np.sin(ang)
    return 0.0, 0.0


@dataclass(frozen=True)
class PlatformRandomization(Validated):
    """The randomisation every platform reads (``cfg.randomization``): a task's randomisation
    section subclasses this and adds its own fields. All off by default.

    (PersonFollow's ``RandomizationConfig`` declares the same fields itself, in an order its
    run folders already record.)
    """

    wheel_radius_error: float = param(
        0.0, 0.0, 0.2, "", "std of the real/assumed wheel radius ratio minus 1"
    )
    track_width_error: float = param(
        0.0, 0.0, 0.2, "", "std of the real/assumed track width ratio minus 1"
    )
    encoder_noise_counts: float = param(
        0.0, 0.0, 100.0, "counts", "std of extra counts read per 10 ms tick"
    )
    friction_spread: float = param(
        0.0, 0.0, 0.9, "", "motor friction and stall duty scale by U(1 - s, 1 + s) (floor)"
    )
    push_prob: float = param(0.0, 0.0, 1.0, "/step", "chance of a push in a control step")
    push_speed_mps: float = param(
        0.3, 0.0, 5.0, "m/s", "a push moves the robot at this speed for one step"
    )


@dataclass(frozen=True)
class PlatformConfig(Sections):
    """Base of a platform's configuration: its sections (geometry, motors, encoders, ...).

    Subclasses set ``NAME`` and provide the geometry every task needs.
    """

    NAME: ClassVar[str] = ""
    #: The platform's manufacturing spread, drawn per episode (its motors' gains, their static
    #: friction, the floor's traction), as dotted ``section.field`` names. A configuration
    #: with all of them 0 (the ``ideal`` presets) keeps none when another platform is named
    #: (:meth:`without_spread`, :func:`follow_env.tasks.config.named_platform`).
    SPREADS: ClassVar[tuple[str, ...]] = ()

    def spread(self) -> dict[str, float]:
        """The fields of :data:`SPREADS` and their values (each a std or a half-range, 1)."""
        out: dict[str, float] = {}
        for name in self.SPREADS:
            section, _, key = name.partition(".")
            out[name] = float(getattr(getattr(self, section), key))
        return out

    def without_spread(self) -> Any:
        """This configuration with every field of :data:`SPREADS` at 0: every motor alike."""
        return type(self).from_overrides(self, dict.fromkeys(self.SPREADS, 0.0))

    @property
    def footprint_length_m(self) -> float:  # pragma: no cover - each platform overrides
        raise NotImplementedError

    @property
    def footprint_width_m(self) -> float:  # pragma: no cover - each platform overrides
        raise NotImplementedError

    def check_control_period(self, control_dt_s: float) -> None:
        """Raise ``ValueError`` if the platform cannot run at this control period."""


@dataclass(frozen=True)
class ActionField:
    """One entry of a platform's action: name (with unit), unit, meaning."""

    name: str
    unit: str
    doc: str


@dataclass(frozen=True)
class Platform:
    """A registered platform: what the runner, the env faces and the tasks need of it.

    :param name: registry name (``"diff_drive"``).
    :param config: its config class (the default instance is ``config()``).
    :param params: its parameter block (begins with :func:`base_param_fields`).
    :param state: its state block.
    :param actions: the action's entries, in order.
    :param module: the module holding the compiled ``reset`` and ``drive``.
    :param action_high: the action bound of each entry (symmetric) for a config.
    :param randomize: per-episode draws into the lanes' parameter records
        ``(params, lanes, cfg, keys)``.
    :param info: ``(info key, state field, index or None, doc)`` the envs report.
    :param doc: one line for docs and errors.
    :param wheels: for drawing: the wheels of a config as rows ``(x, y, length, width,
        roller slope)`` in the body frame (m; slope ``s`` draws rollers along ``(1, s)``, 0
        none).
    """

    name: str
    config: type[PlatformConfig]
    params: Block
    state: Block
    actions: tuple[ActionField, ...]
    module: str
    action_high: Callable[[Any], np.ndarray]
    randomize: Callable[[np.ndarray, np.ndarray, Any, np.ndarray], None]
    info: Sequence[tuple[str, str, int | None, str]] = field(default_factory=tuple)
    doc: str = ""
    wheels: Callable[[Any], np.ndarray] | None = None

    @property
    def action_size(self) -> int:
        """Entries of the action."""
        return len(self.actions)

    def __reduce__(self) -> tuple[Callable[[str], Platform], tuple[str]]:
        """Copied and pickled by name: the registry's own object, whose parameter block the
        runner's cached record types are keyed on (and whose lambdas cannot be pickled)."""
        from follow_env.platforms import get_platform

        return get_platform, (self.name,)


def motor_gains(keys: np.ndarray, n_motors: int, spread: float) -> np.ndarray:
    """Per-episode gain factors ``(len(keys), n_motors)``: ``1 + spread z`` clipped to
    [0.5, 1.5] (reference §2's motor ratios P_i)."""
    gains = 1.0 + LaneRandom(keys[:, streams.MOTOR.index]).normal(
        n_motors, scale=spread, at=MOTOR_GAINS
    )
    return np.clip(gains, 0.5, 1.5)

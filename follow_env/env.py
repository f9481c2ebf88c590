"""The single Gymnasium environment: one lane of the batched core."""

from __future__ import annotations

from typing import Any, ClassVar

import gymnasium as gym
import numpy as np

from follow_env.config import PRESETS, THESIS, EnvConfig
from follow_env.core import BatchedSim
from follow_env.info import INFO_KEYS, lane_info, make_spaces
from follow_env.layout import S_OBS_D, S_OBS_O, S_REWARD, S_TERM, S_TRUNC

__all__ = ["INFO_KEYS", "PersonFollowEnv", "resolve_config"]


def resolve_config(
    config: EnvConfig | str | dict[str, Any] | None = None,
    scenario: str | None = None,
    **overrides: Any,
) -> EnvConfig:
    """Build an :class:`EnvConfig` from ``gym.make`` keyword arguments.

    :param config: a preset name (``"thesis"``, ``"ideal"``, ``"noisy"``), an ``EnvConfig``, or
        a mapping of section overrides applied to the ``thesis`` preset.
    :param scenario: shorthand for ``scenario={"name": ...}``.
    :param overrides: sections (``perception={...}``) or ``section__field=value`` pairs.
    """
    if config is None:
        cfg = THESIS
    elif isinstance(config, EnvConfig):
        cfg = config
    elif isinstance(config, str):
        if config not in PRESETS:
            raise ValueError(
                f"config={config!r} is out of range: must be one of "
                + ", ".join(repr(p) for p in PRESETS)
                + " or an EnvConfig"
            )
        cfg = PRESETS[config]
    elif isinstance(config, dict):
        cfg = EnvConfig.from_overrides(THESIS, config)
    else:
        raise ValueError(
            f"config={config!r} is out of range: must be a preset name, an EnvConfig or a dict"
        )
    flat: dict[str, Any] = {}
    for key, value in overrides.items():
        flat[key.replace("__", ".")] = value
    if scenario is not None:
        flat["scenario.name"] = scenario
    return EnvConfig.from_overrides(cfg, flat) if flat else cfg


class PersonFollowEnv(gym.Env[np.ndarray, np.ndarray]):
    """A differential-drive robot follows a walking person using only an RGB-D camera.

    ## Description

    The simulated twin of a camera-only person-following transport robot (SPEC §1): two wheels
    under PID speed control on a microcontroller, an Intel RealSense D435i camera, and a person
    detector whose first detection is followed. Each step is one 0.1 s control period: the
    action sets the body twist, the wheels track it through 10 ticks of 10 ms (encoder, PID with
    a filtered derivative, DC motors with friction), the person walks on, and the camera
    publishes what the robot's perception would publish. The task is to keep the person centred
    in the image at 1 m, smoothly, without collisions.

    ## Action Space

    ``Box(2,)`` float32, SI units, bounded by what the platform can do (both wheels at their top
    speed): values outside are clipped by the simulation.

    | Num | Action       | Min       | Max      | Unit  |
    |-----|--------------|-----------|----------|-------|
    | 0   | forward speed v | -v_max | v_max    | m/s   |
    | 1   | turn rate w (counter-clockwise positive) | -w_max | w_max | rad/s |

    With the default robot v_max = 1.48 m/s and w_max = 7.42 rad/s. A NaN or infinite action
    raises ``ValueError``.

    ## Observation Space

    ``Box(2,)`` float32: what the robot's perception publishes (SPEC §1.4).

    | Num | Observation                           | Min      | Max         | Unit |
    |-----|---------------------------------------|----------|-------------|------|
    | 0   | filtered distance (0: no reading yet) | 0        | depth_max_m | m    |
    | 1   | box centre column - width // 2        | -width/2 | width/2 - 1 | px   |

    The offset is positive when the person is right of the image centre.

    When nothing is detected the observation keeps its last values, as on the robot.

    ## Rewards

    Dense, from ground truth, per step (weights in ``RewardConfig``)::

        r = alive_bonus - distance_weight * min(|d_true - 1.0 m|, 1 m)
            - offset_weight * min(|offset_true| / (width / 2), 1)
            - accel_weight * |robot acceleration|  - lost_penalty * [person not in frame]
            - collision_penalty * [collision]

    ## Starting State

    Set by the scenario (``straight`` by default): the robot at rest, the person standing
    ``start_distance_m`` (1 m) in front of the camera, centred in the image (SPEC §1.6). The
    first observation is the perception of that frame.

    ## Episode End

    Terminated: the robot's footprint touches a wall or an obstacle, comes closer than
    ``person_clearance_m`` (0.3 m) to the person, touches a bystander, or has not detected
    the person for longer than ``lost_timeout_s`` (3 s). Truncated: the person's walk is over
    and ``settle_s`` (2 s) have passed, or ``max_steps`` steps were taken.
    ``info["termination"]`` names the reason (``collision_wall``, ``collision_person``,
    ``collision_bystander``, ``lost``, ``walk_over``, ``step_limit``).

    ## Arguments

    ``gym.make("PersonFollow-v0", scenario="curve", config="noisy", render_mode="rgb_array",
    perception={"latency_frames": 2}, episode__lost_timeout_s=5.0)``

    * ``config``: preset name (``thesis`` default, ``ideal``, ``noisy``, ``randomized``), an
      ``EnvConfig``, or a dict of section overrides.
    * ``scenario``: a registered scenario name (``straight``, ``curve``, ``random``,
      ``corridor_turn``, ``doorway``, ``occlusion``, ``crossing``, ``crowd``, ``stop_and_go``,
      ``zigzag``, ``random_world``).
    * any config section as a dict (``robot``, ``motor``, ``encoder``, ``pid``, ``camera``,
      ``perception``, ``person``, ``scenario``, ``reward``, ``episode``, ``randomization``), or
      one field as ``section__field=value``.
    * ``render_mode``: ``"rgb_array"`` (top-down view beside the camera view) or ``None``.

    An unknown argument or an out-of-range value raises ``ValueError`` naming it.

    ## Seeding

    ``reset(seed=s)`` seeds a ``numpy.random.SeedSequence``; each episode spawns a child with
    independent streams for the person's path, the detector, the depth noise and the motors.
    Draws are indexed by time, not by what the robot does, so two policies on the same seed
    meet the same person and the same noise, and the same actions give bit-identical episodes.

    ## Info

    Ground truth for metrics (keys in ``INFO_KEYS``): robot pose and speeds, person pose and
    speed, true distance and offset, ``in_frame`` and ``detected``, wheel speed targets,
    encoder-measured and true wheel speeds, duties, and the robot's acceleration computed from
    encoder speed as the robot computes it.

    ## Example

    >>> import gymnasium as gym
    >>> import follow_env
    >>> env = gym.make("PersonFollow-v0", scenario="straight")
    >>> obs, info = env.reset(seed=0)
    >>> obs.shape, obs.dtype
    ((2,), dtype('float32'))
    >>> round(float(obs[0]), 1)
    1.0
    >>> obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
    """

    metadata: ClassVar[dict[str, Any]] = {"render_modes": ["rgb_array"], "render_fps": 10}

    def __init__(
        self,
        config: EnvConfig | str | dict[str, Any] | None = None,
        scenario: str | None = None,
        render_mode: str | None = None,
        **overrides: Any,
    ) -> None:
        self.config = resolve_config(config, scenario, **overrides)
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(
                f"render_mode={render_mode!r} is out of range: must be None or one of "
                + ", ".join(repr(m) for m in self.metadata["render_modes"])
            )
        self.render_mode = render_mode
        self.sim = BatchedSim(self.config, 1)
        cfg = self.config
        self.observation_space, self.action_space = make_spaces(cfg)
        self._action = np.zeros((1, 2))
        self._lane = np.zeros(1, dtype=np.int64)
        self._renderer: Any = None
        self._episode_over = True

    # -- Gymnasium API ---------------------------------------------------------------------------

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """Start an episode. ``seed`` seeds the episode streams; later resets without a seed
        continue from it (each episode spawns the next child ``SeedSequence``)."""
        super().reset(seed=seed)
        if options:
            raise ValueError(f"options={options!r} is out of range: this env takes no options")
        self.sim.reset_lanes(self._lane, None if seed is None else [seed])
        self._episode_over = False
        if self._renderer is not None:
            self._renderer.reset()
        return self._obs(), self._info()

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        """Apply ``[v_mps, w_radps]`` for one control step (0.1 s)."""
        a = self._action
        a[0, 0], a[0, 1] = action[0], action[1]
        if not np.isfinite(a).all():
            raise ValueError(f"action={action!r} is out of range: must be finite [v, w]")
        self.sim.step(a)
        fs = self.sim.fstate[0]
        terminated, truncated = bool(fs[S_TERM]), bool(fs[S_TRUNC])
        if self._renderer is not None:
            self._renderer.record(self)
        return self._obs(), float(fs[S_REWARD]), terminated, truncated, self._info()

    def render(self) -> np.ndarray | None:
        """The ``rgb_array`` frame: top-down view beside the camera view (H x W x 3 uint8)."""
        if self.render_mode is None:
            gym.logger.warn("render() called without a render_mode; returning None")
            return None
        if self._renderer is None:
            from follow_env.render import Renderer

            self._renderer = Renderer(self.config)
            self._renderer.record(self)
        return self._renderer.draw(self)

    def close(self) -> None:
        """Release the renderer."""
        self._renderer = None

    # -- helpers --------------------------------------------------------------------------------

    def _obs(self) -> np.ndarray:
        return self.sim.fstate[0, S_OBS_D : S_OBS_O + 1].astype(np.float32)

    def _info(self) -> dict[str, Any]:
        return lane_info(self.sim, 0)

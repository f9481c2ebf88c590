"""PersonFollow's env classes: the single env (with its manual), the vector env, the SB3 VecEnv.

All three are the generic faces of :mod:`follow_env.sim.faces` and :mod:`follow_env.sim.sb3`
over this task's model (:data:`follow_env.tasks.person_follow.task.TASK`).
"""

from __future__ import annotations

from typing import Any, ClassVar

from follow_env.sim.faces import TaskEnv, TaskVectorEnv
from follow_env.tasks.person_follow.task import TASK

__all__ = ["PersonFollowEnv", "PersonFollowVectorEnv", "make_sb3_vec_env"]


class PersonFollowEnv(TaskEnv):
    """A robot (differential drive by default) follows a walking person using only an RGB-D camera.

    ## Description

    The simulated twin of a camera-only person-following transport robot (reference §1): two wheels
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

    With the default robot v_max = 1.48 m/s and w_max = 7.42 rad/s. An action of another shape
    (after ``np.asarray``), or a NaN or infinite one, raises ``ValueError``; ``step`` before
    ``reset`` raises ``gymnasium.error.ResetNeeded``. On another platform the action is that
    platform's (``platform=``, below). With ``platform="mecanum"`` (reference §2) it is
    ``Box(3,)`` ``[v_mps, vy_mps, w_radps]``: vx forward, vy to the left, w counter-clockwise
    (REP 103), bounded by 1.35 m/s, 1.35 m/s and 8.32 rad/s with the default base.

    ## Observation Space

    ``Box(2,)`` float32: what the robot's perception publishes (reference §1.4).

    | Num | Observation                           | Min      | Max         | Unit |
    |-----|---------------------------------------|----------|-------------|------|
    | 0   | filtered distance (0: no reading yet) | 0        | depth_max_m | m    |
    | 1   | box centre column - width // 2        | -width/2 | width/2 - 1 | px   |

    The offset is positive when the person is right of the image centre.

    When nothing is detected the observation keeps its last values, as on the robot.

    With ``perception={"ahead_rays": n}`` (n > 0) it is ``Box(3,)``: entry 2 is the reading
    ahead, in [0, depth_max_m] m, the nearest valid depth at n columns of the image's middle row
    spread over +- ``ahead_half_angle_deg`` (14 deg), each with the D435i's noise, of this
    frame (no detector latency); ``depth_max_m`` when no column reads (beyond the range, nearer
    than ``depth_min_m`` or invalid all read 0 on the camera); ``ahead_target="exclude"`` skips
    the columns inside the box published this frame. It has draws of its own: every other
    value of an episode is the same with it and without it.

    ## Rewards

    Dense, from ground truth, per step (weights in ``RewardConfig``)::

        r = alive_bonus - distance_weight * min(|d_true - 1.0 m|, 1 m)
            - offset_weight * min(|offset_true| / (width / 2), 1)
            - accel_weight * |robot acceleration|  - lost_penalty * [person not in frame]
            - collision_penalty * [collision]

    ## Starting State

    Set by the scenario (``straight`` by default): the robot at rest, the person standing
    ``start_distance_m`` (1 m) in front of the camera, centred in the image (reference §1.6). The
    first observation is the perception of that frame.

    ## Episode End

    Terminated: the robot's footprint touches a wall or an obstacle, comes closer than
    ``person_clearance_m`` (0.3 m) to the person, touches a bystander, or has published no
    detection for longer than ``lost_timeout_s`` (3 s): anyone's counts, a bystander taken for
    the person too, as on the robot. Truncated: the person's walk is over
    and ``settle_s`` (2 s) have passed, or ``max_steps`` steps were taken.
    ``info["termination"]`` names the reason (``collision_wall``, ``collision_person``,
    ``collision_bystander``, ``lost``, ``walk_over``, ``step_limit``).

    The env ends its episodes itself, so its spec has no ``max_episode_steps``. To cut them
    shorter, give ``gym.make(..., max_episode_steps=n)`` (a ``TimeLimit``; ``n`` up to
    ``max_steps``) or ``episode__max_steps=n``; a ``TimeLimit`` longer than ``max_steps`` is
    refused at the first reset, naming ``episode__max_steps``, since the env would truncate
    first. The vector env and the SB3 adapter take only ``episode__max_steps``.

    ## Arguments

    ``gym.make("PersonFollow-v0", scenario="curve", config="noisy", render_mode="rgb_array",
    perception={"latency_frames": 2}, episode__lost_timeout_s=5.0)``

    * ``config``: preset name (``thesis`` default, ``ideal``, ``noisy``, ``randomized``), an
      ``EnvConfig``, or a dict of section overrides.
    * ``scenario``: a registered scenario name (``straight``, ``curve``, ``random``,
      ``corridor_turn``, ``doorway``, ``occlusion``, ``crossing``, ``lookalike``, ``crowd``,
      ``stop_and_go``, ``zigzag``, ``random_world``).
    * ``platform``: a registered platform name (``"diff_drive"``, the default, or
      ``"mecanum"``) or a platform config object (``DiffDriveConfig(...)``,
      ``MecanumConfig(...)``); in ``config`` dicts also ``{"platform": {"name": "mecanum",
      ...}}``.
    * any config section as a dict (the platform's: ``robot``, ``motor``, ``encoder``, ``pid``
      of the differential drive, ``body``, ``motor``, ``floor``, ``drive``, ``encoder``, ``pid``
      of the mecanum base; ``camera``, ``perception``, ``person``, ``scenario``, ``reward``,
      ``episode``, ``randomization``), or one field as ``section__field=value``.
    * ``render_mode``: ``"rgb_array"`` (a 480 x 1280 frame: top-down view beside the camera
      view), ``"human"`` (the same frame in a pygame window, at 10 frames a second; needs
      pygame and a display) or ``None``.

    An unknown argument or an out-of-range value raises ``ValueError`` naming it.

    ## Seeding

    ``reset(seed=s)`` seeds a ``numpy.random.SeedSequence``; each episode spawns a child with
    independent streams for the person's path, the detector, the depth noise and the motors.
    Draws are indexed by time, not by what the robot does, so two policies on the same seed
    meet the same person and the same noise, and the same actions give bit-identical episodes.

    ## Info

    Ground truth for metrics (keys in ``INFO_KEYS``): robot pose and speeds (``robot_vy_mps``,
    the sideways speed, is 0 unless the base strafes), person pose and speed, true distance and
    offset, ``in_frame`` and ``detected``, the platform's wheels (speed targets,
    encoder-measured and true speeds, duties: ``..._r_...``/``..._l_...`` on the differential
    drive, ``..._fl_...``, ``rl``, ``rr``, ``fr`` on the mecanum base, whose duty is of 255),
    and the robot's forward acceleration computed from encoder speed as the robot computes it.

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

    task: ClassVar[Any] = TASK


class PersonFollowVectorEnv(TaskVectorEnv):
    """``num_envs`` independent PersonFollow robots stepped together by the batched core.

    Made by ``gym.make_vec("PersonFollow-v0", num_envs=N,
    vectorization_mode="vector_entry_point")`` or directly; every keyword argument of
    :class:`PersonFollowEnv` works here too, plus ``autoreset_mode`` (see
    :class:`~follow_env.sim.faces.TaskVectorEnv`). Lane ``i`` after ``reset(seed=s)`` replays
    the single env reset with ``seed=s + i``.
    """

    task: ClassVar[Any] = TASK


def make_sb3_vec_env(num_envs: int, **env_kwargs: Any) -> Any:
    """An SB3 ``VecEnv`` of ``num_envs`` PersonFollow robots over the batched core.

    ``env_kwargs`` are the single env's (``config``, ``scenario``, ``platform``, sections) plus
    ``full_info``. Wrap it as usual: ``VecMonitor(make_sb3_vec_env(16))``,
    ``VecNormalize(...)``. Imports stable-baselines3 (and torch) on first use.
    """
    from follow_env.sim.sb3 import TaskSB3VecEnv

    return TaskSB3VecEnv(TASK, num_envs, **env_kwargs)

"""LineTrace's env classes: the single env (with its manual), the vector env, the SB3 VecEnv.

All three are the generic faces of :mod:`follow_env.sim.faces` and :mod:`follow_env.sim.sb3`
over this task's model (:data:`follow_env.tasks.line_trace.task.TASK`).
"""

from __future__ import annotations

from typing import Any, ClassVar

from follow_env.sim.faces import TaskEnv, TaskVectorEnv
from follow_env.tasks.line_trace.task import TASK

__all__ = ["LineTraceEnv", "LineTraceVectorEnv", "make_sb3_vec_env"]


class LineTraceEnv(TaskEnv):
    """A robot (the mecanum base by default) traces a black line on white floor tiles with a
    5 x 5 grid of light sensors under it.

    ## Description

    The line-tracing robot of the mecanum paper (reference §2), built for RoboCup Junior Rescue
    Line: four mecanum wheels driven open loop by PWM duty, and a 5 x 5 grid of phototransistors
    looking at the floor under the robot's centre. The course is a row of 30 cm tiles with a
    black line 19 mm wide: straights, 90 deg corners, quarter-circle curves, zigzags and gaps of
    up to 20 cm where the line is missing (``track=``). Each step is one 0.02 s control period:
    the action sets the body twist, the platform drives its wheels for the period, and the grid
    reads the floor. The task is to follow the line to its end, close to it and smoothly.

    ## Action Space

    The platform's, float32, SI, bounded by what it can do (values outside are clipped by the
    simulation). On the mecanum base (the default) ``Box(3,)``:

    | Num | Action                                   | Min    | Max   | Unit  |
    |-----|------------------------------------------|--------|-------|-------|
    | 0   | forward speed vx                         | -1.35  | 1.35  | m/s   |
    | 1   | sideways speed vy, to the left           | -1.35  | 1.35  | m/s   |
    | 2   | turn rate w (counter-clockwise positive) | -8.32  | 8.32  | rad/s |

    With ``platform="diff_drive"`` it is ``Box(2,)`` ``[v_mps, w_radps]`` (1.48 m/s,
    7.42 rad/s). An action of another shape, or a NaN or infinite one, raises ``ValueError``;
    ``step`` before ``reset`` raises ``gymnasium.error.ResetNeeded``.

    ## Observation Space

    ``Box(25,)`` float32 in [0, 1]: the grid's readings, row-major, row 0 the front row and
    column 0 the leftmost cell (names ``cell_<row><col>`` in
    ``follow_env.tasks.line_trace.spec.SPEC``). Cell ``(i, j)`` sits ``(2 - i) * pitch``
    ahead of the grid's centre and ``(2 - j) * pitch`` to its left (pitch 12 mm).

    | Num         | Observation                              | Min | Max | Unit |
    |-------------|------------------------------------------|-----|-----|------|
    | 5 i + j     | reading of cell (i, j): share of its spot on the line | 0 | 1 | - |

    A reading is 0 over white floor and 1 fully over the line: the share of the cell's 8 mm
    spot that the drawn line covers, seen through the sensor's optics (light falls with the
    square of the height), dimmed by ambient light (a per-episode level that flickers from
    step to step), scaled by the cell's gain (per episode) and with noise (std 0.03). A cell
    reading above ``sensor.threshold`` (0.5) is *active*. Nothing is read inside a gap.

    ## Rewards

    Dense, from ground truth, per step (weights in ``RewardConfig``)::

        r = progress_weight * (progress this step) / 1 cm
            - cross_track_weight * min(|cross-track error| / 2 cm, 1)
            - accel_weight * |change of (v, vy)| / dt - yaw_accel_weight * |change of w| / dt
            - lost_penalty * [line lost] - left_field_penalty * [left the field]
            + finish_bonus * [track's end reached]

    Progress is the arc length of the line's point nearest the robot; the cross-track error
    is the robot's distance to the line (gaps included), > 0 left of it.

    ## Starting State

    The robot at rest on the line, ``start.distance_m`` (0.15 m, the first tile's centre)
    from its start, facing along it, off by a sideways offset (std 5 mm) and a heading error
    (std 5 deg) drawn per episode. The first observation is the grid's reading there.

    ## Episode End

    Terminated: progress reached the track's end less ``finish_margin_m`` (2 cm:
    ``track_end``, the goal, paid by ``finish_bonus``), no sensor spot has overlapped the line
    (gaps count as line) for longer than ``lost_timeout_s`` (1 s: ``lost``), or the robot's
    centre left the field (the tiles with one empty tile all round: ``left_field``).
    Truncated: ``max_time_s`` (60 s) passed (``time_limit``). ``info["termination"]`` names
    the reason.

    The env ends its episodes itself, so its spec has no ``max_episode_steps``. To cut them
    shorter, give ``gym.make(..., max_episode_steps=n)`` (a ``TimeLimit``; ``n`` up to
    ``max_time_s / control_dt_s``, 3,000 steps) or ``episode__max_time_s``; a ``TimeLimit``
    longer than that is refused at the first reset, naming ``episode__max_time_s``. The vector
    env and the SB3 adapter take only ``episode__max_time_s``.

    ## Arguments

    ``gym.make("LineTrace-v0", platform="mecanum", track="course", config="paper",
    render_mode="rgb_array", sensor={"noise_std": 0.05}, episode__lost_timeout_s=2.0)``

    * ``config``: preset name (``paper`` default, ``ideal``, ``noisy``), a
      ``LineTraceConfig``, or a dict of section overrides. ``ideal`` is the paper's robot
      with noiseless sensing and no motor or floor spread: its gear friction stays, so with
      every motor alike no wheel starts under 16 % duty (41 of 255), that is a straight
      command under 0.24 m/s open loop. The tuned ``pid`` law drives at 0.2 m/s and stands
      still there (under ``paper`` the spreads and the noise make it move in fits); give
      ``drive={"mode": "pid"}`` (wheel PIDs on the encoders) or a faster law.
    * ``track``: a registered track (``straight``, ``corners``, ``curves``, ``zigzag``,
      ``gaps``, ``course``, ``random``: a new course every episode).
    * ``platform``: ``"mecanum"`` (the default, the paper's robot) or ``"diff_drive"``, or a
      platform config object.
    * any config section as a dict (the platform's: ``body``, ``motor``, ``floor``, ``drive``,
      ``encoder``, ``pid`` of the mecanum base, ``robot``, ``motor``, ``encoder``, ``pid`` of
      the differential drive; ``sensor``, ``track``, ``start``, ``reward``, ``episode``,
      ``randomization``), or one field as ``section__field=value``.
    * ``render_mode``: ``"rgb_array"`` (a 480 x 1280 frame: the field beside a close-up of the
      grid over the floor), ``"human"`` (the same in a pygame window) or ``None``.

    An unknown argument or an out-of-range value raises ``ValueError`` naming it.

    ## Seeding

    ``reset(seed=s)`` seeds a ``numpy.random.SeedSequence``; each episode spawns a child with
    independent streams for the light (noise, ambient light, gains), the track (a ``random``
    course, the start) and the motors. Draws are indexed by time, not by what the robot does,
    so two policies on the same seed meet the same course and the same noise, and the same
    actions give bit-identical episodes.

    ## Info

    Ground truth for metrics (``TASK.info_keys(platform)``): time, robot pose and twist,
    encoder speed and acceleration, the platform's wheels, ``progress_m``,
    ``track_length_m``, ``cross_track_m``, ``heading_error_rad``, ``in_gap``,
    ``line_seen``, ``active_cells``, ``lost_s``, ``step`` and ``termination``.

    ## Example

    >>> import gymnasium as gym
    >>> import numpy as np
    >>> import follow_env
    >>> env = gym.make("LineTrace-v0", track="straight", config="ideal")
    >>> obs, info = env.reset(seed=0)
    >>> obs.shape, obs.dtype
    ((25,), dtype('float32'))
    >>> [round(float(v), 2) for v in obs[10:15]]  # the middle row, left to right
    [0.0, 0.12, 1.0, 0.12, 0.0]
    >>> obs, reward, terminated, truncated, info = env.step(np.array([0.3, 0.0, 0.0], np.float32))
    >>> info["termination"], terminated, truncated
    ('', False, False)

    The 19 mm line covers the middle cell's 8 mm spot and reaches 1.5 mm into the spots of the
    cells beside it, 12 mm either side: 3 of their 24 sample points, a reading of 0.12.
    """

    task: ClassVar[Any] = TASK
    # One frame a 0.02 s control step (each env sets its own from its config: render_fps).
    metadata: ClassVar[dict[str, Any]] = {**TaskEnv.metadata, "render_fps": 50}


class LineTraceVectorEnv(TaskVectorEnv):
    """``num_envs`` independent line-tracing robots stepped together by the batched core.

    Made by ``gym.make_vec("LineTrace-v0", num_envs=N, vectorization_mode="vector_entry_point")``
    or directly; every keyword argument of :class:`LineTraceEnv` works here too, plus
    ``autoreset_mode`` (see :class:`~follow_env.sim.faces.TaskVectorEnv`). Lane ``i`` after
    ``reset(seed=s)`` replays the single env reset with ``seed=s + i``.
    """

    task: ClassVar[Any] = TASK


def make_sb3_vec_env(num_envs: int, **env_kwargs: Any) -> Any:
    """An SB3 ``VecEnv`` of ``num_envs`` line-tracing robots over the batched core.

    ``env_kwargs`` are the single env's (``config``, ``track``, ``platform``, sections) plus
    ``full_info``. Imports stable-baselines3 (and torch) on first use.
    """
    from follow_env.sim.sb3 import TaskSB3VecEnv

    return TaskSB3VecEnv(TASK, num_envs, **env_kwargs)

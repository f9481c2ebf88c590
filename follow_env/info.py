"""Observation/action spaces and the ``info`` ground truth, shared by every environment face.

The single env, the Gymnasium vector env and the stable-baselines3 adapter all read the same
columns of the batched core's state here, so their spaces and infos cannot disagree.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium import spaces

from follow_env.config import EnvConfig
from follow_env.core import BatchedSim
from follow_env.layout import (
    I_DETECTED_ID,
    I_REASON,
    I_STEP,
    PS_TH,
    PS_V,
    PS_X,
    PS_Y,
    REASON_NAMES,
    S_ACCEL,
    S_CLEAR_PERSON,
    S_CLEAR_WALL,
    S_DETECTED,
    S_DUTY_L,
    S_DUTY_R,
    S_IN_FRAME,
    S_OBS_D,
    S_OBS_O,
    S_OMEGA_L,
    S_OMEGA_R,
    S_RAW_DEPTH,
    S_T,
    S_TH,
    S_TRUE_D,
    S_TRUE_O,
    S_V,
    S_VMEAS_L,
    S_VMEAS_R,
    S_VROBOT_MEAS,
    S_VTGT_L,
    S_VTGT_R,
    S_W,
    S_X,
    S_Y,
)

__all__ = ["INFO_KEYS", "batch_info", "lane_info", "make_spaces", "observations"]

# info[key] <- fstate column (floats, SI units unless the name says px or pct).
_FLOAT_COLUMNS: tuple[tuple[str, int], ...] = (
    ("time_s", S_T),
    ("robot_x_m", S_X),
    ("robot_y_m", S_Y),
    ("robot_theta_rad", S_TH),
    ("robot_v_mps", S_V),
    ("robot_w_radps", S_W),
    ("true_distance_m", S_TRUE_D),
    ("true_offset_px", S_TRUE_O),
    ("raw_depth_m", S_RAW_DEPTH),
    ("wheel_target_r_mps", S_VTGT_R),
    ("wheel_target_l_mps", S_VTGT_L),
    ("wheel_measured_r_mps", S_VMEAS_R),
    ("wheel_measured_l_mps", S_VMEAS_L),
    ("wheel_true_r_radps", S_OMEGA_R),
    ("wheel_true_l_radps", S_OMEGA_L),
    ("duty_r_pct", S_DUTY_R),
    ("duty_l_pct", S_DUTY_L),
    ("encoder_speed_mps", S_VROBOT_MEAS),
    ("accel_mps2", S_ACCEL),
    ("wall_clearance_m", S_CLEAR_WALL),
    ("person_clearance_m", S_CLEAR_PERSON),
)
_FLOAT_NAMES = tuple(k for k, _ in _FLOAT_COLUMNS)
_FLOAT_COLS = np.array([c for _, c in _FLOAT_COLUMNS])
# The target person's state: info[key] <- pstate[lane, 0, column].
_PERSON_COLUMNS: tuple[tuple[str, int], ...] = (
    ("person_x_m", PS_X),
    ("person_y_m", PS_Y),
    ("person_theta_rad", PS_TH),
    ("person_v_mps", PS_V),
)
_PERSON_NAMES = tuple(k for k, _ in _PERSON_COLUMNS)
_PERSON_COLS = np.array([c for _, c in _PERSON_COLUMNS])
_REASONS = np.array(REASON_NAMES, dtype=object)

INFO_KEYS: tuple[str, ...] = (
    *_FLOAT_NAMES,
    *_PERSON_NAMES,
    "in_frame",
    "detected",
    "detected_person",
    "step",
    "termination",
)
"""Every key of the ``info`` dict: floats, then ``in_frame`` (bool: enough of the target in
the image and in sight to be detected), ``detected`` (bool: this step's observation is a fresh
detection), ``detected_person`` (whose detection it is: 0 the target, >0 a bystander, -1
none), ``step`` (int) and ``termination`` (why the episode ended, or "")."""


def make_spaces(cfg: EnvConfig) -> tuple[spaces.Box, spaces.Box]:
    """``(observation_space, action_space)`` of one robot: ``[distance_m, offset_px]`` and
    ``[v_mps, w_radps]``, float32."""
    half_w = cfg.camera.width_px // 2
    observation = spaces.Box(
        low=np.array([0.0, -half_w], dtype=np.float32),
        high=np.array([cfg.camera.depth_max_m, cfg.camera.width_px - 1 - half_w], np.float32),
        dtype=np.float32,
    )
    v, w = cfg.max_speed_mps, cfg.max_turn_rate_radps
    action = spaces.Box(
        low=np.array([-v, -w], dtype=np.float32),
        high=np.array([v, w], dtype=np.float32),
        dtype=np.float32,
    )
    return observation, action


def observations(sim: BatchedSim) -> np.ndarray:
    """The published observations of every lane, (N, 2) float32."""
    return sim.fstate[:, S_OBS_D : S_OBS_O + 1].astype(np.float32)


def lane_info(sim: BatchedSim, lane: int) -> dict[str, Any]:
    """The ``info`` dict of one lane, as Python scalars."""
    fs = sim.fstate[lane]
    info = dict(zip(_FLOAT_NAMES, fs[_FLOAT_COLS].tolist(), strict=True))
    info.update(zip(_PERSON_NAMES, sim.pstate[lane, 0, _PERSON_COLS].tolist(), strict=True))
    ist = sim.istate[lane]
    info["in_frame"] = bool(fs[S_IN_FRAME])
    info["detected"] = bool(fs[S_DETECTED])
    info["detected_person"] = int(ist[I_DETECTED_ID])
    info["step"] = int(ist[I_STEP])
    info["termination"] = REASON_NAMES[ist[I_REASON]]
    return info


def batch_info(sim: BatchedSim, lanes: np.ndarray | None = None) -> dict[str, np.ndarray]:
    """The ``info`` of many lanes as Gymnasium's dict of arrays, one entry per lane (all lanes,
    or those selected by index array ``lanes``), without the ``_key`` masks."""
    sel = slice(None) if lanes is None else lanes
    fs = sim.fstate[sel]
    # One fresh (keys, lanes) block whose rows are the entries; gathering rows of the
    # transposed view is ~15x faster than transposing a gathered copy at 4096 lanes.
    floats = fs.T[_FLOAT_COLS]
    info: dict[str, np.ndarray] = dict(zip(_FLOAT_NAMES, floats, strict=True))
    person = sim.pstate[sel, 0].T[_PERSON_COLS]
    info.update(zip(_PERSON_NAMES, person, strict=True))
    ist = sim.istate[sel]
    info["in_frame"] = fs[:, S_IN_FRAME] > 0.0
    info["detected"] = fs[:, S_DETECTED] > 0.0
    info["detected_person"] = ist[:, I_DETECTED_ID].copy()
    info["step"] = ist[:, I_STEP].copy()
    info["termination"] = _REASONS[ist[:, I_REASON]]
    return info

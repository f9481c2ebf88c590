"""Metrics of one episode, each one function over a step log (:mod:`eval.steplog`).

## The thesis's metrics (reference §1.6), and how each reading was decided
- ``mean_offset_px``: MeanOffset, the mean absolute pixel offset. From the **observed** offset
  (``obs_offset_px``), because the thesis logged camera data: what the detector published, with
  its jitter, not the true position of the person. Only rows with a fresh detection count
  (``detected == 1``; all rows when the log has no ``detected`` column): between detections the
  observation is a held copy, not a measurement. The ground-truth version is the extra metric
  ``mean_true_offset_px``.
- ``std_offset_px``: StdOffset, the standard deviation of the signed observed offset over the
  same rows (population form, ddof = 0, as ``numpy.std``).
- ``mean_accel_mm_s2``: MeanAccel, the **signed** mean of the robot's acceleration, in mm/s²,
  from encoder speed (``accel_mps2``, as the robot computes it). The signed mean telescopes to
  (v_end - v_start) / T, about 0 for a run that starts and ends at rest, and that is what the
  thesis's Table 4.1 shows: for N samples std(a) <= sqrt(N) mean|a|, so its StdAccel / MeanAccel
  ratios of 111 to 1001 would need 12,000 to 1,000,000 samples if MeanAccel were mean |a|,
  while a 10 m walk logged every 0.1 s gives about 130. The mean magnitude is the further
  metric ``mean_abs_accel_mm_s2``.
- ``std_accel_mm_s2``: StdAccel, the standard deviation of the signed acceleration (ddof = 0),
  mm/s²: the thesis's smoothness figure.
- ``in_frame_rate_pct``: InFrameRate, the share of rows with the person inside the camera frame,
  %. From the ground truth ``in_frame`` when the log has it (simulation), otherwise from
  ``detected`` (all a real robot can know).

## Further metrics
``mean_true_offset_px`` (mean |true offset|, simulation only), ``mean_abs_accel_mm_s2`` (mean
|a|), ``mean_distance_error_m`` and ``rms_distance_error_m`` (distance minus the 1.0 m
reference, reference §1.5; true distance when logged, else the published one where it is > 0),
``reacquire_time_s`` and ``reacquired_pct`` (the losses that ended, and how many did),
``jerk_rms_m_s3``,
``turn_accel_rms_rad_s2``, ``lost_rate_pct`` and ``collision_rate_pct`` (per episode 100 or 0,
so their mean over episodes is a rate), ``target_swap_rate_pct``, the social-navigation
benchmarks' ``success_pct`` (neither collided nor lost, and the person itself detected at least
every 3 s, so that following a stranger is no success; 100 or 0 per episode) and
``following_rate_pct`` (steps within 0.5-1.5 m of the person and facing them, within 60 deg),
and ``path_length_ratio``. The three rates of episodes (lost, collision, success) are registered
``binary=True``: their intervals are Wilson score intervals (:func:`eval.stats.summarize`).

A metric whose columns a log lacks is NaN for that log: the three endings (lost, collision,
success) without a ``termination`` column, as in a robot's log. Adding a metric is one decorated
function here::

    @metric("max_offset_px", "px", "max |offset| (px)")
    def max_offset_px(log: pd.DataFrame) -> float:
        return float(log["obs_offset_px"].abs().max())
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from types import MappingProxyType

import numpy as np
import pandas as pd

__all__ = [
    "HEADLINE_METRICS",
    "METRICS",
    "OUTCOME_METRICS",
    "THESIS_METRICS",
    "Metric",
    "episode_metrics",
    "extra_metrics",
    "metric",
    "metric_digits",
    "metric_label",
]

#: Desired following distance (reference §1.5: "the 1.0 m in V").
TARGET_DISTANCE_M = 1.0
#: Episode endings that count as a collision (``follow_env.INFO_KEYS`` "termination").
COLLISION_ENDINGS = frozenset({"collision_wall", "collision_person", "collision_bystander"})
LOST_ENDING = "lost"

MetricFn = Callable[[pd.DataFrame], float]


@dataclass(frozen=True)
class Metric:
    """A named metric of one episode.

    :param name: column name in tables (unit in the name).
    :param unit: unit for labels.
    :param label: short human label for plots and tables.
    :param fn: the function over a step log.
    :param thesis: one of the thesis's five metrics (reference §1.6).
    :param binary: every episode's value is 0 or 100 (or NaN), so the mean over episodes is a
        rate in %: its interval is then the Wilson score interval of the proportion
        (:func:`eval.stats.summarize`), not a bootstrap's, which collapses to [0, 0] when no
        episode had the event.
    """

    name: str
    unit: str
    label: str
    fn: MetricFn
    thesis: bool = False
    binary: bool = False


_REGISTRY: dict[str, Metric] = {}


def metric(
    name: str, unit: str, label: str, *, thesis: bool = False, binary: bool = False
) -> Callable[[MetricFn], MetricFn]:
    """Register a metric function under ``name`` (module docstring has an example); ``thesis``
    and ``binary`` as :class:`Metric`'s.

    :raises ValueError: if the name is taken.
    """

    def register(fn: MetricFn) -> MetricFn:
        if name in _REGISTRY:
            raise ValueError(f"metric {name!r} is already registered")
        _REGISTRY[name] = Metric(name, unit, label, fn, thesis, binary)
        return fn

    return register


def _camera_rows(log: pd.DataFrame) -> pd.Series:
    """Observed offsets of the rows with a fresh detection (all rows without ``detected``)."""
    offset = log["obs_offset_px"]
    if "detected" in log:
        offset = offset[log["detected"] > 0.5]
    return offset.dropna()


def _finite(values: pd.Series | np.ndarray) -> np.ndarray:
    arr = np.asarray(values, dtype=np.float64)
    return arr[np.isfinite(arr)]


def _mean(values: np.ndarray) -> float:
    return float(np.mean(values)) if values.size else float("nan")


def _std(values: np.ndarray) -> float:
    return float(np.std(values)) if values.size else float("nan")


# -- the thesis's metrics (reference §1.6) ---------------------------------------------------------


@metric("mean_offset_px", "px", "MeanOffset (px)", thesis=True)
def mean_offset_px(log: pd.DataFrame) -> float:
    """MeanOffset [px]: mean |observed offset| over rows with a fresh detection."""
    return _mean(np.abs(_finite(_camera_rows(log))))


@metric("std_offset_px", "px", "StdOffset (px)", thesis=True)
def std_offset_px(log: pd.DataFrame) -> float:
    """StdOffset [px]: standard deviation (ddof 0) of the signed observed offset."""
    return _std(_finite(_camera_rows(log)))


@metric("mean_accel_mm_s2", "mm/s²", "MeanAccel (mm/s²)", thesis=True)
def mean_accel_mm_s2(log: pd.DataFrame) -> float:
    """MeanAccel [mm/s²]: the signed mean acceleration from encoder speed (module docstring)."""
    return 1000.0 * _mean(_finite(log["accel_mps2"]))


@metric("std_accel_mm_s2", "mm/s²", "StdAccel (mm/s²)", thesis=True)
def std_accel_mm_s2(log: pd.DataFrame) -> float:
    """StdAccel [mm/s²]: standard deviation (ddof 0) of the signed acceleration."""
    return 1000.0 * _std(_finite(log["accel_mps2"]))


@metric("in_frame_rate_pct", "%", "InFrameRate (%)", thesis=True)
def in_frame_rate_pct(log: pd.DataFrame) -> float:
    """InFrameRate [%]: rows with the person in the camera frame (ground truth, else detected)."""
    column = "in_frame" if "in_frame" in log else "detected" if "detected" in log else None
    if column is None:
        return float("nan")
    return 100.0 * _mean(_finite(log[column]) > 0.5)


# -- further metrics ------------------------------------------------------------------------------


@metric("mean_abs_accel_mm_s2", "mm/s²", "mean |accel| (mm/s²)")
def mean_abs_accel_mm_s2(log: pd.DataFrame) -> float:
    """Mean |acceleration from encoder speed| [mm/s²]: how hard the robot speeds up and brakes
    on average (MeanAccel, signed, telescopes to about 0)."""
    return 1000.0 * _mean(np.abs(_finite(log["accel_mps2"])))


@metric("mean_true_offset_px", "px", "MeanTrueOffset (px)")
def mean_true_offset_px(log: pd.DataFrame) -> float:
    """Mean |true offset| [px] over every row (simulation ground truth; NaN without it)."""
    if "true_offset_px" not in log:
        return float("nan")
    return _mean(np.abs(_finite(log["true_offset_px"])))


def _distance_error_m(log: pd.DataFrame) -> np.ndarray:
    if "true_distance_m" in log:
        distance = _finite(log["true_distance_m"])
    else:  # a real robot's log: the published distance, where there is one (0 = none yet)
        distance = _finite(log["obs_distance_m"])
        distance = distance[distance > 0.0]
    return distance - TARGET_DISTANCE_M


@metric("mean_distance_error_m", "m", "mean distance error (m)")
def mean_distance_error_m(log: pd.DataFrame) -> float:
    """Mean of (distance - 1.0 m) [m]: > 0 means the robot trails too far behind."""
    return _mean(_distance_error_m(log))


@metric("rms_distance_error_m", "m", "RMS distance error (m)")
def rms_distance_error_m(log: pd.DataFrame) -> float:
    """Root mean square of (distance - 1.0 m) [m]."""
    error = _distance_error_m(log)
    return float(np.sqrt(np.mean(error**2))) if error.size else float("nan")


def _losses(log: pd.DataFrame) -> np.ndarray | None:
    """Each loss of the person in an episode, the time to reacquire it [s] (NaN: never
    reacquired before the episode ended); None without a ``detected`` column.

    A loss starts at a row where the person is out of the frame (ground truth ``in_frame``;
    without it, a row without detection) after a row where it was not, and ends at the next row
    with a detection (and, with ``in_frame``, in the frame).
    """
    if "detected" not in log:
        return None
    detected = log["detected"].to_numpy() > 0.5
    lost = log["in_frame"].to_numpy() < 0.5 if "in_frame" in log else ~detected
    t = log["time_s"].to_numpy()
    starts = np.flatnonzero(lost[1:] & ~lost[:-1]) + 1
    durations = np.full(starts.size, np.nan)
    for i, k in enumerate(starts):
        found = np.flatnonzero(detected[k:] & ~lost[k:])
        if found.size:
            durations[i] = t[k + found[0]] - t[k]
    return durations


@metric("reacquire_time_s", "s", "time to reacquire (s)")
def reacquire_time_s(log: pd.DataFrame) -> float:
    """Mean time [s] from losing the person until the next detection; NaN if never lost.

    Losses that never end (the episode ended first) are not timed: the mean is over the
    losses that ended, so read it with ``reacquired_pct`` (how many did) and ``lost_rate_pct``
    (episodes ended by a loss).
    """
    durations = _losses(log)
    return float("nan") if durations is None else _mean(durations[np.isfinite(durations)])


@metric("reacquired_pct", "%", "losses reacquired (%)")
def reacquired_pct(log: pd.DataFrame) -> float:
    """Share of the episode's losses of the person (:func:`_losses`) that ended with the person
    detected again before the episode ended, %; NaN if never lost. The time to reacquire counts
    only these: a controller that never finds the person again does not get a short one."""
    durations = _losses(log)
    if durations is None or durations.size == 0:
        return float("nan")
    return float(100.0 * np.isfinite(durations).mean())


@metric("jerk_rms_m_s3", "m/s³", "jerk RMS (m/s³)")
def jerk_rms_m_s3(log: pd.DataFrame) -> float:
    """RMS of the jerk [m/s³]: the finite difference of ``accel_mps2`` between rows."""
    t = log["time_s"].to_numpy(dtype=np.float64)
    a = log["accel_mps2"].to_numpy(dtype=np.float64)
    jerk = _finite(np.diff(a) / np.diff(t))
    return float(np.sqrt(np.mean(jerk**2))) if jerk.size else float("nan")


@metric("turn_accel_rms_rad_s2", "rad/s²", "turn accel RMS (rad/s²)")
def turn_accel_rms_rad_s2(log: pd.DataFrame) -> float:
    """RMS of the yaw acceleration [rad/s²]: finite difference of ``robot_w_radps`` between rows.

    The three classical laws share V = kv (d - 1) and differ only in w (reference §1.5), so
    MeanAccel/StdAccel, being forward accelerations, can barely tell them apart; this is the
    smoothness of what they do differ in. NaN without ``robot_w_radps``.
    """
    if "robot_w_radps" not in log:
        return float("nan")
    t = log["time_s"].to_numpy(dtype=np.float64)
    w = log["robot_w_radps"].to_numpy(dtype=np.float64)
    yaw_accel = _finite(np.diff(w) / np.diff(t))
    return float(np.sqrt(np.mean(yaw_accel**2))) if yaw_accel.size else float("nan")


def _ending(log: pd.DataFrame) -> str | None:
    if "termination" not in log:
        return None
    # The last non-blank cell, looked for from the end: an ending is on the last row or two.
    for e in log["termination"].to_numpy(dtype=object)[::-1]:
        if isinstance(e, str) and e:
            return str(e)
    return ""


@metric("lost_rate_pct", "%", "lost person (%)", binary=True)
def lost_rate_pct(log: pd.DataFrame) -> float:
    """100 if the episode ended because the person was lost (``termination == "lost"``), else 0.

    Averaged over episodes it is the lost-person rate in %. NaN without a ``termination`` column.
    """
    ending = _ending(log)
    return float("nan") if ending is None else 100.0 * (ending == LOST_ENDING)


@metric("collision_rate_pct", "%", "collision (%)", binary=True)
def collision_rate_pct(log: pd.DataFrame) -> float:
    """100 if the episode ended in a collision (a wall or obstacle, the person, a bystander),
    else 0.

    Averaged over episodes it is the collision rate in %. NaN without a ``termination`` column.
    """
    ending = _ending(log)
    return float("nan") if ending is None else 100.0 * (ending in COLLISION_ENDINGS)


@metric("target_swap_rate_pct", "%", "target swap (%)")
def target_swap_rate_pct(log: pd.DataFrame) -> float:
    """Share (%) of the frames with a detection in which the perception took a person other
    than the target (``detected_person`` > 0): a bystander stole the target. NaN without a
    ``detected_person`` column (a real robot does not know who it followed)."""
    if "detected_person" not in log:
        return float("nan")
    picked = log["detected_person"].to_numpy(dtype=float)
    picked = picked[np.isfinite(picked) & (picked >= 0)]
    return 100.0 * float(np.mean(picked > 0)) if picked.size else float("nan")


#: The following band of the social-navigation benchmarks [m]: near enough to follow, not so
#: near as to crowd the person (our reference distance, 1.0 m, is its middle).
FOLLOW_BAND_M = (0.5, 1.5)
#: "Facing" the person: the cosine of the angle between the robot's heading and the line to
#: the person above this, i.e. within 60 deg (habitat-lab's social-navigation measures,
#: ``facing_threshold`` 0.5); from the poses, so that a person nearer than the camera's view
#: of 30 % of their body (about 0.66 m on the reference robot) or hidden behind an obstacle
#: still counts as faced.
FACING_COS = 0.5
#: Longest the person may go without a detection of their own and the episode still succeed
#: [s]: the robot's lost rule (``EpisodeConfig.lost_timeout_s``, 3 s) applied to the target's
#: detections instead of anyone's, fixed here so that success means one thing in every run.
TARGET_LOST_S = 3.0


@metric("success_pct", "%", "success (%)", binary=True)
def success_pct(log: pd.DataFrame) -> float:
    """100 if the episode ended with neither a collision nor the person lost, and (where the
    log says whose detection was published, ``detected_person``: a simulation) the person
    itself was detected at least every :data:`TARGET_LOST_S` seconds; else 0. The robot's
    lost rule counts a bystander's detection as a sighting, so a robot that followed a
    stranger to the end of the walk would otherwise succeed. The social-navigation benchmarks'
    success; averaged over episodes it is the success rate in %. NaN without a ``termination``
    column."""
    ending = _ending(log)
    if ending is None:
        return float("nan")
    if ending == LOST_ENDING or ending in COLLISION_ENDINGS:
        return 0.0
    gap = _longest_without_target_s(log)
    return 0.0 if gap > TARGET_LOST_S + 1e-9 else 100.0


def _longest_without_target_s(log: pd.DataFrame) -> float:
    """The longest time [s] from the reset or a detection of the person (``detected_person``
    0) to a row without one, as the robot's lost timer counts; 0 without the columns."""
    if "detected_person" not in log or "time_s" not in log or log.empty:
        return 0.0
    t = log["time_s"].to_numpy(dtype=float)
    seen = log["detected_person"].to_numpy(dtype=float) == 0.0
    seen[0] = True  # the timer starts at the reset
    last = np.maximum.accumulate(np.where(seen, t, -np.inf))
    return float(np.max(t - last))


@metric("following_rate_pct", "%", "following rate (%)")
def following_rate_pct(log: pd.DataFrame) -> float:
    """Share (%) of the steps with the person within :data:`FOLLOW_BAND_M` (true distance,
    both ends included) and the robot facing them (:data:`FACING_COS`, from the poses), the
    reset row left out: the social-navigation benchmarks' following rate. NaN without ground
    truth (a robot log)."""
    poses = ("robot_x_m", "robot_y_m", "robot_theta_rad", "person_x_m", "person_y_m")
    if not all(c in log for c in ("true_distance_m", *poses)):
        return float("nan")
    steps = log.iloc[1:] if len(log) > 1 else log
    if not len(steps):
        return float("nan")
    d = steps["true_distance_m"].to_numpy(dtype=float)
    near = (d >= FOLLOW_BAND_M[0]) & (d <= FOLLOW_BAND_M[1])
    dx = steps["person_x_m"].to_numpy(dtype=float) - steps["robot_x_m"].to_numpy(dtype=float)
    dy = steps["person_y_m"].to_numpy(dtype=float) - steps["robot_y_m"].to_numpy(dtype=float)
    theta = steps["robot_theta_rad"].to_numpy(dtype=float)
    # cos of the angle between the heading (cos, sin) and the unit vector to the person
    with np.errstate(invalid="ignore", divide="ignore"):
        cos = (dx * np.cos(theta) + dy * np.sin(theta)) / np.hypot(dx, dy)
    facing = cos > FACING_COS
    return 100.0 * float(np.mean(near & facing))


def _path_length_m(x: pd.Series, y: pd.Series) -> float:
    return float(np.hypot(np.diff(x.to_numpy()), np.diff(y.to_numpy())).sum())


@metric("path_length_ratio", "", "path length ratio")
def path_length_ratio(log: pd.DataFrame) -> float:
    """Robot path length / person path length over the episode [-]; NaN without poses.

    Near 1 for a robot that follows in the person's footsteps; above 1 when it weaves.
    """
    needed = ("robot_x_m", "robot_y_m", "person_x_m", "person_y_m")
    if not all(c in log for c in needed):
        return float("nan")
    person = _path_length_m(log["person_x_m"], log["person_y_m"])
    if not person > 0.0:
        return float("nan")
    return _path_length_m(log["robot_x_m"], log["robot_y_m"]) / person


METRICS: MappingProxyType[str, Metric] = MappingProxyType(_REGISTRY)
"""Every registered metric by name, in registration order (the table's column order)."""
#: The thesis's five metrics, in the order of its table (reference §1.6).
THESIS_METRICS: tuple[str, ...] = (
    "mean_offset_px",
    "std_offset_px",
    "mean_accel_mm_s2",
    "std_accel_mm_s2",
    "in_frame_rate_pct",
)


#: Shown beside the thesis's five wherever a table leads with them (``follow-eval``'s headline
#: table, the model card): how often an episode ended in a collision or with the person lost,
#: and how far from the 1 m reference the robot kept. The thesis's metrics score centring and
#: smoothness only, so alone they rank a controller that backs into a wall above one that
#: follows.
OUTCOME_METRICS: tuple[str, ...] = (
    "collision_rate_pct",
    "lost_rate_pct",
    "mean_distance_error_m",
    "rms_distance_error_m",
)
#: The headline table's metrics, in column order.
HEADLINE_METRICS: tuple[str, ...] = (*THESIS_METRICS, *OUTCOME_METRICS)


def metric_label(name: str, metrics: Mapping[str, Metric] | None = None) -> str:
    """The table label of metric ``name`` (unit included), from ``metrics`` (default:
    :data:`METRICS`); the name itself for a column that is no registered metric."""
    known = METRICS if metrics is None else metrics
    return known[name].label if name in known else name


def metric_digits(name: str) -> int:
    """Decimals a table shows for metric ``name``: 1 for %, px, mm/s² and mm; 3 for the rest
    (metres to the mm, seconds to the ms, ratios)."""
    return 1 if name.endswith(("_pct", "_px", "_mm_s2", "_mm")) else 3


def extra_metrics() -> tuple[str, ...]:
    """The registered metrics beyond the thesis's five, in registration order."""
    return tuple(n for n in _REGISTRY if n not in THESIS_METRICS)


def episode_metrics(log: pd.DataFrame) -> dict[str, float]:
    """Every registered metric of one step log, by name, in table order."""
    return {name: float(m.fn(log)) for name, m in _REGISTRY.items()}

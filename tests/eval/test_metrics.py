"""eval/metrics.py: each metric on a tiny hand-made step log with a known answer."""

import math

import numpy as np
import pandas as pd
import pytest

from eval.metrics import METRICS, THESIS_METRICS, episode_metrics, extra_metrics, metric


def make_log(**columns: list) -> pd.DataFrame:
    """A step log with 0.1 s rows; unspecified required columns are filled with zeros."""
    n = len(next(iter(columns.values())))
    base = {
        "time_s": [0.1 * k for k in range(n)],
        "obs_distance_m": [1.0] * n,
        "obs_offset_px": [0.0] * n,
        "accel_mps2": [0.0] * n,
    }
    return pd.DataFrame({**base, **columns})


def test_mean_offset_is_mean_absolute_observed_offset_over_detected_rows() -> None:
    # Detected rows: 10, -20, 30 -> (10 + 20 + 30) / 3 = 20; the held 99 is not a measurement.
    log = make_log(obs_offset_px=[10.0, -20.0, 99.0, 30.0], detected=[1, 1, 0, 1])
    assert METRICS["mean_offset_px"].fn(log) == pytest.approx(20.0)


def test_mean_offset_uses_every_row_without_a_detected_column() -> None:
    log = make_log(obs_offset_px=[10.0, -20.0, 99.0, 30.0])
    assert METRICS["mean_offset_px"].fn(log) == pytest.approx(159.0 / 4)


def test_mean_offset_ignores_the_true_offset() -> None:
    # The thesis logged camera data: the observed offset is the one that counts.
    log = make_log(obs_offset_px=[4.0, -4.0], true_offset_px=[100.0, 100.0], detected=[1, 1])
    assert METRICS["mean_offset_px"].fn(log) == pytest.approx(4.0)
    assert METRICS["mean_true_offset_px"].fn(log) == pytest.approx(100.0)


def test_std_offset_is_population_std_of_signed_observed_offset() -> None:
    # Offsets 10, -10 (detected): mean 0, population std 10. The held row is left out.
    log = make_log(obs_offset_px=[10.0, -10.0, 50.0], detected=[1, 1, 0])
    assert METRICS["std_offset_px"].fn(log) == pytest.approx(10.0)


def test_mean_accel_is_the_signed_mean_in_mm_s2() -> None:
    # (0.2 - 0.4 + 0 + 0.3) / 4 = 0.025 m/s² = 25 mm/s²; the magnitude is its own metric
    log = make_log(accel_mps2=[0.2, -0.4, 0.0, 0.3])
    assert METRICS["mean_accel_mm_s2"].fn(log) == pytest.approx(25.0)
    # |0.2| + |-0.4| + |0| + |0.3| = 0.9 m/s² over 4 rows = 225 mm/s²
    assert METRICS["mean_abs_accel_mm_s2"].fn(log) == pytest.approx(225.0)


def test_the_signed_mean_telescopes_to_the_speed_change_over_the_time() -> None:
    # a = dv/dt per row: the mean over N rows is (v_end - v_0) / (N dt): here 0 (rest to rest)
    speed = np.array([0.0, 0.3, 0.8, 0.5, 0.9, 0.0])
    log = make_log(accel_mps2=np.diff(speed, prepend=0.0) / 0.1)
    assert METRICS["mean_accel_mm_s2"].fn(log) == pytest.approx(0.0, abs=1e-9)
    assert METRICS["mean_abs_accel_mm_s2"].fn(log) > 1000


def test_std_accel_is_population_std_of_signed_accel_in_mm_s2() -> None:
    # 0.1, -0.1: mean 0, std 0.1 m/s² = 100 mm/s²
    log = make_log(accel_mps2=[0.1, -0.1])
    assert METRICS["std_accel_mm_s2"].fn(log) == pytest.approx(100.0)


def test_in_frame_rate_uses_ground_truth_when_logged() -> None:
    log = make_log(in_frame=[1, 1, 0, 1], detected=[0, 0, 0, 0])
    assert METRICS["in_frame_rate_pct"].fn(log) == pytest.approx(75.0)


def test_in_frame_rate_falls_back_to_detections_for_a_robot_log() -> None:
    log = make_log(detected=[1, 0, 0, 1, 1])
    assert METRICS["in_frame_rate_pct"].fn(log) == pytest.approx(60.0)


def test_distance_errors_use_true_distance_when_logged() -> None:
    # errors 0.2, -0.2, 0.6: mean 0.2; rms sqrt((0.04 + 0.04 + 0.36) / 3) = sqrt(0.44 / 3)
    log = make_log(true_distance_m=[1.2, 0.8, 1.6], obs_distance_m=[5.0, 5.0, 5.0])
    assert METRICS["mean_distance_error_m"].fn(log) == pytest.approx(0.2)
    assert METRICS["rms_distance_error_m"].fn(log) == pytest.approx(math.sqrt(0.44 / 3))


def test_distance_errors_of_a_robot_log_skip_rows_without_a_reading() -> None:
    # obs 0 = no reading yet; errors 0.5 and 0.3 -> mean 0.4
    log = make_log(obs_distance_m=[0.0, 1.5, 1.3])
    assert METRICS["mean_distance_error_m"].fn(log) == pytest.approx(0.4)


def test_reacquire_time_is_from_leaving_the_frame_to_the_next_detection() -> None:
    # Out of frame at t = 0.2 s; back in frame at 0.4 s; detected again at 0.5 s -> 0.3 s.
    log = make_log(in_frame=[1, 1, 0, 0, 1, 1, 1], detected=[1, 1, 1, 0, 0, 1, 1])
    assert METRICS["reacquire_time_s"].fn(log) == pytest.approx(0.3)


def test_reacquire_time_averages_losses_and_skips_one_never_reacquired() -> None:
    # Losses at 0.1 (back, detected at 0.2: 0.1 s), 0.3 (detected at 0.6: 0.3 s), 0.7 (never).
    log = make_log(in_frame=[1, 0, 1, 0, 0, 1, 1, 0], detected=[1, 0, 1, 0, 0, 0, 1, 0])
    assert METRICS["reacquire_time_s"].fn(log) == pytest.approx(0.2)


def test_reacquire_time_is_nan_when_never_lost() -> None:
    log = make_log(in_frame=[1, 1, 1], detected=[1, 0, 1])
    assert math.isnan(METRICS["reacquire_time_s"].fn(log))
    assert math.isnan(METRICS["reacquired_pct"].fn(log))


def test_the_share_of_losses_reacquired_counts_the_one_the_time_leaves_out() -> None:
    # The three losses above: two found again (0.1 s and 0.3 s), the last never.
    log = make_log(in_frame=[1, 0, 1, 0, 0, 1, 1, 0], detected=[1, 0, 1, 0, 0, 0, 1, 0])
    assert METRICS["reacquired_pct"].fn(log) == pytest.approx(200.0 / 3.0)
    # one loss, never found again: no time to reacquire at all, and none of it reacquired
    never = make_log(in_frame=[1, 1, 0, 0], detected=[1, 1, 0, 0])
    assert math.isnan(METRICS["reacquire_time_s"].fn(never))
    assert METRICS["reacquired_pct"].fn(never) == 0.0
    assert METRICS["reacquired_pct"].fn(make_log(in_frame=[1, 0, 1], detected=[1, 0, 1])) == 100.0


def test_jerk_rms_is_rms_of_accel_differences_over_time() -> None:
    # accel 0, 0.1, 0 over 0.1 s steps: jerk 1, -1 m/s³ -> RMS 1
    log = make_log(accel_mps2=[0.0, 0.1, 0.0])
    assert METRICS["jerk_rms_m_s3"].fn(log) == pytest.approx(1.0)


def test_turn_accel_rms_is_rms_of_yaw_rate_differences_over_time() -> None:
    # w 0, 0.2, 0.2: yaw accel 2, 0 rad/s² -> RMS sqrt(2)
    log = make_log(robot_w_radps=[0.0, 0.2, 0.2])
    assert METRICS["turn_accel_rms_rad_s2"].fn(log) == pytest.approx(math.sqrt(2.0))


@pytest.mark.parametrize(
    ("ending", "lost", "collision"),
    [
        ("lost", 100.0, 0.0),
        ("collision_wall", 0.0, 100.0),
        ("collision_person", 0.0, 100.0),
        ("collision_bystander", 0.0, 100.0),
        ("walk_over", 0.0, 0.0),
    ],
)
def test_lost_and_collision_rates_come_from_the_final_row(
    ending: str, lost: float, collision: float
) -> None:
    log = make_log(termination=["", "", ending])
    assert METRICS["lost_rate_pct"].fn(log) == lost
    assert METRICS["collision_rate_pct"].fn(log) == collision


def test_target_swap_rate_is_the_share_of_detections_that_took_a_bystander() -> None:
    # 5 frames with a detection (index >= 0), 2 of them a bystander's; -1 frames do not count.
    log = make_log(detected_person=[0, 0, -1, 1, 2, 0, -1])
    assert METRICS["target_swap_rate_pct"].fn(log) == pytest.approx(40.0)
    assert math.isnan(METRICS["target_swap_rate_pct"].fn(make_log(detected_person=[-1, -1])))


@pytest.mark.parametrize(
    ("ending", "success"),
    [("walk_over", 100.0), ("step_limit", 100.0), ("lost", 0.0), ("collision_wall", 0.0)],
)
def test_success_is_neither_lost_nor_collided(ending: str, success: float) -> None:
    log = make_log(termination=["", "", ending], detected_person=[-1, 0, 0])
    assert METRICS["success_pct"].fn(log) == success
    assert math.isnan(METRICS["success_pct"].fn(make_log(obs_offset_px=[0.0, 1.0])))


def test_following_a_stranger_to_the_end_is_no_success() -> None:
    # The robot's lost rule counts a bystander's detection as a sighting, so the walk ends
    # well (walk_over); the person itself was not detected for 3.1 s (rows 1..32 at 0.1 s).
    picked = [-1, 0, *[1] * 31, 0]
    log = make_log(detected_person=picked, termination=[""] * 33 + ["walk_over"])
    assert METRICS["success_pct"].fn(log) == 0.0
    # 3.0 s without the person's detection, as the robot's 3 s timer allows: still a success
    log = make_log(detected_person=[-1, 0, *[1] * 29, 0], termination=[""] * 31 + ["walk_over"])
    assert METRICS["success_pct"].fn(log) == 100.0
    # from the reset: a person first detected after 3.1 s was not followed
    log = make_log(detected_person=[-1] * 32 + [0], termination=[""] * 32 + ["walk_over"])
    assert METRICS["success_pct"].fn(log) == 0.0


def _follow_log(distance_m: float, bearing_deg: float) -> pd.DataFrame:
    """Two rows, the robot at the origin facing +x, the person at ``distance_m`` (its true
    distance too) and ``bearing_deg`` to the left."""
    b = math.radians(bearing_deg)
    x, y = distance_m * math.cos(b), distance_m * math.sin(b)
    return make_log(
        true_distance_m=[distance_m] * 2,
        in_frame=[0.0] * 2,  # not asked: near or hidden, the person may be out of the image
        robot_x_m=[0.0] * 2,
        robot_y_m=[0.0] * 2,
        robot_theta_rad=[0.0] * 2,
        person_x_m=[x] * 2,
        person_y_m=[y] * 2,
    )


@pytest.mark.parametrize(
    ("distance_m", "bearing_deg", "following"),
    [
        (0.5, 0.0, 100.0),  # the band's ends are in it
        (1.5, 0.0, 100.0),
        (0.49, 0.0, 0.0),
        (1.51, 0.0, 0.0),
        (1.0, 59.0, 100.0),  # facing: within 60 deg of the heading, either side
        (1.0, -59.0, 100.0),
        (1.0, 61.0, 0.0),
        (1.0, 180.0, 0.0),
    ],
)
def test_following_is_the_band_and_facing_the_person_from_the_poses(
    distance_m: float, bearing_deg: float, following: float
) -> None:
    # "facing" used to be in_frame, which needs 30 % of the body in the image: nobody
    # straight ahead nearer than about 0.66 m was followed
    log = _follow_log(distance_m, bearing_deg)
    assert METRICS["following_rate_pct"].fn(log) == following


def test_following_is_the_share_of_steps_after_the_reset() -> None:
    log = pd.concat([_follow_log(1.0, 0.0), _follow_log(1.0, 90.0).iloc[1:]] * 2)
    log["time_s"] = [0.1 * k for k in range(len(log))]
    # after the reset row: facing, turned away, facing, facing, turned away
    assert len(log) == 6
    assert METRICS["following_rate_pct"].fn(log) == pytest.approx(100.0 * 3 / 5)


def test_path_length_ratio_is_robot_over_person_path() -> None:
    # Person walks 2 m straight; robot goes 1 m then 1 m sideways then back: 3 m -> 1.5
    log = make_log(
        person_x_m=[0.0, 1.0, 2.0, 2.0],
        person_y_m=[0.0, 0.0, 0.0, 0.0],
        robot_x_m=[0.0, 1.0, 1.0, 1.0],
        robot_y_m=[0.0, 0.0, 1.0, 0.0],
    )
    assert METRICS["path_length_ratio"].fn(log) == pytest.approx(1.5)


def test_metrics_needing_absent_columns_are_nan() -> None:
    # A minimal robot log: time, observation, acceleration.
    values = episode_metrics(make_log(obs_offset_px=[1.0, 2.0]))
    for name in (
        "mean_true_offset_px",
        "reacquire_time_s",
        "reacquired_pct",
        "turn_accel_rms_rad_s2",
        "lost_rate_pct",
        "collision_rate_pct",
        "path_length_ratio",
        "target_swap_rate_pct",
        "success_pct",
        "following_rate_pct",
    ):
        assert math.isnan(values[name]), name
    assert values["mean_offset_px"] == pytest.approx(1.5)


def test_thesis_metrics_lead_the_table_in_the_thesis_order() -> None:
    assert list(episode_metrics(make_log(obs_offset_px=[1.0])))[:5] == list(THESIS_METRICS)
    assert THESIS_METRICS == (
        "mean_offset_px",
        "std_offset_px",
        "mean_accel_mm_s2",
        "std_accel_mm_s2",
        "in_frame_rate_pct",
    )


def test_a_new_metric_is_one_decorated_function() -> None:
    from eval import metrics as module

    @metric("test_max_offset_px", "px", "max offset (px)")
    def max_offset(log: pd.DataFrame) -> float:
        return float(np.abs(log["obs_offset_px"]).max())

    try:
        assert "test_max_offset_px" in extra_metrics()
        assert episode_metrics(make_log(obs_offset_px=[3.0, -7.0]))["test_max_offset_px"] == 7.0
    finally:
        del module._REGISTRY["test_max_offset_px"]


def test_registering_a_taken_metric_name_is_rejected() -> None:
    with pytest.raises(ValueError, match="already registered"):
        metric("mean_offset_px", "px", "x")(lambda log: 0.0)

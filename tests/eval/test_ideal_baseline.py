"""``follow-eval run --ideal-baseline``: every controller again under perfect sensing."""

from __future__ import annotations

from pathlib import Path

import pandas as pd
import pytest

from eval.cli import main
from eval.tasks import eval_task
from follow_env.tasks.person_follow.config import RANDOMIZED


def test_perfect_sensing_changes_the_sensing_fields_only() -> None:
    task = eval_task("person_follow")
    noisy = task.perfect_sensing("noisy")
    assert (noisy.perception.miss_prob, noisy.perception.latency_frames) == (0.0, 0)
    assert noisy.camera.depth_invalid_prob == 0.0
    assert noisy.motor.gain_spread == 0.05  # the noisy preset's motors, not perception
    tracked = task.perfect_sensing({"perception": {"association": "tracker"}})
    assert tracked.perception.association == "tracker"
    assert tracked.perception.center_jitter_frac == 0.0
    line = eval_task("line_trace").perfect_sensing("paper")
    assert (line.sensor.noise_std, line.sensor.ambient_max, line.sensor.gain_spread) == (0, 0, 0)
    assert line.start.lateral_spread_m > 0.0  # the start's randomness is not sensing


def test_perfect_sensing_also_draws_no_sensing_error_per_episode() -> None:
    # the randomized preset draws each episode's detector latency up to 3 frames, a camera
    # tilt and noise levels: those draws used to stay under "perfect sensing"
    randomized = eval_task("person_follow").perfect_sensing("randomized")
    r = randomized.randomization
    assert (r.latency_frames_max, r.camera_tilt_deg, r.detector_level_spread) == (0, 0.0, 0.0)
    assert r.depth_noise_scale_max == 1.0
    assert randomized.perception.latency_frames == 0
    # the world's and the robot's draws stay: perfect sensing, the same robot
    assert r.push_prob == RANDOMIZED.randomization.push_prob > 0.0
    assert r.wheel_radius_error == RANDOMIZED.randomization.wheel_radius_error > 0.0


@pytest.fixture(scope="module")
def run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("ideal") / "run"
    grid = ["--policies", "pn,gsmpn", "--scenarios", "straight,crossing", "--episodes", "2"]
    assert main(["run", *grid, "--ideal-baseline", "--out", str(out), "--workers", "1"]) == 0
    return out


def test_every_policy_is_also_labelled_under_perfect_sensing(run: Path) -> None:
    summary = pd.read_csv(run / "summary.csv")
    assert sorted(set(summary["policy"])) == sorted(
        ["pn:tuned", "gsmpn:tuned", "pn:tuned+ideal", "gsmpn:tuned+ideal"]
    )
    pairs = pd.read_csv(run / "comparisons.csv")[["policy_a", "policy_b"]].drop_duplicates()
    assert ("pn:tuned", "pn:tuned+ideal") in set(map(tuple, pairs.to_numpy()))


def test_the_ideal_episodes_see_the_person_where_they_are(run: Path) -> None:
    for name, label in (
        ("pn_tuned_ideal", "pn:tuned+ideal"),
        ("gsmpn_tuned_ideal", "gsmpn:tuned+ideal"),
    ):
        logs = sorted((run / "logs" / name).rglob("seed_*.csv"))
        assert len(logs) == 4  # 2 scenarios x 2 seeds
        for log_path in logs:
            log = pd.read_csv(log_path)
            assert set(log["policy"]) == {label}
            # where the target itself was detected (a crossing bystander may be taken instead)
            seen = log[(log["detected"] == 1) & (log["detected_person"] == 0)]
            assert len(seen) > 10
            assert (seen["obs_offset_px"] - seen["true_offset_px"]).abs().max() <= 1.0  # a pixel
    noisy = pd.read_csv(run / "logs" / "pn_tuned" / "straight" / "seed_0.csv")
    seen = noisy[noisy["detected"] == 1]
    jitter = (seen["obs_offset_px"] - seen["true_offset_px"]).abs().max()
    assert jitter > 5.0  # the detector's noise, which the baseline removes

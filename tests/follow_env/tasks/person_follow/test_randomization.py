"""Domain randomisation and disturbances: ranges, determinism, independence from actions."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from follow_env.sim.runner import BatchedSim
from follow_env.tasks.person_follow.config import NOISY, RANDOMIZED, THESIS, RandomizationConfig
from follow_env.tasks.person_follow.task import batched_sim

N = 400


def _sim(cfg: object, n: int = N, seed0: int = 0) -> BatchedSim:
    sim = batched_sim(cfg, n)  # type: ignore[arg-type]
    sim.reset_lanes(np.arange(n), list(range(seed0, seed0 + n)))
    return sim


def test_randomisation_is_off_by_default() -> None:
    sim = _sim(THESIS, n=8)
    base = batched_sim(THESIS, 1).base_params
    assert np.all(sim.params["platform"]["wheel_r_true"] == base["platform"]["wheel_r"])
    assert np.all(sim.params["platform"]["track_true"] == base["platform"]["track"])
    assert np.all(sim.params["task"]["camera"]["R"] == base["task"]["camera"]["R"])
    assert np.all(sim.params["task"]["detector"]["latency"] == base["task"]["detector"]["latency"])


def test_randomised_values_stay_in_their_documented_ranges() -> None:
    rc = RANDOMIZED.randomization
    sim = _sim(RANDOMIZED)
    base = batched_sim(RANDOMIZED, 1).base_params
    ratio = sim.params["platform"]["wheel_r_true"] / base["platform"]["wheel_r"]
    assert np.all((ratio >= 0.5) & (ratio <= 1.5))
    assert abs(np.std(ratio) - rc.wheel_radius_error) < 0.005
    track = sim.params["platform"]["track_true"] / base["platform"]["track"]
    assert abs(np.std(track) - rc.track_width_error) < 0.006
    latency = sim.params["task"]["detector"]["latency"]
    assert set(np.unique(latency)) == set(range(NOISY.perception.latency_frames, 4))
    depth = sim.params["task"]["depth"]["depth_k"] / base["task"]["depth"]["depth_k"]
    assert np.all((depth >= 1.0) & (depth <= rc.depth_noise_scale_max))
    fric = sim.params["platform"]["fric"] / base["platform"]["fric"]
    assert np.all((fric >= 1 - rc.friction_spread) & (fric <= 1 + rc.friction_spread))
    assert np.allclose(sim.params["platform"]["stall"] / base["platform"]["stall"], fric)
    level = sim.params["task"]["detector"]["jit_c"] / base["task"]["detector"]["jit_c"]
    spread = rc.detector_level_spread
    assert np.all((level >= 1 - spread) & (level <= 1 + spread))
    assert np.all(
        (sim.params["task"]["detector"]["miss_p"] >= 0.0)
        & (sim.params["task"]["detector"]["miss_p"] <= 1.0)
    )
    # Camera tilt: the rotation differs per lane, and stays a rotation.
    rot = sim.params["task"]["camera"]["R"].reshape(-1, 3, 3)
    assert np.allclose(rot @ rot.transpose(0, 2, 1), np.eye(3), atol=1e-12)
    assert np.ptp(rot[:, 2, 2]) > 0.0


def test_randomisation_is_deterministic_per_seed() -> None:
    a, b = _sim(RANDOMIZED, n=16), _sim(RANDOMIZED, n=16)
    assert np.array_equal(a.params, b.params)
    c = _sim(RANDOMIZED, n=16, seed0=100)
    assert not np.array_equal(a.params, c.params)


def test_switching_one_randomisation_on_leaves_the_others_draws_alone() -> None:
    only_wheels = THESIS.replace(randomization={"wheel_radius_error": 0.05})
    wheels_and_latency = THESIS.replace(
        randomization={"wheel_radius_error": 0.05, "latency_frames_max": 3}
    )
    a, b = _sim(only_wheels, n=16), _sim(wheels_and_latency, n=16)
    assert np.array_equal(
        a.params["platform"]["wheel_r_true"], b.params["platform"]["wheel_r_true"]
    )
    assert not np.array_equal(
        a.params["task"]["detector"]["latency"], b.params["task"]["detector"]["latency"]
    )


def test_pushes_move_the_robot_and_do_not_depend_on_the_actions() -> None:
    cfg = THESIS.replace(randomization={"push_prob": 1.0, "push_speed_mps": 0.4})
    still, moving = _sim(cfg, n=4), _sim(cfg, n=4)
    for _ in range(5):
        still.step(np.zeros((4, 2)))
        moving.step(np.tile([0.3, 0.5], (4, 1)))
        push = np.stack([still.body["push_vx"], still.body["push_vy"]], axis=1)
        assert np.allclose(np.hypot(push[:, 0], push[:, 1]), 0.4)
        assert np.array_equal(
            push, np.stack([moving.body["push_vx"], moving.body["push_vy"]], axis=1)
        )
    displaced = np.hypot(still.body["x"] - (-10.0), still.body["y"])
    assert np.all(displaced > 0.0)


def test_encoder_noise_shows_in_the_speed_of_a_wheel_at_rest() -> None:
    quiet = _sim(THESIS.replace(motor={"gain_spread": 0.0}), n=1)
    noisy = _sim(
        THESIS.replace(motor={"gain_spread": 0.0}, randomization={"encoder_noise_counts": 2.0}), n=1
    )
    speeds_quiet, speeds_noisy = [], []
    for _ in range(30):
        quiet.step(np.zeros((1, 2)))
        noisy.step(np.zeros((1, 2)))
        speeds_quiet.append(quiet.state["platform"]["meas"][0, 0])
        speeds_noisy.append(noisy.state["platform"]["meas"][0, 0])
    assert np.all(np.array(speeds_quiet) == 0.0)
    assert np.std(speeds_noisy) > 0.005  # a few counts per 10 ms are several mm/s


@pytest.mark.parametrize(
    ("field", "bad"),
    [("wheel_radius_error", -0.1), ("push_prob", 1.5), ("depth_noise_scale_max", 0.5)],
)
def test_bad_randomisation_values_raise(field: str, bad: float) -> None:
    with pytest.raises(ValueError, match=rf"RandomizationConfig\.{field}="):
        RandomizationConfig(**{field: bad})


def test_latency_range_must_include_the_base_latency() -> None:
    with pytest.raises(ValueError, match="latency_frames_max"):
        dataclasses.replace(
            THESIS, randomization=RandomizationConfig(latency_frames_max=0)
        ).replace(perception={"latency_frames": 2}, randomization={"latency_frames_max": 1})

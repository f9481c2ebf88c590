"""Domain randomisation and disturbances: ranges, determinism, independence from actions."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from follow_env.config import NOISY, RANDOMIZED, THESIS, RandomizationConfig
from follow_env.core import BatchedSim, params_from_config
from follow_env.layout import (
    P_DEPTH_K,
    P_FRIC_DUTY,
    P_JIT_C,
    P_LATENCY,
    P_MISS_P,
    P_R00,
    P_R22,
    P_STALL_DUTY,
    P_TRACK,
    P_TRACK_TRUE,
    P_WHEEL_R,
    P_WHEEL_R_TRUE,
    S_PUSH_VX,
    S_PUSH_VY,
    S_VMEAS_R,
    S_X,
    S_Y,
)

N = 400


def _sim(cfg: object, n: int = N, seed0: int = 0) -> BatchedSim:
    sim = BatchedSim(cfg, n)  # type: ignore[arg-type]
    sim.reset_lanes(np.arange(n), list(range(seed0, seed0 + n)))
    return sim


def test_randomisation_is_off_by_default() -> None:
    sim = _sim(THESIS, n=8)
    base = params_from_config(THESIS)
    assert np.all(sim.params[:, P_WHEEL_R_TRUE] == base[P_WHEEL_R])
    assert np.all(sim.params[:, P_TRACK_TRUE] == base[P_TRACK])
    assert np.all(sim.params[:, P_R00 : P_R22 + 1] == base[P_R00 : P_R22 + 1])
    assert np.all(sim.params[:, P_LATENCY] == base[P_LATENCY])


def test_randomised_values_stay_in_their_documented_ranges() -> None:
    rc = RANDOMIZED.randomization
    sim = _sim(RANDOMIZED)
    base = params_from_config(RANDOMIZED)
    ratio = sim.params[:, P_WHEEL_R_TRUE] / base[P_WHEEL_R]
    assert np.all((ratio >= 0.5) & (ratio <= 1.5))
    assert abs(np.std(ratio) - rc.wheel_radius_error) < 0.005
    track = sim.params[:, P_TRACK_TRUE] / base[P_TRACK]
    assert abs(np.std(track) - rc.track_width_error) < 0.006
    latency = sim.params[:, P_LATENCY]
    assert set(np.unique(latency)) == set(range(NOISY.perception.latency_frames, 4))
    depth = sim.params[:, P_DEPTH_K] / base[P_DEPTH_K]
    assert np.all((depth >= 1.0) & (depth <= rc.depth_noise_scale_max))
    fric = sim.params[:, P_FRIC_DUTY] / base[P_FRIC_DUTY]
    assert np.all((fric >= 1 - rc.friction_spread) & (fric <= 1 + rc.friction_spread))
    assert np.allclose(sim.params[:, P_STALL_DUTY] / base[P_STALL_DUTY], fric)
    level = sim.params[:, P_JIT_C] / base[P_JIT_C]
    spread = rc.detector_level_spread
    assert np.all((level >= 1 - spread) & (level <= 1 + spread))
    assert np.all((sim.params[:, P_MISS_P] >= 0.0) & (sim.params[:, P_MISS_P] <= 1.0))
    # Camera tilt: the rotation differs per lane, and stays a rotation.
    rot = sim.params[:, P_R00 : P_R22 + 1].reshape(-1, 3, 3)
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
    assert np.array_equal(a.params[:, P_WHEEL_R_TRUE], b.params[:, P_WHEEL_R_TRUE])
    assert not np.array_equal(a.params[:, P_LATENCY], b.params[:, P_LATENCY])


def test_pushes_move_the_robot_and_do_not_depend_on_the_actions() -> None:
    cfg = THESIS.replace(randomization={"push_prob": 1.0, "push_speed_mps": 0.4})
    still, moving = _sim(cfg, n=4), _sim(cfg, n=4)
    for _ in range(5):
        still.step(np.zeros((4, 2)))
        moving.step(np.tile([0.3, 0.5], (4, 1)))
        push = still.fstate[:, [S_PUSH_VX, S_PUSH_VY]]
        assert np.allclose(np.hypot(push[:, 0], push[:, 1]), 0.4)
        assert np.array_equal(push, moving.fstate[:, [S_PUSH_VX, S_PUSH_VY]])
    displaced = np.hypot(still.fstate[:, S_X] - (-10.0), still.fstate[:, S_Y])
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
        speeds_quiet.append(quiet.fstate[0, S_VMEAS_R])
        speeds_noisy.append(noisy.fstate[0, S_VMEAS_R])
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

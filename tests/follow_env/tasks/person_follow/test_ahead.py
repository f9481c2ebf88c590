"""The reading ahead: an optional third observation entry, the nearest valid depth across the
image's middle row (``PerceptionConfig.ahead_rays``)."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
import pytest

import follow_env  # noqa: F401  (registers the envs)
from follow_env.sensors.depth import AHEAD, NOISE
from follow_env.tasks.person_follow.config import THESIS, EnvConfig
from follow_env.tasks.person_follow.task import batched_sim

AHEAD_ON = {"ahead_rays": 5}


def _rollout(
    scenario: str, seed: int, steps: int, config: Any = "thesis", **kwargs: Any
) -> tuple[np.ndarray, list[dict[str, Any]]]:
    """Observations and infos of ``steps`` steps of a fixed action sequence."""
    env = gym.make("PersonFollow-v0", scenario=scenario, config=config, **kwargs)
    obs, info = env.reset(seed=seed)
    observations, infos = [obs], [info]
    rng = np.random.default_rng(7)  # the actions: the same sequence for both envs
    for _ in range(steps):
        action = np.array([rng.uniform(0.0, 1.2), rng.uniform(-0.8, 0.8)], dtype=np.float32)
        obs, _, terminated, truncated, info = env.step(action)
        observations.append(obs)
        infos.append(info)
        if terminated or truncated:
            break
    env.close()
    return np.array(observations), infos


def test_off_by_default_the_observation_has_two_entries() -> None:
    env = gym.make("PersonFollow-v0")
    obs, _ = env.reset(seed=0)
    assert obs.shape == (2,)
    assert env.observation_space.shape == (2,)
    assert THESIS.perception.ahead_rays == 0


def test_on_the_observation_has_a_third_entry_within_its_bounds() -> None:
    env = gym.make("PersonFollow-v0", scenario="crowd", perception=AHEAD_ON)
    space = env.observation_space
    assert space.shape == (3,)
    assert space.low[2] == 0.0
    assert space.high[2] == pytest.approx(THESIS.camera.depth_max_m)
    obs, _ = env.reset(seed=3)
    seen = [obs]
    for _ in range(60):
        obs, *_ = env.step(np.array([0.6, 0.2], dtype=np.float32))
        seen.append(obs)
    seen_arr = np.array(seen)
    assert all(space.contains(o) for o in seen_arr)
    assert np.ptp(seen_arr[:, 2]) > 0.1  # the robot turns: what is ahead changes


@pytest.mark.parametrize(("scenario", "config"), [("crowd", "thesis"), ("random_world", "noisy")])
def test_it_changes_nothing_else(scenario: str, config: str) -> None:
    """Its draws are its own: the first two entries and every info value are bit for bit those
    of the env without it, under the same actions."""
    off_obs, off_info = _rollout(scenario, 5, 120, config)
    on_obs, on_info = _rollout(scenario, 5, 120, config, perception=AHEAD_ON)
    np.testing.assert_array_equal(on_obs[:, :2], off_obs)
    assert on_info == off_info


def test_under_exact_depth_it_reads_the_person_straight_ahead() -> None:
    """At the start of `straight` the person stands 1 m in front: the centre columns hit the
    front of their body, whose depth is the true distance (an ideal camera)."""
    env = gym.make("PersonFollow-v0", config="ideal", perception=AHEAD_ON)
    obs, info = env.reset(seed=0)
    assert obs[2] == pytest.approx(info["true_distance_m"], abs=1e-3)
    assert obs[2] == pytest.approx(1.0, abs=0.02)


def test_nothing_within_range_reads_the_far_limit() -> None:
    """A person beyond the depth range reads 0 on the camera, as does every pixel there: the
    reading says the far limit, nothing measurable ahead."""
    env = gym.make(
        "PersonFollow-v0",
        config="ideal",
        perception=AHEAD_ON,
        camera={"depth_max_m": 0.6},
        scenario__start_distance_m=2.0,
    )
    obs, _ = env.reset(seed=0)
    assert obs[2] == pytest.approx(0.6)


def test_invalid_pixels_are_skipped() -> None:
    """Every pixel invalid: no column reads, so the far limit; at half the pixels invalid the
    nearest valid one still sees the person unless all three columns on their body are
    invalid (one start in eight), and then the reading is farther."""
    all_bad, _ = _rollout(
        "straight", 1, 20, camera={"depth_invalid_prob": 1.0}, perception=AHEAD_ON
    )
    assert np.all(all_bad[:, 2] == np.float32(THESIS.camera.depth_max_m))
    env = gym.make("PersonFollow-v0", camera={"depth_invalid_prob": 0.5}, perception=AHEAD_ON)
    starts = [env.reset(seed=seed) for seed in range(40)]
    ahead = np.array([obs[2] for obs, _ in starts], dtype=np.float64)
    true_d = np.array([info["true_distance_m"] for _, info in starts])
    near = np.abs(ahead - true_d) < 0.05
    assert 0.7 < near.mean() < 1.0
    assert np.all(ahead[~near] > true_d[~near])


def test_its_noise_is_the_d435i_model() -> None:
    """The thesis camera's noise, RMS ~ Z^2: a person held at about 1 m reads scattered by the
    depth RMS at 1 m, of whole millimetres."""
    env = gym.make("PersonFollow-v0", perception={"ahead_rays": 1})
    readings, truth = [], []
    for seed in range(40):
        obs, info = env.reset(seed=seed)
        readings.append(obs[2])
        truth.append(info["true_distance_m"])
    err = np.array(readings, dtype=np.float64) - np.array(truth)
    cam = THESIS.camera
    rms_1m = cam.depth_subpixel / (cam.depth_focal_px * cam.depth_baseline_m)
    assert 0.5 * rms_1m < err.std() < 2.0 * rms_1m
    mm = np.array(readings, dtype=np.float64) * 1000.0
    np.testing.assert_allclose(mm, np.round(mm), atol=1e-3)  # float32 of whole mm


def test_the_batched_core_publishes_the_same_reading() -> None:
    cfg = EnvConfig.from_overrides(THESIS, {"perception": AHEAD_ON, "scenario": {"name": "crowd"}})
    sim = batched_sim(cfg, 3)
    sim.reset_lanes(np.arange(3), [11, 12, 13])
    from follow_env.tasks.person_follow.task import TASK

    batch = TASK.observations(sim)
    assert batch.shape == (3, 3)
    for lane, seed in enumerate((11, 12, 13)):
        env = gym.make("PersonFollow-v0", scenario="crowd", perception=AHEAD_ON)
        obs, _ = env.reset(seed=seed)
        np.testing.assert_array_equal(batch[lane], obs)
    sim.close()


def test_the_spec_names_its_settings_with_the_configs_defaults() -> None:
    from follow_env.sensors.detector import PerceptionConfig
    from follow_env.tasks.person_follow.spec import AHEAD_SETTINGS

    default = PerceptionConfig()
    assert {k: getattr(default, k) for k in AHEAD_SETTINGS} == AHEAD_SETTINGS


def test_its_draws_are_declared_apart_from_the_box_centres() -> None:
    assert AHEAD.key == NOISE.key
    assert AHEAD.stride == NOISE.stride
    lo, hi = AHEAD.start, AHEAD.start + AHEAD.count
    assert hi <= NOISE.start or lo >= NOISE.start + NOISE.count


@pytest.mark.parametrize(
    ("overrides", "field"),
    [
        ({"perception": {"ahead_rays": 17}}, "ahead_rays"),
        ({"perception": {"ahead_rays": -1}}, "ahead_rays"),
        ({"perception": {"ahead_rays": 2.5}}, "ahead_rays"),
        ({"perception": {"ahead_half_angle_deg": 50.0}}, "ahead_half_angle_deg"),
        # the camera's field of view is 55 deg wide: +-30 deg falls outside the image
        ({"perception": {"ahead_rays": 3, "ahead_half_angle_deg": 30.0}}, "ahead_half_angle_deg"),
    ],
)
def test_bad_settings_are_refused_naming_the_field(overrides: dict, field: str) -> None:
    with pytest.raises(ValueError, match=rf"PerceptionConfig\.{field}="):
        EnvConfig.from_overrides(THESIS, overrides)


def test_gymnasium_and_sb3_checks_pass_with_it() -> None:
    import warnings

    from gymnasium.utils.env_checker import check_env as gym_check_env
    from stable_baselines3.common.env_checker import check_env as sb3_check_env

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the SI action box's advisory warning (README)
        gym_check_env(
            gym.make("PersonFollow-v0", render_mode="rgb_array", perception=AHEAD_ON).unwrapped
        )
        sb3_check_env(gym.make("PersonFollow-v0", perception=AHEAD_ON).unwrapped)


def test_the_frame_shows_it() -> None:
    """The rendered frame marks the reading's columns and value in its colour, only with it."""
    from follow_env.tasks.person_follow.render_style import C_AHEAD

    def frame(**kwargs: Any) -> np.ndarray:
        env = gym.make("PersonFollow-v0", scenario="crowd", render_mode="rgb_array", **kwargs)
        env.reset(seed=2)
        return env.render()

    def magenta(img: np.ndarray) -> int:
        return int(np.all(img == np.array(C_AHEAD, dtype=np.uint8), axis=-1).sum())

    assert magenta(frame()) == 0
    assert magenta(frame(perception=AHEAD_ON)) > 50


def test_excluding_the_target_reads_what_else_is_ahead() -> None:
    """With ahead_target 'exclude' the columns inside the box published this frame are not
    read: at the start of `straight` (an ideal camera, no latency) the person's three columns
    are skipped and the reading is of the hall behind them; without a fresh detection every
    column is read again."""
    include = gym.make("PersonFollow-v0", config="ideal", perception=AHEAD_ON)
    exclude = gym.make(
        "PersonFollow-v0", config="ideal", perception={**AHEAD_ON, "ahead_target": "exclude"}
    )
    obs_in, info = include.reset(seed=0)
    obs_ex, _ = exclude.reset(seed=0)
    assert info["detected"]
    assert obs_in[2] == pytest.approx(info["true_distance_m"], abs=1e-3)
    assert obs_ex[2] > info["true_distance_m"] + 2.0
    np.testing.assert_array_equal(obs_ex[:2], obs_in[:2])
    blind = gym.make(
        "PersonFollow-v0",
        config="ideal",
        perception={**AHEAD_ON, "ahead_target": "exclude", "miss_prob": 1.0},
    )
    obs_blind, info_blind = blind.reset(seed=0)
    assert not info_blind["detected"]
    assert obs_blind[2] == pytest.approx(info["true_distance_m"], abs=1e-3)

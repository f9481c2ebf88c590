"""The mecanum platform (reference §2): kinematics, motors, rollers, drive, env."""

from __future__ import annotations

from collections.abc import Callable

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from hypothesis import given
from hypothesis import strategies as st

from follow_env.experiments.mecanum import Rig
from follow_env.platforms import get_platform
from follow_env.platforms.mecanum import MecanumConfig, mecanum_fk, mecanum_ik
from follow_env.tasks.person_follow.config import THESIS
from policies import for_platform, make_policy

speeds = st.floats(-2.0, 2.0, allow_nan=False)
A, B, R = 0.086, 0.076, 0.030
# No spread between motors, floor or trials: every lane is the same robot.
EXACT = MecanumConfig().replace(
    motor={"gain_spread": 0.0, "start_spread": 0.0}, floor={"spread": 0.0}
)


@given(vx=speeds, vy=speeds, w=speeds)
def test_inverse_then_forward_kinematics_return_the_twist(vx: float, vy: float, w: float) -> None:
    back = mecanum_fk(*mecanum_ik(vx, vy, w, R, A + B), R, A + B)
    assert np.allclose(back, (vx, vy, w), atol=1e-9)


def test_inverse_kinematics_is_the_papers_matrix() -> None:
    M = np.array([[1, -1, -(A + B)], [1, 1, -(A + B)], [1, -1, A + B], [1, 1, A + B]])
    q = np.array([0.3, -0.2, 0.7])
    assert np.allclose(mecanum_ik(*q, R, A + B), M @ q / R)


def test_forward_kinematics_is_the_least_squares_inverse_for_disagreeing_wheels() -> None:
    M = np.array([[1, -1, -(A + B)], [1, 1, -(A + B)], [1, -1, A + B], [1, 1, A + B]])
    phi = np.array([3.0, -1.0, 2.0, 5.0])
    assert np.allclose(mecanum_fk(*phi, R, A + B), np.linalg.pinv(M / R) @ phi)


def test_the_action_is_vx_vy_w_bounded_by_the_top_speeds() -> None:
    env = gym.make("PersonFollow-v0", platform="mecanum")
    cfg = MecanumConfig()
    top = cfg.motor.no_load_speed_radps * (1 - 26 / 255) * R
    assert [a.name for a in get_platform("mecanum").actions] == ["v_mps", "vy_mps", "w_radps"]
    assert np.allclose(env.action_space.high, [top, top, top / (A + B)], rtol=1e-6)
    env.close()


def _duty_rig(trials: int = 1, **sections: object) -> Rig:
    return Rig(trials, EXACT.replace(**sections) if sections else EXACT)


def test_a_wheel_does_not_start_below_its_static_friction_and_does_above() -> None:
    rig = _duty_rig()
    start = EXACT.motor.start_duty
    for duty, moves in ((start - 1.0, False), (start + 1.0, True)):
        pose = rig.run([((rig.speed(duty), 0.0, 0.0), 1.0, 0.0, False)])
        assert bool(pose[0, -1, 0] > 0.01) is moves, duty


def test_a_diagonal_between_the_axes_stalls_one_wheel_pair_and_runs_along_45_degrees() -> None:
    # 30 deg at duty 50: the pair (1, 3) gets 50 (cos 30 - sin 30) = 18 duty, under the start.
    rig = _duty_rig()
    th = np.radians(30.0)
    pose = rig.run([((rig.speed(50) * np.cos(th), rig.speed(50) * np.sin(th), 0.0), 3.0, 0, 0)])
    x, y, yaw = pose[0, -1]
    assert np.degrees(np.arctan2(y, x)) == pytest.approx(45.0, abs=1.0)
    assert abs(np.degrees(yaw)) < 1.0


def test_the_robot_keeps_turning_after_its_motors_stop_unless_they_brake() -> None:
    spin = [((0.0, 0.0, 3.0), 1.0, 0.0, False), ((0.0, 0.0, 0.0), 1.5, 0.0, False)]
    coast = _duty_rig().run(spin)[0]
    brake = _duty_rig(motor={"zero_duty": "brake"}).run(spin)[0]
    coasted, braked = coast[1, 2] - coast[0, 2], brake[1, 2] - brake[0, 2]
    assert np.degrees(coasted) > 5.0
    assert 0.0 <= braked < 0.6 * coasted  # back-EMF brakes, gear friction too


def test_rollers_roll_across_their_push_direction_so_strafing_costs_more() -> None:
    rig = _duty_rig()
    v = rig.speed(100)
    ahead = rig.run([((v, 0.0, 0.0), 2.0, 0.0, False)])[0, -1]
    side = rig.run([((0.0, v, 0.0), 2.0, 0.0, False)])[0, -1]
    assert ahead[0] > side[1] > 0.5 * ahead[0]
    assert abs(ahead[1]) < 1e-6
    assert abs(side[0]) < 0.01


def test_open_loop_is_slower_than_commanded_and_the_wheel_pid_is_not() -> None:
    v = 0.4
    for mode, low, high in (("open_loop", 0.2, 0.38), ("pid", 0.38, 0.42)):
        rig = _duty_rig(drive={"mode": mode})
        x0 = rig.run([((v, 0.0, 0.0), 2.0, 0.0, False)])[0, -1, 0]
        x1 = rig.run([((v, 0.0, 0.0), 3.0, 0.0, False)])[0, -1, 0]
        assert low < x1 - x0 < high, mode  # the speed over the last second (m/s)


def test_alternating_translation_and_rotation_slices_with_the_heading_follows_the_path() -> None:
    rig = _duty_rig()
    v = rig.speed(100)
    w = v / (A + B)
    d = np.array([np.cos(np.pi / 4), np.sin(np.pi / 4)])
    t_move, t_turn = 2.0 / v, (np.pi / 4) / w
    # Together: one body-frame command. The pair (1, 3) gets almost no duty and stalls, and
    # its held wheels also block the slow turn: the robot arrives, but does not turn.
    together = rig.run([((v * d[0], v * d[1], np.pi / 4 / t_move), t_move, 0.0, False)])[0, -1]
    assert abs(np.degrees(together[2])) < 5.0
    # Sliced (100 ms), each translation slice in the world direction by the true heading.
    segs, moved, turned = [], 0.0, 0.0
    while moved < t_move - 1e-9:
        segs.append(((v * d[0], v * d[1], 0.0), min(0.1, t_move - moved), 0.0, True))
        moved += 0.1
        if turned < t_turn - 1e-9:
            segs.append(((0.0, 0.0, w), min(0.1, t_turn - turned), 0.0, False))
            turned += 0.1
    path = rig.run(segs)[0]
    across = np.abs(path[:, 0] * d[1] - path[:, 1] * d[0])
    assert across.max() < 0.1
    assert np.degrees(path[-1, 2]) > 20.0


@pytest.mark.parametrize(
    "kwargs",
    [
        {"platform": {"name": "mecanum", "drive": {"mode": "pid"}}},
        {"platform": "mecanum", "config": {"platform.drive.mode": "pid"}},
        {"platform": "mecanum", "config": {"drive": {"mode": "pid"}}},
        {"platform": "mecanum", "drive": {"mode": "pid"}},
        {"config": {"platform": {"name": "mecanum", "drive": {"mode": "pid"}}}},
    ],
)
def test_the_platforms_sections_can_be_set_however_it_is_named(kwargs: dict) -> None:
    env = gym.make("PersonFollow-v0", **kwargs)
    platform = env.unwrapped.config.platform
    assert isinstance(platform, MecanumConfig)
    assert platform.drive.mode == "pid"
    env.close()


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"platform": {"drive": {"mode": "pid"}}}, r"platform=\{'drive'.* with its 'name'"),
        ({"platform": 5}, r"platform=5 is out of range"),
        (
            {"platform": "mecanum", "config": {"platform": "diff_drive"}},
            r"the platform is given twice: platform= and config\['platform'\]",
        ),
    ],
)
def test_a_platform_given_wrongly_is_refused(kwargs: dict, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        gym.make("PersonFollow-v0", **kwargs)


def test_reset_zeroes_the_wheels_and_randomize_draws_per_motor() -> None:
    cfg = THESIS.replace(platform="mecanum")
    env = gym.make("PersonFollow-v0", config=cfg)
    env.reset(seed=3)
    gains = env.unwrapped.sim.params["platform"]["gain"][0].copy()
    env.step(np.array([0.5, 0.2, 0.3], np.float32))
    env.reset(seed=3)
    sim = env.unwrapped.sim
    assert np.all(sim.state["platform"]["omega"][0] == 0.0)
    assert np.array_equal(sim.params["platform"]["gain"][0], gains)
    assert len(set(gains.tolist())) == 4  # each motor its own ratio
    env.close()


@pytest.mark.parametrize(
    ("override", "message"),
    [
        ({"body": {"mass_kg": -1.0}}, r"BodyConfig\.mass_kg=-1\.0 is out of range"),
        ({"motor": {"start_duty": 10.0}}, r"MecanumMotorConfig\.start_duty=10\.0"),
        ({"drive": {"mode": "fast"}}, r"DriveConfig\.mode='fast' is out of range"),
        # the tick the user set is named, with the periods it must divide
        (
            {"drive": {"tick_s": 0.003}},
            r"DriveConfig\.tick_s=0\.003 is out of range: must be a tick that divides "
            r"EpisodeConfig\.control_dt_s \(0\.1 s\) and EncoderConfig\.sample_period_s",
        ),
        ({"encoder": {"sample_period_s": 0.0101}}, r"EncoderConfig\.sample_period_s=0\.0101 is"),
    ],
)
def test_bad_values_name_field_value_and_range(override: dict, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        THESIS.replace(platform={"name": "mecanum", **override})


def test_the_platform_is_chosen_by_name_by_dict_or_by_config_object() -> None:
    heavy = MecanumConfig().replace(body={"mass_kg": 3.0})
    by_object = gym.make("PersonFollow-v0", platform=heavy).unwrapped.config
    by_dict = THESIS.replace(platform={"name": "mecanum", "body": {"mass_kg": 3.0}})
    assert by_object.platform == by_dict.platform == heavy
    then_section = THESIS.replace(**{"platform": "mecanum", "floor": {"traction_mu": 0.4}})
    assert then_section.platform.floor.traction_mu == 0.4
    assert THESIS.replace(platform={"name": "mecanum"}).to_dict()["platform"]["name"] == "mecanum"


def test_mecanum_env_passes_gymnasiums_and_sb3s_checkers() -> None:
    from stable_baselines3.common.env_checker import check_env as sb3_check_env

    env = gym.make("PersonFollow-v0", platform="mecanum", scenario="random")
    check_env(env.unwrapped, skip_render_check=True)
    sb3_check_env(env.unwrapped, warn=False)
    env.close()


def test_lanes_of_the_vector_env_equal_single_envs() -> None:
    n, steps = 3, 60
    vec = gym.make_vec(
        "PersonFollow-v0", num_envs=n, vectorization_mode="vector_entry_point",
        platform="mecanum", scenario="curve",
    )  # fmt: skip
    names = ("v_mps", "vy_mps", "w_radps")
    laws = [for_platform(make_policy("gsmpn"), names) for _ in range(n)]
    obs, _ = vec.reset(seed=10)
    for law in laws:
        law.reset()
    vec_obs, vec_x = [obs], []
    for _ in range(steps):
        obs, *_rest, info = vec.step(
            np.stack([law.act(o) for law, o in zip(laws, obs, strict=True)])
        )
        vec_obs.append(obs)
        vec_x.append(info["wheel_true_rr_radps"])
    for i in range(n):
        env = gym.make("PersonFollow-v0", platform="mecanum", scenario="curve")
        law = for_platform(make_policy("gsmpn"), names)
        o, _ = env.reset(seed=10 + i)
        law.reset()
        assert np.array_equal(o, vec_obs[0][i])
        for k in range(steps):
            o, _, _, _, inf = env.step(law.act(o))
            assert np.array_equal(o, vec_obs[k + 1][i])
            assert inf["wheel_true_rr_radps"] == vec_x[k][i]
        env.close()
    vec.close()


def test_the_frame_draws_four_wheels() -> None:
    env = gym.make("PersonFollow-v0", platform="mecanum", render_mode="rgb_array")
    env.reset(seed=0)
    frame = env.render()
    renderer = env.unwrapped._renderer
    assert renderer.wheels.shape == (4, 5)
    assert set(renderer.wheels[:, 4]) == {-1.0, 1.0}  # rollers drawn in both directions
    assert frame.shape == (480, 1280, 3)
    env.close()


@pytest.mark.parametrize("env_id", ["PersonFollow-v0", "LineTrace-v0"])
def test_an_action_past_the_bounds_drives_as_the_action_clipped_to_the_space(env_id: str) -> None:
    env = gym.make(env_id, platform="mecanum")
    high = env.action_space.high
    p = env.unwrapped.config.platform
    limits = np.array([p.max_speed_mps, p.max_speed_mps, p.max_turn_rate_radps])
    # float32 bounds at or above the kernel's float64 clip, the nearest such: they were rounded
    # below it (1.34705877 < 1.3470588 m/s), so ClipAction drove slower than the action past it.
    assert (high.astype(np.float64) >= limits).all()
    assert (np.nextafter(high, np.float32(0)).astype(np.float64) < limits).all()
    clipped = gym.wrappers.ClipAction(env)

    def run(step: Callable[[np.ndarray], tuple], action: np.ndarray) -> np.ndarray:
        """Observations and rewards of 10 steps of ``action`` from the reset with seed 0."""
        env.reset(seed=0)
        rows = []
        for _ in range(10):
            obs, reward, *_ = step(action)
            rows.append(np.r_[obs, reward])
        return np.array(rows)

    for k in range(3):
        past = np.zeros(3, np.float32)
        past[k] = 2 * high[k]
        np.testing.assert_array_equal(run(clipped.step, past), run(env.step, past))
        at = np.zeros(3, np.float32)
        at[k] = high[k]
        np.testing.assert_array_equal(run(env.step, at), run(env.step, past))

"""platforms/diff_drive/chain.py: the reference robot's wheel chain, PID on the PC."""

from __future__ import annotations

import numpy as np
import pytest

from follow_env import PRESETS
from follow_env.platforms.diff_drive.chain import ChainConfig
from follow_env.tasks.person_follow.config import AS_BUILT, AS_LISTED, THESIS
from follow_env.tasks.person_follow.env import PersonFollowEnv

QUIET = {"gain_spread": 0.0}


def _drive(chain: dict, v: float = 0.3, seconds: float = 4.0) -> list[dict]:
    env = PersonFollowEnv(config=AS_BUILT.replace(chain=chain, motor=QUIET), scenario="straight")
    env.reset(seed=0)
    infos = []
    for _ in range(round(seconds / 0.1)):
        infos.append(env.step(np.array([v, 0.0]))[-1])
    return infos


def _steady(infos: list[dict], key: str) -> float:
    return float(np.median([i[key] for i in infos[len(infos) // 2 :]]))


def test_the_reference_firmware_publishes_speed_times_interval_over_10_ms() -> None:
    r = AS_BUILT.platform.robot.wheel_radius_m
    # 15 ms, not 20: at 20 ms the PC's PID (the thesis's gains) no longer holds the wheel still
    for period, factor in ((0.01, 1.0), (0.015, 1.5)):
        infos = _drive({"pc_pid_period_s": period, "pc_lateness_s": 0.0, "register_bits": 32})
        published = _steady(infos, "wheel_measured_r_mps")
        true = _steady(infos, "wheel_true_r_radps") * r
        assert published == pytest.approx(0.3, abs=0.02)  # the PC's PID holds what it sees
        assert published / true == pytest.approx(factor, rel=0.05)  # ... at this true speed


def test_the_fixed_firmware_under_the_pcs_pid_measures_the_true_speed() -> None:
    r = AS_BUILT.platform.robot.wheel_radius_m
    infos = _drive({"firmware": "fixed", "pc_pid_period_s": 0.015, "pc_lateness_s": 0.004})
    assert _steady(infos, "wheel_true_r_radps") * r == pytest.approx(0.3, abs=0.02)


def test_the_16_bit_register_wraps_into_absurd_published_speeds() -> None:
    r = AS_BUILT.platform.robot.wheel_radius_m
    # As listed, the 0.1 s reader holds the wrap's absurd speed long enough to be logged.
    listed = _drive({"pc_lateness_s": 0.0, "reader_period_s": 0.1}, v=0.8, seconds=12.0)
    published = np.abs([i["wheel_measured_r_mps"] for i in listed])
    assert published.max() > 5.0  # a wrap: the register fell back by 65536 counts
    assert np.median(published) < 1.0
    # Read every frame, the spike lasts 10 ms, yet the PC's PID kicks the wheel with it.
    kick = []
    for bits in (16, 32):
        infos = _drive({"pc_lateness_s": 0.0, "register_bits": bits}, v=0.8, seconds=12.0)
        true = np.array([i["wheel_true_r_radps"] for i in infos[20:]]) * r
        kick.append(np.abs(true - 0.8).max())
    assert kick[0] > 0.3
    assert kick[1] < 0.05


def test_timer_lateness_makes_the_logged_acceleration_noisy() -> None:
    steady = _drive({"pc_lateness_s": 0.0, "register_bits": 32})
    late = _drive({"pc_lateness_s": 0.005, "register_bits": 32})
    spread = [np.std([i["accel_mps2"] for i in infos[10:]]) for infos in (steady, late)]
    assert spread[1] > 3 * spread[0]


def test_presets_and_their_checks() -> None:
    assert PRESETS["as_built"] is AS_BUILT
    assert PRESETS["as_listed"] is AS_LISTED
    assert AS_BUILT.platform.chain.pid_on == "pc"
    assert AS_BUILT.platform.pid.anti_windup == "none"
    assert AS_LISTED.platform.chain.reader_period_s == 0.1
    # every other section is the thesis preset's
    for name in ("camera", "perception", "person", "episode", "reward"):
        assert getattr(AS_BUILT, name) == getattr(THESIS, name)
    assert AS_BUILT.platform.motor == THESIS.platform.motor
    with pytest.raises(ValueError, match="the reference firmware has no wheel PID"):
        ChainConfig(firmware="reference", pid_on="mcu")
    with pytest.raises(ValueError, match=r"ChainConfig\.pid_on='gpu' is out of range"):
        ChainConfig(pid_on="gpu")
    with pytest.raises(ValueError, match=r"ChainConfig\.pc_pid_period_s=0 is out of range"):
        ChainConfig(pc_pid_period_s=0)


@pytest.mark.parametrize("preset", [AS_BUILT, AS_LISTED])
def test_every_control_step_of_the_chain_lasts_one_control_period(preset: object) -> None:
    # Idle wheels and a push of 0.3 m/s at every step: the push moves the body 0.3 m/s times
    # the time each step integrates. The first step once ran over 0.2 s: the chain's start-up
    # waited for a step 0, and the runner counts steps from 1.
    cfg = preset.replace(  # type: ignore[attr-defined]
        pid={"kp": 0.0, "ki": 0.0, "kd": 0.0},
        randomization={"push_prob": 1.0, "push_speed_mps": 0.3},
    )
    env = PersonFollowEnv(config=cfg, scenario="straight")
    env.reset(seed=0)
    body = env.unwrapped.sim.state["body"]
    before = np.array([body["x"][0], body["y"][0]])
    for _ in range(3):
        env.step(np.array([0.0, 0.0]))
        after = np.array([body["x"][0], body["y"][0]])
        assert np.hypot(*(after - before)) == pytest.approx(0.3 * 0.1, rel=1e-9)
        before = after

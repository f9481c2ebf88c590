"""bridge/mcu.py: the emulated wheel MCU under both firmwares, on the simulator's wheel models."""

from __future__ import annotations

import numpy as np
import pytest

from bridge.mcu import FIRMWARE_VERSION, EmulatedMCU
from bridge.protocol import Capability, CommandKind, Feedback, WheelCommand
from follow_env.platforms.diff_drive import DiffDriveConfig
from follow_env.platforms.wheels import encoder_count
from follow_env.tasks.person_follow.env import PersonFollowEnv

DUTY = CommandKind.DUTY_PERCENT


def _linear_speed(mcu: EmulatedMCU, k: int = 0) -> float:
    return mcu.omega[k] * mcu.platform.robot.wheel_radius_m


def _drive_reference(
    period_s: float, duration_s: float, duty: int = 50, mcu: EmulatedMCU | None = None
) -> list[Feedback]:
    """Commands every ``period_s`` to the reference firmware; the feedback it answers with."""
    mcu = mcu if mcu is not None else EmulatedMCU(firmware="reference")
    out: list[Feedback] = []
    t = 0.0
    while t < duration_s:
        out.extend(mcu.command(WheelCommand(duty, duty, DUTY), t))
        t = round(t + period_s, 9)
    return out


def test_reference_firmware_divides_by_10_ms_whatever_the_real_interval() -> None:
    # reference §1.1 + the listing: Encoder_Interrupt runs once per command yet divides by 10 ms.
    true = _drive_reference(0.01, 3.0)[-1].right_mm_s
    slow = _drive_reference(0.02, 3.0)[-1].right_mm_s
    m = DiffDriveConfig().motor  # the steady speed at 50 % duty (the motor model)
    steady = 1000 * m.no_load_speed_radps * 0.075 * (50 - m.friction_duty_pct) / (100 - 4.0)
    assert true == pytest.approx(steady, abs=6)  # one encoder count in 10 ms is 5.75 mm/s
    assert slow == pytest.approx(2 * true, rel=0.03)


def test_reference_firmware_answers_only_commands_10_ms_apart() -> None:
    mcu = EmulatedMCU(firmware="reference")
    assert mcu.command(WheelCommand(10, 10, DUTY), 0.010) != []  # 10 ms after power-on
    assert mcu.command(WheelCommand(10, 10, DUTY), 0.015) == []  # 5 ms later: no feedback
    assert mcu.command(WheelCommand(10, 10, DUTY), 0.0205) != []  # HAL tick 20 ms: 10 ms on
    assert mcu.advance(1.0) == []  # nothing unsolicited, however long it waits


def test_reference_firmware_has_no_wheel_pid() -> None:
    mcu = EmulatedMCU(firmware="reference")
    mcu.command(WheelCommand(500, 500, CommandKind.SPEED_MM_S), 0.0)
    mcu.advance(1.0)
    assert mcu.stats.commands_refused == 1
    assert mcu.omega == [0.0, 0.0]
    assert not mcu.hello().capabilities & Capability.SPEED_COMMANDS


def test_reference_firmware_clamps_duty_to_99_percent() -> None:
    mcu = EmulatedMCU(firmware="reference")
    mcu.command(WheelCommand(300, -300, DUTY), 0.0)
    assert mcu.duty == [99.0, -99.0]


def test_the_16_bit_counter_wraps_into_one_absurd_speed() -> None:
    # 65536 counts = 8 turns of the wheel: at 50 % duty about every 5 s.
    mcu = EmulatedMCU(firmware="reference")
    speeds = [f.right_mm_s for f in _drive_reference(0.01, 12.0, mcu=mcu)]
    wraps = encoder_count(mcu.angle[0], mcu.platform.encoder.counts_per_rev) // 2**16
    assert wraps == 2  # 12 s at 50 % duty: about 12,500 counts a second
    absurd = [s for s in speeds if abs(s) > 5000]
    assert len(absurd) == wraps  # one absurd speed per wrap, every other reading plausible
    steady = speeds[len(speeds) // 2 :]
    assert np.median(np.abs(steady)) < 800


def test_fixed_firmware_measures_the_true_speed_every_10_ms() -> None:
    mcu = EmulatedMCU(firmware="fixed")
    mcu.command(WheelCommand(50, 50, DUTY), 0.0)
    feedback = mcu.advance(2.0)
    assert len(feedback) == 200
    assert feedback[-1].right_mm_s == pytest.approx(1000 * _linear_speed(mcu), abs=8)
    more = mcu.advance(2.0 + 0.005)
    assert more == []  # half a period: no new measurement


def test_fixed_firmware_watchdog_stops_the_motors() -> None:
    mcu = EmulatedMCU(firmware="fixed", framing="robust", watchdog_s=0.2)
    mcu.command(WheelCommand(5000, 5000, CommandKind.DUTY_CENTI_PERCENT), 0.0)
    feedback = mcu.advance(1.0)
    assert mcu.duty == [0.0, 0.0]
    assert mcu.watchdog_stopped
    assert mcu.stats.watchdog_stops == 1
    assert feedback[10].status == 0
    assert feedback[-1].status == Feedback.STATUS_WATCHDOG_STOP
    assert _linear_speed(mcu) < 0.05  # coasted to (nearly) a stop


def test_a_speed_command_after_a_watchdog_stop_starts_from_a_clean_pid() -> None:
    # The PID ran, then the commands stopped: the next command must drive the wheels as it
    # would from a fresh start (the integral, last error and derivative were kept: +37 % duty).
    speed = WheelCommand(300, 300, CommandKind.SPEED_MM_S)
    mcu = EmulatedMCU(firmware="fixed", framing="robust")
    mcu.command(speed, 0.0)
    mcu.advance(0.05)
    mcu.advance(3.0)  # the watchdog stops the motors at 0.1 s; they coast to rest
    assert mcu.watchdog_stopped
    fresh = EmulatedMCU(firmware="fixed", framing="robust")
    for m in (mcu, fresh):
        m.omega = [0.0, 0.0]
        m.meas = [0.0, 0.0]
    mcu.command(speed, 3.0)
    fresh.command(speed, 3.0)
    mcu.advance(3.01)
    fresh.advance(3.01)
    assert mcu.duty == fresh.duty


def test_speed_commands_run_the_simulators_own_wheel_pid() -> None:
    # The fixed firmware's PID is the simulator's: one control step of the diff-drive kernel and
    # 10 ticks of the emulated MCU under the same wheel targets end on the same wheel speeds.
    env = PersonFollowEnv(scenario="straight", motor={"gain_spread": 0.0})
    env.reset(seed=0)
    _, _, _, _, info = env.step(np.array([0.5, 0.2]))
    platform = env.config.platform
    assert isinstance(platform, DiffDriveConfig)
    mcu = EmulatedMCU(platform, firmware="fixed", framing="robust")
    track = platform.robot.track_width_m
    targets_mm = [round(1000 * (0.5 + s * 0.1 * track)) for s in (1, -1)]
    assert targets_mm == [
        round(1000 * info["wheel_target_r_mps"]),
        round(1000 * info["wheel_target_l_mps"]),
    ]
    # mm/s on the wire: set the float targets the kernel used, as a speed command would
    mcu.command(WheelCommand(*targets_mm, CommandKind.SPEED_MM_S), 0.0)
    mcu.target = [info["wheel_target_r_mps"], info["wheel_target_l_mps"]]
    mcu.advance(env.config.episode.control_dt_s)
    assert mcu.omega[0] == pytest.approx(info["wheel_true_r_radps"], abs=1e-12)
    assert mcu.omega[1] == pytest.approx(info["wheel_true_l_radps"], abs=1e-12)
    assert mcu.meas[0] == pytest.approx(info["wheel_measured_r_mps"], abs=1e-12)


def test_wheel_angles_between_ticks_follow_the_wheel_speed() -> None:
    mcu = EmulatedMCU(firmware="fixed")
    mcu.command(WheelCommand(60, 60, DUTY), 0.0)
    mcu.advance(1.0)
    a0 = mcu.wheel_angles(1.0)[0]
    a1 = mcu.wheel_angles(1.004)[0]
    assert a1 - a0 == pytest.approx(mcu.omega[0] * 0.004)


def test_bad_settings_are_refused() -> None:
    with pytest.raises(ValueError, match="firmware='v2' is out of range"):
        EmulatedMCU(firmware="v2")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="watchdog_s=0 is out of range"):
        EmulatedMCU(watchdog_s=0)


def test_hello_announces_what_the_firmware_takes() -> None:
    fixed = EmulatedMCU(firmware="fixed", framing="robust").hello()
    assert fixed.capabilities & Capability.SPEED_COMMANDS
    assert fixed.capabilities & Capability.WATCHDOG
    assert fixed.feedback_period_ms == 10
    assert fixed.firmware_version == FIRMWARE_VERSION
    reference = EmulatedMCU(firmware="reference").hello()
    assert reference.capabilities == Capability.DUTY_COMMANDS
    assert reference.feedback_period_ms == 0  # it answers commands, it has no period

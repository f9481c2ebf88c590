"""The runner's settings and its result (:mod:`bridge.runner`)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from follow_env.sim.checks import out_of_range

__all__ = ["COMMAND_MODES", "RunResult", "RunnerConfig"]

COMMAND_MODES = ("auto", "duty", "speed")


@dataclass(frozen=True)
class RunnerConfig:
    """How the runner drives the robot.

    :param control_dt_s: control period, s (reference §1.6: 0.1 s).
    :param wheel_dt_s: wheel loop period, s; ``None``: the platform chain's PC timer period
        (``chain.pc_pid_period_s``) when its PID runs on the PC, else 10 ms (the MCU's
        encoder period).
    :param feedback_timeout_s: stop the wheels when no feedback came for this long, s.
    :param duration_s: end after this long, s (``None``: at the end of the perception).
    :param command: ``"speed"`` (the MCU runs the wheel PID), ``"duty"`` (the PC does), or
        ``"auto"``: speed if the MCU's hello offers it, else duty.
    """

    control_dt_s: float = 0.1
    wheel_dt_s: float | None = None
    feedback_timeout_s: float = 0.1
    duration_s: float | None = None
    command: str = "auto"

    def __post_init__(self) -> None:
        for name, lo, hi in (("control_dt_s", 0.005, 10.0), ("feedback_timeout_s", 0.01, 10.0)):
            value = getattr(self, name)
            if not (isinstance(value, int | float) and lo <= value <= hi):
                raise out_of_range(f"RunnerConfig.{name}", value, f"in [{lo}, {hi}] s")
        if self.wheel_dt_s is not None and not (
            isinstance(self.wheel_dt_s, int | float) and 0.001 <= self.wheel_dt_s <= 1.0
        ):
            raise out_of_range("RunnerConfig.wheel_dt_s", self.wheel_dt_s, "in [0.001, 1.0] s")
        if self.wheel_dt_s is not None and self.wheel_dt_s > self.control_dt_s:
            raise out_of_range(
                "RunnerConfig.wheel_dt_s",
                self.wheel_dt_s,
                f"<= control_dt_s ({self.control_dt_s} s)",
            )
        if self.duration_s is not None and not (
            isinstance(self.duration_s, int | float) and 0 < self.duration_s <= 86400
        ):
            raise out_of_range("RunnerConfig.duration_s", self.duration_s, "in (0, 86400] s")
        if self.command not in COMMAND_MODES:
            raise out_of_range(
                "RunnerConfig.command", self.command, "one of " + ", ".join(COMMAND_MODES)
            )


@dataclass
class RunResult:
    """How a run went."""

    steps: int = 0
    reason: str = ""
    command: str = ""
    lateness_ms: list[float] = field(default_factory=list)  # control loop's wake lateness, ms
    wheel_lateness_ms: list[float] = field(default_factory=list)  # the wheel loop's, ms
    overruns: int = 0
    feedback_frames: int = 0
    log: Path | None = None  # where the step log was written (a spare file if --log failed)
    log_error: str = ""  # why the step log is not at --log, in one line ("" if it is)
    failure: str = ""  # why the wheel loop stopped the robot ("" if it did not)
    stop_error: str = ""  # why no stop command went out at the end ("" if one did)

    def lateness_percentile(self, q: float) -> float:
        """Percentile ``q`` (0-100) of how late the control loop woke, ms."""
        return float(np.percentile(self.lateness_ms, q)) if self.lateness_ms else math.nan

    def summary(self) -> str:
        """One line for the command line."""
        return (
            f"{self.steps} control steps, ended: {self.reason}; commands: {self.command}; "
            f"loop lateness p50 {self.lateness_percentile(50):.2f} ms, p99 "
            f"{self.lateness_percentile(99):.2f} ms, {self.overruns} overruns; "
            f"{self.feedback_frames} feedback frames"
            + (f"; wheel loop: {self.failure}" if self.failure not in ("", self.reason) else "")
            + (f"; {self.stop_error}" if self.stop_error else "")
            + (f"; log: {self.log}" if self.log else "")
        )

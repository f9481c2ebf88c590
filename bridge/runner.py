"""``follow-robot run``: any Policy driving a robot (real or emulated) at the control rate.

Two loops, as on the reference robot (reference §1: a guidance node at 10 Hz, a PID node and
the serial nodes below it):

* the **control loop** (this thread) wakes on a monotonic schedule every ``control_dt_s``
  (0.1 s), reads the perception, asks the policy for ``(v, w)`` (a law that differentiates
  does so over that period: :func:`policies.adapt.at_period`), clips it to the platform's
  bounds, turns it into wheel speed targets with the platform's inverse kinematics (reference
  §1.1) and writes one step-log row; how late each wake-up was is recorded (p50 / p99);
* the **wheel loop** (a thread) runs every ``wheel_dt_s`` (10 ms): it reads the MCU's feedback,
  and sends the wheel command: the speed targets in mm/s to firmware that runs the wheel PID
  itself, or a duty from the PC's own PID (the simulator's PID of reference §1.2, on the
  measured wheel speeds, dt from the clock) to firmware that takes duties, as the reference
  robot's did. When no feedback has come for ``feedback_timeout_s`` (0.1 s) it stops the wheels
  and ends the run.

On Ctrl-C, at the end of the perception (the world's episode, the replay), after
``duration_s``, on a link, perception or policy error (whatever the perception's read or the
policy's ``act`` raised), or when the wheel loop fails, the wheels are commanded to zero before
the link closes; a second Ctrl-C then is deferred (:class:`bridge.interrupts.InterruptGuard`).
The step log (:mod:`bridge.runlog`: the evaluation's layout) is written to a temporary file and
renamed into place, so ``follow-eval metrics`` scores a real run like a simulated one, crediting
no step to a policy that did not drive it."""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from bridge import runlog
from bridge.fit import check_ahead, check_command, check_platform
from bridge.interrupts import InterruptGuard
from bridge.link import LinkError, SerialLink
from bridge.loader import PolicyLoader
from bridge.perception import Frame, PerceptionError, PerceptionSource
from bridge.protocol import Capability, CommandKind, Feedback, Hello, PeerRole, WheelCommand
from bridge.runconfig import COMMAND_MODES, RunnerConfig, RunResult
from bridge.runlog import LOG_COLUMNS, check_log_path, save_rows
from follow_env.platforms.diff_drive import DiffDriveConfig, diff_drive_ik
from follow_env.platforms.wheels import pid_step
from follow_env.sim.checks import out_of_range
from follow_env.tasks.person_follow.steplog import AHEAD_COLUMN
from policies.adapt import at_period

__all__ = ["COMMAND_MODES", "PolicyError", "RunResult", "Runner", "RunnerConfig"]

_ZERO_REPEATS = 3  # stop commands sent at the end (one may be lost on a noisy line)
_FIRST_FEEDBACK_S = 1.0  # longest wait for the MCU's first feedback, s

# The pure-Python bodies of the simulator's compiled functions: the same arithmetic, and the
# runner never compiles a kernel.
_ik = diff_drive_ik.py_func
_pid = pid_step.py_func


class PolicyError(Exception):
    """The policy failed mid-session (its ``act`` raised); the message names it and says how."""


class _Wheels:
    """The wheel loop's shared state (guarded by ``lock``)."""

    def __init__(self) -> None:
        self.lock = threading.Lock()
        self.target = [0.0, 0.0]  # m/s, set by the control loop
        self.measured = [0.0, 0.0]  # m/s, the newest feedback
        self.duty = [math.nan, math.nan]  # %, the PC PID's output (duty mode)
        self.last_feedback = math.nan  # monotonic time of the newest feedback
        self.frames = 0
        self.lateness_ms: list[float] = []  # how late each wheel tick woke (the loop's own)
        self.failure = ""  # why the wheel loop stopped the robot
        self.stopped = False  # the wheel loop sent a stop command itself, on its failure


class Runner:
    """Drive a robot with a policy; see the module docstring.

    :param link: an open serial link to the MCU (or the emulator).
    :param policy: anything with ``reset()`` and ``act(obs) -> [v, w]``.
    :param perception: the observation source.
    :param platform: the differential drive's configuration (geometry, PID gains, bounds);
        another platform is refused here (``ValueError``), as is a policy that does not command
        its ``[v, w]`` (:func:`bridge.fit.check_command`).
    :param config: periods, timeout, duration and command mode; a mode the link's framing
        cannot carry is refused here (``ValueError``).
    :param log: where to write the step log (``None``: no log); a path it cannot be written
        to is refused here (:func:`bridge.runlog.check_log_path`, ``ValueError``). Should the
        writing still fail at the end, the log goes to a spare file and ``RunResult.log_error``
        says where.
    :param meta: the step log's ``policy`` (``policy``'s name, as typed), ``scenario`` and
        ``seed`` values; the ``policy`` column is the label of what drove (module docstring).
    :param monitor: a :class:`bridge.monitor.hub.MonitorHub` to publish to and take modes from;
        its starting mode, unless ``stop`` or ``manual``, is taken to name ``policy``.
    :param policy_factory: builds the policy of a mode the monitor selects (``pn``, ...), in
        a thread of its own (:class:`bridge.loader.PolicyLoader`): the robot runs the mode it
        was in until the new one is built.
    """

    def __init__(
        self,
        link: SerialLink,
        policy: Any,
        perception: PerceptionSource,
        platform: DiffDriveConfig | None = None,
        config: RunnerConfig | None = None,
        log: str | Path | None = None,
        meta: dict[str, Any] | None = None,
        monitor: Any = None,
        policy_factory: Callable[[str], Any] | None = None,
    ) -> None:
        self.link = link
        self.perception = perception
        self.platform = platform if platform is not None else DiffDriveConfig()
        self.config = config if config is not None else RunnerConfig()
        # refused now, not as a crash of the wheel loop or the control loop mid-session
        check_platform(self.platform)
        check_command(policy := at_period(policy, self.config.control_dt_s))  # module docstring
        self.policy = policy
        self._framing_command()
        self.log = Path(log) if log is not None else None
        self.meta = dict(meta or {})
        self.monitor = monitor
        self._wheels = _Wheels()
        self._stop = threading.Event()
        self._rows: list[dict[str, Any]] = []
        self._policies: dict[str, Any] = {}
        self._mode = getattr(policy, "name", "policy")
        self._drivers: dict[str, int] = {}  # what drove steps, numbered as each first did
        self._driver: int | None = None  # which of them drove the newest step
        self._waiting: str | None = None  # the mode chosen, whose policy is being built
        # a mode chosen in the browser is built beside the control loop (bridge/loader.py)
        self._loader = PolicyLoader(policy_factory, self._runnable) if policy_factory else None
        if monitor is not None and monitor.mode not in ("stop", "manual"):
            # the mode the browser shows is the name the policy was built from ("gsmpn"), not
            # its full name ("gsmpn:tuned"): the same policy, not a second one built for it
            self._mode = monitor.mode
            self._policies[self._mode] = policy
        if self.log is not None:  # refused now, not after the session it would have kept
            self.log = check_log_path(self.log)
        self._spare = runlog.spare_folder() if self.log else None  # now: fds may run out

    # ---- command mode -------------------------------------------------------------------

    def _framing_command(self) -> str | None:
        """The command mode the reference framing carries (the wire cannot say which: the
        codec's ``command_kind``); ``None`` for the robust framing, whose frames say.

        :raises ValueError: the configured mode is not the one the framing carries.
        """
        if self.link.framing == "robust":
            return None
        kind = getattr(self.link.codec, "command_kind", CommandKind.DUTY_PERCENT)
        # the reference firmware takes whole-percent duties (reference §1.1)
        carried = {CommandKind.DUTY_PERCENT: "duty", CommandKind.SPEED_MM_S: "speed"}.get(kind)
        if carried is None or self.config.command not in ("auto", carried):
            raise out_of_range(
                "RunnerConfig.command",
                self.config.command,
                f"{carried or 'duty or speed'} or auto: the {self.link.framing} framing of "
                f"{self.link.url} carries {CommandKind(kind).name} commands",
            )
        return carried

    def _choose_command(self) -> str:
        wanted = self.config.command
        carried = self._framing_command()
        if carried is not None:
            return carried
        hello = self.link.handshake(Hello(PeerRole.PC), timeout_s=1.0)
        caps = hello.capabilities
        if wanted == "auto":
            return "speed" if caps & Capability.SPEED_COMMANDS else "duty"
        need = Capability.SPEED_COMMANDS if wanted == "speed" else Capability.DUTY_COMMANDS
        if not caps & need:
            raise LinkError(f"{self.link.url}: the MCU does not take {wanted} commands ({caps!r})")
        return wanted

    def _wheel_command(self, mode: str, target: list[float], duty: list[float]) -> WheelCommand:
        if mode == "speed":
            mm = [max(-32768, min(32767, round(1000.0 * t))) for t in target]
            return WheelCommand(mm[0], mm[1], CommandKind.SPEED_MM_S)
        if self.link.framing == "robust":
            cp = [max(-10000, min(10000, round(100.0 * u))) for u in duty]
            return WheelCommand(cp[0], cp[1], CommandKind.DUTY_CENTI_PERCENT)
        pct = [max(-99, min(99, int(u))) for u in duty]  # int(): as the PID node casts
        return WheelCommand(pct[0], pct[1], CommandKind.DUTY_PERCENT)

    # ---- the wheel loop -----------------------------------------------------------------

    def _wheel_loop(self, mode: str) -> None:
        try:
            self._wheel_ticks(mode)
        except Exception as exc:  # any: a run must never go on without its wheel loop
            self._fail(f"wheel loop failed ({type(exc).__name__}: {exc}): wheels stopped")
        if self._wheels.failure:
            # Stop now, from here: the control loop may sit in the camera's read for up to its
            # timeout before its own shutdown stops the wheels, and the reference firmware
            # holds its last duty until told otherwise (it has no watchdog, reference §1.1).
            self._wheels.stopped = not self._stop_wheels(mode)

    def _wheel_ticks(self, mode: str) -> None:
        cfg, wheels, pid = self.config, self._wheels, self.platform.pid
        chain = self.platform.chain
        # As listed, the PC's PID has no output clamp (the firmware clamps the command).
        as_listed = chain.pid_on == "pc" and pid.anti_windup == "none"
        max_duty = 1e12 if as_listed else self.platform.motor.max_duty_pct
        wheel_dt = self._wheel_dt()
        anti_windup = pid.anti_windup == "clamp"
        state = [[0.0, 0.0, 0.0], [0.0, 0.0, 0.0]]  # integral, e_prev, d_filt per wheel
        start = time.monotonic()
        last_pid = start
        next_tick = start
        duty = [0.0, 0.0]
        # The PC's serial reader (reference §1.7): the PID sees the newest frame every
        # reader_period_s (0: every frame as it arrives); what it sees is also what is logged.
        reader = chain.reader_period_s if mode == "duty" and chain.pid_on == "pc" else 0.0
        next_read = start
        seen = [0.0, 0.0]
        while not self._stop.is_set():
            now = time.monotonic()
            wheels.lateness_ms.append(1000.0 * (now - next_tick))
            try:
                for message in self.link.receive(0.0):
                    if isinstance(message, Feedback):
                        newest = [message.right_mm_s / 1000.0, message.left_mm_s / 1000.0]
                        with wheels.lock:
                            if reader == 0.0:
                                wheels.measured = newest
                            wheels.last_feedback = now
                            wheels.frames += 1
                        seen = newest
            except LinkError as exc:
                self._fail(f"link error: {exc}")
                return
            if reader > 0.0 and now >= next_read:
                next_read += reader
                with wheels.lock:
                    wheels.measured = list(seen)
            with wheels.lock:
                target, measured, last_fb = (
                    list(wheels.target),
                    list(wheels.measured),
                    wheels.last_feedback,
                )
            since = now - (start if math.isnan(last_fb) else last_fb)
            limit = _FIRST_FEEDBACK_S if math.isnan(last_fb) else cfg.feedback_timeout_s
            if since > limit:
                self._fail(
                    f"no feedback from the MCU for {since * 1000:.0f} ms (limit "
                    f"{limit * 1000:.0f} ms): wheels stopped"
                )
                return
            if mode == "duty":
                dt = max(now - last_pid, 1e-4)  # the thesis's PID node takes dt from the clock
                last_pid = now
                for k in (0, 1):
                    integral, e_prev, d_filt = state[k]
                    error = target[k] - measured[k]
                    duty[k], integral, d_filt = _pid(
                        error,
                        e_prev,
                        integral,
                        d_filt,
                        pid.kp,
                        pid.ki,
                        pid.kd,
                        pid.tau_s,
                        dt,
                        max_duty,
                        anti_windup,
                    )
                    state[k] = [integral, error, d_filt]
                with wheels.lock:
                    wheels.duty = list(duty)
            try:
                self.link.send(self._wheel_command(mode, target, duty))
            except LinkError as exc:
                self._fail(f"link error: {exc}")
                return
            next_tick += wheel_dt
            delay = next_tick - time.monotonic()
            if delay < -wheel_dt:  # far behind: start the schedule again from now
                next_tick = time.monotonic()
            elif delay > 0:
                self._stop.wait(delay)

    def _wheel_dt(self) -> float:
        if self.config.wheel_dt_s is not None:
            return self.config.wheel_dt_s
        chain = self.platform.chain
        return chain.pc_pid_period_s if chain.pid_on == "pc" else 0.01

    def _fail(self, why: str) -> None:
        self._wheels.failure = why
        self._stop.set()

    def _stop_wheels(self, mode: str) -> str:
        """Command zero ``_ZERO_REPEATS`` times; ``""`` if one went out, else why none did."""
        sent, why = 0, ""
        zero = self._wheel_command(mode, [0.0, 0.0], [0.0, 0.0])
        for _ in range(_ZERO_REPEATS):
            try:
                self.link.send(zero)
                sent += 1
            except (LinkError, ValueError) as exc:
                why = str(exc)
            time.sleep(0.002)
        return "" if sent else f"the stop command could not be sent ({why})"

    # ---- the control loop ---------------------------------------------------------------

    def run(self) -> RunResult:
        """Run until the perception ends, ``duration_s`` passes, the link fails or Ctrl-C.

        :raises LinkError: the MCU could not be reached or does not take the command mode, or
            (``.result``: the session's :class:`RunResult`, its log saved) it failed mid-run.
        :raises PerceptionError: the perception could not start or feed the policy, or (with
            ``.result``, as above) it failed mid-run: whatever its read raised, named so.
        :raises PolicyError: (with ``.result``, as above) the policy's ``act`` raised mid-run.
        """
        cfg = self.config
        result = RunResult()
        mode = self._choose_command()
        result.command = (
            "speed targets (PID on the MCU)" if mode == "speed" else "duty (PID on the PC)"
        )
        self.perception.start()
        try:
            check_ahead(self.policy, self.perception)
        except PerceptionError:
            self.perception.close()
            raise
        walls = getattr(self.perception, "info", {}).get("walls")
        if self.monitor is not None and walls:
            self.monitor.scene = {"walls": walls}  # the emulated world's, for the top-down view
        self.policy.reset()
        wheel_thread = threading.Thread(target=self._wheel_loop, args=(mode,), name="wheel-loop")
        step = 0
        frame: Frame | None = None
        prev_speed = 0.0
        with InterruptGuard() as guard:
            try:
                start = time.monotonic()
                wheel_thread.start()  # in here: once started, the finally below stops it
                while not self._stop.is_set():
                    scheduled = start + step * cfg.control_dt_s
                    delay = scheduled - time.monotonic()
                    if delay > 0 and self._stop.wait(delay):
                        break
                    woke = time.monotonic()
                    late = woke - scheduled
                    if late > cfg.control_dt_s:  # a whole period lost: skip to the next slot
                        result.overruns += 1
                        step = int((woke - start) // cfg.control_dt_s)
                        continue
                    result.lateness_ms.append(1000.0 * late)
                    frame = self._read()
                    t = step * cfg.control_dt_s
                    if frame.done:
                        result.reason = f"perception over ({frame.termination or 'done'})"
                        break
                    if cfg.duration_s is not None and t >= cfg.duration_s:
                        result.reason = f"duration {cfg.duration_s:g} s reached"
                        break
                    v, w = self._act(frame)
                    prev_speed = self._record(step, t, frame, v, w, prev_speed)
                    step += 1
            except KeyboardInterrupt:
                result.reason = "interrupted (Ctrl-C)"
            except (LinkError, PerceptionError, PolicyError) as exc:
                kinds = ((LinkError, "link"), (PolicyError, "policy"), (Exception, "perception"))
                kind = next(k for t, k in kinds if isinstance(exc, t))
                result.reason = f"{kind} error: {exc}"
                exc.result = result  # type: ignore[attr-defined]  # filled in below
                raise
            finally:
                guard.holding = True  # first, and no call: a 2nd Ctrl-C must not cut this short
                self._stop.set()
                if wheel_thread.ident is not None:
                    wheel_thread.join(timeout=1.0)
                stop_error = self._stop_wheels(mode)  # again: one may be lost on a noisy line
                result.stop_error = "" if self._wheels.stopped else stop_error
                try:
                    self.perception.close()
                    if self._loader is not None:
                        self._loader.close()
                finally:
                    self._finish(result, step, frame, prev_speed)
            if guard.deferred and not result.reason.startswith("interrupted"):
                result.reason += "; interrupted (Ctrl-C) while stopping"
        return result

    def _finish(self, result: RunResult, step: int, frame: Frame | None, prev: float) -> None:
        """Fill in ``result`` and save the step log (``frame``: the last one read, if any)."""
        result.failure = self._wheels.failure
        if result.failure and not result.reason:
            result.reason = result.failure
        if frame is not None:
            self._record(step, step * self.config.control_dt_s, frame, None, None, prev)
        result.steps = step
        result.feedback_frames = self._wheels.frames
        result.wheel_lateness_ms = self._wheels.lateness_ms
        if self.log is not None:
            runlog.label_rows(self._rows, list(self._drivers), "policy" in self.meta)
            result.log, result.log_error = save_rows(self._rows, self.log, self._spare)

    def _read(self) -> Frame:
        """The perception's next frame; whatever its read raises ends the session as a
        perception error (wheels stopped, log saved, the summary said), not as a traceback:
        a camera unplugged mid-run raises what its driver raises (pyrealsense2: RuntimeError)."""
        try:
            return self.perception.read()
        except PerceptionError:
            raise
        except Exception as exc:
            raise PerceptionError(
                f"{self.perception.name}: reading a frame failed ({type(exc).__name__}: {exc})"
            ) from exc

    def _act(self, frame: Frame) -> tuple[float, float]:
        policy = self._current_policy()
        self._drove(policy)
        if policy == "stop":
            v, w = 0.0, 0.0
        elif policy == "manual":
            v, w = self.monitor.manual_command()
        else:
            if getattr(policy, "reads_ahead", None) and frame.ahead_m is None:
                raise PerceptionError(
                    f"{policy.name} reads the reading ahead (ahead_m), but "
                    f"{self.perception.name} published a frame without it"
                )
            obs = np.array(frame.observation(), dtype=np.float32)
            try:
                v, w = (float(x) for x in policy.act(obs))
            except Exception as exc:  # any: the session ends as a failure, said in one line
                name = getattr(policy, "name", type(policy).__name__)
                raise PolicyError(
                    f"policy {name} failed to act ({type(exc).__name__}: {exc})"
                ) from exc
        v_max, w_max = self.platform.max_speed_mps, self.platform.max_turn_rate_radps
        v, w = min(max(v, -v_max), v_max), min(max(w, -w_max), w_max)
        r, track = self.platform.robot.wheel_radius_m, self.platform.robot.track_width_m
        w_r, w_l = _ik(v, w, r, track)
        with self._wheels.lock:
            self._wheels.target = [w_r * r, w_l * r]
        return v, w

    def _drove(self, policy: Any) -> None:
        """Note what drives this step: ``stop``, ``manual``, a mode's or the starting policy."""
        if policy is self.policy:
            policy = str(self.meta.get("policy") or getattr(policy, "name", "policy"))
        name = policy if isinstance(policy, str) else self._mode
        self._driver = self._drivers.setdefault(name, len(self._drivers))

    def _current_policy(self) -> Any:
        self._waiting = None
        if self.monitor is None:
            return self.policy
        mode = self.monitor.mode
        if mode in ("stop", "manual"):
            self._mode = mode
            return mode
        if mode != self._mode or mode not in self._policies:
            if mode not in self._policies:
                if mode == getattr(self.policy, "name", None) or self._loader is None:
                    self._policies[mode] = self.policy
                else:
                    try:
                        built = self._loader.get(mode)
                    except (ValueError, PerceptionError) as exc:
                        # the robot keeps doing what it did; the browser is told why
                        self.monitor.refuse(mode, self._mode, str(exc))
                        return self._running()
                    if built is None:  # still being built: keep doing what it did meanwhile
                        self._waiting = mode
                        return self._running()
                    self._policies[mode] = built
            self._policies[mode].reset()
            self._mode = mode
        return self._policies[mode]

    def _running(self) -> Any:
        """What the robot runs now: ``stop``, ``manual`` or the running mode's policy."""
        if self._mode in ("stop", "manual"):
            return self._mode
        return self._policies.setdefault(self._mode, self.policy)

    def _runnable(self, policy: Any) -> Any:
        """``policy`` at the robot's period (module docstring) if this robot can run it
        (:func:`check_command`, :func:`check_ahead`); else ValueError or PerceptionError."""
        check_command(policy := at_period(policy, self.config.control_dt_s))
        check_ahead(policy, self.perception)
        return policy

    def _record(
        self, step: int, t: float, frame: Frame, v: float | None, w: float | None, prev: float
    ) -> float:
        with self._wheels.lock:
            target, measured = list(self._wheels.target), list(self._wheels.measured)
            duty = list(self._wheels.duty)
        speed = 0.5 * (measured[0] + measured[1])
        row: dict[str, Any] = {
            **self.meta,
            runlog.DRIVER_COLUMN: self._driver,  # the final row (no action): the last step's
            "step": step,
            "time_s": round(t, 9),
            "obs_distance_m": frame.distance_m,
            "obs_offset_px": frame.offset_px,
            AHEAD_COLUMN: frame.ahead_m,
            "detected": int(frame.detected),
            "action_v_mps": v,
            "action_w_radps": w,
            "wheel_target_r_mps": target[0],
            "wheel_target_l_mps": target[1],
            "wheel_measured_r_mps": measured[0],
            "wheel_measured_l_mps": measured[1],
            "duty_r_pct": None if math.isnan(duty[0]) else duty[0],
            "duty_l_pct": None if math.isnan(duty[1]) else duty[1],
            "encoder_speed_mps": speed,
            "accel_mps2": 0.0 if step == 0 else (speed - prev) / self.config.control_dt_s,
            "termination": frame.termination if v is None else "",
        }
        for key, value in frame.truth.items():
            if key in LOG_COLUMNS:  # the truth the log has a column for
                row[key] = value
        self._rows.append(row)
        if self.monitor is not None:
            self.monitor.publish(
                {
                    "time_s": t,
                    "mode": self._mode,
                    # the mode it waits for, not one given up (STOP before it was built)
                    "loading": [] if self._waiting is None else [self._waiting],
                    "obs": frame.observation(),
                    "detected": frame.detected,
                    "command": [v, w],
                    "wheel_target_mps": target,
                    "wheel_measured_mps": measured,
                    "robot": _pose(frame.truth, "robot"),
                    "person": _pose(frame.truth, "person"),
                    "link": self.link.stats.as_dict(),
                }
            )
        return speed


def _pose(truth: dict[str, Any], who: str) -> list[float] | None:
    keys = (f"{who}_x_m", f"{who}_y_m", f"{who}_theta_rad")
    if not all(truth.get(k) is not None for k in keys):
        return None
    return [float(truth[k]) for k in keys]

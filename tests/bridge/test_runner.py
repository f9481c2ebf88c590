"""bridge/runner.py and follow-robot run: a policy drives the emulated robot over a socket."""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from bridge import SerialLink
from bridge.perception import Frame, Replay
from bridge.protocol import Feedback
from bridge.runner import Runner, RunnerConfig
from bridge.sources import open_source
from eval import episode_metrics, run_episode
from eval.steplog import read_step_log, write_step_log
from policies import make_policy

from .conftest import ROOT, EmulatorProcess

Start = Callable[..., EmulatorProcess]


@pytest.mark.slow
def test_the_closed_loop_follows_as_the_simulation_does(
    emulator_process: Start, tmp_path: Path
) -> None:
    # Hardware-in-the-loop on one machine: the emulated MCU (fixed firmware, the simulator's
    # wheel PID) and its world over socket://, the runner at 10 Hz with the sim camera. The walk
    # is the simulator's straight walk on seed 0, the same person and the same detector noise.
    emu = emulator_process("--framing", "robust", "--firmware", "fixed", "--seed", "0")
    log = tmp_path / "hil.csv"
    with SerialLink(emu.url, "robust") as link:
        runner = Runner(
            link,
            make_policy("gsmpn:tuned"),
            open_source("sim", emu.url, seed=0),
            log=log,
            meta={"policy": "gsmpn:tuned", "scenario": "straight", "seed": 0},
        )
        result = runner.run()
    assert result.reason == "perception over (walk_over)"
    assert result.command.startswith("speed targets")
    hil = episode_metrics(read_step_log(log))
    sim_log = run_episode("gsmpn:tuned", "straight", 0).log
    sim = episode_metrics(sim_log)
    assert abs(result.steps - (len(sim_log) - 1)) <= 2
    assert hil["in_frame_rate_pct"] == sim["in_frame_rate_pct"] == 100.0
    # Close, not equal: the runner's commands reach the MCU up to one 10 ms tick later than in
    # the kernel, and the world moves the body by each period's mean twist.
    for key, rel in (
        ("mean_offset_px", 0.15),
        ("std_offset_px", 0.15),
        ("mean_abs_accel_mm_s2", 0.25),
        ("std_accel_mm_s2", 0.25),
    ):
        assert hil[key] == pytest.approx(sim[key], rel=rel), key
    assert hil["rms_distance_error_m"] == pytest.approx(sim["rms_distance_error_m"], abs=0.03)


@pytest.mark.slow
def test_the_reference_firmware_drives_from_the_pcs_pid(emulator_process: Start) -> None:
    emu = emulator_process("--framing", "reference", "--firmware", "reference")
    with SerialLink(emu.url, "reference") as link:
        runner = Runner(
            link,
            make_policy("pn"),
            open_source("sim", emu.url),
            config=RunnerConfig(duration_s=1.5),
        )
        result = runner.run()
    assert result.reason == "duration 1.5 s reached"
    assert result.command == "duty (PID on the PC)"
    info = emu.ask(op="info")
    assert info["mcu"]["commands"] > 100  # the wheel loop: a duty command every 10 ms
    # ... answered at least every other time (10 ms since the last answer, by whole ms)
    assert info["mcu"]["feedback_sent"] >= 0.45 * info["mcu"]["commands"]
    # one per wheel tick (the commands also count the stop sent at the end)
    assert 100 < len(result.wheel_lateness_ms) <= info["mcu"]["commands"]
    assert np.median(result.wheel_lateness_ms) < 5.0
    assert info["wheels"]["duty_pct"] == [0.0, 0.0]  # stopped at the end
    assert result.lateness_percentile(99) < 50.0


@pytest.mark.slow
def test_lost_feedback_stops_the_wheels(emulator_process: Start) -> None:
    emu = emulator_process("--framing", "robust", "--firmware", "fixed")
    with SerialLink(emu.url, "robust") as link:
        runner = Runner(link, make_policy("pn"), open_source("sim", emu.url))

        def cut() -> None:
            time.sleep(1.0)
            emu.ask(op="cut", seconds=5)

        threading.Thread(target=cut, daemon=True).start()
        start = time.monotonic()
        result = runner.run()
        elapsed = time.monotonic() - start
    assert result.reason.startswith("no feedback from the MCU for")
    assert 1.0 < elapsed < 1.6  # 100 ms after the cut, plus the shutdown
    wheels = emu.ask(op="info")["wheels"]
    assert wheels["target_mps"] == [0.0, 0.0]  # the stop command arrived (the line is one-way cut)


def test_lost_feedback_stops_the_wheels_while_the_camera_still_blocks(
    emulator_process: Start,
) -> None:
    # The control loop can sit in the camera's read for up to its timeout; the wheels must not
    # wait for it: the reference firmware has no watchdog and holds its last duty.
    emu = emulator_process("--framing", "reference", "--firmware", "reference")
    cut_at: list[float] = []

    class SlowAfterTheCut:
        def __init__(self, source: Any) -> None:
            self.source = source

        def __getattr__(self, name: str) -> Any:
            return getattr(self.source, name)

        def read(self) -> Frame:
            if cut_at:
                time.sleep(2.0)  # a camera that stopped answering, until its timeout
            return self.source.read()

    with SerialLink(emu.url, "reference") as link:
        runner = Runner(link, make_policy("pn"), SlowAfterTheCut(open_source("sim", emu.url)))
        seen: dict[str, Any] = {}

        def cut_then_look() -> None:
            time.sleep(1.0)
            seen["before"] = emu.ask(op="info")["wheels"]["duty_pct"]
            emu.ask(op="cut", seconds=5)  # the MCU falls silent; it still takes commands
            cut_at.append(time.monotonic())
            time.sleep(0.5)  # the 100 ms limit, and the stop commands
            seen["after"] = emu.ask(op="info")["wheels"]["duty_pct"]
            seen["when"] = time.monotonic() - cut_at[0]

        looker = threading.Thread(target=cut_then_look, daemon=True)
        looker.start()
        result = runner.run()
        ended = time.monotonic() - cut_at[0]
        looker.join(timeout=5.0)
    assert result.reason.startswith("no feedback from the MCU for")
    assert seen["before"] != [0.0, 0.0]  # the robot was driving
    assert seen["when"] < ended - 0.5  # looked while the control loop still waited on the camera
    assert seen["after"] == [0.0, 0.0]  # stopped by the wheel loop itself
    assert result.stop_error == ""


@pytest.mark.slow
def test_ctrl_c_stops_the_wheels_and_keeps_the_log(emulator_process: Start, tmp_path: Path) -> None:
    emu = emulator_process("--framing", "robust", "--firmware", "fixed")
    log = tmp_path / "run.csv"
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "bridge",
            "run",
            "--port",
            emu.url,
            "--framing",
            "robust",
            "--policy",
            "gsmpn",
            "--log",
            str(log),
        ],
        cwd=ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )
    deadline = time.monotonic() + 60
    while emu.ask(op="frame")["step"] < 10:  # driving for a second
        assert time.monotonic() < deadline
        assert proc.poll() is None
        time.sleep(0.1)
    proc.send_signal(signal.SIGINT)
    out, _ = proc.communicate(timeout=20)
    assert proc.returncode == 0, out
    assert "interrupted (Ctrl-C)" in out
    assert emu.ask(op="info")["wheels"]["target_mps"] == [0.0, 0.0]
    steps = read_step_log(log)
    assert len(steps) >= 10
    assert steps["obs_distance_m"].iloc[0] > 0
    assert not list(tmp_path.glob(".*"))  # no temporary file left


def _assert_pn_drove(replayed: Any, n: int) -> None:
    """The first ``n`` commands of the replayed run are pn's on the observations it logged
    (the replay is in time: on a loaded machine a late first step reads a later row)."""
    law = make_policy("pn")
    law.reset()
    expected = [
        law.act(np.array(o, dtype=np.float32))[0]
        for o in replayed[["obs_distance_m", "obs_offset_px"]].to_numpy()[:n]
    ]
    np.testing.assert_allclose(replayed["action_v_mps"].to_numpy()[:n], expected, rtol=1e-6)


def test_a_replayed_log_drives_the_policy_and_is_logged_as_it_was(tmp_path: Path) -> None:
    # loop:// echoes our commands, which the PC side reads as feedback: enough for the plumbing.
    source = tmp_path / "source.csv"
    write_step_log(run_episode("pn", "curve", 1).log, source)
    log = tmp_path / "replayed.csv"
    with SerialLink("loop://", "reference") as link:
        runner = Runner(
            link, make_policy("pn"), Replay(source), config=RunnerConfig(duration_s=1.0), log=log
        )
        result = runner.run()
    assert result.reason == "duration 1 s reached"
    replayed, original = read_step_log(log), read_step_log(source)
    n = len(replayed) - 1
    assert n >= 8
    np.testing.assert_allclose(
        replayed["obs_offset_px"].to_numpy()[:n], original["obs_offset_px"].to_numpy()[:n]
    )
    _assert_pn_drove(replayed, n)


def _replay_choosing(
    tmp_path: Path, hub: Any, mode: str, factory: Callable[[str], Any], duration_s: float
) -> tuple[Any, Path]:
    """pn drives a replayed curve walk with ``hub`` as its monitor, ``mode`` chosen in the
    browser before the first step and built by ``factory``; the result and the run's log."""
    source = tmp_path / "source.csv"
    write_step_log(run_episode("pn", "curve", 1).log, source)
    log = tmp_path / "replayed.csv"
    with SerialLink("loop://", "reference") as link:
        runner = Runner(
            link,
            make_policy("pn"),
            Replay(source),
            config=RunnerConfig(duration_s=duration_s),
            log=log,
            monitor=hub,
            policy_factory=factory,
        )
        hub.set_mode(mode)
        return runner.run(), log


@pytest.mark.slow
@pytest.mark.parametrize(
    ("mode", "why"),
    [
        ("ppo_ahead", "reads the reading ahead .* but replay:.* does not publish it"),
        ("ppo_mecanum", r"commands \[v_mps, vy_mps, w_radps\], but this robot takes"),
    ],
)
def test_a_mode_the_robot_cannot_run_is_refused_and_the_robot_drives_on(
    tmp_path: Path, mode: str, why: str
) -> None:
    from bridge.monitor.hub import MonitorHub, monitor_modes

    make_policy(mode)  # loaded once before: building it then takes ms, not seconds
    hub = MonitorHub("pn", modes=monitor_modes([mode]))
    result, log = _replay_choosing(tmp_path, hub, mode, make_policy, 1.0)
    assert result.reason == "duration 1 s reached"
    assert hub.mode == "pn"  # back to what the robot was running
    assert re.search(f"^{mode} {why}", hub.notice), hub.notice
    assert hub.latest()["notice"] == hub.notice
    replayed = read_step_log(log)
    n = len(replayed) - 1
    assert n >= 8
    _assert_pn_drove(replayed, n)


def test_a_mode_is_built_beside_the_control_loop_which_runs_the_old_one_meanwhile(
    tmp_path: Path,
) -> None:
    # An agent's first load (torch, weights) takes about 2 s; built inside the loop it would
    # leave the wheels at their last targets that long. Here building mpn takes 1 s: the loop
    # goes on with pn meanwhile, publishing that mpn is loading, then switches.
    from bridge.monitor.hub import MonitorHub, monitor_modes

    class Recording(MonitorHub):
        def publish(self, state: dict[str, Any]) -> None:
            states.append(state)
            super().publish(state)

    def slow(mode: str) -> Any:
        time.sleep(1.0)
        return make_policy(mode)

    states: list[dict[str, Any]] = []
    hub = Recording("pn", modes=monitor_modes())
    result, log = _replay_choosing(tmp_path, hub, "mpn", slow, 2.5)
    assert result.reason == "duration 2.5 s reached"
    acted = [s for s in states if s["command"][0] is not None]
    modes = [s["mode"] for s in acted]
    loading = [s for s in acted if s["loading"]]
    assert loading
    assert all(s["mode"] == "pn" and s["loading"] == ["mpn"] for s in loading)
    assert len(loading) >= 5  # the loop did not wait: built inside it, there would be none
    switch = modes.index("mpn")
    assert modes[:switch] == ["pn"] * switch
    assert modes[switch:] == ["mpn"] * (len(modes) - switch)
    assert not any(s["loading"] for s in acted[switch:])
    replayed = read_step_log(log)
    _assert_pn_drove(replayed, switch)
    law = make_policy("mpn")  # reset at the switch, then fed the observations from there on
    law.reset()
    rows = replayed[["obs_distance_m", "obs_offset_px"]].to_numpy()[switch : len(acted)]
    expected = [law.act(np.array(o, dtype=np.float32))[0] for o in rows]
    got = replayed["action_v_mps"].to_numpy()[switch : len(acted)]
    np.testing.assert_allclose(got, expected, rtol=1e-6)


class _Recording:
    """A monitor hub that keeps every state published, and a browser that chooses modes at
    given times of the session (seconds after its first state)."""

    def __init__(self, start: str, choices: list[tuple[float, str]], modes: Any = None) -> None:
        from bridge.monitor.hub import MonitorHub, monitor_modes

        states: list[dict[str, Any]] = []

        class Hub(MonitorHub):
            def publish(self, state: dict[str, Any]) -> None:
                states.append(state)
                super().publish(state)

        self.hub = Hub(start, modes=modes or monitor_modes())
        self.states = states
        self._choices = choices
        threading.Thread(target=self._browse, daemon=True).start()

    def _browse(self) -> None:
        while not self.states:
            time.sleep(0.005)
        begun = time.monotonic()
        for at, mode in self._choices:
            time.sleep(max(0.0, begun + at - time.monotonic()))
            self.hub.set_mode(mode)
            if mode == "manual":
                self.hub.set_manual(0.2, 0.1)


def test_a_mode_given_up_before_it_was_built_is_not_shown_loading(tmp_path: Path) -> None:
    # mpn takes 1 s to build; STOP is pressed before it is ready. The build finishes unused,
    # and from STOP on the page is told nothing is loading.
    def slow(mode: str) -> Any:
        time.sleep(1.0)
        return make_policy(mode)

    browser = _Recording("pn", [(0.3, "mpn"), (0.6, "stop")])
    with SerialLink("loop://", "reference") as link:
        runner = Runner(
            link,
            make_policy("pn"),
            Replay(_curve(tmp_path)),
            config=RunnerConfig(duration_s=2.5),
            monitor=browser.hub,
            policy_factory=slow,
        )
        runner.run()
    stopped = [s for s in browser.states if s["mode"] == "stop"]
    assert any(s["loading"] == ["mpn"] for s in browser.states if s["mode"] == "pn")
    assert len(stopped) >= 10  # well past the moment mpn was built (1.3 s)
    assert [s["loading"] for s in stopped] == [[]] * len(stopped)


def test_a_step_the_monitor_drove_is_not_credited_to_the_starting_policy(tmp_path: Path) -> None:
    # run --policy gsmpn:tuned --monitor: the browser chooses manual, then mpn. follow-eval
    # metrics reads the policy column as the session's label: it names every driver.
    from bridge.monitor.hub import monitor_modes
    from eval.scoring import read_episodes

    browser = _Recording(
        "gsmpn:tuned", [(0.5, "manual"), (1.0, "mpn")], modes=monitor_modes(["gsmpn:tuned"])
    )
    log = tmp_path / "run.csv"
    meta = {"policy": "gsmpn:tuned", "scenario": "robot:replay", "seed": None}
    with SerialLink("loop://", "reference") as link:
        runner = Runner(
            link,
            make_policy("gsmpn:tuned"),
            Replay(_curve(tmp_path)),
            config=RunnerConfig(duration_s=2.0),
            log=log,
            meta=meta,
            monitor=browser.hub,
            policy_factory=make_policy,
        )
        runner.run()
    rows = read_step_log(log)
    names = ["gsmpn:tuned", "manual", "mpn"]
    assert set(rows["policy"]) == {"mixed:gsmpn:tuned,manual,mpn"}
    acted = [s for s in browser.states if s["command"][0] is not None]
    drove = [names[int(k)] for k in rows["driver"][: len(acted)]]
    assert drove == [s["mode"] for s in acted]  # each step, by what drove it
    assert drove[0] == "gsmpn:tuned"
    assert {"manual", "mpn"} <= set(drove)
    assert rows["driver"].iloc[-1] == rows["driver"].iloc[-2]  # the final row: the last step's
    (episode,) = read_episodes([log], task="person_follow")
    assert episode.policy == "mixed:gsmpn:tuned,manual,mpn"  # not scored as gsmpn:tuned


def test_a_session_one_policy_drove_is_credited_to_it(tmp_path: Path) -> None:
    log = tmp_path / "run.csv"
    meta = {"policy": "pn", "scenario": "robot:replay", "seed": None}
    browser = _Recording("pn", [])
    with SerialLink("loop://", "reference") as link:
        Runner(
            link,
            make_policy("pn"),
            Replay(_curve(tmp_path)),
            config=RunnerConfig(duration_s=1.0),
            log=log,
            meta=meta,
            monitor=browser.hub,
        ).run()
    rows = read_step_log(log)
    assert set(rows["policy"]) == {"pn"}
    assert set(rows["driver"]) == {0.0}


@pytest.mark.slow
def test_the_robots_monitor_refuses_an_agent_its_camera_cannot_feed(
    emulator_process: Start,
) -> None:
    # follow-robot monitor on the emulated robot: the world's camera publishes no reading ahead,
    # so ppo_ahead is offered (it commands [v, w]) but refused once chosen, and the robot stays
    # stopped; the mecanum base's agent is not offered at all.
    import asyncio
    import json

    import websockets

    emu = emulator_process("--framing", "robust", "--firmware", "fixed", "--seed", "0")
    command = [sys.executable, "-m", "bridge", "monitor", "--port", emu.url, "--perception"]
    proc = subprocess.Popen(
        [*command, "sim", "--framing", "robust", "--http", "127.0.0.1:0"],
        cwd=ROOT,
        stdout=subprocess.PIPE,
        text=True,
    )

    async def choose(url: str) -> list[dict]:
        async with websockets.connect(url) as ws:
            scene = json.loads(await ws.recv())
            await ws.send(json.dumps({"type": "mode", "mode": "ppo_ahead"}))
            seen = [scene]
            while not (seen[-1].get("type") == "state" and seen[-1]["refusals"]):
                seen.append(json.loads(await asyncio.wait_for(ws.recv(), 10.0)))
            return seen

    try:
        modes, served = proc.stdout.readline(), proc.stdout.readline()
        url = served.split("monitor on http://", 1)[1].strip()
        seen = asyncio.run(choose(f"ws://{url}ws"))
    finally:
        proc.send_signal(signal.SIGINT)
        out, _ = proc.communicate(timeout=20)
    assert modes.startswith(
        "follow-robot: monitor modes pn, mpn, gsmpn, ppo, ppo_ahead, ppo_law, ppo_ensemble, manual"
    )
    assert "not offered: ppo_mecanum commands [v_mps, vy_mps, w_radps]" in modes
    assert ["ppo_ahead", "PPO (ahead)"] in seen[0]["modes"]
    assert {"type": "ack", "mode": "ppo_ahead"} in seen
    last = seen[-1]
    assert last["mode"] == "stop"
    assert last["notice"].startswith("ppo_ahead reads the reading ahead")
    assert last["command"] == [0.0, 0.0]
    assert proc.returncode == 0, out


def _curve(tmp_path: Path) -> Path:
    source = tmp_path / "source.csv"
    write_step_log(run_episode("pn", "curve", 1).log, source)
    return source


def _stopped(link: SerialLink) -> bool:
    """Whether the last commands the runner sent were its three stop commands: loop:// echoes
    what is sent, and the wheel loop, which read the echoes, ended before those went out."""
    echoed = [m for m in link.receive(0.2) if isinstance(m, Feedback)]
    return len(echoed) >= 3 and all((m.right_mm_s, m.left_mm_s) == (0, 0) for m in echoed[-3:])


def test_a_failing_wheel_loop_ends_the_run_stops_the_wheels_and_says_why(tmp_path: Path) -> None:
    # Whatever the wheel loop raises (here a bug standing in for any), the run must not go on
    # without it: the control loop ends, the wheels get the stop command, the result says why.
    with SerialLink("loop://", "reference") as link:
        runner = Runner(
            link, make_policy("pn"), Replay(_curve(tmp_path)), config=RunnerConfig(duration_s=5)
        )
        command = runner._wheel_command
        ticks = []

        def buggy(*args: Any) -> Any:
            if threading.current_thread().name == "wheel-loop":
                ticks.append(1)
                if len(ticks) == 30:
                    raise RuntimeError("a bug")
            return command(*args)

        runner._wheel_command = buggy  # type: ignore[method-assign]
        start = time.monotonic()
        result = runner.run()
        elapsed = time.monotonic() - start
        assert _stopped(link)
    assert elapsed < 2.0  # not the 5 s the run was to take
    assert result.reason == result.failure
    assert result.reason == "wheel loop failed (RuntimeError: a bug): wheels stopped"
    assert result.stop_error == ""
    assert f"ended: {result.reason}" in result.summary()


class _Unplugged(Replay):
    """A replay whose 6th read raises what pyrealsense2 does when the camera is unplugged."""

    reads = 0

    def read(self) -> Frame:
        self.reads += 1
        if self.reads == 6:
            raise RuntimeError("Frame didn't arrive within 1000")
        return super().read()


def _failing_on_the_6th_act(policy: Any) -> Any:
    """``policy``, whose 6th ``act`` returns one value instead of two (a bug standing in for
    any)."""
    act, calls = policy.act, []

    def failing(obs: Any) -> Any:
        calls.append(obs)
        return act(obs)[:1] if len(calls) == 6 else act(obs)

    policy.act = failing
    return policy


@pytest.mark.parametrize("failing", ["perception", "policy"])
def test_a_failing_read_or_act_ends_the_run_stops_the_wheels_and_keeps_the_log(
    failing: str, tmp_path: Path
) -> None:
    # Whatever the perception's read or the policy's act raises: the session ends as a failure
    # of the one that failed, with its result on the error, the wheels stopped, the log saved.
    from bridge.perception import PerceptionError

    if failing == "perception":
        policy, source = make_policy("pn"), _Unplugged(_curve(tmp_path))
        error: type[Exception] = PerceptionError
        why = f"{source.name}: reading a frame failed (RuntimeError: Frame didn't arrive within "
        why += "1000)"
    else:
        from bridge.runner import PolicyError

        policy, source = _failing_on_the_6th_act(make_policy("pn")), Replay(_curve(tmp_path))
        error = PolicyError
        why = "policy pn:tuned failed to act (ValueError: not enough values to unpack (expected "
        why += "2, got 1))"
    log = tmp_path / "run.csv"
    with SerialLink("loop://", "reference") as link:
        runner = Runner(link, policy, source, config=RunnerConfig(duration_s=5), log=log)
        with pytest.raises(error) as caught:
            runner.run()
        assert _stopped(link)
    assert str(caught.value) == why
    result = caught.value.result  # type: ignore[attr-defined]
    assert result.reason == f"{failing} error: {why}"
    assert result.steps == 5
    assert result.log == log
    assert len(read_step_log(log)) == 6  # the 5 steps, and the last frame with no command


def test_a_stop_command_that_cannot_be_sent_is_said(tmp_path: Path) -> None:
    with SerialLink("loop://", "reference") as link:
        runner = Runner(
            link, make_policy("pn"), Replay(_curve(tmp_path)), config=RunnerConfig(duration_s=5)
        )
        threading.Timer(0.5, link.close).start()  # the adapter is pulled out
        result = runner.run()
    assert result.reason.startswith("link error: loop://: ")
    assert result.reason.endswith("not open")
    assert result.stop_error.startswith("the stop command could not be sent (")
    assert result.stop_error in result.summary()


@pytest.mark.parametrize(
    ("kwargs", "why"),
    [
        (
            {"config": RunnerConfig(command="speed")},
            r"RunnerConfig.command='speed' is out of range: must be duty or auto: the "
            r"reference framing of loop:// carries DUTY_PERCENT commands",
        ),
        ({"platform": "mecanum"}, "config.platform=MecanumConfig is out of range"),
        ({"policy": "ppo_mecanum"}, r"ppo_mecanum commands \[v_mps, vy_mps, w_radps\]"),
    ],
)
def test_a_runner_refuses_what_would_fail_mid_session(
    kwargs: dict[str, Any], why: str, tmp_path: Path
) -> None:
    from follow_env.platforms.mecanum import MecanumConfig

    if kwargs.get("platform") == "mecanum":
        kwargs["platform"] = MecanumConfig()
    policy = make_policy(kwargs.pop("policy", "pn"))
    with SerialLink("loop://", "reference") as link, pytest.raises(ValueError, match=why):
        Runner(link, policy, Replay(_curve(tmp_path)), **kwargs)


def test_a_second_ctrl_c_while_stopping_does_not_lose_the_log(tmp_path: Path) -> None:
    # Ctrl-C pressed twice: the first ends the control loop, the second arrives while the
    # runner stops the wheels and closes the perception. Both are real SIGINTs to this process.
    class Interrupted(Replay):
        reads = 0

        def read(self) -> Frame:
            self.reads += 1
            if self.reads == 5:
                os.kill(os.getpid(), signal.SIGINT)
            return super().read()

        def close(self) -> None:
            os.kill(os.getpid(), signal.SIGINT)
            super().close()

    log = tmp_path / "run.csv"
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        with SerialLink("loop://", "reference") as link:
            runner = Runner(link, make_policy("pn"), Interrupted(_curve(tmp_path)), log=log)
            try:
                result = runner.run()
            except KeyboardInterrupt:
                pytest.fail("the second Ctrl-C cut the shutdown short")
            assert _stopped(link)
        assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
    finally:
        signal.signal(signal.SIGINT, previous)
    assert result.reason == "interrupted (Ctrl-C)"
    assert len(read_step_log(log)) == 5  # 4 steps and the last frame
    assert [p.name for p in tmp_path.iterdir()] == sorted(["run.csv", "source.csv"])


def test_runner_settings_are_checked() -> None:
    with pytest.raises(ValueError, match=r"RunnerConfig.control_dt_s=0 is out of range"):
        RunnerConfig(control_dt_s=0)
    with pytest.raises(ValueError, match=r"RunnerConfig.wheel_dt_s=0.2 is out of range"):
        RunnerConfig(wheel_dt_s=0.2)
    with pytest.raises(ValueError, match=r"RunnerConfig.command='pwm' is out of range"):
        RunnerConfig(command="pwm")
    with pytest.raises(ValueError, match=r"RunnerConfig.duration_s=-1 is out of range"):
        RunnerConfig(duration_s=-1)


def test_a_runner_needs_a_folder_for_its_log(tmp_path: Path) -> None:
    source = tmp_path / "obs.csv"
    source.write_text("time_s,obs_distance_m,obs_offset_px\n0,1.0,0\n0.1,1.0,2\n")
    with SerialLink("loop://") as link, pytest.raises(ValueError, match="does not exist"):
        Runner(link, make_policy("pn"), Replay(source), log=tmp_path / "no" / "x.csv")


RUN = ["run", "--port", "loop://", "--policy", "pn"]
REPLAY = "replay:" + str(Path(__file__).with_name("data") / "replay_obs.csv")


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["run", "--policy", "pn"], "run needs --port URL"),
        (["run", "--port", "loop://", "--policy", "nope"], "nope"),
        ([*RUN, "--perception", "sim"], "socket://HOST:PORT"),
        ([*RUN, "--perception", "sim:localhost:99999"], "'99999' is out of range: must be in 1-"),
        ([*RUN, "--perception", "sim:::1:5761"], "an IPv6 host in brackets"),
        ([*RUN, "--perception", "webcam"], "out of range"),
        ([*RUN, "--perception", "replay:/no/such.csv"], "such.csv: no such file"),
        ([*RUN, "--perception", "realsense:/no/m.pt"], "is not a file"),
        ([*RUN, "--perception", "replay:" + __file__], "missing column"),
        ([*RUN, "--duration", "0"], "out of range"),
        (["run", "--port", "/dev/nonexistent", "--policy", "pn", "--perception", REPLAY], "open"),
        (["emulate", "--listen", "tcp://x"], "socket://HOST:PORT"),
        (["emulate", "--scenario", "moon"], "moon"),
        (["emulate", "--config", '{"motor": {"time_constant_s": -1}}'], "time_constant_s"),
        (["monitor", "--sim", "--http", "0.0.0.0:0"], "--token"),
        (["monitor"], "monitor needs --port URL"),
    ],
)
def test_bad_arguments_give_one_line_and_exit_2(
    argv: list[str], message: str, capsys: pytest.CaptureFixture[str]
) -> None:
    from bridge.cli import main

    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("follow-robot: error:")
    assert message in err
    assert "\n" not in err


def test_the_runner_runs_a_law_at_its_control_period(tmp_path: Path) -> None:
    """A law differentiates over the robot's period (RunnerConfig.control_dt_s), the starting
    policy and a mode the monitor selects alike; before, a 20 Hz loop ran gsmpn:thesis's rate
    over 0.1 s, at half its size."""
    replay = tmp_path / "obs.csv"
    replay.write_text("time_s,obs_distance_m,obs_offset_px,detected\n0,1.5,10,1\n0.05,1.5,12,1\n")
    with SerialLink("loop://", "reference") as link:
        runner = Runner(
            link,
            make_policy("gsmpn:thesis"),
            Replay(replay),
            config=RunnerConfig(control_dt_s=0.05),
        )
        assert runner.policy.params.dt_s == 0.05
        assert runner.policy.name == "gsmpn:thesis"
        assert runner._runnable(make_policy("mpn:thesis")).params.dt_s == 0.05
        pn = make_policy("pn")
        assert runner._runnable(pn) is pn  # PN keeps no rate

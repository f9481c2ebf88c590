"""follow-robot's command line: a bad value gives one line naming the option, the value and what
is wrong, exit status 2, before any long work starts, and leaves no file behind."""

from __future__ import annotations

import contextlib
import os
import shutil
import socket
import stat
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import pytest

from bridge.cli import main
from bridge.runner import Runner

DATA = Path(__file__).with_name("data")
RUN = ["run", "--policy", "pn", "--port", "loop://", "--duration", "1"]
REPLAY = ["--perception", "replay:" + str(DATA / "replay_obs.csv")]


def _one_line(capsys: pytest.CaptureFixture[str], *parts: str) -> str:
    """The error line on stderr, checked: one line, no traceback, naming every one of ``parts``."""
    err = capsys.readouterr().err
    assert err.count("\n") == 1, err
    assert err.startswith("follow-robot: error: "), err
    assert "Traceback" not in err
    for part in parts:
        assert part in err, (part, err)
    return err.strip()


def _files(folder: Path) -> list[str]:
    return sorted(str(p.relative_to(folder)) for p in folder.rglob("*"))


@pytest.fixture
def spare(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """The system's temporary folder, where a log that cannot be saved at --log goes: a folder
    of the test's own, ``tmp_path / "spare"``."""
    folder = tmp_path / "spare"
    folder.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(folder))
    return folder


@pytest.fixture
def no_session(monkeypatch: pytest.MonkeyPatch) -> None:
    """Fail a test whose bad argument lets a robot session start."""

    def started(self: Runner) -> Any:
        raise AssertionError("the session started before the arguments were checked")

    monkeypatch.setattr(Runner, "run", started)


# ---- run --log ----------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("log", "why"),
    [
        ("nodir/x.csv", "the folder nodir does not exist"),
        ("afile/x.csv", "afile is not a folder"),
        ("adir", "is a folder; give a file name"),
        ("", "empty; give a file name"),
        pytest.param(
            "/proc/audit.csv",
            "cannot create a file in the folder /proc",
            marks=pytest.mark.skipif(sys.platform != "linux", reason="/proc is Linux's"),
        ),
    ],
)
def test_a_log_that_cannot_be_written_is_refused_before_the_session(
    log: str,
    why: str,
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
    no_session: None,
) -> None:
    monkeypatch.chdir(tmp_path)
    (tmp_path / "afile").write_text("")
    (tmp_path / "adir").mkdir()
    before = _files(tmp_path)
    assert main([*RUN, *REPLAY, "--log", log]) == 2
    _one_line(capsys, f"--log {log or repr(log)}", why)
    assert _files(tmp_path) == before  # no log, no temporary or probe file


def test_a_log_that_fails_at_the_end_is_kept_elsewhere_and_said_in_one_line(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str], spare: Path
) -> None:
    from eval.steplog import read_step_log

    folder = tmp_path / "usb"
    folder.mkdir()
    session = Runner.run

    def unplugged(self: Runner) -> Any:  # the stick is pulled out during the session
        shutil.rmtree(folder)
        return session(self)

    monkeypatch.setattr(Runner, "run", unplugged)
    log = folder / "run.csv"
    assert main([*RUN, *REPLAY, "--log", str(log)]) == 1
    line = _one_line(capsys, f"--log {log}", "could not be written", f"saved to {spare}")
    (kept,) = spare.iterdir()  # the session's rows, and no temporary file beside them
    assert str(kept) in line
    assert len(read_step_log(kept)) >= 2
    assert not folder.exists()


@pytest.mark.parametrize("kind", ["fifo", "device"])
def test_a_log_that_is_not_a_regular_file_is_refused_and_never_replaced(
    kind: str, tmp_path: Path, capsys: pytest.CaptureFixture[str], no_session: None
) -> None:
    # os.replace would put a regular file in the place of a FIFO or a device node (/dev/null,
    # for root, is in a folder root may write to)
    if kind == "fifo":
        node = tmp_path / "pipe.csv"
        os.mkfifo(node)
    else:
        node = Path("/dev/null")
    before = os.stat(node).st_mode
    assert main([*RUN, *REPLAY, "--log", str(node)]) == 2
    _one_line(capsys, f"--log {node}: is not a regular file")
    assert os.stat(node).st_mode == before


def test_the_final_save_never_replaces_what_became_a_fifo(tmp_path: Path, spare: Path) -> None:
    from bridge.runlog import save_rows

    node = tmp_path / "run.csv"
    os.mkfifo(node)  # made during the session, after --log was checked
    where, why = save_rows([{"step": 0, "time_s": 0.0}], node)
    assert stat.S_ISFIFO(os.stat(node).st_mode)
    assert "is not a regular file" in why
    assert where is not None
    assert where.parent == spare
    assert where.read_text() == "step,time_s\n0,0\n"
    assert _files(tmp_path) == ["run.csv", "spare", f"spare/{where.name}"]


@pytest.mark.parametrize(
    "name",
    [
        "x" * 246 + ".csv",  # 250 bytes
        "x" * 251 + ".csv",  # 255 bytes: the longest the folder takes
        "a." + "b" * 240,  # 242 bytes, nearly all suffix (the temporary name leaves it out)
    ],
)
def test_a_long_log_name_the_folder_takes_is_written_there(
    name: str, tmp_path: Path, spare: Path
) -> None:
    from eval.steplog import read_step_log

    log = tmp_path / name
    assert main([*RUN, *REPLAY, "--log", str(log)]) == 0
    assert len(read_step_log(log)) >= 2
    assert _files(tmp_path) == sorted([log.name, "spare"])  # no temporary file, no spare copy


def test_a_log_name_longer_than_the_folder_takes_is_refused_before_the_session(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], no_session: None
) -> None:
    log = tmp_path / ("x" * 252 + ".csv")  # 256 bytes: over the 255 of ext4, tmpfs, xfs, btrfs
    assert main([*RUN, *REPLAY, "--log", str(log)]) == 2
    _one_line(capsys, f"--log {log}: cannot create a file in the folder", "256 bytes")
    assert _files(tmp_path) == []


def _not_utf8(folder: Path, name: bytes) -> Path:
    """``folder / name`` as a command line gives a name whose bytes are not UTF-8: each such
    byte as a lone surrogate (``b"\\xff"`` as ``"\\udcff"``)."""
    return folder / os.fsdecode(name)


@pytest.mark.parametrize("option", ["--perception", "--policy"])
def test_a_name_that_is_not_utf8_text_is_refused_before_the_session_with_a_log(
    option: str, tmp_path: Path, capsys: pytest.CaptureFixture[str], no_session: None
) -> None:
    # the log's policy and scenario columns hold the two as typed, and the log is UTF-8 text:
    # at the end of the session it could not be written
    replay = _not_utf8(tmp_path, b"r\xff.csv")
    replay.write_text(_LOG)
    value = f"replay:{replay}" if option == "--perception" else str(_not_utf8(tmp_path, b"m\xff"))
    argv = [*RUN, *REPLAY, option, value, "--log", str(tmp_path / "run.csv")]
    assert main(argv) == 2
    shown = value.replace("\udcff", "\\xff")  # the byte as typed, not its surrogate
    _one_line(capsys, f"{option} {shown}: is not UTF-8 text", "run without --log")
    assert _files(tmp_path) == [replay.name]


def test_a_replay_whose_name_is_not_utf8_text_runs_without_a_log(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    replay = _not_utf8(tmp_path, b"r\xff.csv")
    replay.write_text(_LOG)
    assert main([*RUN, "--perception", f"replay:{replay}"]) == 0
    assert "ended: duration 1 s reached" in capsys.readouterr().out


def test_rows_that_cannot_be_written_at_log_are_saved_in_the_spare_file(
    tmp_path: Path, spare: Path
) -> None:
    # any failure, not only the file system's: here a value that is not UTF-8 text (a Runner
    # given such metadata from Python, which the command line refuses)
    from bridge.runlog import save_rows

    log = tmp_path / "run.csv"
    rows = [{"scenario": "robot:replay:r\udcff.csv", "step": k, "time_s": k / 10} for k in (0, 1)]
    where, why = save_rows(rows, log)
    assert where is not None
    assert where.parent == spare
    assert why == (
        f"--log {log}: the step log could not be written (a value holds \\udcff, which is not "
        f"UTF-8 text); saved to {where} instead"
    )
    # UTF-8 text, what is not UTF-8 written as an escape
    assert where.read_text(encoding="utf-8") == (
        "scenario,step,time_s\nrobot:replay:r\\udcff.csv,0,0\nrobot:replay:r\\udcff.csv,1,0.1\n"
    )
    assert _files(tmp_path) == ["spare", f"spare/{where.name}"]  # nothing at --log, no temp


def test_rows_that_cannot_be_written_anywhere_are_said_lost_in_one_line(
    tmp_path: Path, spare: Path
) -> None:
    from bridge.runlog import save_rows

    class Unprintable:
        def __str__(self) -> str:
            raise ValueError("no text for this")

    log = tmp_path / "run.csv"
    where, why = save_rows([{"step": 0, "time_s": Unprintable()}], log)
    assert where is None
    assert why == (
        f"--log {log}: the step log could not be written (ValueError: no text for this), nor "
        f"in {spare} (ValueError: no text for this): lost"
    )
    assert _files(tmp_path) == ["spare"]  # no empty spare file, no temporary file


def test_a_session_whose_log_metadata_is_not_utf8_text_keeps_its_rows(
    tmp_path: Path, spare: Path
) -> None:
    from bridge import SerialLink
    from bridge.perception import Replay
    from bridge.runner import RunnerConfig
    from eval.steplog import read_step_log
    from policies import make_policy

    replay = tmp_path / "obs.csv"
    replay.write_text(_LOG)
    log = tmp_path / "run.csv"
    meta = {"policy": "pn", "scenario": "robot:replay:r\udcff.csv", "seed": None}
    with SerialLink("loop://", "reference") as link:
        runner = Runner(
            link,
            make_policy("pn"),
            Replay(replay),
            config=RunnerConfig(duration_s=0.5),
            log=log,
            meta=meta,
        )
        result = runner.run()  # before: UnicodeEncodeError out of its finally, no log at all
    assert result.reason == "duration 0.5 s reached"
    assert result.log is not None
    assert result.log.parent == spare
    assert result.log_error.startswith(f"--log {log}: the step log could not be written (")
    assert len(read_step_log(result.log)) == result.steps + 1
    assert not log.exists()


# ---- run: what the robot cannot do ----------------------------------------------------------


@pytest.mark.parametrize(
    ("argv", "parts"),
    [
        (["--framing", "reference", "--command", "speed"], ["--command speed", "--framing"]),
        (
            ["--config", '{"platform": "mecanum"}'],
            ["config.platform=MecanumConfig is out of range", "differential drive"],
        ),
        (
            ["--policy", "ppo_mecanum"],
            ["--policy ppo_mecanum: ppo_mecanum commands [v_mps, vy_mps, w_radps], but this"],
        ),
        # nothing would send its commands: the robot would idle, logged as driven by hand
        (["--policy", "manual"], ["--policy manual: the monitor's page sends", "--monitor"]),
    ],
)
def test_what_the_robot_cannot_run_is_refused_before_the_session(
    argv: list[str],
    parts: list[str],
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    no_session: None,
) -> None:
    assert main([*RUN, *REPLAY, "--log", str(tmp_path / "run.csv"), *argv]) == 2
    _one_line(capsys, *parts)
    assert _files(tmp_path) == []


def test_an_error_mid_session_still_says_how_it_went_and_where_the_log_is(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str], spare: Path
) -> None:
    # the camera fails after a few frames, and the log's folder went away before that: the
    # summary and the spare log's place are said, then the error, and the exit status is 1
    from bridge.perception import PerceptionError, Replay
    from eval.steplog import read_step_log

    folder = tmp_path / "usb"
    folder.mkdir()
    replay = tmp_path / "obs.csv"
    replay.write_text(_LOG)
    read = Replay.read

    def failing(self: Replay) -> Any:
        self.reads = getattr(self, "reads", 0) + 1
        if self.reads == 5:
            shutil.rmtree(folder)
            raise PerceptionError("the camera timed out")
        return read(self)

    monkeypatch.setattr(Replay, "read", failing)
    log = folder / "run.csv"
    assert main([*RUN, "--perception", f"replay:{replay}", "--log", str(log)]) == 1
    out, err = capsys.readouterr()
    assert err.count("\n") == 1, err
    assert err.startswith("follow-robot: error: the camera timed out; --log"), err
    assert "could not be written" in err
    (kept,) = spare.iterdir()
    assert f"saved to {kept} instead" in err
    assert "4 control steps, ended: perception error: the camera timed out" in out
    assert f"log: {kept}" in out
    assert len(read_step_log(kept)) == 5  # the 4 steps, and the last frame with no command


@pytest.mark.slow
def test_a_camera_unplugged_mid_session_ends_it_with_the_summary_and_the_log(
    emulator_process: Any,
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    # Any error of the perception's read, not only a PerceptionError: here what pyrealsense2
    # raises when the camera is unplugged, after 15 frames of the emulator's world.
    import bridge.cli

    emu = emulator_process()  # the reference firmware, which holds its last duty until told
    opened = bridge.cli.open_source
    seen: dict[str, Any] = {}

    def unplugged(*args: Any, **kwargs: Any) -> Any:
        source = opened(*args, **kwargs)
        read = source.read
        reads: list[int] = []

        def failing() -> Any:
            reads.append(1)
            if len(reads) == 16:
                seen["driving"] = emu.ask(op="info")["wheels"]["duty_pct"]
                raise RuntimeError("Frame didn't arrive within 1000")
            return read()

        source.read = failing
        return source

    monkeypatch.setattr(bridge.cli, "open_source", unplugged)
    log = tmp_path / "run.csv"
    assert main(["run", "--port", emu.url, "--policy", "pn", "--log", str(log)]) == 1
    out, err = capsys.readouterr()
    why = "sim: reading a frame failed (RuntimeError: Frame didn't arrive within 1000)"
    assert err == f"follow-robot: error: {why}\n"
    assert f"15 control steps, ended: perception error: {why}" in out
    assert f"log: {log}" in out
    assert seen["driving"] != [0.0, 0.0]
    assert emu.ask(op="info")["wheels"]["duty_pct"] == [0.0, 0.0]  # the wheels were stopped
    from eval.steplog import read_step_log

    assert len(read_step_log(log)) == 16  # the 15 steps, and the last frame with no command


def test_a_policy_that_fails_mid_session_ends_it_with_the_summary_and_the_log(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    import policies
    from eval.steplog import read_step_log

    made = policies.make_policy

    def failing_after_some_steps(name: str) -> Any:
        policy = made(name)
        act = policy.act
        calls: list[int] = []

        def failing(obs: Any) -> Any:
            calls.append(1)
            if len(calls) == 6:
                raise ZeroDivisionError("float division by zero")
            return act(obs)

        policy.act = failing
        return policy

    monkeypatch.setattr(policies, "make_policy", failing_after_some_steps)
    replay = tmp_path / "obs.csv"
    replay.write_text(_LOG)
    log = tmp_path / "run.csv"
    assert main([*RUN, "--perception", f"replay:{replay}", "--log", str(log)]) == 1
    out, err = capsys.readouterr()
    why = "policy pn:tuned failed to act (ZeroDivisionError: float division by zero)"
    assert err == f"follow-robot: error: {why}\n"
    assert f"5 control steps, ended: policy error: {why}" in out
    assert f"log: {log}" in out
    assert len(read_step_log(log)) == 6  # the 5 steps, and the last frame with no command


# ---- run --perception replay: -------------------------------------------------------------

_LOG = "time_s,obs_distance_m,obs_offset_px,detected\n" + "".join(
    f"{k / 10:g},{1.0 + k / 100:g},{k},1\n" for k in range(12)
)


@pytest.mark.parametrize(
    ("text", "why"),
    [
        (_LOG[: _LOG.index("0.9,") + 6], "line 11: expected 4 fields as in the header, found 2"),
        (_LOG.replace("\n0.3,1.03,3,", "\n0.3,1.03,abc,"), "line 5, column obs_offset_px: 'abc'"),
        (_LOG.replace("\n0.3,1.03,", "\n0.3,inf,"), "line 5, column obs_distance_m: 'inf' is not"),
        # finite, but infinite as the float32 a policy reads
        (
            _LOG.replace("\n0.3,1.03,3,", "\n0.3,1.03,1e39,"),
            "line 5, column obs_offset_px: 1e+39 is out of range",
        ),
        # numpy's parser reads "3\0" as 3
        (
            _LOG.replace("\n0.3,1.03,3,", "\n0.3,1.03,3\x00,"),
            "line 5, column obs_offset_px: '3\\x00' holds a NUL byte",
        ),
    ],
)
def test_a_damaged_replay_is_refused_naming_the_file_line_and_column(
    text: str, why: str, tmp_path: Path, capsys: pytest.CaptureFixture[str], no_session: None
) -> None:
    replay = tmp_path / "cut.csv"
    replay.write_text(text)
    log = tmp_path / "out.csv"
    assert main([*RUN, "--perception", f"replay:{replay}", "--log", str(log)]) == 2
    _one_line(capsys, f"{replay}: {why}")
    assert _files(tmp_path) == ["cut.csv"]


# ---- monitor ------------------------------------------------------------------------------


@pytest.fixture
def no_server(monkeypatch: pytest.MonkeyPatch) -> None:
    """Fail (rather than serve for ever) a test whose bad argument lets the monitor start."""

    def started(args: Any, hub: Any) -> Any:
        raise AssertionError("the monitor started before the arguments were checked")

    monkeypatch.setattr("bridge.cli._start_monitor", started)


@pytest.mark.parametrize(
    ("argv", "parts"),
    [
        (["--sim", "--scenario", "bogus"], ["ScenarioConfig.name='bogus' is out of range"]),
        (
            ["--sim", "--config", '{"scenario": {"name": "bogus"}}'],
            ["ScenarioConfig.name='bogus' is out of range"],
        ),
        (["--sim", "--duration", "1"], ["--duration 1.0: monitor --sim", "does not use it"]),
        (["--sim", "--log", "x.csv"], ["--log x.csv: monitor --sim"]),
        (["--sim", "--perception", "sim"], ["--perception sim: monitor --sim"]),
        (["--sim", "--port", "loop://"], ["--port loop://: monitor --sim"]),
        (["--sim", "--framing", "robust", "--command", "duty"], ["--framing robust, --command"]),
        (["--port", "loop://", "--scenario", "curve"], ["--scenario curve: monitor --port"]),
        (["--port", "loop://", "--policy", "pn"], ["--policy pn: monitor --port"]),
    ],
)
def test_the_monitor_refuses_what_it_would_ignore_before_it_starts(
    argv: list[str],
    parts: list[str],
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
    no_server: None,
) -> None:
    monkeypatch.chdir(tmp_path)
    assert main(["monitor", *argv, "--http", "127.0.0.1:0"]) == 2
    _one_line(capsys, *parts)
    assert _files(tmp_path) == []


@pytest.mark.parametrize(
    ("argv", "parts"),
    [
        (["--token", "\udcff"], ["--token '\\udcff' is out of range: must be text"]),
        (["--http", "::1"], ["argument --http: '::1' is not HOST:PORT", "[::1]:8000"]),
    ],
)
def test_a_monitor_option_that_cannot_work_is_named(
    argv: list[str], parts: list[str], capsys: pytest.CaptureFixture[str], no_server: None
) -> None:
    # a command-line argument whose bytes are not UTF-8 arrives with lone surrogates
    assert main(["monitor", "--sim", "--http", "127.0.0.1:0", *argv]) == 2
    _one_line(capsys, *parts)


def test_the_monitor_on_a_port_in_use_says_so_in_one_line(
    capfd: pytest.CaptureFixture[str],
) -> None:
    import argparse

    from bridge.cli import UsageError, _http, _start_monitor
    from bridge.monitor.hub import MonitorHub

    assert _http("[::1]:8000") == ("::1", 8000)
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        args = argparse.Namespace(http=("127.0.0.1", port), token=None)
        with pytest.raises(UsageError) as refused:
            _start_monitor(args, MonitorHub())
    message = str(refused.value)
    assert message.startswith(f"--http 127.0.0.1:{port}: the monitor could not listen")
    assert "address already in use" in message
    assert "\n" not in message
    assert capfd.readouterr().err == ""  # uvicorn's own error line is held back


# Two ways to name a scenario: the option, and the configuration's (no default may override it).
CURVE = [["--scenario", "curve"], ["--config", '{"scenario": {"name": "curve"}}']]


@pytest.mark.parametrize("argv", CURVE)
def test_the_sim_monitor_runs_the_scenario_it_is_given(
    argv: list[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    from bridge.monitor.sim import SimDriver

    seen: list[str] = []

    def started(args: Any, hub: Any) -> Any:  # the driver is built by now: stop before serving
        raise _ServedError

    built = SimDriver.__init__

    def init(self: SimDriver, *args: Any, **kwargs: Any) -> None:
        built(self, *args, **kwargs)
        seen.append(self.env.config.scenario.name)

    monkeypatch.setattr(SimDriver, "__init__", init)
    monkeypatch.setattr("bridge.cli._start_monitor", started)
    with pytest.raises(_ServedError):
        main(["monitor", "--sim", *argv, "--http", "127.0.0.1:0"])
    assert seen == ["curve"]


@pytest.mark.parametrize("argv", CURVE)
def test_the_emulator_builds_the_scenario_it_is_given(
    argv: list[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    seen: list[str] = []

    class Built:  # stands in for the emulator once the command has chosen its world
        def __init__(self, url: str, framing: str, firmware: str, config: Any, seed: int) -> None:
            seen.append(config.scenario.name)
            raise _ServedError

    monkeypatch.setattr("bridge.emulator.Emulator", Built)
    with pytest.raises(_ServedError):
        main(["emulate", "--listen", "socket://127.0.0.1:0", *argv])
    assert seen == ["curve"]  # --config's scenario is not overridden by a default


class _ServedError(Exception):
    """The monitor got as far as serving."""


# ---- emulate --listen ---------------------------------------------------------------------


@pytest.mark.parametrize(
    ("url", "why"),
    [
        ("socket://localhost:99999", "port '99999' is out of range: must be in 0-65535"),
        ("socket://localhost:abc", "port 'abc' is not a number"),
        ("socket://localhost:65535", "no PORT + 1 for the camera"),
    ],
)
def test_a_bad_listen_address_names_the_option(
    url: str, why: str, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["emulate", "--listen", url]) == 2
    _one_line(capsys, f"--listen {url!r}", why)


def test_an_interrupt_while_starting_is_one_line(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    def killed(*args: Any, **kwargs: Any) -> Any:  # SIGTERM (raised as Ctrl-C) mid start-up
        raise KeyboardInterrupt

    monkeypatch.setattr("bridge.cli._env_config", killed)
    assert main(["monitor", "--sim", "--http", "127.0.0.1:0"]) == 130
    err = capsys.readouterr().err
    assert err == "follow-robot: interrupted\n"  # no traceback


def test_the_printed_monitor_url_carries_any_token_intact(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    import argparse
    from urllib.parse import parse_qs, urlsplit

    from bridge.cli import _start_monitor

    class Served:
        url = "http://127.0.0.1:8000/"

    monkeypatch.setattr("bridge.monitor.app.serve", lambda *args: Served())
    token = "a+b&c#d%e é"  # what a URL would otherwise mangle (+ reads as a space)
    args = argparse.Namespace(http=("127.0.0.1", 8000), token=token)
    _start_monitor(args, hub=None)
    url = capsys.readouterr().out.strip().rsplit(" ", 1)[1]
    assert parse_qs(urlsplit(url).query)["token"] == [token]


def test_a_log_path_that_is_not_utf8_is_printed_as_typed_under_a_strict_stdout(
    tmp_path: Path,
) -> None:
    # Under a UTF-8 locale Python's streams refuse a lone surrogate: the session ran, its log
    # was saved, and then the summary line naming the log ended in a traceback.
    import subprocess
    import sys

    log = tmp_path / os.fsdecode(b"run\xff.csv")
    env = {**os.environ, "PYTHONIOENCODING": "utf-8"}
    argv = [sys.executable, "-m", "bridge", *RUN, *REPLAY, "--log", os.fsencode(log)]
    done = subprocess.run(argv, capture_output=True, env=env, timeout=120, check=False)
    assert done.returncode == 0, done.stderr.decode("utf-8", "replace")
    assert b"Traceback" not in done.stderr
    assert os.fsencode(log) in done.stdout  # the bytes as typed
    assert log.is_file()


# ---- the monitor's token from the environment, and the session's file limit ----------------


def test_the_token_may_come_from_the_environment_where_ps_does_not_show_it(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    env = "PERSONFOLLOW_MONITOR_TOKEN"  # bridge.cli.TOKEN_ENV
    seen: list[str | None] = []
    monkeypatch.setattr("bridge.cli._run", lambda args, monitor: seen.append(args.token) or 0)
    off_loopback = ["run", "--port", "loop://", "--policy", "pn", "--http", "0.0.0.0:0"]
    monkeypatch.setenv(env, "s3cret")
    assert main(off_loopback) == 0
    assert main([*off_loopback, "--token", "given"]) == 0  # the option, when given, wins
    assert seen == ["s3cret", "given"]
    monkeypatch.delenv(env)
    assert main(off_loopback) == 2
    _one_line(capsys, "not loopback; give --token (or set PERSONFOLLOW_MONITOR_TOKEN)")
    monkeypatch.setenv(env, "\udcff")  # bytes that are not UTF-8
    assert main(off_loopback) == 2
    _one_line(capsys, "PERSONFOLLOW_MONITOR_TOKEN '\\udcff' is out of range: must be text")
    with pytest.raises(SystemExit):
        main(["run", "--help"])
    assert "$PERSONFOLLOW_MONITOR_TOKEN" in capsys.readouterr().out


def _replay_of(tmp_path: Path, seconds: float) -> Path:
    """A replay of ``seconds`` of a person standing 1 m ahead."""
    rows = [f"{k / 10:.1f},1.0,{k % 7},1" for k in range(round(seconds * 10))]
    replay = tmp_path / "long.csv"
    replay.write_text("time_s,obs_distance_m,obs_offset_px,detected\n" + "\n".join(rows) + "\n")
    return replay


def _limit_files(soft: int, hard: int | None = None) -> Any:
    """A ``preexec_fn`` setting the child's limit of open files (``hard``: as it is)."""

    def limit() -> None:
        import resource

        _, old_hard = resource.getrlimit(resource.RLIMIT_NOFILE)
        resource.setrlimit(resource.RLIMIT_NOFILE, (soft, old_hard if hard is None else hard))

    return limit


def _soft_files_limit(pid: int) -> int | None:
    with contextlib.suppress(OSError):
        for line in Path(f"/proc/{pid}/limits").read_text().splitlines():
            if line.startswith("Max open files"):
                return int(line.split()[3])
    return None


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="/proc/PID/limits is Linux's")
def test_a_robot_session_raises_its_file_limit_to_the_hard_one(tmp_path: Path) -> None:
    import resource
    import subprocess

    _, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    if hard == resource.RLIM_INFINITY or hard <= 256:
        pytest.skip(f"the hard limit of open files is {hard}: nothing to raise it to")
    argv = [*RUN[:-1], "4", "--perception", f"replay:{_replay_of(tmp_path, 10)}"]
    proc = subprocess.Popen(
        [sys.executable, "-m", "bridge", *argv],
        cwd=Path(__file__).resolve().parents[2],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        preexec_fn=_limit_files(256),
    )
    seen = set()
    try:
        while proc.poll() is None:
            if (soft := _soft_files_limit(proc.pid)) is not None:
                seen.add(soft)
            time.sleep(0.02)
    finally:
        _, err = proc.communicate(timeout=60)
    assert proc.returncode == 0, err.decode()
    assert hard in seen, seen  # raised for the session (the serial port, log and monitor)


@pytest.mark.slow
@pytest.mark.skipif(sys.platform == "win32", reason="POSIX file-descriptor limits")
def test_idle_connections_to_the_monitor_do_not_lose_the_step_log(tmp_path: Path) -> None:
    # The reviewer's: a client holds hundreds of idle TCP connections to the monitor (no
    # request, no token) as the session ends. Its limit of open files cannot be raised here:
    # the monitor holds at most MAX_CONNECTIONS of them and accepts a few at a time, so the
    # session keeps the descriptors for its log.
    import subprocess

    from eval.steplog import read_step_log

    log = tmp_path / "run.csv"
    replay = _replay_of(tmp_path, 20)
    argv = [*RUN[:-1], "5", "--perception", f"replay:{replay}", "--log", str(log)]
    proc = subprocess.Popen(
        [sys.executable, "-m", "bridge", *argv, "--monitor", "--http", "127.0.0.1:0"],
        cwd=Path(__file__).resolve().parents[2],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=_limit_files(160, 160),
    )
    held: list[socket.socket] = []
    try:
        assert proc.stdout is not None
        proc.stdout.readline()  # the modes offered
        served = proc.stdout.readline()
        port = int(served.rsplit(":", 1)[1].strip(" /\n"))
        while proc.poll() is None and len(held) < 400:
            with contextlib.suppress(OSError):
                held.append(socket.create_connection(("127.0.0.1", port), timeout=2))
        out, err = proc.communicate(timeout=60)  # the connections held to the end
    finally:
        for sock in held:
            sock.close()
        if proc.poll() is None:
            proc.kill()
    assert len(held) > 64  # more than the monitor holds (the old one took all, and ran out)
    assert proc.returncode == 0, err
    assert "Traceback" not in err
    assert f"log: {log}" in out
    assert len(read_step_log(log)) >= 40
    assert sorted(p.name for p in tmp_path.iterdir()) == ["long.csv", "run.csv"]

"""bridge/perception.py, sources.py, realsense.py: the runner's observation sources."""

from __future__ import annotations

import socket
import threading
from pathlib import Path

import numpy as np
import pytest

from bridge.perception import PerceptionError, Replay, SimCamera, perception_address
from bridge.realsense import PERSON_CLASS, RealSensePerception
from bridge.sources import open_source
from eval.steplog import StepLogError, read_step_log


class Clock:
    def __init__(self) -> None:
        self.t = 100.0

    def __call__(self) -> float:
        return self.t


def test_replay_gives_the_row_of_the_moment(tmp_path: Path) -> None:
    log = tmp_path / "log.csv"
    log.write_text(
        "time_s,obs_distance_m,obs_offset_px,detected\n0,1.0,0,1\n0.1,1.1,5,0\n0.2,1.2,-7,1\n"
    )
    clock = Clock()
    replay = Replay(log, clock=clock)
    replay.start()
    assert replay.read().distance_m == 1.0
    clock.t += 0.15
    frame = replay.read()
    assert (frame.distance_m, frame.offset_px, frame.detected, frame.done) == (
        1.1,
        5.0,
        False,
        False,
    )
    clock.t += 0.1
    last = replay.read()
    assert last.offset_px == -7.0
    assert last.done
    assert last.termination == "replay_over"


def test_replay_finds_the_row_of_any_moment_in_a_long_log(tmp_path: Path) -> None:
    # found by bisection (an hour's log is 36,000 rows): the last row at or before the moment
    times = np.cumsum(np.random.default_rng(0).uniform(0.05, 0.15, 3000))
    rows = "".join(f"{float(t)!r},{k},0,1\n" for k, t in enumerate(times))
    log = tmp_path / "log.csv"
    log.write_text("time_s,obs_distance_m,obs_offset_px,detected\n" + rows)
    clock = Clock()
    replay = Replay(log, clock=clock)
    replay.start()
    start = clock.t
    for k in (0, 1, 1234, 2998, 2999):
        for dt, row in ((0.0, k), (-1e-6, k - 1), (1e-6, k)):
            clock.t = start + (times[k] - times[0]) + dt
            frame = replay.read()
            assert frame.distance_m == max(row, 0)
            assert frame.done == (row == 2999)


@pytest.mark.parametrize(
    ("text", "error"),
    [
        ("", "empty file"),
        ("time_s,obs_distance_m,obs_offset_px\n\n", "no data rows"),
        ("time_s,obs_distance_m\n0,1\n", "missing column(s) obs_offset_px"),
        (
            "time_s,obs_distance_m,obs_offset_px\n0,1,x\n",
            "line 2, column obs_offset_px: 'x' is not a number",
        ),
        ("time_s,obs_distance_m,obs_offset_px\n0,1,inf\n", "line 2, column obs_offset_px: 'inf'"),
        (
            "time_s,obs_distance_m,obs_offset_px\n0,1,0\n0,1,0\n",
            "line 3, column time_s: 0 s is not after",
        ),
        # cut off mid-row: refused as `follow-eval metrics` refuses it, not replayed short
        ("time_s,obs_distance_m,obs_offset_px\n0,1,0\n0.1,1", "line 3: expected 3 fields"),
        ("time_s,obs_distance_m,obs_offset_px\n0,1,0,7\n", "line 2: expected 3 fields"),
    ],
)
def test_a_bad_replay_names_the_file_and_the_line(tmp_path: Path, text: str, error: str) -> None:
    log = tmp_path / "bad.csv"
    log.write_text(text)
    with pytest.raises(PerceptionError, match=r"bad\.csv") as info:
        Replay(log)
    assert error in str(info.value)


@pytest.mark.parametrize(
    "rows",
    [
        "0,1,0,0\n0.1,1,x,0\n",
        "0,1,0,0\n0,1,0,0\n",
        "0,1,0,0\n0.1,,0,0\n",
        "0,1,0,0\n0.1,1,nan,0\n",
        "0,1,0,0\n0.1,1\n",
    ],
)
def test_a_replay_refuses_what_the_evaluation_refuses_in_the_same_words(
    tmp_path: Path, rows: str
) -> None:
    """One reader for both: ``follow-eval metrics`` and the replay source name the same
    problem with the same message."""
    log = tmp_path / "bad.csv"
    log.write_text("time_s,obs_distance_m,obs_offset_px,accel_mps2\n" + rows)
    with pytest.raises(StepLogError) as scored:
        read_step_log(log)
    with pytest.raises(PerceptionError) as replayed:
        Replay(log)
    assert str(replayed.value) == str(scored.value)


def test_open_source_parses_the_perception_argument(tmp_path: Path) -> None:
    sim = open_source("sim", "socket://127.0.0.1:5760")
    assert isinstance(sim, SimCamera)
    assert sim.address == ("127.0.0.1", 5761)
    other = open_source("sim:10.0.0.2:7000", "/dev/ttyUSB0")
    assert isinstance(other, SimCamera)
    assert other.address == ("10.0.0.2", 7000)
    assert open_source("sim:[::1]:5761", "/dev/ttyUSB0").address == ("::1", 5761)
    assert perception_address("socket://robot.local:80") == ("robot.local", 81)
    for bad, error in (
        ("sim", "needs --port socket://"),
        ("sim:nohost", "sim:HOST:PORT"),
        ("sim:::1:5761", r"an IPv6 host in brackets: sim:\[::1\]:5761"),
        ("sim:[::1]", "expected sim or sim:HOST:PORT"),
        ("sim:host:0", "port '0' is out of range: must be in 1-65535"),
        ("sim:host:65536", "port '65536' is out of range: must be in 1-65535"),
        ("sim:host:x1", "port 'x1' is not a number"),
        ("replay", "needs a step log"),
        ("realsense", "needs a detector model file"),
        ("lidar", "out of range"),
    ):
        with pytest.raises(ValueError, match=error):
            open_source(bad, "/dev/ttyUSB0")


def _camera_answering(reply: bytes) -> tuple[socket.socket, threading.Thread]:
    """A camera server that answers every request line with ``reply`` (one client)."""
    server = socket.create_server(("127.0.0.1", 0))

    def serve() -> None:
        conn, _ = server.accept()
        with conn, conn.makefile("rwb") as f:
            info = b'{"ahead": null, "seed": 0}\n'
            for k, _line in enumerate(iter(f.readline, b"")):
                f.write(info if k == 0 else reply)  # the info first, then the reply tested
                f.flush()

    thread = threading.Thread(target=serve, daemon=True)
    thread.start()
    return server, thread


@pytest.mark.parametrize(
    ("reply", "error"),
    [
        (b"not json\n", "sent a malformed reply to {'op': 'reset'}: 'not json' (a JSON object"),
        (b"[1]\n", "sent a malformed reply to {'op': 'reset'}: '[1]'"),
        (b'{"ok": 1}\n', "the emulator camera's frame has no 'distance_m'"),
        (
            b'{"distance_m": "far", "offset_px": 0, "detected": 1, "done": 0, "termination": ""}\n',
            "the emulator camera's frame is malformed: could not convert string to float",
        ),
    ],
)
def test_a_malformed_camera_reply_is_a_perception_error(reply: bytes, error: str) -> None:
    server, thread = _camera_answering(reply)
    camera = SimCamera(*server.getsockname()[:2], timeout_s=2.0)
    try:
        with pytest.raises(PerceptionError) as raised:
            _start_and_read(camera)  # the reset's reply, or the frame's, is the bad one
        assert error in str(raised.value)
    finally:
        camera.close()
        server.close()
        thread.join(timeout=2.0)


def _start_and_read(camera: SimCamera) -> None:
    camera.start()
    camera.read()


def test_an_absent_emulator_is_named() -> None:
    camera = SimCamera("127.0.0.1", 1, timeout_s=0.5)
    with pytest.raises(PerceptionError, match=r"no emulator camera at 127\.0\.0\.1:1"):
        camera.start()
    with pytest.raises(PerceptionError, match="not started"):
        camera.read()


# ---- the RealSense camera node, with a fake camera and a fake detector ------------------------


class FakeCamera:
    """A 640 x 480 colour image and a depth image whose value we set per frame."""

    def __init__(self) -> None:
        self.depth = 2.0

    def __call__(self) -> tuple[np.ndarray, np.ndarray]:
        depth = np.full((480, 640), 5.0)
        depth[200:300, 300:400] = self.depth  # the person
        return np.zeros((480, 640, 3), np.uint8), depth


def _node(boxes: list) -> tuple[RealSensePerception, FakeCamera, list]:  # type: ignore[type-arg]
    camera = FakeCamera()
    node = RealSensePerception(grab=camera, detect=lambda colour: boxes, filter_history=3)
    node.start()
    return node, camera, boxes


def test_the_first_person_box_is_measured_at_its_centre_pixel() -> None:
    chair = (0.0, 0.0, 100.0, 100.0, 56)  # not a person: skipped
    person = (301.0, 201.0, 399.0, 299.0, PERSON_CLASS)  # centre (350, 250)
    other = (10.0, 10.0, 50.0, 400.0, PERSON_CLASS)  # a second person, listed later
    node, _, _ = _node([chair, person, other])
    frame = node.read()
    assert frame.detected
    assert frame.distance_m == 2.0
    assert frame.offset_px == 350 - 320


def test_the_distance_filter_is_the_simulators() -> None:
    node, camera, boxes = _node([(301.0, 201.0, 399.0, 299.0, PERSON_CLASS)])
    readings = []
    for depth in (2.0, 2.3, 2.6, 1.5, 0.0, 1.8):
        camera.depth = depth
        readings.append(node.read().distance_m)
    # receding readings are averaged over the history (3), an approach resets it, an invalid
    # depth (0) keeps the last value (reference §1.4 step 4)
    assert readings == pytest.approx([2.0, 2.15, 2.3, 1.5, 1.5, 1.65])
    boxes.clear()
    held = node.read()
    assert not held.detected
    assert (held.distance_m, held.offset_px) == (1.65, 30.0)  # nothing detected: held


def test_the_realsense_node_never_downloads_a_model(tmp_path: Path) -> None:
    with pytest.raises(PerceptionError, match="is not a file"):
        RealSensePerception(tmp_path / "yolov8n.pt")
    with pytest.raises(PerceptionError, match="call start"):
        RealSensePerception(grab=FakeCamera(), detect=lambda c: []).read()


def test_an_unplugged_camera_or_a_failing_detector_is_a_perception_error() -> None:
    # pyrealsense2's wait_for_frames raises RuntimeError when no frame comes (the camera was
    # unplugged); the runner ends a session on a PerceptionError as a perception failure
    def unplugged() -> tuple[np.ndarray, np.ndarray]:
        raise RuntimeError("Frame didn't arrive within 1000")

    node = RealSensePerception(grab=unplugged, detect=lambda colour: [])
    node.start()
    with pytest.raises(PerceptionError) as caught:
        node.read()
    assert str(caught.value) == (
        "realsense: no frame from the camera (Frame didn't arrive within 1000); is it still "
        "plugged in?"
    )

    def broken(colour: np.ndarray) -> list[tuple[float, float, float, float, int]]:
        raise RuntimeError("CUDA error: out of memory")

    node = RealSensePerception(grab=FakeCamera(), detect=broken)
    node.start()
    with pytest.raises(PerceptionError, match=r"^realsense: the detector failed \(CUDA error"):
        node.read()


# ---- the reading ahead ---------------------------------------------------------------------


def test_a_replay_carries_the_reading_ahead_when_its_log_has_it(tmp_path: Path) -> None:
    log = tmp_path / "log.csv"
    log.write_text("time_s,obs_distance_m,obs_offset_px,obs_ahead_m\n0,1.0,0,2.5\n0.1,1.1,5,0.8\n")
    replay = Replay(log, clock=Clock())
    replay.start()
    frame = replay.read()
    assert frame.ahead_m == 2.5
    assert frame.observation() == [1.0, 0.0, 2.5]
    assert replay.ahead == "unknown"  # the log holds the reading, not its settings
    plain = tmp_path / "plain.csv"
    plain.write_text("time_s,obs_distance_m,obs_offset_px\n0,1.0,0\n")
    without = Replay(plain, clock=Clock())
    without.start()
    assert without.read().ahead_m is None
    assert without.ahead is None
    bad = tmp_path / "bad.csv"
    bad.write_text("time_s,obs_distance_m,obs_offset_px,obs_ahead_m\n0,1.0,0,\n")
    missing = r"bad\.csv: line 2, column obs_ahead_m: value is missing"
    with pytest.raises(PerceptionError, match=missing):
        Replay(bad)


def test_the_realsense_node_reads_ahead_as_the_simulator_does() -> None:
    """Five columns of the middle row over +-14 deg, the nearest valid depth; 0 (invalid) and
    depths beyond the range skipped; the far limit when none reads."""
    camera = FakeCamera()
    node = RealSensePerception(
        grab=camera, detect=lambda colour: [], ahead={"ahead_rays": 5}, fx_px=400.0
    )
    node.start()
    assert node.ahead == {"ahead_rays": 5, "ahead_half_angle_deg": 14.0, "ahead_target": "include"}
    # tan(14 deg) * 400 = 99.7 px: columns 220, 270, 320, 370, 420 of row 240
    depth = np.full((480, 640), 12.0)  # beyond the 10 m range: not valid
    assert node.reading_ahead(depth) == 10.0
    depth[240, 420] = 3.0
    depth[240, 421] = 0.5  # not a column: not seen
    assert node.reading_ahead(depth) == 3.0
    depth[240, 270] = 0.0  # invalid
    depth[240, 220] = np.nan
    assert node.reading_ahead(depth) == 3.0
    depth[240, 320] = 1.25
    assert node.reading_ahead(depth) == 1.25
    frame = node.read()  # FakeCamera's person spans rows 200-300 at 2 m, columns 300-400
    assert not frame.detected
    assert frame.ahead_m == 2.0
    assert frame.observation() == [0.0, 0.0, 2.0]
    off = RealSensePerception(grab=camera, detect=lambda colour: [])
    off.start()
    assert off.ahead is None
    assert off.read().ahead_m is None


@pytest.mark.parametrize(
    ("ahead", "error"),
    [
        ({"ahead_rays": 99}, r"PerceptionConfig\.ahead_rays=99 is out of range"),
        ({"ahead_rays": 5, "ahead_half_angle_deg": 40.0}, r"ahead_half_angle_deg=40\.0 is out"),
        ({"ahead_rays": 5, "rows": 2}, "unknown setting"),
    ],
)
def test_bad_reading_ahead_settings_are_refused(ahead: dict, error: str) -> None:
    with pytest.raises(ValueError, match=error):
        RealSensePerception(grab=FakeCamera(), detect=lambda colour: [], ahead=ahead)


def test_the_realsense_node_can_leave_the_person_out_of_the_reading() -> None:
    camera = FakeCamera()  # the person: 2 m over columns 300-400; the rest of the row 5 m
    person = (301.0, 201.0, 399.0, 299.0, PERSON_CLASS)
    settings = {"ahead_rays": 5, "ahead_target": "exclude"}
    node = RealSensePerception(grab=camera, detect=lambda c: [person], ahead=settings, fx_px=400.0)
    node.start()
    assert node.read().ahead_m == 5.0  # columns 320 and 370 are the person's: skipped
    node = RealSensePerception(grab=camera, detect=lambda c: [], ahead=settings, fx_px=400.0)
    node.start()
    assert node.read().ahead_m == 2.0  # nobody detected: nothing to leave out

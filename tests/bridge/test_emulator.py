"""bridge/emulator.py: the emulated robot over real sockets, as a runner or a user meets it."""

from __future__ import annotations

import json
import socket
import time
from collections.abc import Iterator

import pytest

from bridge import CommandKind, Feedback, Hello, PeerRole, SerialLink, WheelCommand
from bridge.emulator import Emulator


@pytest.fixture
def emulator(request: pytest.FixtureRequest) -> Iterator[Emulator]:
    framing, firmware = getattr(request, "param", ("reference", "reference"))
    emu = Emulator("socket://127.0.0.1:0", framing=framing, firmware=firmware).start()
    yield emu
    emu.stop()


class Camera:
    """A JSON-lines client of the emulator's camera socket."""

    def __init__(self, emu: Emulator) -> None:
        self.sock = socket.create_connection(emu.camera_address, timeout=2.0)
        self.file = self.sock.makefile("rwb")

    def raw(self, line: bytes) -> dict:
        self.file.write(line + b"\n")
        self.file.flush()
        return json.loads(self.file.readline())

    def ask(self, **request: object) -> dict:
        return self.raw(json.dumps(request).encode())

    def close(self) -> None:
        self.file.close()
        self.sock.close()


def _feedback(link: SerialLink, seconds: float) -> list[Feedback]:
    out: list[Feedback] = []
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        out += [m for m in link.receive(0.02) if isinstance(m, Feedback)]
    return out


def test_reference_firmware_speaks_only_when_spoken_to(emulator: Emulator) -> None:
    with SerialLink(emulator.url, "reference") as link:
        assert _feedback(link, 0.15) == []
        link.send(WheelCommand(40, 40, CommandKind.DUTY_PERCENT))
        answer = _feedback(link, 0.15)
        assert len(answer) == 1
        assert answer[0].right_count is None  # the reference frame carries two speeds only


@pytest.mark.parametrize("emulator", [("robust", "fixed")], indirect=True)
def test_fixed_firmware_streams_feedback_and_says_hello(emulator: Emulator) -> None:
    with SerialLink(emulator.url, "robust") as link:
        hello = link.handshake(Hello(PeerRole.PC), timeout_s=1.0)
        assert hello.role == PeerRole.MCU
        stream: list[Feedback] = []
        for _ in range(10):  # a command every 30 ms keeps the 100 ms watchdog quiet
            link.send(WheelCommand(400, 400, CommandKind.SPEED_MM_S))
            stream += _feedback(link, 0.03)
        assert len(stream) >= 15  # every 10 ms (allowing for a loaded machine)
        assert stream[-1].right_mm_s > 0  # the wheel PID is driving the wheel
        assert stream[-1].mcu_time_ms is not None


def test_garbage_on_the_line_does_not_stop_the_mcu(emulator: Emulator) -> None:
    with socket.create_connection(emulator.camera_address):
        pass  # a camera client that leaves at once
    frame = bytes.fromhex("a5a5001e001e")  # right 30 %, left 30 %
    with socket.create_connection(("127.0.0.1", int(emulator.url.rsplit(":", 1)[1]))) as raw:
        raw.sendall(b"\x00\xff\xa5garbage\xa5\x01" + frame)  # 12 bytes: two blocks, no header
        time.sleep(0.2)
    # The reference firmware reads 6-byte blocks and does not resynchronise (as on the robot).
    assert emulator.stats.misaligned_blocks == 2
    assert emulator.mcu.stats.commands == 1
    assert emulator.mcu.duty == [30.0, 30.0]
    with SerialLink(emulator.url, "reference") as link:  # a new connection starts clean
        link.send(WheelCommand(30, 30, CommandKind.DUTY_PERCENT))
        time.sleep(0.05)
        link.send(WheelCommand(30, 30, CommandKind.DUTY_PERCENT))
        assert _feedback(link, 0.2)
    assert emulator.stats.connections == 2


def test_the_camera_follows_the_world_and_refuses_bad_requests(emulator: Emulator) -> None:
    camera = Camera(emulator)
    first = camera.ask(op="reset", seed=3)
    assert first["step"] == 0
    assert first["distance_m"] > 0
    assert camera.ask(op="frame")["step"] == 0  # the world waits for the robot
    assert "error" in camera.raw(b"{not json")
    assert "out of range" in camera.ask(op="fly")["error"]
    assert "integer" in camera.ask(op="reset", seed="x")["error"]
    assert "seconds" in camera.ask(op="cut", seconds=-1)["error"]
    assert "JSON object" in camera.raw(b"[1, 2]")["error"]
    with SerialLink(emulator.url, "reference") as link:
        link.send(WheelCommand(0, 0, CommandKind.DUTY_PERCENT))  # the robot is on: time runs
        time.sleep(0.35)
        frame = camera.ask(op="frame")
        assert 2 <= frame["step"] <= 5
        assert frame["person_x_m"] > first["person_x_m"]  # the person walks on
        info = camera.ask(op="info")
    assert info["firmware"] == "reference"
    assert info["seed"] == 3
    assert len(info["walls"]) >= 4
    assert emulator.stats.perception_errors == 5
    camera.close()


def test_the_camera_answers_hostile_requests_once_each_and_keeps_its_world(
    emulator: Emulator,
) -> None:
    camera = Camera(emulator)
    assert camera.ask(op="reset", seed=3)["step"] == 0
    # a seed the env refuses: an error, and the world keeps its seed for the next reset
    assert "seed=-1 is out of range" in camera.ask(op="reset", seed=-1)["error"]
    assert "out of range" in camera.ask(op="reset", seed=2**256)["error"]
    assert camera.ask(op="info")["seed"] == 3
    assert camera.ask(op="reset")["step"] == 0
    assert "error" in camera.raw(b"[" * 3000)  # nested past Python's recursion limit
    # Overlong lines, in one write or spread over several reads: exactly one reply each, so
    # the next request's reply is its own.
    for size in (6_000, 9_000, 20_000):
        padded = json.dumps({"op": "info", "pad": "a" * size}).encode()
        assert "longer than 4096 bytes" in camera.raw(padded)["error"]
        assert camera.ask(op="info")["seed"] == 3
    camera.sock.sendall(b'{"op": "info", "pad": "' + b"a" * 5000)  # no newline yet
    time.sleep(0.05)
    camera.sock.sendall(b'"}\n{"op": "info"}\n')
    assert "longer than 4096 bytes" in json.loads(camera.file.readline())["error"]
    assert json.loads(camera.file.readline())["seed"] == 3
    assert emulator.stats.perception_errors == 7
    camera.close()


@pytest.mark.parametrize("emulator", [("robust", "fixed")], indirect=True)
def test_a_cut_silences_the_mcu_for_its_duration(emulator: Emulator) -> None:
    camera = Camera(emulator)
    with SerialLink(emulator.url, "robust") as link:
        link.send(WheelCommand(0, 0, CommandKind.SPEED_MM_S))
        assert _feedback(link, 0.1)
        assert camera.ask(op="cut", seconds=0.3) == {"cut_s": 0.3}
        link.receive(0.0)  # drop what was in flight
        time.sleep(0.02)
        link.receive(0.0)
        assert _feedback(link, 0.2) == []
        time.sleep(0.15)
        assert _feedback(link, 0.1)
    camera.close()


def test_the_emulator_refuses_bad_settings() -> None:
    with pytest.raises(ValueError, match="framing='v1' is out of range"):
        Emulator("socket://127.0.0.1:0", framing="v1")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="is not a socket://HOST:PORT address"):
        Emulator("/dev/ttyUSB0")


def test_a_world_configured_with_the_reading_ahead_publishes_it() -> None:
    """The world's frames carry ahead_m and its info the settings; the sim camera hands both
    to the runner, which refuses an agent trained with other settings or a world without."""
    from bridge.fit import check_ahead
    from bridge.perception import PerceptionError, SimCamera
    from follow_env.tasks.person_follow.config import THESIS

    class Reader:  # what the runner asks of an agent that reads ahead
        name = "agent"

        def __init__(self, ahead: dict) -> None:
            self.reads_ahead = ahead

    config = THESIS.replace(perception={"ahead_rays": 3, "ahead_half_angle_deg": 10.0})
    emu = Emulator("socket://127.0.0.1:0", config=config).start()
    plain = Emulator("socket://127.0.0.1:0").start()
    try:
        camera = SimCamera(*emu.camera_address, seed=2)
        camera.start()
        frame = camera.read()
        assert frame.ahead_m is not None
        assert 0.1 <= frame.ahead_m <= 10.0
        assert len(frame.observation()) == 3
        settings = {"ahead_rays": 3, "ahead_half_angle_deg": 10.0, "ahead_target": "include"}
        assert camera.ahead == settings
        check_ahead(Reader(settings), camera)
        with pytest.raises(PerceptionError, match="publishes it with"):
            check_ahead(Reader({**settings, "ahead_target": "exclude"}), camera)
        camera.close()
        other = SimCamera(*plain.camera_address)
        other.start()
        assert other.read().ahead_m is None
        assert other.ahead is None
        with pytest.raises(PerceptionError, match=r"does not publish it: start the emulator"):
            check_ahead(Reader({"ahead_rays": 5}), other)
        other.close()
    finally:
        emu.stop()
        plain.stop()


def test_an_ipv6_emulator_gives_an_address_a_link_and_the_camera_open() -> None:
    from bridge.perception import perception_address

    try:
        emu = Emulator("socket://[::1]:0").start()
    except OSError as exc:  # a host without IPv6 loopback
        pytest.skip(f"no IPv6 loopback here: {exc}")
    try:
        port = emu._serial.getsockname()[1]
        assert emu.url == f"socket://[::1]:{port}"  # brackets: pyserial and --port read it
        assert perception_address(emu.url) == emu.camera_address == ("::1", port + 1)
        with SerialLink(emu.url, "reference") as link:
            assert _feedback(link, 0.15) == []  # (and the emulator has taken the connection)
            link.send(WheelCommand(40, 40, CommandKind.DUTY_PERCENT))
            assert len(_feedback(link, 0.15)) == 1
        camera = Camera(emu)  # the camera answers on the address given
        assert camera.ask(op="frame")["step"] >= 0
        camera.close()
    finally:
        emu.stop()

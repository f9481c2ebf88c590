"""bridge/link.py: SerialLink over real pyserial transports (loop://, socket://)."""

from __future__ import annotations

import contextlib
import os
import pty
import socket
import socketserver
import threading
import time
import tty
from collections.abc import Iterator

import pytest

from bridge import (
    CommandKind,
    Feedback,
    Hello,
    IncompatibleVersionError,
    LinkError,
    LinkOpenError,
    PeerRole,
    SerialLink,
    WheelCommand,
    make_codec,
)
from bridge.protocol import PROTOCOL_VERSION, encode_frame, pack_message

FIRMWARE_KIND = {"reference": CommandKind.DUTY_PERCENT, "robust": CommandKind.SPEED_MM_S}


def codec_options(framing: str) -> dict[str, object]:
    """The reference wire does not say what its commands mean: tell the codec."""
    return {"command_kind": FIRMWARE_KIND[framing]} if framing == "reference" else {}


def receive_n(link: SerialLink, n: int, timeout_s: float = 2.0) -> list:
    """Read until ``n`` messages arrived or ``timeout_s`` passed."""
    got: list = []
    deadline = time.monotonic() + timeout_s
    while len(got) < n and time.monotonic() < deadline:
        got += link.receive(timeout_s=0.05)
    return got


# ---- loop:// ------------------------------------------------------------------------------


@pytest.mark.parametrize("framing", ["reference", "robust"])
def test_loop_round_trip(framing: str) -> None:
    kind = FIRMWARE_KIND[framing]
    with SerialLink("loop://", framing, **codec_options(framing)) as link:
        commands = [WheelCommand(k, -k, kind) for k in range(-30, 30, 7)]
        for command in commands:
            link.send(command)
        got = receive_n(link, len(commands))
        if framing == "reference":
            # One wire format both ways: the PC end reads what it hears as feedback.
            assert got == [Feedback(c.right, c.left) for c in commands]
        else:
            assert got == commands
        assert link.stats.frames_ok == link.stats.frames_sent == len(commands)
        assert link.stats.bytes_received == link.stats.bytes_sent


def test_receive_without_data_returns_empty_after_the_timeout() -> None:
    with SerialLink("loop://", "robust") as link:
        t0 = time.monotonic()
        assert link.receive(timeout_s=0.05) == []
        waited = time.monotonic() - t0
    assert 0.04 <= waited < 0.5


def test_receive_with_zero_timeout_does_not_wait() -> None:
    with SerialLink("loop://", "reference") as link:
        t0 = time.monotonic()
        assert link.receive() == []
        assert time.monotonic() - t0 < 0.02


def test_reference_frame_ending_in_a5_is_delivered_after_the_line_goes_idle() -> None:
    # left = -91 = 0xFFA5: the decoder cannot tell the frame is over until the next byte,
    # or until the line has been quiet for idle_flush_s.
    with SerialLink("loop://", "reference", idle_flush_s=0.02) as link:
        link.send(WheelCommand(10, -91, CommandKind.DUTY_PERCENT))
        assert link.receive() == []
        t0 = time.monotonic()
        assert link.receive(timeout_s=0.5) == [Feedback(10, -91)]
        assert time.monotonic() - t0 < 0.2


def test_a_peer_of_another_version_raises_after_the_messages_before_it() -> None:
    with SerialLink("loop://", "robust") as link:
        link.send(Feedback(1, 2, 3, 4, 5, 0))
        msg_type, payload = pack_message(Feedback(6, 7, 8, 9, 10, 0))
        link._port.write(encode_frame(msg_type, 1, payload, version=PROTOCOL_VERSION + 1))
        link.send(Feedback(11, 12, 13, 14, 15, 0))
        time.sleep(0.05)
        assert link.receive(timeout_s=0.2) == [Feedback(1, 2, 3, 4, 5, 0)]
        with pytest.raises(IncompatibleVersionError, match=r"protocol version 2.*version 1"):
            link.receive()
        assert link.receive() == [Feedback(11, 12, 13, 14, 15, 0)]  # nothing after it lost
        assert link.stats.version_mismatches == 1


def test_send_refuses_what_the_framing_cannot_carry_and_sends_nothing() -> None:
    with SerialLink("loop://", "reference") as link:
        with pytest.raises(ValueError, match=r"no hello"):
            link.send(Hello(PeerRole.PC))
        assert link.stats.bytes_sent == 0


# ---- socket:// against a local TCP server ---------------------------------------------------


class _McuHandler(socketserver.BaseRequestHandler):
    """A minimal MCU: answers every command with feedback of twice its values, and a hello
    with its own hello."""

    def handle(self) -> None:
        framing = self.server.framing  # type: ignore[attr-defined]
        codec = make_codec(framing, role="mcu", **codec_options(framing))
        self.request.settimeout(5.0)
        count = 0
        while True:
            try:
                data = self.request.recv(4096)
            except OSError:
                return
            if not data:
                return
            for message in codec.feed(data):
                if isinstance(message, Hello):
                    reply = Hello(PeerRole.MCU, feedback_period_ms=10, firmware_version=(1, 2, 3))
                    self.request.sendall(codec.encode(reply))
                elif isinstance(message, WheelCommand):
                    count += 1
                    extra = (
                        {}
                        if framing == "reference"
                        else dict(
                            right_count=count, left_count=-count, mcu_time_ms=10 * count, status=0
                        )
                    )
                    feedback = Feedback(2 * message.right, 2 * message.left, **extra)
                    self.request.sendall(codec.encode(feedback))


@pytest.fixture(params=["reference", "robust"])
def mcu_server(request: pytest.FixtureRequest) -> Iterator[tuple[str, str]]:
    server = socketserver.ThreadingTCPServer(("127.0.0.1", 0), _McuHandler)
    server.daemon_threads = True
    server.framing = request.param  # type: ignore[attr-defined]
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    host, port = server.server_address[:2]
    try:
        yield f"socket://{host}:{port}", request.param
    finally:
        server.shutdown()
        server.server_close()
        thread.join(timeout=5)


def test_socket_round_trip_with_a_local_mcu(mcu_server: tuple[str, str]) -> None:
    url, framing = mcu_server
    kind = FIRMWARE_KIND[framing]
    with SerialLink(url, framing, **codec_options(framing)) as link:
        if framing == "robust":
            peer = link.handshake(Hello(PeerRole.PC, firmware_version=(0, 1, 0)), timeout_s=2.0)
            assert (peer.role, peer.firmware_version) == (PeerRole.MCU, (1, 2, 3))
        commands = [WheelCommand(10 * k, -5 * k, kind) for k in range(20)]
        got = []
        for command in commands:
            link.send(command)
            got += link.receive(timeout_s=0.01)
        got += receive_n(link, len(commands) - len(got))
    assert [(f.right_mm_s, f.left_mm_s) for f in got] == [
        (2 * c.right, 2 * c.left) for c in commands
    ]
    if framing == "robust":
        assert [f.mcu_time_ms for f in got] == [10 * (k + 1) for k in range(20)]
        assert link.stats.frames_lost == 0
    assert link.stats.frames_ok == len(commands) + (framing == "robust")


def test_a_socket_link_sends_each_frame_at_once() -> None:
    # Nagle's algorithm with the peer's delayed acknowledgement bunched the runner's 10 ms
    # commands into fours when the reference firmware answered only some of them.
    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen(1)
    host, port = server.getsockname()
    try:
        with SerialLink(f"socket://{host}:{port}", "reference") as link:
            sock = link._port._socket  # pyserial's transport; no public handle
            assert sock.getsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY) != 0
    finally:
        server.close()


def test_handshake_with_a_silent_peer_times_out_with_a_clear_error() -> None:
    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen(1)
    host, port = server.getsockname()
    try:
        with (
            SerialLink(f"socket://{host}:{port}", "robust") as link,
            pytest.raises(LinkError, match=r"no hello from the peer within 0.1 s"),
        ):
            link.handshake(Hello(PeerRole.PC), timeout_s=0.1)
    finally:
        server.close()


def test_handshake_keeps_the_messages_that_arrived_before_the_hello() -> None:
    with SerialLink("loop://", "robust") as link:
        link.send(Feedback(1, 2, 3, 4, 5, 0))
        # loop:// echoes: the hello that comes back is our own, after the feedback.
        assert link.handshake(Hello(PeerRole.PC), timeout_s=0.5).role == PeerRole.PC
        assert link.receive() == [Feedback(1, 2, 3, 4, 5, 0)]


@pytest.fixture
def pty_port() -> Iterator[tuple[int, str]]:
    """A pseudo-terminal pair in raw mode: (the peer's end, the device path a link opens)."""
    peer, device = pty.openpty()
    tty.setraw(peer)
    tty.setraw(device)
    yield peer, os.ttyname(device)
    for fd in (peer, device):
        with contextlib.suppress(OSError):
            os.close(fd)


def test_handshake_keeps_the_messages_that_came_in_the_same_read_after_the_hello(
    pty_port: tuple[int, str],
) -> None:
    # A USB-serial adapter hands over what arrived in its latency window at once: the MCU's
    # hello and its first feedback 10 ms later come in one read.
    peer, path = pty_port
    mcu = make_codec("robust", role="mcu")
    feedback = Feedback(100, 100, 1, 1, 10, 0)
    with SerialLink(path, "robust") as link:  # opening empties the port's input
        os.write(peer, mcu.encode(Hello(PeerRole.MCU, 0x0F, 10, (1, 0, 0))) + mcu.encode(feedback))
        assert link.handshake(Hello(PeerRole.PC), timeout_s=0.5).role == PeerRole.MCU
        assert link.receive(timeout_s=0.5) == [feedback]


def test_a_device_another_link_holds_is_refused(pty_port: tuple[int, str]) -> None:
    # two follow-robot runs on one port would both command the wheels
    peer, path = pty_port
    with SerialLink(path, "reference") as link:
        with pytest.raises(LinkOpenError, match=rf"'{path}': another program has it open"):
            SerialLink(path, "reference")
        link.send(WheelCommand(40, 40, CommandKind.DUTY_PERCENT))
        assert len(os.read(peer, 64)) == 6  # the first link still drives
    with SerialLink(path, "reference"):  # free again once the first is closed
        pass


def test_a_port_that_disappears_while_its_bytes_drain_is_a_link_error(
    pty_port: tuple[int, str],
) -> None:
    # pyserial's flush is termios.tcdrain, whose error is neither an OSError nor pyserial's own
    peer, path = pty_port
    with SerialLink(path, "robust") as link:
        write = link._port.write

        def write_then_unplug(data: bytes) -> int | None:
            written = write(data)
            os.close(peer)  # the adapter is pulled out while the bytes go out
            return written

        link._port.write = write_then_unplug
        with pytest.raises(LinkError, match=rf"{path}: write failed"):
            link.send(WheelCommand(0, 0, CommandKind.DUTY_CENTI_PERCENT))


@pytest.mark.parametrize("value", [float("nan"), float("inf"), -1.0])
def test_timeouts_that_are_not_finite_are_refused_naming_them(value: float) -> None:
    # a NaN timeout used to spin a read for ever, an infinite one to raise OverflowError
    with SerialLink("loop://", "robust") as link:
        with pytest.raises(ValueError, match=rf"timeout_s={value} must be a finite number >= 0 s"):
            link.receive(timeout_s=value)
        with pytest.raises(ValueError, match=rf"timeout_s={value} must be a finite number"):
            link.handshake(Hello(PeerRole.PC), timeout_s=value)
        assert link.stats.frames_sent == 0  # the hello was not sent
    for field in ("idle_flush_s", "write_timeout_s"):
        with pytest.raises(ValueError, match=rf"{field}={value} must be a finite number > 0 s"):
            SerialLink("loop://", "robust", **{field: value})


def test_peer_closing_the_connection_is_a_link_error() -> None:
    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen(1)
    host, port = server.getsockname()
    try:
        with SerialLink(f"socket://{host}:{port}", "robust") as link:
            conn, _ = server.accept()
            conn.close()
            with pytest.raises(LinkError, match=rf"socket://{host}:{port}: read failed"):
                link.receive(timeout_s=1.0)
    finally:
        server.close()


# ---- opening ------------------------------------------------------------------------------


def _closed_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.mark.parametrize(
    "url", ["nosuchscheme://x", "/dev/ttyPF-does-not-exist", f"socket://127.0.0.1:{_closed_port()}"]
)
def test_unopenable_url_gives_one_error_naming_it(url: str) -> None:
    with pytest.raises(LinkOpenError, match=rf"cannot open serial link '{url}'"):
        SerialLink(url)


def test_unknown_framing_is_refused_naming_the_choices() -> None:
    with pytest.raises(
        ValueError, match=r"framing='cobs' is unknown: choose one of reference, robust"
    ):
        SerialLink("loop://", "cobs")  # type: ignore[arg-type]


def test_option_of_the_other_framing_is_refused_naming_it() -> None:
    with pytest.raises(ValueError, match=r"'command_kind' does not apply to the robust framing"):
        SerialLink("loop://", "robust", command_kind=CommandKind.SPEED_MM_S)

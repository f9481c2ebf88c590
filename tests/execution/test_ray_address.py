"""A Ray cluster address is checked as ``ray.init`` will use it, and within a bounded time.

``ray.init`` on an address where no Ray GCS answers retries for minutes: ``auto`` read from the
address file a crashed ``ray start`` left behind, or a port where another service listens,
used to hang a command that way. Real Ray resolves the addresses here (``RAY_TMPDIR`` points
it at a folder of the test's); the listeners are plain sockets.
"""

from __future__ import annotations

import socket
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

import execution.ray_address
from execution import Backend, BackendUnavailableError
from execution.backend import _check_reachable

pytest.importorskip("ray", reason="Ray is a dev dependency: pip install -e '.[dev]'")


def closed_port() -> int:
    """A port nothing listens at (bound on every interface, never listening, released)."""
    with socket.socket() as s:
        s.bind(("0.0.0.0", 0))
        return int(s.getsockname()[1])


def require_no_ray_here(request: pytest.FixtureRequest) -> None:
    """Skip the test if a Ray runs on this machine: Ray's ``auto`` takes the one Ray running
    here over its address file, which is then not what a command connects to.

    A test that calls this is marked ``before_ray`` and runs before the suite starts its own
    Ray (tests/conftest.py). If a Ray is up in this process already and the mark is missing,
    the test fails, naming the mark; with the mark, pytest's ``--ff`` or ``--nf`` reordered it,
    and it skips, saying so.
    """
    import ray
    from ray._private import services

    if ray.is_initialized():
        if request.node.get_closest_marker("before_ray") is None:
            pytest.fail("a Ray is up in this process already: mark the test before_ray")
        pytest.skip("a Ray is up in this process already (--ff or --nf ran this test later)")
    services.find_gcs_addresses.cache_clear()
    if services.find_gcs_addresses():
        pytest.skip("a Ray runs on this machine, started outside this process: auto takes it")


def stale_address_file(ray_tmpdir: Path, address: str) -> Path:
    """The file ``ray start`` writes under ``RAY_TMPDIR`` and a crash leaves behind."""
    (ray_tmpdir / "ray").mkdir(parents=True, exist_ok=True)
    file = ray_tmpdir / "ray" / "ray_current_cluster"
    file.write_text(address)
    return file


class Listener:
    """A TCP server on every interface (Ray names this machine by its own address, not
    127.0.0.1) that accepts connections and, if ``reply`` is given, sends it and closes (an
    HTTP service such as Ray's dashboard), else says nothing and keeps them open."""

    def __init__(self, reply: bytes | None = None) -> None:
        self.server = socket.create_server(("0.0.0.0", 0))
        self.port = int(self.server.getsockname()[1])
        self.reply = reply
        self.kept: list[socket.socket] = []
        threading.Thread(target=self._serve, daemon=True).start()

    def _serve(self) -> None:
        while True:
            try:
                conn, _ = self.server.accept()
            except OSError:  # closed
                return
            if self.reply is None:
                self.kept.append(conn)
                continue
            try:
                conn.recv(1024)
                conn.sendall(self.reply)
            except OSError:
                pass
            conn.close()

    def close(self) -> None:
        self.server.close()
        for conn in self.kept:
            conn.close()


@pytest.fixture
def silent() -> Iterator[Listener]:
    listener = Listener()
    yield listener
    listener.close()


@pytest.fixture
def http() -> Iterator[Listener]:
    listener = Listener(b"HTTP/1.1 400 Bad Request\r\nContent-Length: 0\r\n\r\n")
    yield listener
    listener.close()


def test_the_before_ray_tests_are_run_first() -> None:
    # Without the conftest's ordering they would run after a test that starts the session's
    # Ray and skip (require_no_ray_here). Collected after a file that starts it, in a process
    # of their own: the marked tests come first, in their collection order.
    root = Path(__file__).resolve().parents[2]
    files = [
        "tests/eval/test_backends.py",  # starts the session's Ray
        "tests/execution/test_ray_address.py",
        "tests/eval/test_tuning_stops.py",
    ]
    argv = [sys.executable, "-m", "pytest", "--collect-only", "-q", "-p", "no:cacheprovider"]
    done = subprocess.run(
        [*argv, *files], cwd=root, capture_output=True, text=True, timeout=120, check=True
    )
    ids = [line for line in done.stdout.splitlines() if "::" in line]
    assert len(ids) > 10, done.stdout
    assert ids[:2] == [
        "tests/execution/test_ray_address.py::test_auto_naming_a_gone_cluster_is_refused_at_once",
        "tests/eval/test_tuning_stops.py::test_auto_from_a_stale_address_file_writes_no_journal",
    ]
    assert ids[2].startswith("tests/eval/test_backends.py::")


@pytest.mark.before_ray  # conftest: before the session's Ray, which auto would take
def test_auto_naming_a_gone_cluster_is_refused_at_once(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, request: pytest.FixtureRequest
) -> None:
    require_no_ray_here(request)
    monkeypatch.setenv("RAY_TMPDIR", str(tmp_path))
    monkeypatch.delenv("RAY_ADDRESS", raising=False)
    port = closed_port()
    file = stale_address_file(tmp_path, f"127.0.0.1:{port}")
    started = time.monotonic()
    with pytest.raises(BackendUnavailableError, match="cannot reach the Ray cluster at auto") as e:
        _check_reachable("auto")
    assert f":{port}, from {file})" in str(e.value)
    # RAY_ADDRESS=auto with no --address is the same
    monkeypatch.setenv("RAY_ADDRESS", "auto")
    with pytest.raises(BackendUnavailableError, match=f":{port}, from {file}"):
        Backend("ray").check_reachable()
    assert time.monotonic() - started < 10


def test_ray_address_naming_a_gone_cluster_is_refused_at_once(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    port = closed_port()  # RAY_ADDRESS comes before any running Ray, for auto as for no address
    monkeypatch.setenv("RAY_ADDRESS", f"localhost:{port}")
    for address in (None, "auto"):
        with pytest.raises(BackendUnavailableError, match=f":{port}.*Connection refused"):
            Backend("ray", address=address).check_reachable()


def test_a_port_where_no_ray_gcs_answers_is_refused_within_the_deadline(
    silent: Listener, http: Listener, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(execution.ray_address, "GCS_ANSWER_S", 2.0)
    started = time.monotonic()
    with pytest.raises(BackendUnavailableError, match="no Ray GCS answers") as e:
        _check_reachable(f"127.0.0.1:{silent.port}")
    assert f"127.0.0.1:{silent.port} (" in str(e.value)  # and the address Ray would use
    assert "nothing answered within 2 s" in str(e.value)
    assert time.monotonic() - started < 2.0 + 5
    started = time.monotonic()
    with pytest.raises(BackendUnavailableError, match=r"no Ray GCS answers .*HTTP"):
        Backend("ray", address=f"localhost:{http.port}").check_reachable()
    assert time.monotonic() - started < 5  # an HTTP reply is refused at once


def test_the_deadline_is_a_bounded_constant() -> None:
    assert 5 <= execution.ray_address.GCS_ANSWER_S <= 30

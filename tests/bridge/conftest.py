"""Shared fixtures of the bridge tests: an emulator in its own process, as users run it."""

from __future__ import annotations

import contextlib
import json
import os
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


def free_port_pair() -> int:
    """A port P with P and P + 1 free on loopback (the emulator's serial line and camera)."""
    for _ in range(100):
        with socket.socket() as a:
            a.bind(("127.0.0.1", 0))
            port = a.getsockname()[1]
            with socket.socket() as b:
                try:
                    b.bind(("127.0.0.1", port + 1))
                except OSError:
                    continue
        return port
    raise RuntimeError("no two free consecutive ports on loopback")


class EmulatorProcess:
    """``python -m bridge emulate`` in a subprocess; its camera socket for inspection."""

    def __init__(self, *args: str) -> None:
        self.port = free_port_pair()
        self.url = f"socket://127.0.0.1:{self.port}"
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "bridge", "emulate", "--listen", self.url, *args],
            cwd=ROOT,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
            env={**os.environ, "PYTHONUNBUFFERED": "1"},
        )
        self.output: list[str] = []
        # The first run after an edit compiles the kernels (a minute or two on CI).
        deadline = time.monotonic() + 400
        while time.monotonic() < deadline:
            line = self.proc.stdout.readline() if self.proc.stdout else ""
            if not line and self.proc.poll() is not None:
                raise RuntimeError("the emulator exited: " + "".join(self.output))
            self.output.append(line)
            if "emulating" in line:
                return
        raise RuntimeError("the emulator did not start: " + "".join(self.output))

    def ask(self, **request: object) -> dict:
        """One request to the camera socket."""
        with socket.create_connection(("127.0.0.1", self.port + 1), timeout=2.0) as sock:
            f = sock.makefile("rwb")
            f.write(json.dumps(request).encode() + b"\n")
            f.flush()
            return json.loads(f.readline())

    def stop(self) -> str:
        """SIGTERM (a clean stop), then the rest of its output."""
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
        try:
            rest, _ = self.proc.communicate(timeout=10)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            rest, _ = self.proc.communicate()
        return "".join(self.output) + (rest or "")


@pytest.fixture
def emulator_process() -> Iterator[Callable[..., EmulatorProcess]]:
    started: list[EmulatorProcess] = []

    def start(*args: str) -> EmulatorProcess:
        emu = EmulatorProcess(*args)
        started.append(emu)
        return emu

    yield start
    for emu in started:
        with contextlib.suppress(Exception):
            emu.stop()

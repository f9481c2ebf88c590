"""The monitor page in a real browser: headless Chromium (the system's) through playwright.

``make test`` installs Chromium from the distribution's packages where it is missing; this
test is skipped (saying why) only where no Chromium can be found, and never downloads one.
"""

from __future__ import annotations

import http.server
import shutil
import socket
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from bridge.monitor.app import Server, create_app
from bridge.monitor.hub import MonitorHub, monitor_modes
from bridge.monitor.sim import SimDriver
from policies import make_policy

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
pytestmark = pytest.mark.skipif(
    CHROMIUM is None, reason="no system Chromium (make test installs it with apt-get as root)"
)
ARGS = [
    "--no-sandbox",
    "--disable-gpu",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--no-first-run",
]


@pytest.fixture
def monitor() -> Iterator[tuple[MonitorHub, Server]]:
    # the agent that reads ahead is offered, but this simulated camera publishes no reading
    hub = MonitorHub("stop", modes=monitor_modes(["ppo_ahead"]))
    driver = SimDriver(hub, make_policy, scenario="curve", speed=2.0).start()
    server = Server(create_app(hub, token="t0k"), "127.0.0.1", 0).start()
    yield hub, server
    server.stop()
    driver.stop()


@pytest.mark.slow
def test_the_page_streams_draws_and_changes_the_mode(
    monitor: tuple[MonitorHub, Server], tmp_path: Path
) -> None:
    from playwright.sync_api import sync_playwright

    hub, server = monitor
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, headless=True, args=ARGS)
        page = browser.new_page()
        page.goto(server.url + "?token=t0k")
        page.wait_for_function("window.monitorStats && window.monitorStats.frames >= 3")
        # one button per mode the robot offers, in its order, from the server's scene message
        buttons = page.eval_on_selector_all(
            "#modes button", "bs => bs.map(b => [b.dataset.mode, b.textContent])"
        )
        assert buttons == hub.buttons()
        assert ["ppo_ahead", "PPO (ahead)"] in buttons
        before = page.evaluate("document.getElementById('view').toDataURL()")
        page.click("button[data-mode='gsmpn']")
        page.wait_for_function("window.monitorStats.mode === 'gsmpn'", timeout=5000)
        assert hub.mode == "gsmpn"
        frames = page.evaluate("window.monitorStats.frames")
        page.wait_for_function(f"window.monitorStats.frames >= {frames + 5}")
        after = page.evaluate("document.getElementById('view').toDataURL()")
        assert after != before  # the canvas was redrawn as the robot moved
        assert page.text_content("#mode") == "gsmpn"
        assert "active" in (page.get_attribute("button[data-mode='gsmpn']", "class") or "")
        latency = page.evaluate("window.monitorStats.latencyMs.slice(-5)")
        assert all(0 <= ms < 1000 for ms in latency), latency
        # a mode the simulation cannot feed: refused, the robot drives on, the page says why
        page.click("button[data-mode='ppo_ahead']")
        page.wait_for_function("window.monitorStats.notice !== ''", timeout=5000)
        assert page.text_content("#msg").startswith("refused: ppo_ahead reads the reading ahead")
        page.wait_for_function("window.monitorStats.mode === 'gsmpn'", timeout=5000)
        assert hub.mode == "gsmpn"
        assert "active" in (page.get_attribute("button[data-mode='gsmpn']", "class") or "")
        shot = tmp_path / "monitor.png"
        page.screenshot(path=str(shot))
        assert shot.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
        assert shot.stat().st_size > 10_000
        page.click("button[data-mode='stop']")
        page.wait_for_function("window.monitorStats.mode === 'stop'", timeout=5000)
        errors = page.evaluate("window.monitorStats.errors")
        assert errors == 0
        browser.close()


@pytest.mark.slow
def test_the_page_without_the_token_is_refused(monitor: tuple[MonitorHub, Server]) -> None:
    from playwright.sync_api import sync_playwright

    _, server = monitor
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, headless=True, args=ARGS)
        page = browser.new_page()
        page.goto(server.url)
        time.sleep(1.5)
        assert page.evaluate("window.monitorStats.frames") == 0
        assert "disconnected" in page.text_content("#conn")
        browser.close()


class _Session:
    """A robot session without a robot: a hub, a driver publishing its mode at 10 Hz (and the
    manual command it takes), and the monitor on ``port``."""

    def __init__(self, port: int = 0, start: str = "stop") -> None:
        self.hub = MonitorHub(start, modes=monitor_modes(["ppo_ahead"]))
        self._stop = threading.Event()
        threading.Thread(target=self._drive, daemon=True).start()
        self.server = Server(create_app(self.hub), "127.0.0.1", port).start()

    def _drive(self) -> None:
        k = 0
        while not self._stop.is_set():
            command = list(self.hub.manual_command())
            self.hub.publish({"time_s": 0.1 * k, "mode": self.hub.mode, "command": command})
            k += 1
            time.sleep(0.1)

    def stop(self) -> None:
        self._stop.set()
        self.server.stop()


@pytest.mark.slow
def test_only_the_page_that_selected_manual_drives(tmp_path: Path) -> None:
    # An operator's page and a second one merely watching, its sliders at zero: the robot's
    # manual command is the operator's throughout, not the two pages' in turn.
    from playwright.sync_api import sync_playwright

    session = _Session()
    try:
        with sync_playwright() as p:
            browser = p.chromium.launch(executable_path=CHROMIUM, headless=True, args=ARGS)
            operator, watcher = browser.new_page(), browser.new_page()
            for page in (operator, watcher):
                page.goto(session.server.url)
                page.wait_for_function("window.monitorStats.frames >= 2")
            operator.click("button[data-mode='manual']")
            operator.wait_for_function("window.monitorStats.mode === 'manual'", timeout=5000)
            operator.evaluate(
                "() => { const v = document.getElementById('v'); v.value = 0.5;"
                " v.dispatchEvent(new Event('input')); }"
            )
            time.sleep(0.5)
            seen = []
            for _ in range(30):
                seen.append(session.hub.manual_command())
                time.sleep(0.05)
            assert set(seen) == {(0.5, 0.0)}
            assert watcher.evaluate("window.monitorStats.errors") == 0  # it sent none
            # the watcher moves its slider: it does not drive, and its page says how to
            watcher.evaluate(
                "() => { const v = document.getElementById('v'); v.value = -0.3;"
                " v.dispatchEvent(new Event('input')); }"
            )
            assert watcher.text_content("#msg") == "select manual on this page to drive from it"
            time.sleep(0.3)
            assert session.hub.manual_command() == (0.5, 0.0)
            # it selects manual: from then on it drives, and the operator's page stops sending
            watcher.click("button[data-mode='manual']")
            time.sleep(0.5)  # (one sent before its page heard of it may be refused)
            refused = operator.evaluate("window.monitorStats.errors")
            time.sleep(0.6)
            assert operator.evaluate("window.monitorStats.errors") == refused  # none sent since
            assert session.hub.manual_command() == (-0.3, 0.0)
            assert watcher.evaluate("window.monitorStats.errors") == 0
            browser.close()
    finally:
        session.stop()


@pytest.mark.slow
def test_a_page_left_open_across_two_sessions_shows_the_second_ones_refusal() -> None:
    # The page reconnects by itself to the next session on the same address; the refusals of
    # the new session are counted afresh, not compared with the old session's count.
    from playwright.sync_api import sync_playwright

    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, headless=True, args=ARGS)
        page = browser.new_page()
        first = _Session(port, "pn")
        try:
            page.goto(first.server.url)
            page.wait_for_function("window.monitorStats.frames >= 2")
            for k in range(2):
                first.hub.refuse("ppo_ahead", "pn", f"first session, refusal {k + 1}")
                page.wait_for_function(f"window.monitorStats.refusals === {k + 1}", timeout=5000)
            assert page.text_content("#msg") == "refused: first session, refusal 2"
        finally:
            first.stop()
        page.wait_for_function("document.getElementById('conn').className === 'bad'")
        second = _Session(port, "pn")
        try:
            page.wait_for_function(
                "document.getElementById('conn').textContent === 'connected'", timeout=10000
            )
            frames = page.evaluate("window.monitorStats.frames")
            page.wait_for_function(f"window.monitorStats.frames >= {frames + 2}")
            second.hub.refuse("ppo_ahead", "pn", "second session, refusal 1")
            page.wait_for_function(
                "document.getElementById('msg').textContent === "
                "'refused: second session, refusal 1'",
                timeout=5000,
            )
            assert page.evaluate("window.monitorStats.refusals") == 1
        finally:
            second.stop()
        browser.close()


@pytest.mark.slow
def test_a_page_of_another_local_origin_cannot_drive_the_robot() -> None:
    # Any other page the user has open (a dev server, a notebook: here one on another port of
    # this machine) could open the monitor's WebSocket: its Origin is not the monitor's.
    from playwright.sync_api import sync_playwright

    session = _Session(start="gsmpn")
    other = _other_site(
        f"""<script>
        const ws = new WebSocket("ws://127.0.0.1:{session.server.port}/ws");
        window.wsClosed = null;
        ws.onclose = (e) => {{ window.wsClosed = e.code; }};
        ws.onopen = () => {{ ws.send(JSON.stringify({{type: "mode", mode: "manual"}}));
          setInterval(() => ws.send(JSON.stringify({{type: "manual", v_mps: 2, w_radps: 8}})),
                      100); }};
        </script>"""
    )
    try:
        with sync_playwright() as p:
            browser = p.chromium.launch(executable_path=CHROMIUM, headless=True, args=ARGS)
            page = browser.new_page()
            page.goto(f"http://localhost:{other.server_address[1]}/")
            page.wait_for_function("window.wsClosed !== null", timeout=5000)
            assert page.evaluate("window.wsClosed") == 1006  # refused at the handshake
            time.sleep(0.5)
            assert session.hub.mode == "gsmpn"
            assert session.hub.manual_command() == (0.0, 0.0)
            # the monitor's own page, by either loopback name, still connects
            for host in ("127.0.0.1", "localhost"):
                own = browser.new_page()
                own.goto(f"http://{host}:{session.server.port}/")
                own.wait_for_function("window.monitorStats.frames >= 2")
            browser.close()
    finally:
        other.shutdown()
        session.stop()


def _other_site(body: str) -> http.server.HTTPServer:
    """Another site on this machine serving one page, ``body``, on a free port."""
    page = body.encode()

    class Handler(http.server.BaseHTTPRequestHandler):
        def do_GET(self) -> None:
            self.send_response(200)
            self.send_header("Content-Type", "text/html")
            self.send_header("Content-Length", str(len(page)))
            self.end_headers()
            self.wfile.write(page)

        def log_message(self, *args: object) -> None:
            pass

    server = http.server.HTTPServer(("127.0.0.1", 0), Handler)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    return server

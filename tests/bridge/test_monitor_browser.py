"""The monitor page in a real browser: headless Chromium (the system's) through playwright.

``make test`` installs Chromium from the distribution's packages where it is missing; this
test is skipped (saying why) only where no Chromium can be found, and never downloads one.
"""

from __future__ import annotations

import shutil
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

"""``make bench``, robot side: the runner's loop lateness at 10 Hz, idle and with the machine
busy, and the monitor's latency from a published state to the browser.

    python -m bench.robot [--quick]

Lateness is how long after its scheduled instant the control loop woke (p50 / p99, ms); the
baseline is the same loop on an idle machine, measured in the same run. The monitor's latency
is from :meth:`MonitorHub.publish` to the page's WebSocket handler (both clocks are this
machine's), against a plain Python WebSocket client of the same server as the baseline.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import multiprocessing as mp
import shutil
import tempfile
import threading
import time
from pathlib import Path

import numpy as np


def _burn(stop: mp.synchronize.Event) -> None:  # type: ignore[name-defined]
    x = 0
    while not stop.is_set():
        for _ in range(10_000):
            x = (x * 1103515245 + 12345) & 0xFFFFFFFF


def _runner_lateness(seconds: float) -> tuple[float, float]:
    from bridge import SerialLink
    from bridge.perception import Replay
    from bridge.runner import Runner, RunnerConfig
    from policies import make_policy

    with tempfile.TemporaryDirectory() as tmp:
        log = Path(tmp) / "obs.csv"
        rows = [f"{0.1 * k:.1f},1.2,{(k % 40) - 20}" for k in range(int(seconds * 10) + 20)]
        log.write_text("time_s,obs_distance_m,obs_offset_px\n" + "\n".join(rows) + "\n")
        with SerialLink("loop://", "reference") as link:  # echoes commands: feedback enough
            runner = Runner(
                link, make_policy("gsmpn"), Replay(log), config=RunnerConfig(duration_s=seconds)
            )
            result = runner.run()
    return result.lateness_percentile(50), result.lateness_percentile(99)


def bench_runner(quick: bool) -> list[tuple[str, float, str]]:
    """The control loop's lateness, idle and with both cores kept busy by other processes."""
    seconds = 3.0 if quick else 20.0
    idle = _runner_lateness(seconds)
    stop = mp.get_context("spawn").Event()
    burners = [mp.get_context("spawn").Process(target=_burn, args=(stop,)) for _ in range(2)]
    for p in burners:
        p.start()
    try:
        time.sleep(0.5)
        busy = _runner_lateness(seconds)
    finally:
        stop.set()
        for p in burners:
            p.join()
    return [
        ("runner lateness p50, idle (ms)", idle[0], "1.00x (base)"),
        ("runner lateness p99, idle (ms)", idle[1], "1.00x (base)"),
        ("runner lateness p50, 2 cores busy", busy[0], f"{busy[0] / idle[0]:.1f}x idle"),
        ("runner lateness p99, 2 cores busy", busy[1], f"{busy[1] / idle[1]:.1f}x idle"),
    ]


def _python_client_latency(url: str, n: int) -> list[float]:
    import websockets

    async def run() -> list[float]:
        out: list[float] = []
        async with websockets.connect(url) as ws:
            while len(out) < n:
                message = json.loads(await ws.recv())
                if message.get("type") == "state":
                    out.append(1000.0 * (time.time() - message["t_wall"]))
        return out

    return asyncio.run(run())


def bench_monitor(quick: bool) -> list[tuple[str, float, str]]:
    """State to browser, against state to a Python WebSocket client (ms)."""
    from bridge.monitor.app import Server, create_app
    from bridge.monitor.hub import MonitorHub

    chromium = shutil.which("chromium") or shutil.which("chromium-browser")
    hub = MonitorHub("gsmpn")
    stop = threading.Event()

    def publish() -> None:  # a driver at the control rate, the robot moving on a circle
        k = 0
        while not stop.wait(0.1):
            a = 0.05 * k
            hub.publish(
                {
                    "time_s": 0.1 * k,
                    "mode": hub.mode,
                    "obs": [1.1, 20 * np.sin(a)],
                    "command": [0.5, 0.2],
                    "robot": [3 * np.cos(a), 3 * np.sin(a), a + 1.57],
                    "person": [3.5 * np.cos(a + 0.3), 3.5 * np.sin(a + 0.3), a + 1.87],
                }
            )
            k += 1

    server = Server(create_app(hub), "127.0.0.1", 0).start()
    threading.Thread(target=publish, daemon=True).start()
    n = 30 if quick else 150
    try:
        base = _python_client_latency(f"ws://127.0.0.1:{server.port}/ws", n)
        rows = [
            ("monitor: state to Python client p50 (ms)", float(np.median(base)), "1.00x (base)")
        ]
        if chromium is None:
            return [*rows, ("monitor: state to browser", float("nan"), "no chromium here")]
        from playwright.sync_api import sync_playwright

        with sync_playwright() as p:
            browser = p.chromium.launch(
                executable_path=chromium, headless=True, args=["--no-sandbox", "--disable-gpu"]
            )
            page = browser.new_page()
            page.goto(server.url)
            page.wait_for_function(f"window.monitorStats.frames >= {n}", timeout=120_000)
            ms = page.evaluate("window.monitorStats.latencyMs")
            browser.close()
        p50, p99 = float(np.median(ms)), float(np.percentile(ms, 99))
        rows += [
            ("monitor: state to browser p50 (ms)", p50, f"{p50 / rows[0][1]:.1f}x base"),
            ("monitor: state to browser p99 (ms)", p99, f"{p99 / rows[0][1]:.1f}x base"),
        ]
        return rows
    finally:
        stop.set()
        server.stop()


def main() -> None:
    parser = argparse.ArgumentParser(
        prog="python -m bench.robot", description=__doc__.split("\n")[0]
    )
    parser.add_argument("--quick", action="store_true", help="shorter runs")
    args = parser.parse_args()
    for rows in (bench_runner(args.quick), bench_monitor(args.quick)):
        for name, value, ratio in rows:
            print(f"| {name:<42} | {value:>10.2f} | {ratio:>16} |")


if __name__ == "__main__":
    main()

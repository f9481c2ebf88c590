"""bridge/monitor: the WebSocket through FastAPI's TestClient, the hub, the --sim driver."""

from __future__ import annotations

import contextlib
import json
import socket
import time
import urllib.error
import urllib.request
from collections.abc import Iterator
from urllib.parse import quote

import pytest
from fastapi.testclient import TestClient
from starlette.testclient import WebSocketDenialResponse
from websockets.exceptions import ConnectionClosed, InvalidStatus
from websockets.sync.client import connect

from bridge.monitor.app import (
    MAX_CLIENTS,
    MAX_CONNECTIONS,
    MAX_MESSAGE_BYTES,
    RATE_LIMIT_PER_S,
    WS_MAX_BYTES,
    Server,
    create_app,
    serve,
)
from bridge.monitor.hub import MODES, MonitorHub, monitor_modes
from bridge.monitor.sim import SimDriver
from policies import make_policy


def _state(hub: MonitorHub, t: float = 0.0) -> None:
    hub.publish(
        {
            "time_s": t,
            "mode": hub.mode,
            "obs": [1.0, 12.0],
            "robot": [0.0, 0.0, 0.0],
            "person": [1.0, 0.0, 0.0],
        }
    )


def _next(ws, kind: str) -> dict:  # type: ignore[no-untyped-def]
    """The next message of ``kind``, passing over the streamed scene and states: any other
    reply first fails the test (waiting for one that never comes would hang it)."""
    for _ in range(50):
        message = ws.receive_json()
        if message["type"] == kind:
            return message
        assert message["type"] in ("scene", "state"), f"{message} while waiting for {kind}"
    raise AssertionError(f"no {kind} message")


def _next_raw(ws, kind: str) -> dict:  # type: ignore[no-untyped-def]
    """``_next`` for a ``websockets`` client of a real server (which times out)."""
    for _ in range(50):
        message = json.loads(ws.recv(timeout=5))
        if message["type"] == kind:
            return message
        assert message["type"] in ("scene", "state"), f"{message} while waiting for {kind}"
    raise AssertionError(f"no {kind} message")


BUTTONS = [
    ["pn", "PN"],
    ["mpn", "MPN"],
    ["gsmpn", "GS-MPN"],
    ["ppo", "PPO"],
    ["manual", "manual"],
    ["stop", "STOP"],
]


@pytest.fixture
def hub() -> MonitorHub:
    h = MonitorHub("stop", scene={"walls": [[0, 0, 1, 0]]})
    _state(h)
    return h


@pytest.fixture
def served(hub: MonitorHub) -> Iterator[Server]:
    """The monitor over ``hub`` on a real uvicorn server (loopback, a free port)."""
    server = Server(create_app(hub, rate_hz=50), "127.0.0.1", 0).start()
    yield server
    server.stop()


def _ws_url(server: Server, host: str = "127.0.0.1") -> str:
    return f"ws://{host}:{server.port}/ws"


def test_the_page_and_its_script_are_served(hub: MonitorHub) -> None:
    client = TestClient(create_app(hub))
    page = client.get("/")
    assert page.status_code == 200
    assert "<canvas" in page.text
    assert "cdn" not in page.text.lower()  # everything is served from here
    assert client.get("/static/monitor.js").status_code == 200
    assert client.get("/state").json()["mode"] == "stop"


def test_states_stream_and_modes_change(hub: MonitorHub) -> None:
    client = TestClient(create_app(hub, rate_hz=50))
    with client.websocket_connect("/ws") as ws:
        assert ws.receive_json() == {
            "type": "scene",
            "walls": [[0, 0, 1, 0]],
            "modes": BUTTONS,
            "session": hub.session,
            "version": 0,
            "client": 1,
        }
        first = _next(ws, "state")
        assert first["obs"] == [1.0, 12.0]
        _state(hub, 0.1)
        assert _next(ws, "state")["seq"] == first["seq"] + 1
        ws.send_text(json.dumps({"type": "mode", "mode": "gsmpn"}))
        assert _next(ws, "ack") == {"type": "ack", "mode": "gsmpn"}
        assert hub.mode == "gsmpn"
        ws.send_json({"type": "mode", "mode": "manual"})
        _next(ws, "ack")
        ws.send_json({"type": "manual", "v_mps": 0.3, "w_radps": -0.5})
        assert _next(ws, "ack")["manual"] == [0.3, -0.5]
        assert hub.manual_command() == (0.3, -0.5)
        ws.send_json({"type": "ping", "t": 12.5})
        assert _next(ws, "pong") == {"type": "pong", "t": 12.5}


@pytest.mark.parametrize(
    ("text", "error"),
    [
        ("not json", "json"),
        ('{"type": "mode", "mode": "fly"}', "mode"),
        ('{"type": "mode"}', "mode"),
        ('{"type": "teleport"}', "type"),
        ('{"type": "manual", "v_mps": 9, "w_radps": 0}', "v_mps"),
        ('{"type": "manual", "v_mps": "fast", "w_radps": 0}', "v_mps"),
        ('{"type": "manual", "v_mps": 0, "w_radps": 0, "x": 1}', "x"),
        ("[1, 2]", "object"),
        ('{"type": "manual", "v_mps": true, "w_radps": 0}', "manual.v_mps: input should be"),
        ('{"type": "manual", "v_mps": 0, "w_radps": false}', "manual.w_radps: input should be"),
        ('{"type": "manual", "v_mps": "0.5", "w_radps": 0}', "manual.v_mps: input should be"),
        ('{"type": "ping", "t": true}', "ping.t: input should be"),
        ('{"type": "ping", "t": NaN}', "ping.t: input should be a finite number"),
        ('{"type": "ping", "t": -Infinity}', "ping.t: input should be a finite number"),
        ('{"type": "ping", "t": "' + "x" * 5000 + '"}', "4096 bytes"),
    ],
)
def test_a_malformed_message_gets_an_error_and_the_connection_goes_on(
    hub: MonitorHub, text: str, error: str
) -> None:
    client = TestClient(create_app(hub))
    with client.websocket_connect("/ws") as ws:
        ws.send_text(text)
        reply = _next(ws, "error")
        assert error.lower() in reply["error"].lower()
        ws.send_json({"type": "mode", "mode": "pn"})  # the same connection still works
        assert _next(ws, "ack")["mode"] == "pn"
    assert hub.mode == "pn"


def test_a_binary_message_gets_an_error_and_the_connection_goes_on(hub: MonitorHub) -> None:
    client = TestClient(create_app(hub))
    with client.websocket_connect("/ws") as ws:
        ws.send_bytes(b'{"type": "ping", "t": 1}')
        assert "binary messages are not accepted" in _next(ws, "error")["error"]
        ws.send_json({"type": "ping", "t": 2})
        assert _next(ws, "pong") == {"type": "pong", "t": 2.0}


@pytest.mark.parametrize("token", ["s3cret", "clé"])
def test_a_wrong_token_is_refused_at_the_handshake(hub: MonitorHub, token: str) -> None:
    client = TestClient(create_app(hub, token=token))
    for url in ("/ws", "/ws?token=guess", "/ws?token=%C3%A9", "/ws?token=%ff", "/ws?token=cl"):
        with pytest.raises(WebSocketDenialResponse) as refused, client.websocket_connect(url):
            pass
        assert refused.value.status_code == 403
        assert refused.value.text == "wrong or missing token"
    with client.websocket_connect(f"/ws?token={quote(token)}") as ws:
        assert ws.receive_json()["type"] == "scene"


def test_the_state_route_needs_the_token_as_the_websocket_does(hub: MonitorHub) -> None:
    client = TestClient(create_app(hub, token="clé"))
    for url in ("/state", "/state?token=guess", "/state?token=%ff", "/state?token=cl"):
        refused = client.get(url)
        assert refused.status_code == 403
        assert refused.text == "wrong or missing token"
    assert client.get(f"/state?token={quote('clé')}").json()["mode"] == "stop"
    # no other route answers with anything of the robot's: no API schema, no docs
    for url in ("/openapi.json", "/docs", "/redoc"):
        assert client.get(url).status_code == 404
    assert client.get("/").status_code == 200  # the page: the same for everyone


def test_the_state_route_serves_a_state_with_nan(hub: MonitorHub) -> None:
    hub.publish({"time_s": float("nan"), "mode": "stop", "obs": [1.0, float("inf")]})
    state = TestClient(create_app(hub)).get("/state")
    assert state.status_code == 200
    assert state.json()["obs"] == [1.0, None]


def test_a_token_that_is_not_text_is_refused_at_once(hub: MonitorHub) -> None:
    with pytest.raises(ValueError, match="token is out of range: must be text"):
        create_app(hub, token="\udcff")  # a byte that is not UTF-8 on the command line


def test_the_server_refuses_a_token_says_why_and_bounds_a_message(hub: MonitorHub) -> None:
    from websockets.exceptions import ConnectionClosedError, InvalidStatus
    from websockets.sync.client import connect

    server = serve(hub, "127.0.0.1", 0, token="clé")
    url = f"ws://127.0.0.1:{server.port}/ws?token="
    try:
        with pytest.raises(InvalidStatus) as refused:
            connect(url + "guess", open_timeout=5).close()
        assert refused.value.response.status_code == 403
        assert refused.value.response.body == b"wrong or missing token"
        with connect(url + quote("clé"), open_timeout=5) as ws:
            ws.send("x" * (2 * MAX_MESSAGE_BYTES))  # too long for the app: an error reply
            assert _next_raw(ws, "error")["error"] == f"message over {MAX_MESSAGE_BYTES} bytes"
            ws.send(b'{"type": "ping", "t": 3}')
            assert "binary" in _next_raw(ws, "error")["error"]
            ws.send('{"type": "ping", "t": 4}')
            assert _next_raw(ws, "pong")["t"] == 4.0
            # far beyond it: never buffered, the connection closes with 1009 (message too big)
            ws.send("x" * (WS_MAX_BYTES + 1))
            with pytest.raises(ConnectionClosedError) as closed:
                _next_raw(ws, "pong")
            assert closed.value.rcvd.code == 1009
        with connect(url + quote("clé"), open_timeout=5) as ws:  # the server goes on
            ws.send('{"type": "ping", "t": 5}')
            assert _next_raw(ws, "pong")["t"] == 5.0
    finally:
        server.stop()


def test_a_client_that_leaves_mid_stream_does_not_stop_the_server(hub: MonitorHub) -> None:
    app = create_app(hub, rate_hz=50)
    client = TestClient(app)
    with client.websocket_connect("/ws") as ws:
        _next(ws, "state")
        ws.send_json({"type": "mode", "mode": "mpn"})
    # gone without a close handshake of its own while states were streaming
    for k in range(5):
        _state(hub, 0.2 + k)
    with client.websocket_connect("/ws") as ws:
        assert _next(ws, "state")["mode"] == "mpn"
    time.sleep(0.05)
    assert app.state.clients == 0


def test_states_with_numpy_values_and_nan_still_reach_the_page(hub: MonitorHub) -> None:
    import numpy as np

    client = TestClient(create_app(hub, rate_hz=50))
    with client.websocket_connect("/ws") as ws:
        _next(ws, "state")
        hub.publish({"time_s": np.float64(1.5), "obs": np.array([1.0, np.nan]), "duty": [np.inf]})
        state = _next(ws, "state")
    assert state["time_s"] == 1.5
    assert state["obs"] == [1.0, None]
    assert state["duty"] == [None]


def test_a_stale_manual_command_reads_as_zero() -> None:
    hub = MonitorHub("manual", manual_timeout_s=0.05)
    hub.set_manual(0.4, 0.1)
    assert hub.manual_command() == (0.4, 0.1)
    time.sleep(0.08)
    assert hub.manual_command() == (0.0, 0.0)
    with pytest.raises(ValueError, match="mode='jump' is out of range"):
        hub.set_mode("jump")
    with pytest.raises(ValueError, match="v_mps=nan is out of range"):
        hub.set_manual(float("nan"), 0.0)


def test_serving_off_loopback_needs_a_token(hub: MonitorHub) -> None:
    with pytest.raises(ValueError, match="--token"):
        serve(hub, "0.0.0.0", 0)


def test_the_sim_driver_steps_in_real_time_under_the_hubs_mode() -> None:
    hub = MonitorHub("gsmpn")
    driver = SimDriver(hub, make_policy, scenario="straight", speed=5.0).start()
    try:
        time.sleep(1.0)
        moving = hub.latest()
        assert moving is not None
        assert moving["mode"] == "gsmpn"
        assert 2.0 <= moving["time_s"] <= 6.0  # 5x real time, allowing for a loaded machine
        assert moving["command"][0] != 0.0
        assert len(hub.scene["walls"]) >= 4
        hub.set_mode("stop")
        time.sleep(0.5)
        stopped = hub.latest()
        assert stopped is not None
        assert stopped["mode"] == "stop"
        assert stopped["command"] == [0.0, 0.0]
    finally:
        driver.stop()


def test_a_hub_offers_the_reference_modes_and_the_policies_it_is_given() -> None:
    assert MonitorHub().modes == ("pn", "mpn", "gsmpn", "ppo", "manual", "stop")
    assert set(MonitorHub().modes) == set(MODES)
    modes = monitor_modes(["ppo_ahead", "gsmpn", "ppo_ahead", "pn:thesis"])
    assert modes == ("pn", "mpn", "gsmpn", "ppo", "ppo_ahead", "pn:thesis", "manual", "stop")
    hub = MonitorHub(modes=modes)
    assert hub.buttons()[4:6] == [["ppo_ahead", "PPO (ahead)"], ["pn:thesis", "pn:thesis"]]
    hub.set_mode("ppo_ahead")
    assert hub.mode == "ppo_ahead"
    with pytest.raises(ValueError, match=r"mode='ppo_ahead' is out of range: must be one of pn"):
        MonitorHub().set_mode("ppo_ahead")
    for bad in (("pn", "gsmpn"), ("pn", "stop", "pn"), ("stop", "")):
        with pytest.raises(ValueError, match=r"modes=.* is out of range"):
            MonitorHub(modes=bad)


def test_a_mode_the_robot_does_not_offer_gets_an_error_and_the_mode_stays(hub: MonitorHub) -> None:
    client = TestClient(create_app(hub))
    with client.websocket_connect("/ws") as ws:
        ws.send_json({"type": "mode", "mode": "gsmpn"})
        _next(ws, "ack")
        ws.send_json({"type": "mode", "mode": "ppo_ahead"})
        assert "mode='ppo_ahead' is out of range" in _next(ws, "error")["error"]
        ws.send_json({"type": "mode", "mode": "x" * 65})
        assert "mode" in _next(ws, "error")["error"]
        assert hub.mode == "gsmpn"


def test_a_refused_mode_goes_back_and_every_state_says_why(hub: MonitorHub) -> None:
    hub.set_mode("gsmpn")
    hub.set_mode("ppo")
    hub.refuse("ppo", "gsmpn", "ppo needs the reading ahead")
    assert hub.mode == "gsmpn"
    _state(hub, 0.2)
    assert hub.latest()["notice"] == "ppo needs the reading ahead"
    assert hub.latest()["refusals"] == 1
    hub.set_mode("pn")
    hub.refuse("ppo", "gsmpn", "ppo again")  # the browser has moved on: its choice stays
    assert hub.mode == "pn"
    assert hub.notice == "ppo again"
    assert hub.refusals == 2


def test_the_sim_driver_refuses_an_agent_it_cannot_feed_and_keeps_driving() -> None:
    hub = MonitorHub("gsmpn", modes=monitor_modes(["ppo_mecanum", "ppo_ahead"]))
    driver = SimDriver(hub, make_policy, scenario="straight", speed=5.0)
    with pytest.raises(ValueError, match="'ppo_mecanum' was trained on the mecanum platform"):
        driver.check("ppo_mecanum")
    with pytest.raises(ValueError, match=r"ppo_ahead reads the reading ahead .* publishes none"):
        driver.check("ppo_ahead")
    driver.start()
    try:
        time.sleep(0.5)
        hub.set_mode("ppo_ahead")
        time.sleep(0.5)
        state = hub.latest()
        assert hub.mode == state["mode"] == "gsmpn"
        assert state["notice"].startswith("ppo_ahead reads the reading ahead")
        assert state["command"][0] != 0.0
    finally:
        driver.stop()


def test_the_sim_driver_runs_the_agent_that_reads_ahead_where_the_camera_publishes_it() -> None:
    ahead = make_policy("ppo_ahead").reads_ahead
    hub = MonitorHub("stop", modes=monitor_modes(["ppo_ahead"]))
    driver = SimDriver(hub, make_policy, scenario="straight", config={"perception": ahead})
    driver.check("ppo_ahead")
    driver.speed = 5.0
    driver.start()
    try:
        hub.set_mode("ppo_ahead")
        time.sleep(1.0)
        state = hub.latest()
        assert state["mode"] == "ppo_ahead"
        assert len(state["obs"]) == 3  # distance, offset and the reading ahead
        assert state["notice"] == ""
    finally:
        driver.stop()


@pytest.mark.slow
def test_the_sim_monitor_offers_the_shipped_agents_its_simulation_can_run() -> None:
    import json
    import signal
    import subprocess
    import sys
    import urllib.request

    from .conftest import ROOT

    command = [sys.executable, "-m", "bridge", "monitor", "--sim", "--http", "127.0.0.1:0"]
    proc = subprocess.Popen(command, cwd=ROOT, stdout=subprocess.PIPE, text=True)
    try:
        modes, served = proc.stdout.readline(), proc.stdout.readline()
        url = served.split("monitor on ", 1)[1].strip()
        deadline = time.monotonic() + 20.0
        state: dict = {}
        while "obs" not in state and time.monotonic() < deadline:
            time.sleep(0.2)
            state = json.loads(urllib.request.urlopen(url + "state", timeout=5).read())
    finally:
        proc.send_signal(signal.SIGINT)
        proc.wait(timeout=10)
    assert modes == (
        "follow-robot: monitor modes pn, mpn, gsmpn, ppo, ppo_ahead, ppo_law, ppo_ensemble, "
        "manual, stop (not offered: policy 'ppo_mecanum' was trained on the mecanum platform, "
        "acting [v_mps, vy_mps, w_radps]; it cannot drive a platform acting [v_mps, w_radps] "
        "(train an agent for that platform, or run it @mecanum))\n"
    )
    # the simulated camera publishes the reading ahead that ppo_ahead reads
    assert state["mode"] == "stop"
    assert len(state["obs"]) == 3


def test_the_sim_driver_drives_a_mecanum_base_with_its_agent_and_the_laws() -> None:
    hub = MonitorHub("gsmpn", modes=monitor_modes(["ppo_mecanum"]))
    driver = SimDriver(hub, make_policy, scenario="straight", config={"platform": "mecanum"})
    with pytest.raises(ValueError, match="'ppo' was trained on the diff_drive platform"):
        driver.check("ppo")
    driver.speed = 5.0
    driver.start()
    try:
        time.sleep(0.8)
        law = hub.latest()
        assert law["mode"] == "gsmpn"
        assert law["command"][0] != 0.0  # the law's [v, w], with vy = 0
        assert len(law["wheel_target_mps"]) == len(law["wheel_measured_mps"]) == 4
        hub.set_mode("ppo_mecanum")
        time.sleep(0.8)
        agent = hub.latest()
        assert agent["mode"] == "ppo_mecanum"
        assert agent["notice"] == ""
        hub.set_mode("manual")
        hub.set_manual(0.0, 0.0)
        time.sleep(0.3)
        assert hub.latest()["command"] == [0.0, 0.0]
    finally:
        driver.stop()


def test_a_shipped_agent_that_does_not_load_is_not_offered_and_said_why(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    import policies
    from bridge import cli
    from policies.learned.ppo import AgentLoadError

    real = policies.make_policy

    def make(name: str, task: str | None = None) -> object:
        if name == "ppo_ahead":
            raise AgentLoadError("policies/agents/ppo_ahead/model.zip: model file not found")
        return real(name, task)

    monkeypatch.setattr(policies, "make_policy", make)
    agents, broken = cli._shipped_agents()
    assert "ppo_ahead" not in agents
    assert "ppo_mecanum" in agents
    assert broken == ["ppo_ahead (policies/agents/ppo_ahead/model.zip: model file not found)"]


# ---- manual commands: numbers only, from the page that selected manual ---------------------


def test_manual_commands_take_whole_and_decimal_numbers(hub: MonitorHub) -> None:
    client = TestClient(create_app(hub))
    with client.websocket_connect("/ws") as ws:
        ws.send_json({"type": "mode", "mode": "manual"})
        _next(ws, "ack")
        ws.send_text('{"type": "manual", "v_mps": 1, "w_radps": -0.5}')
        assert _next(ws, "ack")["manual"] == [1.0, -0.5]
        ws.send_text('{"type": "ping", "t": 3}')
        assert _next(ws, "pong")["t"] == 3.0
    assert hub.manual_command() == (1.0, -0.5)


def test_manual_commands_are_taken_only_from_the_client_that_selected_manual(
    hub: MonitorHub,
) -> None:
    client = TestClient(create_app(hub, rate_hz=50))
    with client.websocket_connect("/ws") as operator, client.websocket_connect("/ws") as watcher:
        me = _next(operator, "scene").get("client")  # each connection's id
        other = _next(watcher, "scene").get("client")
        operator.send_json({"type": "mode", "mode": "manual"})
        _next(operator, "ack")
        operator.send_json({"type": "manual", "v_mps": 0.5, "w_radps": 0.0})
        _next(operator, "ack")
        # a second page left open, its sliders at zero: its commands are refused, not mixed in
        watcher.send_json({"type": "manual", "v_mps": 0.0, "w_radps": 0.0})
        assert "only from the page that selected manual" in _next(watcher, "error")["error"]
        assert hub.manual_command() == (0.5, 0.0)
        _state(hub, 0.1)
        assert _next(operator, "state")["manual_by"] == me  # the page knows it drives
        assert me is not None
        assert other not in (None, me)
        # the last page to select manual drives; the first one's commands are refused now
        watcher.send_json({"type": "mode", "mode": "manual"})
        _next(watcher, "ack")
        watcher.send_json({"type": "manual", "v_mps": -0.2, "w_radps": 0.1})
        _next(watcher, "ack")
        operator.send_json({"type": "manual", "v_mps": 0.5, "w_radps": 0.0})
        assert "selected manual" in _next(operator, "error")["error"]
        assert hub.manual_command() == (-0.2, 0.1)
        # out of manual, nobody's manual command is taken
        operator.send_json({"type": "mode", "mode": "stop"})
        _next(operator, "ack")
        watcher.send_json({"type": "manual", "v_mps": 0.3, "w_radps": 0.0})
        _next(watcher, "error")
    assert hub.manual_command() == (0.0, 0.0)


# ---- the scene: sent again when it changes, with the session's id ----------------------------


def test_a_changed_scene_reaches_a_client_connected_before_it() -> None:
    hub = MonitorHub("stop")  # no walls yet: the driver sets them when its world is built
    _state(hub)
    server = Server(create_app(hub), "127.0.0.1", 0).start()
    try:
        with connect(_ws_url(server), open_timeout=5) as ws:
            first = _next_raw(ws, "scene")
            assert "walls" not in first
            hub.scene = {"walls": [[0, 0, 1, 0]]}
            second = _next_raw(ws, "scene")
            assert second["walls"] == [[0, 0, 1, 0]]
            assert second["version"] == first["version"] + 1
            assert second["session"] == first["session"] == hub.session
            hub.scene = {"walls": [[0, 0, 1, 0]]}  # the same walls: not sent again
            hub.scene = {"walls": [[0, 0, 2, 0]]}
            third = _next_raw(ws, "scene")
            assert third["walls"] == [[0, 0, 2, 0]]
            assert third["version"] == second["version"] + 1
    finally:
        server.stop()


def test_each_episodes_walls_reach_a_connected_client_of_the_sim_driver() -> None:
    hub = MonitorHub("gsmpn")
    driver = SimDriver(hub, make_policy, scenario="random_world", speed=100.0)
    driver.env.reset(seed=0)  # compiled (after an edit of the simulator) before the clock runs
    server = Server(create_app(hub, rate_hz=50), "127.0.0.1", 0).start()
    try:
        with connect(_ws_url(server), open_timeout=5) as ws:
            driver.start()
            walls, episodes = [], set()
            deadline = time.monotonic() + 30.0
            while len(episodes) < 2 and time.monotonic() < deadline:
                message = json.loads(ws.recv(timeout=10))
                if message["type"] == "scene" and "walls" in message:
                    walls.append(message["walls"])
                elif message["type"] == "state":
                    episodes.add(message["episode"])
                    current = hub.scene["walls"]
        assert len(episodes) >= 2
        assert len(walls) >= 2  # one per episode: random_world's walls differ by seed
        assert walls[0] != walls[-1]
        assert walls[-1] == current  # the page draws the walls of the episode it shows
    finally:
        server.stop()
        driver.stop()


def test_every_hub_has_a_session_id_of_its_own() -> None:
    first, second = MonitorHub(), MonitorHub()
    assert first.session != second.session
    version, scene = first.scene_message()
    assert (version, scene["session"], scene["version"]) == (0, first.session, 0)


# ---- what one client may cost the robot's process ------------------------------------------


def _fds() -> int:
    """This process's open file descriptors (the server runs in it, in a thread)."""
    import os

    return len(os.listdir("/proc/self/fd"))


@pytest.mark.skipif(not __import__("os").path.isdir("/proc/self/fd"), reason="no /proc")
def test_idle_connections_beyond_the_cap_are_answered_and_closed_as_they_come(
    served: Server,
) -> None:
    extra = 30
    before = _fds()
    held: list[socket.socket] = []
    try:
        for _ in range(MAX_CONNECTIONS + extra):  # no request, no handshake: idle
            held.append(socket.create_connection(("127.0.0.1", served.port), timeout=5))
        time.sleep(0.5)
        answered = []
        for sock in held:
            sock.setblocking(False)
            with contextlib.suppress(BlockingIOError):  # held open, unread: the first ones
                answered.append(sock.recv(4096))
        assert len(answered) == extra
        for reply in answered:
            assert reply.startswith(b"HTTP/1.1 503 Service Unavailable\r\n"), reply
            assert reply.endswith(f"holds {MAX_CONNECTIONS} connections at most".encode())
        # the server holds no descriptor for the connections it refused: ours, and its cap's
        assert _fds() - before <= len(held) + MAX_CONNECTIONS + 2
    finally:
        for sock in held:
            sock.close()
    time.sleep(0.3)
    with urllib.request.urlopen(f"http://127.0.0.1:{served.port}/state", timeout=5) as reply:
        assert json.loads(reply.read())["type"] == "state"  # the server goes on


def test_a_connection_that_sends_no_whole_request_head_is_closed_in_time(hub: MonitorHub) -> None:
    server = Server(create_app(hub), "127.0.0.1", 0, header_timeout_s=0.5).start()
    try:
        idle = socket.create_connection(("127.0.0.1", server.port), timeout=5)
        slow = socket.create_connection(("127.0.0.1", server.port), timeout=5)
        slow.sendall(b"GET /state HTTP/1.1\r\nHost: 127.0.0.1\r\n")  # and never the end
        with connect(_ws_url(server), open_timeout=5) as ws:
            time.sleep(1.2)
            for sock in (idle, slow):
                assert sock.recv(4096).startswith(b"HTTP/1.1 408 Request Timeout\r\n")
                assert sock.recv(4096) == b""  # closed
                sock.close()
            ws.send('{"type": "ping", "t": 1}')  # a WebSocket lives on past the deadline
            assert _next_raw(ws, "pong")["t"] == 1.0
    finally:
        server.stop()


def test_a_websocket_client_beyond_the_cap_is_refused_saying_why(served: Server) -> None:
    with contextlib.ExitStack() as held:
        clients = [
            held.enter_context(connect(_ws_url(served), open_timeout=5)) for _ in range(MAX_CLIENTS)
        ]
        with pytest.raises(InvalidStatus) as refused, connect(_ws_url(served), open_timeout=5):
            pass
        assert refused.value.response.status_code == 503
        assert refused.value.response.body == (
            f"the monitor serves {MAX_CLIENTS} clients at most: close one".encode()
        )
        clients[0].close()
        time.sleep(0.3)
        with connect(_ws_url(served), open_timeout=5) as ws:  # one left: room for one more
            assert _next_raw(ws, "scene")["type"] == "scene"


def _replies(ws, quiet_s: float = 0.5) -> list[dict]:  # type: ignore[no-untyped-def]
    """The replies (not the streamed scene and states) until none came for ``quiet_s``."""
    replies = []
    while True:
        try:
            message = json.loads(ws.recv(timeout=quiet_s))
        except TimeoutError:
            return replies
        if message["type"] not in ("scene", "state"):
            replies.append(message)


def test_a_client_over_the_message_rate_gets_one_error_and_the_rest_are_dropped(
    served: Server,
) -> None:
    with connect(_ws_url(served), open_timeout=5) as ws:
        for k in range(RATE_LIMIT_PER_S + 10):
            ws.send(json.dumps({"type": "ping", "t": k}))
        replies = _replies(ws)
        assert [r["type"] for r in replies] == ["pong"] * RATE_LIMIT_PER_S + ["error"]
        assert [r["t"] for r in replies[:-1]] == list(range(RATE_LIMIT_PER_S))
        assert replies[-1]["error"].startswith(f"over {RATE_LIMIT_PER_S} messages a second")
        time.sleep(1.0)  # the next second: answered again
        ws.send('{"type": "ping", "t": 99}')
        assert _next_raw(ws, "pong")["t"] == 99.0


def _flood(url: str, n: int) -> tuple[int, ConnectionClosed]:
    """Send ``n`` pings as fast as a client can (reading the replies as they come, as the
    reviewer's flood did); how many replies came before the connection closed, and how."""
    import asyncio

    from websockets.asyncio.client import connect as connect_async

    async def flood() -> tuple[int, ConnectionClosed]:
        async with connect_async(url, open_timeout=5) as ws:
            replies = 0

            async def read() -> None:
                nonlocal replies
                async for message in ws:
                    replies += json.loads(message)["type"] in ("pong", "error")

            reader = asyncio.create_task(read())
            try:
                for k in range(n):
                    await ws.send('{"type": "ping", "t": 1}')
                    if k % 50 == 0:
                        await asyncio.sleep(0)
                await asyncio.wait_for(reader, 10)
            except ConnectionClosed as closed:
                return replies, closed
        raise AssertionError("the server did not close the flooding client")

    return asyncio.run(flood())


def test_a_flooding_client_is_closed_with_1008_and_the_server_goes_on(served: Server) -> None:
    replies, closed = _flood(_ws_url(served), 5000)
    assert closed.rcvd is not None
    assert closed.rcvd.code == 1008
    assert closed.rcvd.reason == f"over {RATE_LIMIT_PER_S} messages a second"
    assert replies == RATE_LIMIT_PER_S + 1  # its first second's pongs and one error: no more
    with connect(_ws_url(served), open_timeout=5) as ws:
        ws.send('{"type": "ping", "t": 2}')
        assert _next_raw(ws, "pong")["t"] == 2.0


# ---- other sites' pages ---------------------------------------------------------------------


@pytest.mark.parametrize(
    "origin",
    ["https://evil.example", "http://localhost:1", "http://127.0.0.1:1", "null", "file://"],
)
def test_a_websocket_from_a_page_of_another_origin_is_refused(
    served: Server, hub: MonitorHub, origin: str
) -> None:
    with (
        pytest.raises(InvalidStatus) as refused,
        connect(_ws_url(served), origin=origin, open_timeout=5),  # type: ignore[arg-type]
    ):
        pass
    assert refused.value.response.status_code == 403
    assert (
        refused.value.response.body
        == f"Origin {origin!r} is not this monitor's page: refused".encode()
    )
    assert hub.mode == "stop"


def test_the_monitors_own_page_and_a_script_connect(served: Server) -> None:
    own = f"http://127.0.0.1:{served.port}"
    for url, origin in (
        (_ws_url(served), own),
        (_ws_url(served, "localhost"), f"http://localhost:{served.port}"),
        (_ws_url(served), None),  # a script sends no Origin
    ):
        with connect(url, origin=origin, open_timeout=5) as ws:  # type: ignore[arg-type]
            ws.send('{"type": "mode", "mode": "pn"}')
            assert _next_raw(ws, "ack")["mode"] == "pn"


def test_a_request_for_another_host_is_refused(served: Server) -> None:
    # a DNS-rebinding page: its own name, resolved to this machine
    request = urllib.request.Request(
        f"http://127.0.0.1:{served.port}/state", headers={"Host": f"evil.example:{served.port}"}
    )
    with pytest.raises(urllib.error.HTTPError) as refused:
        urllib.request.urlopen(request, timeout=5)
    assert refused.value.code == 400
    assert (
        refused.value.read()
        == f"Host 'evil.example:{served.port}' is not this monitor's address".encode()
    )
    with socket.create_connection(("127.0.0.1", served.port), timeout=5) as sock:
        sock.sendall(
            b"GET /ws HTTP/1.1\r\nHost: evil.example\r\nUpgrade: websocket\r\n"
            b"Connection: Upgrade\r\nSec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\n"
            b"Sec-WebSocket-Version: 13\r\nOrigin: http://evil.example\r\n\r\n"
        )
        assert sock.recv(4096).startswith(b"HTTP/1.1 400 ")
    with urllib.request.urlopen(f"http://localhost:{served.port}/", timeout=5) as page:
        assert page.status == 200  # the loopback names are all this monitor's


def test_a_client_over_the_rate_three_seconds_running_is_closed() -> None:
    from bridge.monitor.app import _Rate

    rate = _Rate(20)
    seconds = [[rate.take(t + k / 100) for k in range(25)] for t in (0.0, 1.0, 2.0)]
    for verdicts in seconds[:2]:  # over it: one error reply, the rest dropped
        assert verdicts == ["ok"] * 20 + ["over"] + ["drop"] * 4
    assert seconds[2] == ["ok"] * 20 + ["close"] * 5  # the third second running
    rate = _Rate(20)
    over = [rate.take(0.0) for _ in range(25)]
    assert [rate.take(2.5) for _ in range(21)] == ["ok"] * 20 + ["over"]  # a quiet second between
    assert over[-1] == "drop"
    assert _Rate(20).take(0.0) == "ok"
    flood = _Rate(20)
    assert [flood.take(0.0) for _ in range(101)][-2:] == ["drop", "close"]  # five times over

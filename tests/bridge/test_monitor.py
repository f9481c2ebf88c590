"""bridge/monitor: the WebSocket through FastAPI's TestClient, the hub, the --sim driver."""

from __future__ import annotations

import json
import time
from urllib.parse import quote

import pytest
from fastapi.testclient import TestClient
from starlette.testclient import WebSocketDenialResponse

from bridge.monitor.app import MAX_MESSAGE_BYTES, WS_MAX_BYTES, create_app, serve
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
        assert ws.receive_json() == {"type": "scene", "walls": [[0, 0, 1, 0]], "modes": BUTTONS}
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

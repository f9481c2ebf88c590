"""bridge/monitor: the WebSocket through FastAPI's TestClient, the hub, the --sim driver."""

from __future__ import annotations

import json
import time

import pytest
from fastapi.testclient import TestClient
from starlette.websockets import WebSocketDisconnect

from bridge.monitor.app import create_app, serve
from bridge.monitor.hub import MonitorHub
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
    for _ in range(50):
        message = ws.receive_json()
        if message["type"] == kind:
            return message
    raise AssertionError(f"no {kind} message")


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
        assert ws.receive_json() == {"type": "scene", "walls": [[0, 0, 1, 0]]}
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


def test_a_wrong_token_is_refused_at_the_handshake(hub: MonitorHub) -> None:
    client = TestClient(create_app(hub, token="s3cret"))
    for url in ("/ws", "/ws?token=guess"):
        with pytest.raises(WebSocketDisconnect) as refused, client.websocket_connect(url) as ws:
            ws.receive_json()
        assert refused.value.code == 1008
    with client.websocket_connect("/ws?token=s3cret") as ws:
        assert ws.receive_json()["type"] == "scene"


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

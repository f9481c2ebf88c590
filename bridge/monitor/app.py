"""The monitor's FastAPI app: a static page, and a WebSocket that streams state and takes modes.

``GET /`` serves the page (``static/index.html``: Canvas2D, no framework, no CDN: it works
offline, beside the robot). ``/ws`` is the WebSocket:

* server to client, JSON: ``{"type": "scene", "modes": [[mode, label], ...], ...}`` once (the
  mode buttons, in order, and walls to draw), then ``{"type":
  "state", ...}`` at ``rate_hz`` (10 Hz) whenever the driver has published a newer state;
  replies ``{"type": "ack", ...}`` or ``{"type": "error", "error": ...}`` to every message;
* client to server, JSON validated with pydantic: ``{"type": "mode", "mode": "gsmpn"}``
  (one of the hub's modes: ``pn, mpn, gsmpn, ppo, manual, stop``, and any policy the robot's
  command line added, such as ``ppo_ahead``), ``{"type": "manual", "v_mps": 0.3,
  "w_radps": 0.0}`` and ``{"type": "ping", "t": ...}`` (``t`` a finite number or absent),
  each a text message. A malformed message (a binary one, one that is not JSON or not one of
  these, one over :data:`MAX_MESSAGE_BYTES`) gets an error reply saying what is wrong; the
  connection and the server go on. The server never buffers a message over
  :data:`WS_MAX_BYTES`: one that long closes the connection with 1009 (message too big).

With a ``token`` the WebSocket handshake must carry it (``/ws?token=...``, any text, compared
as UTF-8); a wrong or missing token is refused before the connection opens: HTTP 403 with the
body ``wrong or missing token``. ``GET /state`` (the robot's state, for scripts) needs it the
same way (``/state?token=...``); the page and its static files, the same for everyone, do not
(the page reads the token from its own URL), and the app serves no API schema. The command line
requires a token for any host other than loopback.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import math
import secrets
import threading
import time
from pathlib import Path
from typing import Annotated, Any, Literal

import uvicorn
from fastapi import FastAPI, Request, WebSocket, WebSocketDisconnect
from fastapi.responses import FileResponse, JSONResponse, PlainTextResponse
from fastapi.staticfiles import StaticFiles
from pydantic import BaseModel, ConfigDict, Field, TypeAdapter, ValidationError

from bridge.monitor.hub import MANUAL_LIMITS, MonitorHub

__all__ = ["LOOPBACK_HOSTS", "MAX_MESSAGE_BYTES", "WS_MAX_BYTES", "Server", "create_app", "serve"]

STATIC = Path(__file__).with_name("static")
MAX_MESSAGE_BYTES = 4096
"""Longest client message accepted."""
WS_MAX_BYTES = 4 * MAX_MESSAGE_BYTES
"""Longest message the server reads (uvicorn's ``ws_max_size``; its default is 16 MiB): one a
little over :data:`MAX_MESSAGE_BYTES` still gets an error reply, and one far over it is
refused before it is buffered (close code 1009)."""
LOOPBACK_HOSTS = frozenset({"127.0.0.1", "localhost", "::1"})
_POLL_S = 0.005  # how often a client's sender looks for a new state, s


class _Message(BaseModel):
    model_config = ConfigDict(extra="forbid")


class ModeMessage(_Message):
    """Select an operating mode."""

    type: Literal["mode"]
    mode: str = Field(min_length=1, max_length=64)  # one of the hub's modes (it checks)


class ManualMessage(_Message):
    """A manual command, m/s and rad/s (used in ``manual`` mode)."""

    type: Literal["manual"]
    v_mps: float = Field(ge=-MANUAL_LIMITS[0], le=MANUAL_LIMITS[0], allow_inf_nan=False)
    w_radps: float = Field(ge=-MANUAL_LIMITS[1], le=MANUAL_LIMITS[1], allow_inf_nan=False)


class PingMessage(_Message):
    """Echoed back (clients measure the round trip)."""

    type: Literal["ping"]
    # finite: the reply echoes it, and JavaScript's JSON.parse refuses NaN and Infinity
    t: float | None = Field(default=None, allow_inf_nan=False)


ClientMessage = TypeAdapter(
    Annotated[ModeMessage | ManualMessage | PingMessage, Field(discriminator="type")]
)


def _error_text(exc: ValidationError) -> str:
    parts = []
    for err in exc.errors()[:3]:
        where = ".".join(str(p) for p in err["loc"]) or "message"
        parts.append(f"{where}: {err['msg']}")
    return "; ".join(parts)


def create_app(hub: MonitorHub, token: str | None = None, rate_hz: float = 10.0) -> FastAPI:
    """The monitor app over ``hub``.

    :param hub: the state and mode store the robot's driver shares.
    :param token: required at the WebSocket handshake and by ``/state`` when given (any text:
        it is compared as UTF-8 bytes).
    :param rate_hz: state messages per second at most.
    """
    if not 0.1 <= rate_hz <= 100.0:
        raise ValueError(f"rate_hz={rate_hz} is out of range: must be in [0.1, 100] Hz")
    expected = None if token is None else _token_bytes(token)
    # no /docs, /redoc nor /openapi.json: routes that would answer without the token
    app = FastAPI(title="PersonFollow monitor", docs_url=None, redoc_url=None, openapi_url=None)
    app.state.hub = hub
    app.state.clients = 0
    app.mount("/static", StaticFiles(directory=STATIC), name="static")

    @app.get("/", include_in_schema=False)
    async def index() -> FileResponse:
        return FileResponse(STATIC / "index.html", media_type="text/html")

    def allowed(given: str) -> bool:
        # compare_digest takes str only when it is ASCII; UTF-8 bytes take any token. The query
        # string was decoded with errors replaced (``%ff``), so encoding it cannot fail.
        return expected is None or secrets.compare_digest(given.encode("utf-8"), expected)

    @app.get("/state", response_model=None)
    async def state(request: Request) -> JSONResponse | PlainTextResponse:
        """The newest state (for scripts; the page uses the WebSocket); 403 without the token."""
        if not allowed(request.query_params.get("token", "")):
            return PlainTextResponse("wrong or missing token", status_code=403)
        return JSONResponse(_clean(hub.latest() or {"type": "state", "seq": 0}))

    @app.websocket("/ws")
    async def websocket(ws: WebSocket) -> None:
        if not allowed(ws.query_params.get("token", "")):
            await _refuse(ws, "wrong or missing token")
            return
        await ws.accept()
        app.state.clients += 1
        sender = asyncio.create_task(_send_states(ws, hub, 1.0 / rate_hz))
        try:
            await _receive(ws, hub)
        except WebSocketDisconnect:
            pass
        finally:
            sender.cancel()
            with contextlib.suppress(asyncio.CancelledError, Exception):
                await sender
            app.state.clients -= 1

    return app


def _token_bytes(token: str) -> bytes:
    """``token`` as UTF-8; ``ValueError`` for one that is not text (a command-line argument
    whose bytes are not UTF-8 arrives with lone surrogates) and so could never be matched."""
    try:
        return token.encode("utf-8")
    except UnicodeEncodeError:
        raise ValueError("token is out of range: must be text (its bytes are not UTF-8)") from None


async def _refuse(ws: WebSocket, reason: str) -> None:
    """Refuse a handshake with HTTP 403 and ``reason`` as its body, where the server can send
    a body (uvicorn and the TestClient can); else by closing, which a server turns into a bare
    403 (a close reason before the connection opens never reaches the client)."""
    if "websocket.http.response" in ws.scope.get("extensions", {}):
        await ws.send_denial_response(PlainTextResponse(reason, status_code=403))
    else:
        await ws.close(code=1008, reason=reason)


async def _send_states(ws: WebSocket, hub: MonitorHub, period_s: float) -> None:
    # A new state goes out within a few ms of being published (polled every 5 ms), and no
    # client gets more than one per period.
    await ws.send_text(json.dumps({"type": "scene", **hub.scene, "modes": hub.buttons()}))
    last, last_sent = -1, -math.inf
    loop = asyncio.get_running_loop()
    while True:
        state = hub.latest()
        now = loop.time()
        if state is not None and state["seq"] != last and now - last_sent >= 0.9 * period_s:
            last, last_sent = state["seq"], now
            await ws.send_text(json.dumps(_clean(state), allow_nan=False))
        await asyncio.sleep(min(_POLL_S, period_s))


def _clean(value: Any) -> Any:
    """JSON-ready: numpy values as Python ones, NaN and infinities as ``null`` (JavaScript's
    ``JSON.parse`` refuses them)."""
    if isinstance(value, dict):
        return {k: _clean(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_clean(v) for v in value]
    if hasattr(value, "tolist"):
        return _clean(value.tolist())
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


async def _receive(ws: WebSocket, hub: MonitorHub) -> None:
    """Answer the client's messages until it leaves (``WebSocketDisconnect``)."""
    while True:
        # not receive_text(): it fails with KeyError on a binary message, ending the connection
        message = await ws.receive()
        if message["type"] == "websocket.disconnect":
            raise WebSocketDisconnect(message.get("code", 1000), message.get("reason"))
        text = message.get("text")
        if text is None:
            await ws.send_json(
                {"type": "error", "error": "binary messages are not accepted: send JSON as text"}
            )
            continue
        await _answer(ws, hub, text)


async def _answer(ws: WebSocket, hub: MonitorHub, text: str) -> None:
    """Validate one text message, act on it and reply (an error reply for a malformed one)."""
    if len(text.encode()) > MAX_MESSAGE_BYTES:
        await ws.send_json({"type": "error", "error": f"message over {MAX_MESSAGE_BYTES} bytes"})
        return
    try:
        message = ClientMessage.validate_json(text)
    except ValidationError as exc:
        await ws.send_json({"type": "error", "error": _error_text(exc)})
        return
    if isinstance(message, ModeMessage):
        try:
            hub.set_mode(message.mode)
        except ValueError as exc:  # not a mode of this robot: the mode stays as it was
            await ws.send_json({"type": "error", "error": str(exc)})
            return
        await ws.send_json({"type": "ack", "mode": message.mode})
    elif isinstance(message, ManualMessage):
        hub.set_manual(message.v_mps, message.w_radps)
        await ws.send_json({"type": "ack", "manual": [message.v_mps, message.w_radps]})
    else:
        await ws.send_json({"type": "pong", "t": message.t})


class Server:
    """uvicorn serving an app in a background thread; :meth:`stop` ends it."""

    def __init__(self, app: FastAPI, host: str = "127.0.0.1", port: int = 8000) -> None:
        # ws_max_size: the server reads no message far longer than the app accepts (the
        # default, 16 MiB, would buffer one in full only for the app to refuse it)
        config = uvicorn.Config(
            app, host=host, port=port, log_level="warning", lifespan="off", ws_max_size=WS_MAX_BYTES
        )
        self._server = uvicorn.Server(config)
        self._thread = threading.Thread(target=self._serve, name="monitor", daemon=True)
        self.host = host
        self.port = port

    def _serve(self) -> None:
        # uvicorn ends a start-up that failed with sys.exit(): start() says why, in one line
        with contextlib.suppress(SystemExit):
            self._server.run()

    def start(self, timeout_s: float = 10.0) -> Server:
        """Start serving; returns once the socket listens (``RuntimeError`` if it cannot, saying
        why in one line: uvicorn's own error line, such as a port in use, is held back)."""
        held = _Held()
        logger = logging.getLogger("uvicorn.error")
        logger.addFilter(held)
        try:
            self._thread.start()
            end = time.monotonic() + timeout_s
            while not self._server.started:
                if not self._thread.is_alive() or time.monotonic() > end:
                    why = f" ({'; '.join(held.errors)})" if held.errors else ""
                    raise RuntimeError(
                        f"the monitor could not listen on {self.host}:{self.port}{why}"
                    )
                time.sleep(0.02)
        finally:
            logger.removeFilter(held)
        if self.port == 0:
            sock = self._server.servers[0].sockets[0]
            self.port = sock.getsockname()[1]
        return self

    @property
    def url(self) -> str:
        """The page's address."""
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"http://{host}:{self.port}/"

    def stop(self) -> None:
        """Stop serving (idempotent)."""
        self._server.should_exit = True
        if self._thread.is_alive():
            self._thread.join(timeout=5.0)


class _Held(logging.Filter):
    """Keeps uvicorn's error records of a start-up out of the log (the caller says why in
    its own one line) and the messages for it."""

    def __init__(self) -> None:
        super().__init__()
        self.errors: list[str] = []

    def filter(self, record: logging.LogRecord) -> bool:
        if record.levelno < logging.ERROR:
            return True
        self.errors.append(record.getMessage())
        return False


def serve(
    hub: MonitorHub, host: str = "127.0.0.1", port: int = 8000, token: str | None = None
) -> Server:
    """Serve the monitor over ``hub`` in a background thread; ``ValueError`` for a host that
    is not loopback without a token."""
    if host not in LOOPBACK_HOSTS and not token:
        raise ValueError(
            f"--host {host} is not loopback: give --token so that only you can drive the robot"
        )
    return Server(create_app(hub, token), host, port).start()

"""The monitor's FastAPI app: a static page, and a WebSocket that streams state and takes modes.

``GET /`` serves the page (``static/index.html``: Canvas2D, no framework, no CDN: it works
offline, beside the robot). ``/ws`` is the WebSocket:

* server to client, JSON: ``{"type": "scene", "modes": [[mode, label], ...], "session": id,
  "version": n, "client": k, ...}`` on connect and whenever the scene changes (the mode
  buttons, in order, walls to draw, the hub's id, the scene's version, this connection's id:
  a state's ``manual_by`` names the client whose manual commands are taken), then ``{"type":
  "state", ...}`` at ``rate_hz`` (10 Hz) whenever the driver has published a newer state;
  replies ``{"type": "ack", ...}`` or ``{"type": "error", "error": ...}`` to every message;
* client to server, JSON validated with pydantic: ``{"type": "mode", "mode": "gsmpn"}``
  (one of the hub's modes: ``pn, mpn, gsmpn, ppo, manual, stop``, and any policy the robot's
  command line added, such as ``ppo_ahead``), ``{"type": "manual", "v_mps": 0.3,
  "w_radps": 0.0}`` (numbers, not ``true`` nor ``"0.3"``; taken only from the client that
  selected ``manual`` last) and ``{"type": "ping", "t": ...}`` (``t`` a finite number or
  absent), each a text message. A malformed message (a binary one, one that is not JSON or not
  one of these, one over :data:`MAX_MESSAGE_BYTES`) gets an error reply saying what is wrong;
  the connection and the server go on. The server never buffers a message over
  :data:`WS_MAX_BYTES`: one that long closes the connection with 1009 (message too big).

With a ``token`` the WebSocket handshake must carry it (``/ws?token=...``, any text, compared
as UTF-8); a wrong or missing token is refused before the connection opens: HTTP 403 with the
body ``wrong or missing token``. ``GET /state`` (the robot's state, for scripts) needs it the
same way (``/state?token=...``); the page and its static files, the same for everyone, do not
(the page reads the token from its own URL), and the app serves no API schema. The command line
requires a token for any host other than loopback.

The server runs beside the control loop, so what clients may cost is bounded: at most
:data:`MAX_CLIENTS` WebSockets (one more: HTTP 503 saying why), :data:`RATE_LIMIT_PER_S`
messages a second from each (the first beyond gets an error reply, the rest of that second are
dropped unread; over it three seconds running, or five times over in one, closes it with 1008);
with :class:`Server`, :data:`MAX_CONNECTIONS` TCP connections (one more is answered 503 and
closed as it is accepted, unread: idle ones cannot use up the file descriptors) and
:data:`HEADER_TIMEOUT_S` for each request's head. :class:`Server` refuses a ``Host`` that is
not one of its names (400: a DNS-rebinding page) and a WebSocket whose ``Origin`` is not the
``Host`` it asked for (403: a page of another site or port); a script sends no ``Origin``.
"""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import json
import logging
import math
import secrets
import threading
import time
from http import HTTPStatus
from pathlib import Path
from typing import Annotated, Any, Literal
from urllib.parse import urlsplit

import uvicorn
from fastapi import FastAPI, Request, WebSocket, WebSocketDisconnect
from fastapi.responses import FileResponse, JSONResponse, PlainTextResponse
from fastapi.staticfiles import StaticFiles
from pydantic import BaseModel, ConfigDict, Field, TypeAdapter, ValidationError
from starlette.datastructures import Headers
from starlette.types import ASGIApp, Receive, Scope, Send
from uvicorn.protocols.http.h11_impl import H11Protocol

from bridge.address import host_text
from bridge.monitor.hub import MANUAL_LIMITS, MonitorHub

__all__ = [
    "HEADER_TIMEOUT_S",
    "LOOPBACK_HOSTS",
    "MAX_CLIENTS",
    "MAX_CONNECTIONS",
    "MAX_MESSAGE_BYTES",
    "RATE_LIMIT_PER_S",
    "WS_MAX_BYTES",
    "Server",
    "create_app",
    "serve",
]

STATIC = Path(__file__).with_name("static")
MAX_MESSAGE_BYTES = 4096
"""Longest client message accepted."""
WS_MAX_BYTES = 4 * MAX_MESSAGE_BYTES
"""Longest message the server reads (uvicorn's ``ws_max_size``; its default is 16 MiB): one a
little over :data:`MAX_MESSAGE_BYTES` still gets an error reply, and one far over it is
refused before it is buffered (close code 1009)."""
LOOPBACK_HOSTS = frozenset({"127.0.0.1", "localhost", "::1"})
MAX_CLIENTS = 32
"""WebSocket clients served at once (pages and scripts); one more is refused (HTTP 503)."""
MAX_CONNECTIONS = 64
"""TCP connections a :class:`Server` holds at once, WebSockets included; one more is answered
503 and closed as it is accepted (uvicorn's ``limit_concurrency`` is the same)."""
HEADER_TIMEOUT_S = 10.0
"""Longest a connection may take to send a request's head (from its opening, or from the
previous response), s; then it is closed (408)."""
KEEP_ALIVE_S = 5
"""An idle connection after a response is closed after this long, s (uvicorn's
``timeout_keep_alive``)."""
BACKLOG = 16
"""Connections accepted in one go (and the listening socket's queue; uvicorn's ``backlog``,
whose default, 2048, would accept that many idle connections before the first is refused):
it bounds the descriptors in flight beyond :data:`MAX_CONNECTIONS` to a few times this."""
RATE_LIMIT_PER_S = 20
"""Messages a second one client may send (the page sends five manual commands a second)."""
_POLL_S = 0.005  # how often a client's sender looks for a new state, s


class _Message(BaseModel):
    model_config = ConfigDict(extra="forbid")


class ModeMessage(_Message):
    """Select an operating mode."""

    type: Literal["mode"]
    mode: str = Field(min_length=1, max_length=64)  # one of the hub's modes (it checks)


class ManualMessage(_Message):
    """A manual command, m/s and rad/s (used in ``manual`` mode); JSON numbers only (strict:
    ``true`` or ``"0.3"`` is refused, not read as 1.0 or 0.3)."""

    type: Literal["manual"]
    v_mps: float = Field(
        ge=-MANUAL_LIMITS[0], le=MANUAL_LIMITS[0], allow_inf_nan=False, strict=True
    )
    w_radps: float = Field(
        ge=-MANUAL_LIMITS[1], le=MANUAL_LIMITS[1], allow_inf_nan=False, strict=True
    )


class PingMessage(_Message):
    """Echoed back (clients measure the round trip)."""

    type: Literal["ping"]
    # finite: the reply echoes it, and JavaScript's JSON.parse refuses NaN and Infinity
    t: float | None = Field(default=None, allow_inf_nan=False, strict=True)


ClientMessage = TypeAdapter(
    Annotated[ModeMessage | ManualMessage | PingMessage, Field(discriminator="type")]
)


def _error_text(exc: ValidationError) -> str:
    parts = []
    for err in exc.errors()[:3]:
        where = ".".join(str(p) for p in err["loc"]) or "message"
        parts.append(f"{where}: {err['msg']}")
    return "; ".join(parts)


def create_app(
    hub: MonitorHub, token: str | None = None, rate_hz: float = 10.0, max_clients: int = MAX_CLIENTS
) -> FastAPI:
    """The monitor app over ``hub``.

    :param hub: the state and mode store the robot's driver shares.
    :param token: required at the WebSocket handshake and by ``/state`` when given (any text:
        it is compared as UTF-8 bytes).
    :param rate_hz: state messages per second at most.
    :param max_clients: WebSocket clients served at once; one more is refused (HTTP 503).
    """
    if not 0.1 <= rate_hz <= 100.0:
        raise ValueError(f"rate_hz={rate_hz} is out of range: must be in [0.1, 100] Hz")
    if not 1 <= max_clients <= 1024:
        raise ValueError(f"max_clients={max_clients} is out of range: must be in [1, 1024]")
    expected = None if token is None else _token_bytes(token)
    # no /docs, /redoc nor /openapi.json: routes that would answer without the token
    app = FastAPI(title="PersonFollow monitor", docs_url=None, redoc_url=None, openapi_url=None)
    app.state.hub = hub
    app.state.clients = 0
    ids = itertools.count(1)  # each connection's id: manual commands name their client by it
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
        if app.state.clients >= max_clients:  # counted before any await: no race past it
            await _refuse(ws, f"the monitor serves {max_clients} clients at most: close one", 503)
            return
        app.state.clients += 1
        client = next(ids)
        sender: asyncio.Task[None] | None = None
        try:
            await ws.accept()
            sender = asyncio.create_task(_send_states(ws, hub, 1.0 / rate_hz, client))
            await _receive(ws, hub, client)
        except WebSocketDisconnect:
            pass
        finally:
            if sender is not None:
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


async def _refuse(ws: WebSocket, reason: str, status: int = 403) -> None:
    """Refuse a handshake with HTTP ``status`` and ``reason`` as its body, where the server
    can send a body (uvicorn and the TestClient can); else by closing, which a server turns
    into a bare 403 (a close reason before the connection opens never reaches the client)."""
    if "websocket.http.response" in ws.scope.get("extensions", {}):
        await ws.send_denial_response(PlainTextResponse(reason, status_code=status))
    else:
        await ws.close(code=1008, reason=reason)


async def _send_states(ws: WebSocket, hub: MonitorHub, period_s: float, client: int) -> None:
    # A new state goes out within a few ms of being published (polled every 5 ms), and no
    # client gets more than one per period; the scene on connect, and again when it changed.
    scene_version = -1
    last, last_sent = -1, -math.inf
    loop = asyncio.get_running_loop()
    while True:
        if hub.scene_version != scene_version:
            scene_version, scene = hub.scene_message()
            await ws.send_text(json.dumps(_clean({**scene, "client": client}), allow_nan=False))
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


class _Rate:
    """How many messages a client sent in the current second (windows of 1 s): up to
    ``limit`` are answered; beyond, the first gets an error reply and the rest are dropped
    unread; over ``limit`` three windows running, or over five times it in one, closes it."""

    def __init__(self, limit: int) -> None:
        self.limit = limit
        self._start = -math.inf  # the window's start, s (the event loop's clock)
        self._count = 0
        self._strikes = 0  # windows over the limit in a row, up to the current one

    def take(self, now: float) -> Literal["ok", "over", "drop", "close"]:
        """The verdict on a message received at ``now``, s."""
        if now - self._start >= 1.0:
            over = self._count > self.limit and now - self._start < 2.0  # the window before
            self._strikes = self._strikes + 1 if over else 0
            self._start, self._count = now, 0
        self._count += 1
        if self._count > 5 * self.limit or (self._strikes >= 2 and self._count > self.limit):
            return "close"
        if self._count <= self.limit:
            return "ok"
        return "over" if self._count == self.limit + 1 else "drop"


async def _receive(ws: WebSocket, hub: MonitorHub, client: int) -> None:
    """Answer the client's messages until it leaves (``WebSocketDisconnect``) or sends more
    than :data:`RATE_LIMIT_PER_S` for long (closed with 1008)."""
    rate = _Rate(RATE_LIMIT_PER_S)
    loop = asyncio.get_running_loop()
    while True:
        # not receive_text(): it fails with KeyError on a binary message, ending the connection
        message = await ws.receive()
        if message["type"] == "websocket.disconnect":
            raise WebSocketDisconnect(message.get("code", 1000), message.get("reason"))
        verdict = rate.take(loop.time())
        if verdict == "close":
            await ws.close(code=1008, reason=f"over {RATE_LIMIT_PER_S} messages a second")
            return
        if verdict == "over":
            await ws.send_json(
                {
                    "type": "error",
                    "error": f"over {RATE_LIMIT_PER_S} messages a second: dropped, with the "
                    "rest of this second's (going on closes the connection)",
                }
            )
        if verdict != "ok":
            continue
        text = message.get("text")
        if text is None:
            await ws.send_json(
                {"type": "error", "error": "binary messages are not accepted: send JSON as text"}
            )
            continue
        await _answer(ws, hub, text, client)


async def _answer(ws: WebSocket, hub: MonitorHub, text: str, client: int) -> None:
    """Validate one text message, act on it and reply (an error reply for a malformed one)."""
    if len(text.encode()) > MAX_MESSAGE_BYTES:
        await ws.send_json({"type": "error", "error": f"message over {MAX_MESSAGE_BYTES} bytes"})
        return
    try:
        message = ClientMessage.validate_json(text)
    except ValidationError as exc:
        await ws.send_json({"type": "error", "error": _error_text(exc)})
        return
    try:
        if isinstance(message, ModeMessage):
            hub.set_mode(message.mode, client)  # not a mode of this robot: it stays as it was
            reply: dict[str, Any] = {"type": "ack", "mode": message.mode}
        elif isinstance(message, ManualMessage):
            hub.set_manual(message.v_mps, message.w_radps, client)  # not the manual page: no
            reply = {"type": "ack", "manual": [message.v_mps, message.w_radps]}
        else:
            reply = {"type": "pong", "t": message.t}
    except ValueError as exc:
        reply = {"type": "error", "error": str(exc)}
    await ws.send_json(reply)


def _names(host: str) -> frozenset[str] | None:
    """The names a request to a server bound to ``host`` may give as its ``Host``: the
    loopback names for a loopback host, any (``None``) for every interface (a token guards
    those), else ``host`` itself."""
    host = host.strip("[]").lower()
    if host in LOOPBACK_HOSTS:
        return LOOPBACK_HOSTS
    return None if host in ("", "0.0.0.0", "::") else frozenset({host})


def _address(netloc: str, scheme: str) -> tuple[str, int] | None:
    """``(host, port)`` of a ``Host`` header or an origin's ``host[:port]`` (the scheme's
    default port if none); ``None`` if it is not one."""
    if not netloc or any(c in netloc for c in "@/\\?#"):
        return None
    try:
        parts = urlsplit(f"//{netloc}")
        port = parts.port
    except ValueError:
        return None
    default = 443 if scheme in ("https", "wss") else 80
    return (parts.hostname, default if port is None else port) if parts.hostname else None


class _SameOrigin:
    """ASGI middleware: a request whose ``Host`` is not one of ``names`` (``None``: any) is
    refused with 400, and a WebSocket whose ``Origin`` is not the ``Host`` it asked for with
    403 (a page of another site or port); one without ``Origin`` (a script) goes through."""

    def __init__(self, app: ASGIApp, names: frozenset[str] | None) -> None:
        self.app = app
        self.names = names

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] in ("http", "websocket"):
            status, why = self._refusal(scope)
            if why and scope["type"] == "http":
                await PlainTextResponse(why, status_code=status)(scope, receive, send)
                return
            if why:
                await _refuse(WebSocket(scope, receive, send), why, status)
                return
        await self.app(scope, receive, send)

    def _refusal(self, scope: Scope) -> tuple[int, str]:
        headers = Headers(scope=scope)
        host = headers.get("host", "")
        address = _address(host, scope.get("scheme", "http"))
        if address is None or (self.names is not None and address[0] not in self.names):
            return 400, f"Host {host!r} is not this monitor's address"
        origin = headers.get("origin")
        if scope["type"] == "websocket" and origin is not None:
            parts = urlsplit(origin)
            own = parts.scheme in ("http", "https") and not parts.path.strip("/")
            if not own or _address(parts.netloc, parts.scheme) != address:
                return 403, f"Origin {origin!r} is not this monitor's page: refused"
        return 200, ""


def _capped(max_connections: int, header_timeout_s: float) -> type[H11Protocol]:
    """uvicorn's HTTP/1.1 protocol (h11), holding at most ``max_connections`` connections (one
    more is answered 503 and closed as it is accepted) and closing one that has not sent a
    request's head ``header_timeout_s`` after it opened or after its last response (408)."""
    busy = _raw_response(503, f"the monitor holds {max_connections} connections at most")
    late = _raw_response(408, f"no request within {header_timeout_s:g} s")

    class Capped(H11Protocol):
        refused = False

        def connection_made(self, transport: asyncio.Transport) -> None:  # type: ignore[override]
            super().connection_made(transport)
            # those refused just now are in the set until their close is done: not counted
            held = sum(not getattr(c, "refused", False) for c in self.connections)
            if held > max_connections:
                self.refused = True
                transport.write(busy)  # a few bytes: the kernel takes them, nothing waits
                transport.close()
            else:
                self._deadline()

        def on_response_complete(self) -> None:
            super().on_response_complete()
            self._deadline()

        def _deadline(self) -> None:
            self.loop.call_later(header_timeout_s, self._late, self.cycle)

        def _late(self, cycle: Any) -> None:
            transport = self.transport
            # unless a request came since (a new cycle), it became a WebSocket, or it closed
            mine = self.cycle is cycle and transport.get_protocol() is self
            if mine and not transport.is_closing():
                transport.write(late)
                transport.close()

    return Capped


def _raw_response(status: int, text: str) -> bytes:
    """A whole HTTP/1.1 response that closes the connection, sent before any request."""
    head = f"HTTP/1.1 {status} {HTTPStatus(status).phrase}\r\ncontent-type: text/plain"
    tail = f"content-length: {len(text)}\r\nconnection: close\r\n\r\n{text}"
    return f"{head}\r\n{tail}".encode("ascii")


class Server:
    """uvicorn serving an app in a background thread; :meth:`stop` ends it.

    :param max_connections: TCP connections held at once (:data:`MAX_CONNECTIONS`).
    :param header_timeout_s: longest wait for a request's head, s (:data:`HEADER_TIMEOUT_S`).

    Requests whose ``Host`` is not one of ``host``'s names, and WebSockets from a page of
    another origin, are refused (module docstring).
    """

    def __init__(
        self,
        app: ASGIApp,
        host: str = "127.0.0.1",
        port: int = 8000,
        max_connections: int = MAX_CONNECTIONS,
        header_timeout_s: float = HEADER_TIMEOUT_S,
    ) -> None:
        # ws_max_size: the server reads no message far longer than the app accepts (the
        # default, 16 MiB, would buffer one in full only for the app to refuse it)
        config = uvicorn.Config(
            _SameOrigin(app, _names(host)),
            host=host,
            port=port,
            log_level="warning",
            lifespan="off",
            ws_max_size=WS_MAX_BYTES,
            http=_capped(max_connections, header_timeout_s),
            limit_concurrency=max_connections,
            timeout_keep_alive=KEEP_ALIVE_S,
            backlog=BACKLOG,
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
                        f"the monitor could not listen on {host_text(self.host)}:{self.port}{why}"
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
        return f"http://{host_text(self.host)}:{self.port}/"

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

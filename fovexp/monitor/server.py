"""``fovexp monitor``'s web server: a read-only page over a results folder, on Starlette and
uvicorn, updated by server-sent events (docs/EXPERIMENT.md, "The operator's live view").

Routes (every one GET or HEAD):

- ``/``: the page (``static/index.html``; its script and style sheet under ``/static/``, shipped
  in the wheel: nothing is fetched from elsewhere, so it works offline);
- ``/api/sessions``: every session under the results folder (JSON);
- ``/api/session?key=EXPERIMENT/PARTICIPANT/SESSION``: one session's view (JSON);
- ``/api/stream?key=...``: the same as server-sent events, a new event whenever something
  changed (the runner writes its status a few times a second) and at least every 2 s;
- ``/report/...``: ``fovexp analyze``'s report folder (``--report``), when one is given.

:class:`Guard` refuses, before any route runs, what a read-only page never needs: another method,
a request body, an over-long address, a missing or wrong token (when the server is reachable from
the network), a Host header other than the loopback's (when it is not: a web page elsewhere
cannot reach it by a DNS name pointing at 127.0.0.1). A session is named by its key, which must
be one of the sessions found under the results folder, whose folder must lie inside it.

Every refused request (the guard's refusals, and a route's 4xx: a path or session that is not
there) is logged as one line on the ``fovexp.monitor`` logger (``fovexp monitor`` prints it on
stderr): the time, the client's address, the method, the path with any ``token`` value in the
query replaced by ``REDACTED`` (and the token itself wherever else it appears), and why, so the
operator sees every attempt without the log giving the token away.
"""

from __future__ import annotations

import asyncio
import hmac
import http
import ipaddress
import json
import logging
import threading
import time
from collections.abc import AsyncIterator, Awaitable, Callable, MutableMapping
from pathlib import Path
from typing import Any
from urllib.parse import parse_qs, quote, unquote_plus

from starlette.applications import Starlette
from starlette.requests import Request
from starlette.responses import FileResponse, JSONResponse, Response, StreamingResponse
from starlette.routing import Mount, Route
from starlette.staticfiles import StaticFiles

from .view import ResultsView

Scope = MutableMapping[str, Any]
Message = MutableMapping[str, Any]
Receive = Callable[[], Awaitable[Message]]
Send = Callable[[Message], Awaitable[None]]
ASGIApp = Callable[[Scope, Receive, Send], Awaitable[None]]

STATIC = Path(__file__).resolve().parent / "static"
#: the cookie that carries the token after the first request with ``?token=``
TOKEN_COOKIE = "fovexp_monitor_token"
#: the longest path and query string accepted (bytes)
MAX_PATH, MAX_QUERY = 1024, 2048
#: how often the stream looks for changes, and the longest silence between two events (s)
STREAM_TICK_S, STREAM_KEEPALIVE_S = 0.25, 2.0
LOOPBACK_HOSTS = frozenset({"127.0.0.1", "localhost", "::1", "[::1]"})
#: the logger of refused requests (module docstring)
LOG = logging.getLogger("fovexp.monitor")
#: what stands in a logged address for a token
REDACTED = "REDACTED"
#: the longest path a log line shows (characters; the rest is counted)
MAX_LOGGED_PATH = 300

_HEADERS = [
    (b"x-content-type-options", b"nosniff"),
    (b"referrer-policy", b"no-referrer"),  # the token never leaks through a link
    (b"x-frame-options", b"DENY"),
    (b"cache-control", b"no-store"),
]
_CSP_PAGE = (b"default-src 'self'; img-src 'self' data:; style-src 'self'; script-src 'self'; "
             b"connect-src 'self'; frame-ancestors 'none'; base-uri 'none'; form-action 'none'")
# report.html carries its own style sheet and no script
_CSP_REPORT = (b"default-src 'self'; img-src 'self' data:; style-src 'unsafe-inline'; "
               b"script-src 'none'; frame-ancestors 'none'; base-uri 'none'; form-action 'none'")


def is_loopback(host: str) -> bool:
    """Whether binding ``host`` serves this machine only."""
    if host in ("localhost",):
        return True
    try:
        return ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:
        return False


class Guard:
    """Refuses hostile requests before the app sees them (module docstring), and adds the
    security headers to every response. ``token`` None: no token (a loopback-only server)."""

    def __init__(self, app: ASGIApp, token: str | None, loopback_only: bool) -> None:
        self.app, self.token, self.loopback_only = app, token, loopback_only

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        refusal, set_cookie = self._check(scope)
        path = scope.get("path", "")
        csp = _CSP_REPORT if path.startswith("/report/") else _CSP_PAGE

        async def send_with_headers(message: Message) -> None:
            if message["type"] == "http.response.start":
                headers = list(message.get("headers", []))
                headers += [*_HEADERS, (b"content-security-policy", csp)]
                if set_cookie:
                    headers.append((b"set-cookie", f"{TOKEN_COOKIE}={self.token}; HttpOnly; "
                                    "SameSite=Strict; Path=/".encode()))
                message["headers"] = headers
            await send(message)

        if refusal is not None:
            status, text = refusal
            self._log_refusal(scope, status, text)
            await Response(text + "\n", status_code=status, media_type="text/plain")(
                scope, receive, send_with_headers)
            return
        answered: list[int] = []

        async def send_noting_status(message: Message) -> None:
            if message["type"] == "http.response.start":
                answered.append(int(message.get("status", 200)))
            await send_with_headers(message)

        await self.app(scope, receive, send_noting_status)
        if answered and 400 <= answered[0] < 500:  # a path or session that is not there
            self._log_refusal(scope, answered[0], _phrase(answered[0]))

    def _log_refusal(self, scope: Scope, status: int, reason: str) -> None:
        """One line for a refused request (module docstring); never the token."""
        client = scope.get("client")
        if client:
            host = str(client[0])
            where = f"[{host}]:{client[1]}" if ":" in host else f"{host}:{client[1]}"
        else:
            where = "?"
        method = _printable(str(scope.get("method", "?")))[:20]
        line = (f"fovexp monitor: refused {time.strftime('%Y-%m-%d %H:%M:%S')} {where} "
                f"{method} {redacted_target(scope, self.token)}: {status} {reason}")
        LOG.warning(self._redact(line))

    def _redact(self, text: str) -> str:
        if self.token:
            for form in {self.token, quote(self.token, safe="")}:
                text = text.replace(form, REDACTED)
        return text

    def _check(self, scope: Scope) -> tuple[tuple[int, str] | None, bool]:
        """(status, reason) of a refusal or None; and whether to set the token's cookie."""
        headers = {k.decode("latin-1").lower(): v.decode("latin-1")
                   for k, v in scope.get("headers", [])}
        if scope.get("method") not in ("GET", "HEAD"):
            return (405, "read-only: only GET and HEAD"), False
        length = headers.get("content-length", "0").strip() or "0"
        if "transfer-encoding" in headers or not length.isdigit() or int(length) > 0:
            return (413, "a request body is never accepted"), False
        raw_path = scope.get("raw_path") or scope.get("path", "").encode()
        query = scope.get("query_string", b"")
        if len(raw_path) > MAX_PATH or len(query) > MAX_QUERY:
            return (414, "address too long"), False
        if self.loopback_only:
            host = headers.get("host", "")
            name = host.rsplit(":", 1)[0] if not host.startswith("[") else host.split("]")[0] + "]"
            if name not in LOOPBACK_HOSTS:
                return (400, f"Host {host[:60]!r}: this server answers 127.0.0.1 only"), False
        if self.token is None:
            return None, False
        given = parse_qs(query.decode("latin-1")).get("token", [None])[-1]
        if given is not None:
            if hmac.compare_digest(given.encode(), self.token.encode()):
                return None, True
            return (403, "wrong token"), False
        cookie = _cookie(headers.get("cookie", ""), TOKEN_COOKIE)
        if cookie is not None and hmac.compare_digest(cookie.encode(), self.token.encode()):
            return None, False
        return (403, "this server needs the token it printed at its start: open the address "
                     "with ?token=..."), False


def _phrase(status: int) -> str:
    try:
        return http.HTTPStatus(status).phrase.lower()
    except ValueError:
        return "refused"


def _printable(text: str) -> str:
    """``text`` with control and non-ASCII characters escaped: one log line, as sent."""
    return "".join(c if " " <= c <= "~" else f"\\x{ord(c):02x}" for c in text)


def redacted_target(scope: Scope, token: str | None = None) -> str:
    """The request's path and query as sent, for a log line: the value of every ``token``
    parameter (however its name is encoded or capitalised) replaced by :data:`REDACTED`, and
    ``token`` itself wherever else it appears; escaped to one printable line, and cut at
    :data:`MAX_LOGGED_PATH` characters (the rest counted)."""
    path = (scope.get("raw_path") or scope.get("path", "").encode()).decode("latin-1")
    query = scope.get("query_string", b"").decode("latin-1")
    pairs = []
    for pair in query.split("&") if query else []:
        name, eq, _ = pair.partition("=")
        if unquote_plus(name).strip().lower() == "token":
            pair = f"{name}={REDACTED}" if eq else name
        pairs.append(pair)
    target = path + ("?" + "&".join(pairs) if query else "")
    if token:
        for form in {token, quote(token, safe="")}:
            target = target.replace(form, REDACTED)
    target = _printable(target)
    if len(target) > MAX_LOGGED_PATH:
        target = f"{target[:MAX_LOGGED_PATH]}... ({len(target)} characters)"
    return target


def _cookie(header: str, name: str) -> str | None:
    for part in header.split(";"):
        k, _, v = part.strip().partition("=")
        if k == name:
            return v
    return None


def create_app(view: ResultsView, token: str | None = None, loopback_only: bool = True,
               stopping: threading.Event | None = None) -> ASGIApp:
    """The monitor's ASGI app over ``view`` (module docstring); ``stopping`` ends the event
    streams (the server is shutting down)."""
    lock = threading.Lock()  # the view's caches are not shared between threads
    stopping = stopping or threading.Event()

    def locked(fn: Callable[..., Any], *args: Any) -> Any:
        with lock:
            return fn(*args)

    def snapshot(key: str | None) -> dict[str, Any]:
        data: dict[str, Any] = locked(view.snapshot, key)
        return data

    async def index(request: Request) -> Response:
        return FileResponse(STATIC / "index.html", media_type="text/html")

    async def sessions(request: Request) -> Response:
        data = await asyncio.to_thread(snapshot, None)
        return JSONResponse({"server_time": data["server_time"], "sessions": data["sessions"]})

    async def session(request: Request) -> Response:
        key = request.query_params.get("key", "")
        data = await asyncio.to_thread(locked, view.session, key)
        if data is None:
            return JSONResponse({"error": "no such session under the results folder"},
                                status_code=404)
        return JSONResponse(data)

    async def stream(request: Request) -> Response:
        key = request.query_params.get("key") or None
        if key is not None:
            if await asyncio.to_thread(locked, view.resolve, key) is None:
                return JSONResponse({"error": "no such session under the results folder"},
                                    status_code=404)

        async def events() -> AsyncIterator[str]:
            last, sent_at = None, -1e9
            loop = asyncio.get_running_loop()
            yield "retry: 1000\n\n"
            while not stopping.is_set():
                data = await asyncio.to_thread(snapshot, key)
                body = json.dumps({k: v for k, v in data.items() if k != "server_time"},
                                  default=str)
                now = loop.time()
                if body != last or now - sent_at >= STREAM_KEEPALIVE_S:
                    last, sent_at = body, now
                    yield f"data: {json.dumps(data, default=str)}\n\n"
                await asyncio.sleep(STREAM_TICK_S)

        return StreamingResponse(events(), media_type="text/event-stream",
                                 headers={"x-accel-buffering": "no"})

    routes: list[Any] = [
        Route("/", index, methods=["GET", "HEAD"]),
        Route("/api/sessions", sessions, methods=["GET", "HEAD"]),
        Route("/api/session", session, methods=["GET", "HEAD"]),
        Route("/api/stream", stream, methods=["GET"]),
        Mount("/static", app=StaticFiles(directory=STATIC), name="static"),
    ]
    if view.report is not None and view.report.is_dir():
        routes.append(Mount("/report", app=StaticFiles(directory=view.report), name="report"))
    else:
        async def no_report(request: Request) -> Response:
            return Response("no report folder: start fovexp monitor with --report DIR (the "
                            "folder fovexp analyze wrote)\n", status_code=404,
                            media_type="text/plain")
        routes.append(Route("/report/{rest:path}", no_report, methods=["GET", "HEAD"]))
    app = Starlette(routes=routes)
    return Guard(app, token, loopback_only)


__all__ = ["Guard", "LOG", "MAX_LOGGED_PATH", "MAX_PATH", "MAX_QUERY", "REDACTED", "STATIC",
           "TOKEN_COOKIE", "create_app", "is_loopback", "redacted_target"]

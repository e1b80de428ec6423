"""The ASGI middleware in front of every request: body limit, Host and Origin checks, security headers.

- Request bodies are capped at `MAX_BODY_BYTES` (64 KiB; the largest real request is well under 1 KiB):
  anything beyond it is answered 413 and never reaches the app. The process never holds more than the cap
  per request (`tests/server/station/test_body_limit.py` measures it): the rest of an oversized body (up
  to `DRAIN_LIMIT_BYTES`) is read and dropped so the client, which sends it all before reading, gets the
  answer; a longer declared body is answered at once and its connection closed.
- In open mode a Host that is not this machine is refused (400); a state-changing request (POST, PUT,
  PATCH, DELETE) from a foreign origin is refused (403) and audited.
- Every HTTP response carries Content-Security-Policy (with frame-ancestors 'self': only the station's own
  landing page may frame its pages), X-Content-Type-Options: nosniff, X-Frame-Options: SAMEORIGIN,
  Referrer-Policy: no-referrer, Cross-Origin-Opener-Policy and Cross-Origin-Resource-Policy: same-origin;
  Strict-Transport-Security under TLS; API responses are not cached.
"""

from __future__ import annotations

import json
from collections.abc import Callable

from starlette.types import ASGIApp, Message, Receive, Scope, Send

from server.station.api.gate import Gate

MAX_BODY_BYTES = 64 * 1024
DRAIN_LIMIT_BYTES = 32 * 1024 * 1024  # an oversized body up to this is read (and dropped) before the 413
MUTATING = {"POST", "PUT", "PATCH", "DELETE"}

CSP_DEFAULT = (
    "default-src 'none'; script-src 'self'; style-src 'self'; img-src 'self' data:; connect-src 'self'; "
    "frame-src 'self'; frame-ancestors 'self'; base-uri 'none'; form-action 'self'"
)
# the viser client is one HTML file with inline scripts and styles, web workers, WebAssembly and a library
# that evaluates strings: the page is the station's own, and connect-src/frame-ancestors still bind it
CSP_OPERATOR = (
    "default-src 'self'; script-src 'self' 'unsafe-inline' 'unsafe-eval' 'wasm-unsafe-eval' blob:; "
    "style-src 'self' 'unsafe-inline'; img-src 'self' data: blob:; font-src 'self' data:; "
    "connect-src 'self' data: blob:; worker-src 'self' blob:; frame-ancestors 'self'; base-uri 'none'; "
    "form-action 'self'"
)
# Swagger UI starts from an inline script
CSP_DOCS = (
    "default-src 'none'; script-src 'self' 'unsafe-inline'; style-src 'self' 'unsafe-inline'; "
    "img-src 'self' data:; connect-src 'self'; frame-ancestors 'self'; base-uri 'none'; form-action 'self'"
)


def csp_for(path: str) -> str:
    if path.startswith("/operator"):
        return CSP_OPERATOR
    if path == "/docs":
        return CSP_DOCS
    return CSP_DEFAULT


Refused = Callable[[Scope, str, str], None]
"""on_refused(scope, command, reason): audit a request refused here."""


class Guard:
    """The middleware (see the module docstring). on_refused audits refused state-changing requests."""

    def __init__(
        self, app: ASGIApp, *, gate: Gate, on_refused: Refused, max_body_bytes: int = MAX_BODY_BYTES
    ) -> None:
        self.app = app
        self.gate = gate
        self.on_refused = on_refused
        self.max_body_bytes = max_body_bytes

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] == "websocket":
            headers = _headers(scope)
            problem = self.gate.bad_host(headers)
            if problem is not None:
                await send({"type": "websocket.close", "code": 1008, "reason": problem[:120]})
                return
            await self.app(scope, receive, send)
            return
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        headers = _headers(scope)
        send = self._with_headers(scope, send)
        problem = self.gate.bad_host(headers)
        if problem is not None:
            await _problem(send, 400, problem)
            return
        method = scope["method"]
        if method in MUTATING:
            foreign = self.gate.foreign_origin(headers, scheme=scope.get("scheme", "http"))
            if foreign is not None:
                reason = f"refused: {foreign}; commands are accepted only from the station's own pages"
                self.on_refused(scope, f"{method} {scope['path']}", reason)
                await _problem(send, 403, reason)
                return
        declared = headers.get("content-length")
        if declared is not None:
            try:
                too_big = int(declared) > self.max_body_bytes
            except ValueError:
                await _problem(send, 400, "Content-Length is not a number")
                return
            if too_big:
                await self._too_large(receive, send, received=0, more=int(declared) <= DRAIN_LIMIT_BYTES)
                return
        if method in MUTATING or declared is not None or "transfer-encoding" in headers:
            body = bytearray()
            more = True
            while more:
                message = await receive()
                if message["type"] == "http.disconnect":
                    return
                body += message.get("body", b"")
                more = message.get("more_body", False)
                if len(body) > self.max_body_bytes:
                    await self._too_large(receive, send, received=len(body), more=more)
                    return
            await self.app(scope, _replay(bytes(body), receive), send)
            return
        await self.app(scope, receive, send)

    async def _too_large(self, receive: Receive, send: Send, *, received: int, more: bool) -> None:
        """Answer 413. The rest of a body up to DRAIN_LIMIT_BYTES is read and thrown away first (never held):
        a client sends its whole body before it reads the answer, and closing on unread data would reset
        the connection and lose the answer. A longer body is answered at once and its connection closed."""
        while more and received <= DRAIN_LIMIT_BYTES:
            message = await receive()
            if message["type"] == "http.disconnect":
                return
            received += len(message.get("body", b""))
            more = message.get("more_body", False)
        await _problem(
            send,
            413,
            f"request body larger than {self.max_body_bytes} bytes: every skyring request is small JSON",
            close=True,
        )

    def _with_headers(self, scope: Scope, send: Send) -> Send:
        path = scope["path"]
        tls = scope.get("scheme") == "https"

        async def wrapped(message: Message) -> None:
            if message["type"] == "http.response.start":
                headers = list(message.get("headers", []))
                present = {k.lower() for k, _ in headers}
                extra = {
                    b"content-security-policy": csp_for(path).encode(),
                    b"x-content-type-options": b"nosniff",
                    b"x-frame-options": b"SAMEORIGIN",
                    b"referrer-policy": b"no-referrer",
                    b"cross-origin-opener-policy": b"same-origin",
                    b"cross-origin-resource-policy": b"same-origin",
                }
                if tls:
                    extra[b"strict-transport-security"] = b"max-age=31536000"
                if path.startswith(("/api", "/auth")):
                    extra[b"cache-control"] = b"no-store"
                headers += [(k, v) for k, v in extra.items() if k not in present]
                message = {**message, "headers": headers}
            await send(message)

        return wrapped


def _headers(scope: Scope) -> dict[str, str]:
    return {k.decode("latin-1").lower(): v.decode("latin-1") for k, v in scope.get("headers", [])}


def _replay(body: bytes, receive: Receive) -> Receive:
    sent = False

    async def replay() -> Message:
        nonlocal sent
        if not sent:
            sent = True
            return {"type": "http.request", "body": body, "more_body": False}
        return await receive()

    return replay


async def _problem(send: Send, status: int, detail: str, *, close: bool = False) -> None:
    body = json.dumps({"detail": detail}).encode()
    headers = [(b"content-type", b"application/json"), (b"content-length", str(len(body)).encode())]
    if close:
        headers.append((b"connection", b"close"))
    await send({"type": "http.response.start", "status": status, "headers": headers})
    await send({"type": "http.response.body", "body": body})

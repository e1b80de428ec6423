"""The operator's 3-D page behind the station's one gate: viser listens on 127.0.0.1 only (an internal port),
and this front serves its page at /operator/ and forwards its WebSocket at /operator, so the page has the
station's origin, sign-in, Origin check and security headers.

viser has no hook to tell who a connection belongs to, so each forwarded connection carries a fresh random
ticket header (`webui.app.TICKET_HEADER`) bound to the browser's session; `TicketAccess` turns a viser
client id back into that operator (re-checking the session on every use, so a sign-out takes control away at
once). A connection straight to viser's internal port carries no ticket and is closed before viser sends
it anything, so a local web page cannot read the scene or command through that port either.
"""

from __future__ import annotations

import asyncio
import contextlib
import secrets
import threading
from pathlib import Path

import viser
import websockets
from fastapi import APIRouter, Request, WebSocket
from fastapi.responses import HTMLResponse, RedirectResponse, Response
from websockets.asyncio.client import connect

from server.station.api.deps import caller
from server.station.api.display import sign_in_redirect_target
from server.station.api.gate import Gate, bearer_or_cookie
from webui.access import Principal, Surface
from webui.app import TICKET_HEADER

VISER_PAGE = Path(viser.__file__).resolve().parent / "client" / "build" / "index.html"
MAX_MESSAGE_BYTES = 1 << 20  # browser -> viser messages are small GUI and camera updates

router = APIRouter(include_in_schema=False)


class TicketAccess:
    """`webui.access.ClientAccess` for forwarded viser connections: ticket -> session token -> operator."""

    def __init__(self, gate: Gate) -> None:
        self._gate = gate
        self._lock = threading.Lock()
        self._tickets: dict[str, tuple[str | None, str]] = {}  # ticket -> (session token, remote)
        self._clients: dict[int, tuple[str | None, str]] = {}

    def issue(self, token: str | None, remote: str) -> str:
        ticket = secrets.token_urlsafe(24)
        with self._lock:
            self._tickets[ticket] = (token, remote)
        return ticket

    def revoke(self, ticket: str) -> None:
        with self._lock:
            self._tickets.pop(ticket, None)

    def client_connected(self, client_id: int, ticket: str | None) -> bool:
        """Admit a viser client only with a ticket this front issued for a connection it is forwarding."""
        with self._lock:
            issued = self._tickets.get(ticket or "")
            if issued is None:
                return False
            self._clients[client_id] = issued
            return True

    def client_disconnected(self, client_id: int) -> None:
        with self._lock:
            self._clients.pop(client_id, None)

    def principal_of(self, client_id: int) -> Principal:
        with self._lock:
            known = self._clients.get(client_id)
        if known is None:  # not forwarded by this front (refused at connect): nobody vouches for it
            return Principal(name="", role=None, surface=Surface.PAGE, remote="direct")
        token, remote = known
        return self._gate.principal(token, surface=Surface.PAGE, remote=remote)


@router.get("/operator")
def operator_redirect() -> RedirectResponse:
    return RedirectResponse("/operator/", status_code=308)


@router.get("/operator/", response_class=HTMLResponse)
def operator_page(request: Request) -> Response:
    if caller(request).role is None:
        return RedirectResponse(sign_in_redirect_target("/operator/", request), status_code=303)
    page: bytes = request.app.state.operator_page
    return Response(page, media_type="text/html; charset=utf-8")


@router.websocket("/operator")
async def operator_socket(websocket: WebSocket) -> None:
    app = websocket.app
    gate: Gate = app.state.gate
    access: TicketAccess = app.state.access
    client = websocket.client
    remote = f"{client.host}:{client.port}" if client is not None else ""
    token = bearer_or_cookie(websocket.headers, websocket.cookies)
    foreign = gate.foreign_origin(
        websocket.headers, scheme="https" if websocket.url.scheme == "wss" else "http"
    )
    if foreign is not None or gate.principal(token, surface=Surface.PAGE, remote=remote).role is None:
        await websocket.close(code=1008)
        return
    offered = [p.strip() for p in websocket.headers.get("sec-websocket-protocol", "").split(",") if p.strip()]
    ticket = access.issue(token, remote)
    try:
        async with connect(
            f"ws://127.0.0.1:{app.state.viser_port}",
            subprotocols=offered or None,  # type: ignore[arg-type]
            additional_headers={TICKET_HEADER: ticket},
            max_size=None,
            compression=None,
            # No keepalive on this loopback hop inside the process: a ping unanswered for 20 s (viser's thread
            # starved on a loaded machine) would drop a healthy operator's page. The browser's side keeps its.
            ping_interval=None,
        ) as upstream:
            await websocket.accept(subprotocol=upstream.subprotocol)

            async def down() -> None:
                async for message in upstream:
                    if isinstance(message, bytes):
                        await websocket.send_bytes(message)
                    else:
                        await websocket.send_text(message)

            async def up() -> None:
                while True:
                    message = await websocket.receive()
                    if message["type"] == "websocket.disconnect":
                        return
                    data = message.get("bytes") if message.get("bytes") is not None else message.get("text")
                    if data is None:
                        continue
                    if len(data) > MAX_MESSAGE_BYTES:
                        return
                    await upstream.send(data)

            tasks = [asyncio.create_task(down()), asyncio.create_task(up())]
            try:
                await asyncio.wait(tasks, return_when=asyncio.FIRST_COMPLETED)
            finally:
                for task in tasks:
                    task.cancel()
                await asyncio.gather(*tasks, return_exceptions=True)
    except (OSError, websockets.exceptions.WebSocketException):
        pass
    finally:
        access.revoke(ticket)
        with contextlib.suppress(Exception):
            await websocket.close()

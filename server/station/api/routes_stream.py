"""The WebSocket `/ws`: the operator's view streamed at `rate_hz`, and operator commands sent the other way.

Each frame is the `SceneView` JSON of `GET /api/state`, encoded once per period for every client. A client
that falls behind skips frames (it always gets the newest); one whose send has not gone through within
`SEND_TIMEOUT_S` (its socket buffer full) is dropped and counted, so nothing is buffered without bound.

Commands: a text message `{"id": "...", "command": "land_all"}` (or set_formation with d_des_m and h_des_m,
add_obstacle with x_m, y_m and radius_m, remove_obstacle with obstacle_id, land/hold/release with
vehicle_id, start_formation, stop_formation, acknowledge_alert with alert_id, acknowledge_all_alerts; release
and start_formation take an optional `override`: true to take off although the pre-take-off checks refuse)
is answered `{"reply_to": "...", "accepted": true|false, "detail": "...", "result": ...}`; it runs the same
ground-station command on behalf of the signed-in operator and is audited (surface "ws") whether accepted or
refused. The handshake is refused (HTTP 403) from a foreign origin and, when sign-in is required, without a
session (cookie or bearer token).
"""

from __future__ import annotations

import asyncio
import contextlib
import json
from typing import Annotated, Literal

from fastapi import APIRouter, WebSocket
from pydantic import Field, TypeAdapter, ValidationError

from server.station.api.gate import Gate, bearer_or_cookie
from server.station.api.models import Strict
from server.station.commands import CommandError
from server.station.ground_station import GroundStation
from webui.access import Principal, Surface, acting_as
from webui.schema import scene_json

SEND_TIMEOUT_S = 2.0
MAX_PENDING_REPLIES = 16

router = APIRouter()


class _Command(Strict):
    id: str = Field(min_length=1, max_length=64)


class SetFormation(_Command):
    command: Literal["set_formation"]
    d_des_m: float
    h_des_m: float


class AddObstacle(_Command):
    command: Literal["add_obstacle"]
    x_m: float
    y_m: float
    radius_m: float


class RemoveObstacle(_Command):
    command: Literal["remove_obstacle"]
    obstacle_id: str = Field(min_length=1, max_length=64)


class Land(_Command):
    command: Literal["land", "hold"]
    vehicle_id: int


class Release(_Command):
    command: Literal["release"]
    vehicle_id: int
    override: bool = False


class StartFormation(_Command):
    command: Literal["start_formation"]
    override: bool = False


class TeamCommand(_Command):
    command: Literal["land_all", "stop_formation", "acknowledge_all_alerts"]


class AcknowledgeAlert(_Command):
    command: Literal["acknowledge_alert"]
    alert_id: str = Field(min_length=1, max_length=64)


AnyCommand = (
    SetFormation
    | AddObstacle
    | RemoveObstacle
    | Land
    | Release
    | StartFormation
    | TeamCommand
    | AcknowledgeAlert
)
WsCommand = Annotated[AnyCommand, Field(discriminator="command")]
WS_COMMAND = TypeAdapter(WsCommand)


class StateFeed:
    """The newest encoded frame of the view, made once per period while anyone listens."""

    def __init__(self, station: GroundStation, rate_hz: float) -> None:
        self._station = station
        self._period = 1.0 / rate_hz
        self._frame = b""
        self._seq = 0
        self._changed = asyncio.Event()
        self._listeners = 0
        self._task: asyncio.Task | None = None
        self.dropped_clients = 0

    async def _run(self) -> None:
        while self._listeners > 0:
            view = await asyncio.to_thread(self._station.scene_view)  # it may wait out a stall
            self._frame = scene_json(view)
            self._seq += 1
            self._changed.set()
            self._changed = asyncio.Event()
            await asyncio.sleep(self._period)
        self._task = None

    @contextlib.asynccontextmanager
    async def listening(self):
        self._listeners += 1
        if self._task is None:
            self._task = asyncio.create_task(self._run())
        try:
            yield self
        finally:
            self._listeners -= 1

    async def next_frame(self, seen: int) -> tuple[int, bytes]:
        """The newest frame after `seen` (waits for it)."""
        while self._seq <= seen:
            await self._changed.wait()
        return self._seq, self._frame


def _run_command(station: GroundStation, command: AnyCommand) -> object:
    if isinstance(command, SetFormation):
        return station.set_formation(d_des_m=command.d_des_m, h_des_m=command.h_des_m)
    if isinstance(command, AddObstacle):
        return station.add_obstacle(x_m=command.x_m, y_m=command.y_m, radius_m=command.radius_m)
    if isinstance(command, RemoveObstacle):
        return station.remove_obstacle(command.obstacle_id)
    if isinstance(command, Land):
        return (station.land if command.command == "land" else station.hold)(command.vehicle_id)
    if isinstance(command, AcknowledgeAlert):
        return station.acknowledge_alert(command.alert_id)
    if isinstance(command, Release):
        return station.release(command.vehicle_id, override=command.override)
    if isinstance(command, StartFormation):
        return station.set_formation_enabled(True, override=command.override)
    if command.command == "land_all":
        return station.land_all()
    if command.command == "acknowledge_all_alerts":
        return station.acknowledge_all_alerts()
    return station.set_formation_enabled(False)


def handle_command(station: GroundStation, principal: Principal, text: str) -> dict:
    """Run one command message for `principal`; the reply (refusals included, all audited)."""
    try:
        raw = json.loads(text)
    except ValueError:
        raw = None
    reply_to = raw.get("id") if isinstance(raw, dict) and isinstance(raw.get("id"), str) else None
    principal = principal.for_command(reply_to if reply_to and len(reply_to) <= 64 else None)
    try:
        command = WS_COMMAND.validate_python(raw)
    except ValidationError as exc:
        detail = "malformed command: " + "; ".join(
            f"{'.'.join(str(p) for p in e['loc'])}: {e['msg']}" for e in exc.errors()
        )
        name = (
            raw.get("command") if isinstance(raw, dict) and isinstance(raw.get("command"), str) else "unknown"
        )
        station.audit(principal, str(name)[:64], {}, accepted=False, message=detail)
        return {"reply_to": reply_to, "accepted": False, "detail": detail, "result": None}
    try:
        with acting_as(principal):
            result = _run_command(station, command)
    except CommandError as exc:
        return {"reply_to": reply_to, "accepted": False, "detail": str(exc), "result": None}
    return {"reply_to": reply_to, "accepted": True, "detail": "", "result": result}


@router.websocket("/ws")
async def stream(websocket: WebSocket) -> None:
    app = websocket.app
    gate: Gate = app.state.gate
    station: GroundStation = app.state.station
    feed: StateFeed = app.state.feed
    client = websocket.client
    remote = f"{client.host}:{client.port}" if client is not None else ""
    foreign = gate.foreign_origin(
        websocket.headers, scheme="https" if websocket.url.scheme == "wss" else "http"
    )
    token = bearer_or_cookie(websocket.headers, websocket.cookies)
    principal = gate.principal(token, surface=Surface.WS, remote=remote)
    if foreign is not None or principal.role is None:
        await websocket.close(code=1008)  # before accept: the handshake is answered 403
        return
    await websocket.accept()
    replies: asyncio.Queue[dict] = asyncio.Queue(MAX_PENDING_REPLIES)

    async def read() -> None:
        while True:
            text = await websocket.receive_text()
            current = gate.principal(
                token, surface=Surface.WS, remote=remote
            )  # a sign-out takes effect at once
            reply = await asyncio.to_thread(handle_command, station, current, text)
            replies.put_nowait(reply)  # QueueFull: a client that sends without reading is dropped

    async def write() -> None:
        seen = 0
        async with feed.listening():
            while True:
                frame_task = asyncio.ensure_future(feed.next_frame(seen))
                reply_task = asyncio.ensure_future(replies.get())
                try:
                    done, _ = await asyncio.wait(
                        {frame_task, reply_task}, return_when=asyncio.FIRST_COMPLETED
                    )
                finally:  # also when this writer is cancelled: no waiter outlives it
                    for task in (frame_task, reply_task):
                        task.cancel()
                if reply_task in done:
                    await asyncio.wait_for(
                        websocket.send_text(json.dumps(reply_task.result())), SEND_TIMEOUT_S
                    )
                if frame_task in done:
                    seen, frame = frame_task.result()
                    await asyncio.wait_for(websocket.send_text(frame.decode()), SEND_TIMEOUT_S)

    tasks = [asyncio.create_task(read()), asyncio.create_task(write())]
    try:
        done, _ = await asyncio.wait(tasks, return_when=asyncio.FIRST_EXCEPTION)
        for task in done:
            if isinstance(task.exception(), TimeoutError | asyncio.QueueFull):
                feed.dropped_clients += 1
    finally:
        for task in tasks:
            task.cancel()
        await asyncio.gather(*tasks, return_exceptions=True)
        with contextlib.suppress(Exception):
            await websocket.close(code=1013)

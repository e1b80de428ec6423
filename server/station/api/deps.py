"""FastAPI dependencies shared by the routers: the station and gate of the app, who is calling, and the
operator a command runs for (refused and audited here when the caller may not command)."""

from __future__ import annotations

import re
from typing import Annotated

from fastapi import Depends, HTTPException, Request
from fastapi.responses import Response
from pydantic import TypeAdapter

from server.station.api.gate import Gate, bearer_or_cookie
from server.station.ground_station import GroundStation
from webui.access import Principal, Surface

COMMAND_ID = re.compile(r"^[A-Za-z0-9_.:-]{1,64}$")


def station_of(request: Request) -> GroundStation:
    return request.app.state.station


def gate_of(request: Request) -> Gate:
    return request.app.state.gate


def remote_of(request: Request) -> str:
    client = request.client
    return f"{client.host}:{client.port}" if client is not None else ""


def caller(request: Request) -> Principal:
    """Who sent this request (not signed in: role None), with a command id: the request's X-Command-Id when
    it is a sane one, else a fresh one."""
    token = bearer_or_cookie(request.headers, request.cookies)
    principal = gate_of(request).principal(token, surface=Surface.API, remote=remote_of(request))
    given = request.headers.get("x-command-id")
    return principal.for_command(given if given and COMMAND_ID.match(given) else None)


def viewer(request: Request) -> Principal:
    """A caller who may watch (any signed-in role; everyone in open mode), else 401."""
    principal = caller(request)
    if principal.role is None:
        raise HTTPException(401, "sign in first: POST /auth/login (or open /login in a browser)")
    return principal


def commander(request: Request) -> Principal:
    """A caller who may command, else 401 (not signed in) or 403 (an observer), audited as refused."""
    principal = caller(request)
    if principal.may_command:
        return principal
    endpoint = request.scope.get("endpoint")
    command = getattr(endpoint, "__name__", request.url.path)
    if principal.role is None:
        status, detail = 401, "sign in as an operator to command the MAVs: POST /auth/login"
    else:
        status, detail = 403, f"{principal.name!r} is an {principal.role.value}: only an operator may command"
    arguments = {**request.path_params, **_query_arguments(request)}
    station_of(request).audit(principal, command, arguments, accepted=False, message=detail)
    raise HTTPException(status, detail, headers={"X-Command-Id": principal.command_id})


def _query_arguments(request: Request, *, most: int = 8, longest: int = 100) -> dict[str, str]:
    """The query parameters of a refused command for its audit record (e.g. override=true), bounded: the
    first `most`, each cut to `longest` characters."""
    items = list(request.query_params.items())[:most]
    return {k[:longest]: v[:longest] for k, v in items}


Viewer = Annotated[Principal, Depends(viewer)]
Commander = Annotated[Principal, Depends(commander)]


def json_response(
    adapter: TypeAdapter, value: object, *, status_code: int = 200, principal: Principal | None = None
) -> Response:
    """`value` as JSON through its TypeAdapter (the view types' own schema), with the command id if any."""
    headers = (
        {"X-Command-Id": principal.command_id} if principal is not None and principal.command_id else None
    )
    return Response(
        adapter.dump_json(value), status_code=status_code, media_type="application/json", headers=headers
    )

"""The ground station's HTTP front, assembled: REST under /api, the stream and commands on /ws, sign-in under
/auth, the operator's 3-D page at /operator/ (forwarded to viser), the landing page at /, OpenAPI at /docs,
all behind one `Guard` (body limit, Host/Origin checks, security headers) and one `Gate` (who is calling).

Every refusal is a `Problem` body (`{"detail": ..., "errors": [...]}`) with the status OpenAPI lists: 401 not
signed in, 403 an observer or a foreign origin, 404 an unknown vehicle or obstacle, 413 a body over 64 KiB,
422 a malformed request or a value the station does not allow now; nothing changes, and a refused command is
audited like an accepted one.
"""

from __future__ import annotations

import swagger_ui_bundle
from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from fastapi.staticfiles import StaticFiles
from starlette.exceptions import HTTPException
from starlette.types import Scope

from server.station.api import (
    operator_page,
    routes_auth,
    routes_commands,
    routes_pages,
    routes_state,
    routes_stream,
)
from server.station.api.deps import caller
from server.station.api.gate import Gate, bearer_or_cookie
from server.station.api.guard import MAX_BODY_BYTES, MUTATING, Guard
from server.station.api.models import FieldProblem, Problem
from server.station.commands import CommandError, UnknownTargetError
from server.station.ground_station import GroundStation, NotAuthorisedError
from webui.access import Surface


def _problem(
    status: int, detail: str, errors: list[FieldProblem] | None = None, headers=None
) -> JSONResponse:
    return JSONResponse(
        Problem(detail=detail, errors=errors or []).model_dump(), status_code=status, headers=headers
    )


def _install_error_handlers(app: FastAPI) -> None:
    @app.exception_handler(UnknownTargetError)
    async def _unknown(_: Request, exc: UnknownTargetError) -> JSONResponse:
        return _problem(404, str(exc))

    @app.exception_handler(NotAuthorisedError)
    async def _not_authorised(_: Request, exc: NotAuthorisedError) -> JSONResponse:
        return _problem(403 if exc.signed_in else 401, str(exc))

    @app.exception_handler(CommandError)
    async def _refused(_: Request, exc: CommandError) -> JSONResponse:
        return _problem(422, str(exc))

    @app.exception_handler(HTTPException)
    async def _http(request: Request, exc: HTTPException) -> JSONResponse:
        headers = exc.headers
        if exc.status_code == 405:  # list every method of the path, not only those of the route matched first
            methods = sorted(
                {
                    m
                    for r in app.routes
                    if getattr(r, "path", None) and r.matches(request.scope)[0].value
                    for m in (getattr(r, "methods", None) or ())
                }
            )
            headers = {"Allow": ", ".join(methods)}
        return _problem(exc.status_code, str(exc.detail), headers=headers)

    @app.exception_handler(RequestValidationError)
    async def _malformed(request: Request, exc: RequestValidationError) -> JSONResponse:
        errors = [
            FieldProblem(
                loc=[p if isinstance(p, int) else str(p) for p in e["loc"]], msg=e["msg"], type=e["type"]
            )
            for e in exc.errors()
        ]
        detail = "malformed request: " + "; ".join(f"{'.'.join(map(str, e.loc))}: {e.msg}" for e in errors)
        if request.method in MUTATING:
            principal = caller(request)
            endpoint = request.scope.get("endpoint")
            command = getattr(endpoint, "__name__", request.url.path)
            station: GroundStation = request.app.state.station
            station.audit(principal, command, {}, accepted=False, message=detail[:500])
        return _problem(422, detail, errors)


def create_app(
    station: GroundStation,
    *,
    viser_port: int,
    gate: Gate | None = None,
    access: operator_page.TicketAccess | None = None,
    ws_rate_hz: float = 20.0,
    max_body_bytes: int = MAX_BODY_BYTES,
) -> FastAPI:
    """The app over `station`. viser_port: viser's internal port on 127.0.0.1 (the page is forwarded there);
    gate: sign-in and origin rules (default: open mode, for a loopback station); access: the ticket access
    the viser UI was given (made here if None); ws_rate_hz: frames per second on /ws (>= 10 for the
    operator)."""
    gate = gate or Gate(None)
    app = FastAPI(
        title="skyring ground station",
        description="Live state and operator commands for a team of MAVs flying the active-perception "
        "formation. Sign in with POST /auth/login and send the token as `Authorization: Bearer <token>` "
        "(browsers get a cookie). Refusals are a Problem body saying what to do instead.",
        version="0.2.0",
        docs_url=None,
        redoc_url=None,
    )
    app.state.station = station
    app.state.gate = gate
    app.state.access = access or operator_page.TicketAccess(gate)
    app.state.viser_port = viser_port
    app.state.feed = routes_stream.StateFeed(station, ws_rate_hz)
    app.state.operator_page = operator_page.VISER_PAGE.read_bytes()
    _install_error_handlers(app)
    app.mount("/static/swagger", StaticFiles(directory=swagger_ui_bundle.swagger_ui_path), name="swagger")
    app.mount("/static/skyring", StaticFiles(directory=routes_pages.STATIC_DIR), name="skyring")
    for router in (
        routes_pages.router,
        routes_auth.router,
        routes_state.router,
        routes_commands.router,
        routes_stream.router,
        operator_page.router,
    ):
        app.include_router(router)

    def refused(scope: Scope, command: str, reason: str) -> None:
        headers = {k.decode("latin-1").lower(): v.decode("latin-1") for k, v in scope.get("headers", [])}
        cookies = {}
        for part in headers.get("cookie", "").split(";"):
            name, _, value = part.strip().partition("=")
            if name:
                cookies[name] = value
        client = scope.get("client")
        remote = f"{client[0]}:{client[1]}" if client else ""
        principal = gate.principal(bearer_or_cookie(headers, cookies), surface=Surface.API, remote=remote)
        station.audit(principal.for_command(), command, {}, accepted=False, message=reason)

    app.add_middleware(Guard, gate=gate, on_refused=refused, max_body_bytes=max_body_bytes)
    return app

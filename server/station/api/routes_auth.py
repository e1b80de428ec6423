"""Signing in and out: `POST /auth/login` opens a session (token in the body and in an HttpOnly,
SameSite=Strict cookie), `POST /auth/logout` ends it, `GET /auth/me` says who the caller is. Sign-ins,
failed ones too, are audited (never with the secret)."""

from __future__ import annotations

from fastapi import APIRouter, HTTPException, Request
from fastapi.responses import JSONResponse, Response

from server.station.api.deps import caller, gate_of, remote_of, station_of
from server.station.api.gate import SESSION_COOKIE, bearer_or_cookie
from server.station.api.models import COMMON_REFUSALS, Identity, SignedIn, SignInRequest, problem
from webui.access import Principal, Surface

router = APIRouter(prefix="/auth", tags=["sign-in"])


@router.post(
    "/login",
    response_model=SignedIn,
    responses={
        400: COMMON_REFUSALS[400],
        401: problem("wrong name or secret"),
        403: COMMON_REFUSALS[403],
        404: problem("this station runs without sign-in (loopback only)"),
        413: COMMON_REFUSALS[413],
        422: COMMON_REFUSALS[422],
        429: problem("too many failed sign-ins from this address: wait a minute"),
    },
)
def login(body: SignInRequest, request: Request) -> JSONResponse:
    gate = gate_of(request)
    if gate.open:
        raise HTTPException(404, "this station runs without sign-in: every local caller is the operator")
    host = request.client.host if request.client is not None else ""
    who = Principal(name=body.name, role=None, surface=Surface.API, remote=remote_of(request)).for_command()
    if gate.locked_out(host):
        station_of(request).audit(who, "sign_in", {}, accepted=False, message="locked out")
        raise HTTPException(429, "too many failed sign-ins from this address: wait a minute")
    opened = gate.sign_in(body.name, body.secret, host=host)
    if opened is None:
        station_of(request).audit(who, "sign_in", {}, accepted=False, message="wrong name or secret")
        raise HTTPException(401, "wrong name or secret")
    token, user = opened
    station_of(request).audit(
        Principal(
            name=user.name, role=user.role, surface=Surface.API, remote=who.remote, command_id=who.command_id
        ),
        "sign_in",
        {},
        accepted=True,
    )
    response = JSONResponse(
        SignedIn(name=user.name, role=user.role.value, token=token, expires_in_s=gate.session_s).model_dump()
    )
    response.set_cookie(
        SESSION_COOKIE,
        token,
        max_age=int(gate.session_s),
        httponly=True,
        samesite="strict",
        secure=gate.secure,
        path="/",
    )
    return response


@router.post("/logout", status_code=204, responses={403: COMMON_REFUSALS[403]})
def logout(request: Request) -> Response:
    gate_of(request).sign_out(bearer_or_cookie(request.headers, request.cookies))
    response = Response(status_code=204)
    response.delete_cookie(
        SESSION_COOKIE, path="/", httponly=True, samesite="strict", secure=gate_of(request).secure
    )
    return response


@router.get("/me", response_model=Identity)
def me(request: Request) -> Identity:
    principal = caller(request)
    return Identity(
        name=principal.name,
        role=principal.role.value if principal.role is not None else "",
        sign_in_required=not gate_of(request).open,
    )

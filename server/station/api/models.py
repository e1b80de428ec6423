"""The request and error bodies of the REST API: one strict pydantic model per request (no coercion: "9"
and true are not numbers; unknown fields are refused) and one error body for every refusal. Responses are
the operator's view types themselves (`webui.view`), so they are not repeated here."""

from __future__ import annotations

from typing import Any

from pydantic import BaseModel, ConfigDict, Field


class Strict(BaseModel):
    model_config = ConfigDict(strict=True, extra="forbid")


class FormationRequest(Strict):
    """The operator's formation parameters (metres)."""

    d_des_m: float = Field(description="desired horizontal distance of every MAV from the person (m)")
    h_des_m: float = Field(description="desired height of every MAV above the person's body centre (m)")


class ObstacleRequest(Strict):
    """A virtual obstacle to add: a vertical cylinder standing at ENU (x_m, y_m)."""

    x_m: float = Field(description="ENU x of the axis (m), inside the arena")
    y_m: float = Field(description="ENU y of the axis (m), inside the arena")
    radius_m: float = Field(description="cylinder radius (m), > 0")


class SignInRequest(Strict):
    """A sign-in: the operator's name and secret."""

    name: str = Field(min_length=1, max_length=64)
    secret: str = Field(min_length=1, max_length=256)


class SignedIn(BaseModel):
    """An open session: send `token` as `Authorization: Bearer <token>` (browsers get it as a cookie)."""

    name: str
    role: str = Field(description='"operator" (may command) or "observer" (may watch)')
    token: str
    expires_in_s: float


class Identity(BaseModel):
    """Who the caller is: name ("" when not signed in), role ("" when not signed in), and whether the
    station requires sign-in."""

    name: str
    role: str
    sign_in_required: bool


class FieldProblem(BaseModel):
    """One malformed part of a request: where (e.g. ["body", "d_des_m"]), what is wrong, and its kind."""

    loc: list[str | int]
    msg: str
    type: str


class Problem(BaseModel):
    """Every refusal: `detail` says what went wrong and what to do instead; `errors` lists each malformed
    field of a request that did not match its schema (empty otherwise)."""

    detail: str
    errors: list[FieldProblem] = Field(default_factory=list)


class LandAll(BaseModel):
    landing: list[int] = Field(description="the MAVs told to land")


class Acknowledged(BaseModel):
    acknowledged: int = Field(description="alerts newly acknowledged")


Responses = dict[int | str, dict[str, Any]]
"""FastAPI's `responses=`: status -> OpenAPI response (model and description)."""


def problem(description: str) -> dict[str, Any]:
    return {"model": Problem, "description": description}


COMMON_REFUSALS: Responses = {
    400: problem("the body is not JSON, or a bad Content-Length or Host"),
    401: problem("not signed in (the station requires sign-in)"),
    403: problem("signed in as an observer, or sent from a page of another origin"),
    413: problem("request body larger than 64 KiB"),
    422: problem("refused: a malformed request, or a value the station does not allow now"),
}

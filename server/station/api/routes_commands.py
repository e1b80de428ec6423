"""Operator commands over REST: each calls the same `GroundStation` method the page and the WebSocket call,
on behalf of the signed-in operator (`Commander`), and answers with the state it changed. A refusal is a
`Problem` (422; 404 for an unknown vehicle or obstacle; 401/403 for a caller who may not command) and
changes nothing; every command, accepted or refused, is audited with its X-Command-Id."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Path, Query, Request
from fastapi.responses import Response
from pydantic import TypeAdapter

from server.station.api.deps import Commander, json_response, station_of
from server.station.api.models import (
    COMMON_REFUSALS,
    Acknowledged,
    FormationRequest,
    LandAll,
    ObstacleRequest,
    Responses,
    problem,
)
from server.station.api.routes_state import FORMATION
from webui.access import acting_as
from webui.schema import ALERT, VEHICLE
from webui.view import Alert, FormationState, ObstacleView, VehicleView

OBSTACLE = TypeAdapter(ObstacleView)
LAND_ALL = TypeAdapter(LandAll)
ACKNOWLEDGED = TypeAdapter(Acknowledged)
NOT_FOUND: Responses = {404: problem("no such vehicle or obstacle")}
ObstacleId = Annotated[str, Path(min_length=1, max_length=64, description="e.g. v1")]
AlertId = Annotated[str, Path(min_length=1, max_length=64, description="e.g. a3")]
VehicleId = Annotated[int, Path(ge=0, le=1_000_000, description="1..K")]
Override = Annotated[
    bool, Query(description="take off or join although the pre-take-off checks refuse a MAV (audited)")
]

router = APIRouter(prefix="/api", tags=["commands"], responses=COMMON_REFUSALS)


def _formation(request: Request, principal) -> Response:
    return json_response(FORMATION, FormationState.of(station_of(request).scene_view()), principal=principal)


def _vehicle(request: Request, vehicle_id: int, principal) -> Response:
    view = next(v for v in station_of(request).scene_view().vehicles if v.vehicle_id == vehicle_id)
    return json_response(VEHICLE, view, principal=principal)


@router.put("/formation", response_model=FormationState, summary="Set d_des and h_des for every MAV")
def set_formation(body: FormationRequest, request: Request, principal: Commander) -> Response:
    with acting_as(principal):
        station_of(request).set_formation(d_des_m=body.d_des_m, h_des_m=body.h_des_m)
    return _formation(request, principal)


@router.post(
    "/formation/start",
    response_model=FormationState,
    responses={
        422: problem(
            "refused: a malformed request, or a MAV waiting to take off stands inside the person's keep-out "
            "or within d_min of a teammate (repeat with override=true to start anyway)"
        )
    },
    summary="Start formation control",
)
def start_formation(request: Request, principal: Commander, override: Override = False) -> Response:
    with acting_as(principal):
        station_of(request).set_formation_enabled(True, override=override)
    return _formation(request, principal)


@router.post(
    "/formation/stop",
    response_model=FormationState,
    summary="Stop formation control: every MAV holds position",
)
def stop_formation(request: Request, principal: Commander) -> Response:
    with acting_as(principal):
        station_of(request).set_formation_enabled(False)
    return _formation(request, principal)


@router.post("/obstacles", response_model=ObstacleView, status_code=201, summary="Add a virtual obstacle")
def add_obstacle(body: ObstacleRequest, request: Request, principal: Commander) -> Response:
    with acting_as(principal):
        obstacle_id = station_of(request).add_obstacle(x_m=body.x_m, y_m=body.y_m, radius_m=body.radius_m)
    added = next(o for o in station_of(request).scene_view().obstacles if o.obstacle_id == obstacle_id)
    return json_response(OBSTACLE, added, status_code=201, principal=principal)


@router.delete(
    "/obstacles/{obstacle_id}",
    status_code=204,
    responses=NOT_FOUND,
    summary="Remove a virtual obstacle (trees stay)",
)
def remove_obstacle(obstacle_id: ObstacleId, request: Request, principal: Commander) -> Response:
    with acting_as(principal):
        station_of(request).remove_obstacle(obstacle_id)
    return Response(status_code=204, headers={"X-Command-Id": principal.command_id})


@router.post(
    "/vehicles/{vehicle_id}/land", response_model=VehicleView, responses=NOT_FOUND, summary="Land one MAV"
)
def land(vehicle_id: VehicleId, request: Request, principal: Commander) -> Response:
    with acting_as(principal):
        station_of(request).land(vehicle_id)
    return _vehicle(request, vehicle_id, principal)


@router.post(
    "/vehicles/{vehicle_id}/hold",
    response_model=VehicleView,
    responses={
        404: problem("no such vehicle"),
        422: problem(
            "refused: a malformed request, or the MAV is not flying (on the ground, landing, or "
            "holding already)"
        ),
    },
    summary="Stop one flying MAV where it is (release gives it back to the formation)",
)
def hold(vehicle_id: VehicleId, request: Request, principal: Commander) -> Response:
    with acting_as(principal):
        station_of(request).hold(vehicle_id)
    return _vehicle(request, vehicle_id, principal)


@router.post(
    "/vehicles/{vehicle_id}/release",
    response_model=VehicleView,
    responses={
        **NOT_FOUND,
        422: problem(
            "refused: a malformed request; the MAV is not landed or holding (nor airborne and free), is in "
            "its autopilot's failsafe, the formation has no room for it, or it stands inside the person's "
            "keep-out or within d_min of a teammate (repeat with override=true to release it anyway)"
        ),
    },
    summary="Give a landed MAV (or an airborne one skyring does not fly) back to the formation",
)
def release(
    vehicle_id: VehicleId, request: Request, principal: Commander, override: Override = False
) -> Response:
    with acting_as(principal):
        station_of(request).release(vehicle_id, override=override)
    return _vehicle(request, vehicle_id, principal)


@router.post("/land_all", response_model=LandAll, summary="Land every MAV")
def land_all(request: Request, principal: Commander) -> Response:
    with acting_as(principal):
        landing = station_of(request).land_all()
    return json_response(LAND_ALL, LandAll(landing=landing), principal=principal)


@router.post(
    "/alerts/{alert_id}/acknowledge",
    response_model=Alert,
    responses={404: problem("no such alert")},
    summary="Mark one alert as seen (it stays in the list)",
)
def acknowledge_alert(alert_id: AlertId, request: Request, principal: Commander) -> Response:
    with acting_as(principal):
        station_of(request).acknowledge_alert(alert_id)
    alert = next(a for a in station_of(request).scene_view().alerts if a.alert_id == alert_id)
    return json_response(ALERT, alert, principal=principal)


@router.post("/alerts/acknowledge", response_model=Acknowledged, summary="Mark every alert as seen")
def acknowledge_all_alerts(request: Request, principal: Commander) -> Response:
    with acting_as(principal):
        count = station_of(request).acknowledge_all_alerts()
    return json_response(ACKNOWLEDGED, Acknowledged(acknowledged=count), principal=principal)

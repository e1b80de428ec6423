"""Reading the state: everything the operator sees, the formation, the obstacles, the alerts (any signed-in
role)."""

from __future__ import annotations

from fastapi import APIRouter, Request
from fastapi.responses import Response
from pydantic import TypeAdapter

from server.station.api.deps import Viewer, json_response, station_of
from server.station.api.models import COMMON_REFUSALS
from webui.schema import ALERTS, OBSTACLES, SCENE
from webui.view import Alert, FormationState, ObstacleView, SceneView

FORMATION = TypeAdapter(FormationState)

router = APIRouter(prefix="/api", tags=["state"], responses={401: COMMON_REFUSALS[401]})


@router.get("/state", response_model=SceneView, summary="Everything the operator sees, now")
def get_state(request: Request, _: Viewer) -> Response:
    return json_response(SCENE, station_of(request).scene_view())


@router.get("/formation", response_model=FormationState, summary="The formation and what it may be set to")
def get_formation(request: Request, _: Viewer) -> Response:
    return json_response(FORMATION, FormationState.of(station_of(request).scene_view()))


@router.get("/obstacles", response_model=list[ObstacleView], summary="Trees and virtual obstacles")
def get_obstacles(request: Request, _: Viewer) -> Response:
    return json_response(OBSTACLES, station_of(request).scene_view().obstacles)


@router.get("/alerts", response_model=list[Alert], summary="Every alert so far, most urgent first")
def get_alerts(request: Request, _: Viewer) -> Response:
    return json_response(ALERTS, station_of(request).scene_view().alerts)

"""The ground station's HTTP face: REST under /api, a state stream on /ws, OpenAPI at /docs, and a landing
page at / that embeds the viser operator page.

Every command endpoint calls the same `GroundStation` method the viser GUI calls. A refusal is HTTP 422 (404
for an unknown vehicle or obstacle) with {"detail": "<what to do instead>"} and nothing changed. Bodies and
responses are pydantic models, so /docs documents them.
"""

from __future__ import annotations

import asyncio
import contextlib
import html
import math
from typing import Annotated

import swagger_ui_bundle
from fastapi import FastAPI, Path, Query, Request, WebSocket, WebSocketDisconnect
from fastapi.exceptions import RequestValidationError
from fastapi.openapi.docs import get_swagger_ui_html
from fastapi.responses import HTMLResponse, JSONResponse
from fastapi.staticfiles import StaticFiles
from pydantic import BaseModel, Field

from server.station.commands import CommandError, UnknownTargetError
from server.station.ground_station import GroundStation
from webui.view import Alert, SceneView, VehicleView

Vector3 = Annotated[list[float], Field(min_length=3, max_length=3)]
Override = Annotated[
    bool, Query(description="take off or join although the pre-take-off checks refuse a MAV (logged)")
]


class FormationModel(BaseModel):
    """The operator's formation parameters (metres)."""

    d_des_m: float = Field(description="desired horizontal distance of every MAV from the person (m)")
    h_des_m: float = Field(description="desired height of every MAV above the person's body centre (m)")


class FormationStateModel(FormationModel):
    enabled: bool = Field(description="formation control running (False: every MAV holds position)")
    d_des_range_m: tuple[float, float] = Field(description="what d_des_m may be set to now")
    h_des_range_m: tuple[float, float] = Field(description="what h_des_m may be set to")


class ObstacleIn(BaseModel):
    """A virtual obstacle to add: a vertical cylinder standing at ENU (x_m, y_m)."""

    x_m: float
    y_m: float
    radius_m: float = Field(description="cylinder radius (m), > 0")


class ObstacleModel(BaseModel):
    obstacle_id: str
    kind: str = Field(description='"tree" (part of the map) or "virtual" (placed by the operator)')
    x_m: float
    y_m: float
    radius_m: float
    height_m: float


class EstimateModel(BaseModel):
    position_m: Vector3
    position_cov_m2: list[Vector3] = Field(description="(3, 3) fused position covariance")
    position_cov_trace_m2: float
    source_vehicle_id: int | None = Field(description="the MAV whose tracker replica this is")


class CommandOutcomeModel(BaseModel):
    """One operator command as one vehicle's agent answered it."""

    command_id: int
    action: str = Field(description='"configure", "land", "hold" or "release"')
    outcome: str = Field(
        description='"pending", "acked", "refused" (message says why) or "failed" (timed out)'
    )
    message: str


class AgentModel(BaseModel):
    """A vehicle's onboard agent as the station hears it over Zenoh (`skyring serve --agents ...`)."""

    lost: bool = Field(description="no state heard from it for longer than the station's limit (0.5 s)")
    age_s: float = Field(description="seconds since its last state message")
    clock_offset_s: float | None = Field(description="its clock minus the station's (heartbeat round trip)")
    clock_skew: bool = Field(description="the offset exceeds 50 ms")
    tick_period_p99_error_s: float | None = Field(description="99th percentile of |tick period - nominal|")
    station_lost: bool = Field(description="it reports that it no longer hears the station")
    rejected_messages: int = Field(
        description="network messages it rejected (malformed, foreign, replayed...)"
    )
    commands: list[CommandOutcomeModel] = Field(description="recent commands, newest last")


class VehicleModel(BaseModel):
    vehicle_id: int
    phase: str
    in_formation: bool
    mode: str
    armed: bool
    in_air: bool
    position_m: Vector3
    yaw_rad: float
    battery_fraction: float | None
    link_age_s: float
    link_stale: bool
    solve_status: str
    solver_time_s: float | None
    plan_positions_m: list[Vector3] = Field(description="the latest horizon plan, (N+2, 3)")
    autopilot_mode: str = Field(
        description='the autopilot\'s own mode (PX4: "OFFBOARD", "LAND", "HOLD", "RETURN_TO_LAUNCH", ...)'
    )
    failsafe: bool = Field(description="the autopilot runs one of its own failsafes now")
    failsafe_reason: str | None = Field(description="the autopilot's words for its failsafe")
    can_arm: bool | None = Field(description="the autopilot's pre-arm checks pass (null: unknown or armed)")
    arming_refusal: str | None = Field(
        description="the autopilot's words for why it refused the last take-off (null once one succeeds)"
    )
    takeoff_check: str | None = Field(
        description="why this MAV may not take off or join where it stands (person keep-out, d_min), if so"
    )
    agent: AgentModel | None = Field(default=None, description="its onboard agent (None: in-process agents)")


class PersonModel(BaseModel):
    truth_m: Vector3 | None = Field(description="true body centre (simulation only)")
    estimate: EstimateModel | None
    tracking_error_m: float | None = Field(
        description="mean over MAVs of |estimate - truth| (simulation only)"
    )


class CountersModel(BaseModel):
    """Bad inputs refused and counted since start."""

    refused_commands: int = Field(description="operator commands refused (HTTP 422 / GUI notification)")
    rejected_detections: int = Field(description="detections the trackers gated out, stale or invalid")
    rejected_messages: int = Field(description="malformed or misaddressed messages between MAVs")
    controller_errors: int = Field(description="controller exceptions caught (the MAV braked)")
    braking_ticks: int = Field(description="ticks a MAV braked instead of applying an unsolved plan")


class AlertModel(BaseModel):
    """One alert (`webui.view.Alert`): persistent, time-stamped, acknowledged or not, active or cleared."""

    alert_id: str
    kind: str = Field(
        description="battery, separation, trunk_clearance, arena, link, agent, realtime, failsafe, arming "
        "or solver"
    )
    vehicle_id: int | None = Field(description="the MAV it concerns (null: the whole team)")
    subject: str = Field(description='the other party ("MAV 3", "trunk t4"), "" when none')
    severity: str = Field(description="info, warning or critical (the worst since it was last raised)")
    message: str = Field(description="the condition as it stands (or stood when it cleared)")
    first_s: float = Field(description="mission time it was first raised")
    last_s: float = Field(description="mission time the condition last held")
    first_utc_s: float | None = Field(description="wall time it was first raised (UTC, s since the epoch)")
    active: bool = Field(description="the condition still holds")
    acknowledged: bool = Field(description="an operator has seen it (cleared when it returns or worsens)")
    count: int = Field(description="times it was raised")


class AcknowledgedModel(BaseModel):
    acknowledged: int = Field(description="alerts newly acknowledged")


class StateModel(BaseModel):
    time_s: float
    formation: FormationStateModel
    vehicles: list[VehicleModel]
    person: PersonModel
    obstacles: list[ObstacleModel]
    arena_min_m: Vector3
    arena_max_m: Vector3
    counters: CountersModel
    alerts: list[AlertModel] = Field(description="every alert so far, most urgent first")


class LandAllModel(BaseModel):
    landing: list[int] = Field(description="the MAVs told to land")


def _num(value: float | None) -> float | None:
    return None if value is None or not math.isfinite(value) else float(value)


def _vec(values) -> list[float]:
    return [float(v) if math.isfinite(v) else 0.0 for v in values]


def formation_model(view: SceneView) -> FormationStateModel:
    return FormationStateModel(
        d_des_m=view.formation.d_des_m,
        h_des_m=view.formation.h_des_m,
        enabled=view.formation_enabled,
        d_des_range_m=(view.d_des_range_m.low, view.d_des_range_m.high),
        h_des_range_m=(view.h_des_range_m.low, view.h_des_range_m.high),
    )


def obstacle_model(obstacle) -> ObstacleModel:
    return ObstacleModel(
        obstacle_id=obstacle.obstacle_id,
        kind=obstacle.kind,
        x_m=float(obstacle.center_m[0]),
        y_m=float(obstacle.center_m[1]),
        radius_m=obstacle.radius_m,
        height_m=obstacle.height_m,
    )


def vehicle_model(v: VehicleView) -> VehicleModel:
    return VehicleModel(
        vehicle_id=v.vehicle_id,
        phase=v.phase,
        in_formation=v.in_formation,
        mode=v.mode,
        armed=v.armed,
        in_air=v.in_air,
        position_m=_vec(v.position_m),
        yaw_rad=float(v.yaw_rad),
        battery_fraction=_num(v.battery_fraction),
        link_age_s=float(v.link_age_s),
        link_stale=v.link_stale,
        solve_status=v.solve_status,
        solver_time_s=_num(v.solver_time_s),
        plan_positions_m=[_vec(p) for p in v.plan_positions_m],
        autopilot_mode=v.autopilot_mode,
        failsafe=v.failsafe,
        failsafe_reason=v.failsafe_reason,
        can_arm=v.can_arm,
        arming_refusal=v.arming_refusal,
        takeoff_check=v.takeoff_check,
        agent=None if v.agent is None else agent_model(v.agent),
    )


def agent_model(a) -> AgentModel:
    return AgentModel(
        lost=a.lost,
        age_s=float(a.age_s),
        clock_offset_s=_num(a.clock_offset_s),
        clock_skew=a.clock_skew,
        tick_period_p99_error_s=_num(a.tick_period_p99_error_s),
        station_lost=a.station_lost,
        rejected_messages=a.rejected_messages,
        commands=[
            CommandOutcomeModel(command_id=c, action=act, outcome=out, message=msg)
            for c, act, out, msg in a.commands
        ],
    )


def alert_model(alert: Alert) -> AlertModel:
    return AlertModel(
        alert_id=alert.alert_id,
        kind=alert.kind,
        vehicle_id=alert.vehicle_id,
        subject=alert.subject,
        severity=alert.severity.value,
        message=alert.message,
        first_s=alert.first_s,
        last_s=alert.last_s,
        first_utc_s=_num(alert.first_utc_s),
        active=alert.active,
        acknowledged=alert.acknowledged,
        count=alert.count,
    )


def state_model(view: SceneView, *, counters: dict[str, int]) -> StateModel:
    """The JSON state snapshot: the same view the 3-D page draws."""
    estimate = None
    if view.person_estimate is not None:
        cov = view.person_estimate.position_cov_m2
        estimate = EstimateModel(
            position_m=_vec(view.person_estimate.position_m),
            position_cov_m2=[_vec(row) for row in cov],
            position_cov_trace_m2=float(view.person_estimate.position_cov_trace_m2),
            source_vehicle_id=view.estimate_source_id,
        )
    person = PersonModel(
        truth_m=None if view.person_truth_m is None else _vec(view.person_truth_m),
        estimate=estimate,
        tracking_error_m=_num(view.tracking_error_m),
    )
    return StateModel(
        time_s=view.time_s,
        formation=formation_model(view),
        vehicles=[vehicle_model(v) for v in view.vehicles],
        person=person,
        obstacles=[obstacle_model(o) for o in view.obstacles],
        arena_min_m=_vec(view.arena_min_m),
        arena_max_m=_vec(view.arena_max_m),
        counters=CountersModel(**counters),
        alerts=[alert_model(a) for a in view.alerts],
    )


def landing_page(*, viser_url: str) -> str:
    """The page at /: the operator's 3-D view embedded full size (focused, so that its keyboard shortcuts work
    at once), with links to it, the API and the docs."""
    url = html.escape(viser_url, quote=True)
    return f"""<!doctype html>
<html lang="en"><head><meta charset="utf-8"><title>skyring ground station</title>
<link rel="icon" href="data:,">
<style>
html, body {{ margin: 0; height: 100%; font-family: sans-serif; }}
header {{ padding: 6px 12px; background: #223; color: #eee; font-size: 14px; }}
header a {{ color: #9cf; margin-left: 16px; }}
iframe {{ border: 0; width: 100%; height: calc(100% - 32px); display: block; }}
</style></head>
<body>
<header><b>skyring ground station</b>
<a id="operator-link" href="{url}" target="_blank">operator view (full window)</a>
<a href="/docs">API docs</a><a href="/api/state">state (JSON)</a></header>
<iframe id="operator-view" src="{url}" title="operator 3-D view"></iframe>
<script>
// keys go to the operator page (its Shift+L opens LAND ALL) unless the operator clicks elsewhere
const view = document.getElementById("operator-view");
view.addEventListener("load", () => view.focus());
</script>
</body></html>"""


def create_app(station: GroundStation, *, viser_port: int, ws_rate_hz: float = 20.0) -> FastAPI:
    """The FastAPI app over `station`; the landing page embeds viser at http://<the host the browser used>:
    viser_port. ws_rate_hz: how often /ws sends the state (>= 10 Hz for the operator)."""
    app = FastAPI(
        title="skyring ground station",
        description="Live state and operator commands for a team of MAVs flying the "
        "active-perception formation. Refusals are HTTP 422 with a message saying what "
        "to do instead.",
        version="0.1.0",
        docs_url=None,
    )
    # /docs from the swagger-ui files of the installed wheel: the field laptop may have no internet.
    app.mount("/static/swagger", StaticFiles(directory=swagger_ui_bundle.swagger_ui_path), name="swagger")

    @app.get("/docs", response_class=HTMLResponse, include_in_schema=False)
    async def docs() -> HTMLResponse:
        return get_swagger_ui_html(
            openapi_url=app.openapi_url or "/openapi.json",
            title="skyring API",
            swagger_js_url="/static/swagger/swagger-ui-bundle.js",
            swagger_css_url="/static/swagger/swagger-ui.css",
            swagger_favicon_url="/static/swagger/favicon-32x32.png",
        )

    @app.exception_handler(UnknownTargetError)
    async def _unknown(_: Request, exc: UnknownTargetError) -> JSONResponse:
        return JSONResponse(status_code=404, content={"detail": str(exc)})

    @app.exception_handler(CommandError)
    async def _refused(_: Request, exc: CommandError) -> JSONResponse:
        return JSONResponse(status_code=422, content={"detail": str(exc)})

    @app.exception_handler(RequestValidationError)
    async def _malformed(_: Request, exc: RequestValidationError) -> JSONResponse:
        problems = "; ".join(f"{'.'.join(str(p) for p in e['loc'])}: {e['msg']}" for e in exc.errors())
        return JSONResponse(status_code=422, content={"detail": f"malformed request: {problems}"})

    def state() -> StateModel:
        with station.lock:  # the view and the counters of one instant
            view, counters = station.scene_view(), station.counters()
        return state_model(view, counters=counters)

    @app.get("/", response_class=HTMLResponse, include_in_schema=False)
    async def index(request: Request) -> str:
        host = request.url.hostname or "127.0.0.1"
        return landing_page(viser_url=f"http://{host}:{viser_port}/")

    @app.get("/api/state", response_model=StateModel, summary="Everything the operator sees, now")
    async def get_state() -> StateModel:
        return state()

    @app.get("/api/formation", response_model=FormationStateModel)
    async def get_formation() -> FormationStateModel:
        return formation_model(station.scene_view())

    @app.put(
        "/api/formation",
        response_model=FormationStateModel,
        responses={422: {"description": "d_des or h_des not finite or outside the allowed range"}},
    )
    async def put_formation(body: FormationModel) -> FormationStateModel:
        station.set_formation(d_des_m=body.d_des_m, h_des_m=body.h_des_m)
        return formation_model(station.scene_view())

    @app.post(
        "/api/formation/start",
        response_model=FormationStateModel,
        responses={422: {"description": "a MAV inside the person's keep-out or within d_min of a teammate"}},
    )
    async def start_formation(override: Override = False) -> FormationStateModel:
        station.set_formation_enabled(True, override=override)
        return formation_model(station.scene_view())

    @app.post(
        "/api/formation/stop",
        response_model=FormationStateModel,
        summary="Stop formation control: every MAV holds position",
    )
    async def stop_formation() -> FormationStateModel:
        station.set_formation_enabled(False)
        return formation_model(station.scene_view())

    @app.get("/api/obstacles", response_model=list[ObstacleModel])
    async def get_obstacles() -> list[ObstacleModel]:
        return [obstacle_model(o) for o in station.scene_view().obstacles]

    @app.post(
        "/api/obstacles",
        response_model=ObstacleModel,
        status_code=201,
        responses={422: {"description": "outside the arena, bad radius, or covering the person or a MAV"}},
    )
    async def post_obstacle(body: ObstacleIn) -> ObstacleModel:
        obstacle_id = station.add_obstacle(x_m=body.x_m, y_m=body.y_m, radius_m=body.radius_m)
        return next(obstacle_model(o) for o in station.scene_view().obstacles if o.obstacle_id == obstacle_id)

    @app.delete(
        "/api/obstacles/{obstacle_id}",
        status_code=204,
        responses={404: {"description": "no such obstacle"}, 422: {"description": "a tree"}},
    )
    async def delete_obstacle(obstacle_id: Annotated[str, Path()]) -> None:
        station.remove_obstacle(obstacle_id)

    @app.post(
        "/api/vehicles/{vehicle_id}/land",
        response_model=VehicleModel,
        responses={404: {"description": "no such vehicle"}},
    )
    async def land(vehicle_id: Annotated[int, Path()]) -> VehicleModel:
        station.land(vehicle_id)
        return _vehicle(vehicle_id)

    @app.post(
        "/api/vehicles/{vehicle_id}/hold",
        response_model=VehicleModel,
        summary="Stop one flying MAV where it is (release gives it back to the formation)",
        responses={
            404: {"description": "no such vehicle"},
            422: {"description": "not flying (on the ground, landing, or holding already)"},
        },
    )
    async def hold(vehicle_id: Annotated[int, Path()]) -> VehicleModel:
        station.hold(vehicle_id)
        return _vehicle(vehicle_id)

    @app.get("/api/alerts", response_model=list[AlertModel], summary="Every alert so far, most urgent first")
    async def get_alerts() -> list[AlertModel]:
        return [alert_model(a) for a in station.scene_view().alerts]

    @app.post(
        "/api/alerts/{alert_id}/acknowledge",
        response_model=AlertModel,
        summary="Mark one alert as seen (it stays in the list)",
        responses={404: {"description": "no such alert"}},
    )
    async def acknowledge_alert(alert_id: Annotated[str, Path()]) -> AlertModel:
        station.acknowledge_alert(alert_id)
        return next(alert_model(a) for a in station.scene_view().alerts if a.alert_id == alert_id)

    @app.post("/api/alerts/acknowledge", response_model=AcknowledgedModel, summary="Mark every alert as seen")
    async def acknowledge_all_alerts() -> AcknowledgedModel:
        return AcknowledgedModel(acknowledged=station.acknowledge_all_alerts())

    @app.post(
        "/api/vehicles/{vehicle_id}/release",
        response_model=VehicleModel,
        responses={
            404: {"description": "no such vehicle"},
            422: {
                "description": "not landed or holding (nor airborne and free), in its autopilot's failsafe, "
                "no room in the formation, or inside the person's keep-out or within d_min of a teammate"
            },
        },
    )
    async def release(vehicle_id: Annotated[int, Path()], override: Override = False) -> VehicleModel:
        station.release(vehicle_id, override=override)
        return _vehicle(vehicle_id)

    @app.post("/api/land_all", response_model=LandAllModel)
    async def land_all() -> LandAllModel:
        return LandAllModel(landing=station.land_all())

    @app.websocket("/ws")
    async def stream(websocket: WebSocket) -> None:
        await websocket.accept()
        period = 1.0 / ws_rate_hz
        with contextlib.suppress(WebSocketDisconnect, RuntimeError, asyncio.CancelledError):
            while True:
                await websocket.send_text(state().model_dump_json())
                await asyncio.sleep(period)

    def _vehicle(vehicle_id: int) -> VehicleModel:
        return next(vehicle_model(v) for v in station.scene_view().vehicles if v.vehicle_id == vehicle_id)

    return app

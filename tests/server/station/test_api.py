"""The ground station's REST API and state stream, over a real simulated mission stepped by the test.

Every refusal is checked to be HTTP 422 (404 for an unknown target) with an actionable message and to leave
the state exactly as it was (only the refused-commands counter moves).
"""

from __future__ import annotations

import asyncio
import json
import math
import time

import httpx
import numpy as np
import pytest
import uvicorn
import websockets

from server.station.api.app import create_app
from server.station.ground_station import GroundStation
from vehicles.mission import Phase
from vehicles.sim.scenario import Scenario, build_sim

RATE_HZ = 20.0  # control rate of these tests (the mission runs at any rate; 20 Hz keeps them fast)
VISER_PORT = 18080


def make_station(**scenario) -> GroundStation:
    setup = build_sim(Scenario(**{"vehicles": 3, "seed": 3, **scenario}))
    return GroundStation(mission=setup.mission, control_period_s=1.0 / RATE_HZ)


def run_for(station: GroundStation, seconds: float) -> None:
    for _ in range(round(seconds * RATE_HZ)):
        station.tick()


def run_until(station: GroundStation, condition, *, limit_s: float) -> float:
    """Tick until condition(snapshot) holds; returns the simulated seconds it took (fails after limit_s)."""
    start = station.time_s
    while not condition(station.snapshot()):
        assert station.time_s - start < limit_s, f"condition not met within {limit_s} s of simulated time"
        station.tick()
    return station.time_s - start


def all_in_formation(snap) -> bool:
    return all(v.phase == Phase.FORMATION for v in snap.vehicles)


@pytest.fixture
def station() -> GroundStation:
    """Three MAVs on the ground at their start ring, one tick in (taking off)."""
    s = make_station()
    s.tick()
    return s


@pytest.fixture
def flying() -> GroundStation:
    """Three MAVs flying in formation."""
    s = make_station()
    run_until(s, all_in_formation, limit_s=30.0)
    return s


def client_for(station: GroundStation) -> httpx.AsyncClient:
    app = create_app(station, viser_port=VISER_PORT)
    return httpx.AsyncClient(transport=httpx.ASGITransport(app=app), base_url="http://127.0.0.1:8000")


def without_counters(state: dict) -> dict:
    """The state but for the counters and the view's wall time (utc_s moves on by itself)."""
    return {k: v for k, v in state.items() if k not in ("counters", "utc_s")}


async def assert_refused(
    client: httpx.AsyncClient, method: str, url: str, *, status: int = 422, match: str, **kwargs
) -> None:
    before = (await client.get("/api/state")).json()
    response = await client.request(method, url, **kwargs)
    assert response.status_code == status, response.text
    assert match in response.json()["detail"]
    after = (await client.get("/api/state")).json()
    assert without_counters(after) == without_counters(before)
    assert after["counters"]["refused_commands"] == before["counters"]["refused_commands"] + 1


def horizontal_distances(station: GroundStation) -> np.ndarray:
    snap = station.snapshot()
    assert snap.person_truth is not None
    person = snap.person_truth.position_m[:2]
    return np.array(
        [
            np.hypot(*(v.autopilot.position_m[:2] - person))
            for v in snap.vehicles
            if v.autopilot is not None
            if v.phase == Phase.FORMATION
        ]
    )


def bearings_deg(station: GroundStation, ids) -> np.ndarray:
    snap = station.snapshot()
    assert snap.person_truth is not None
    person = snap.person_truth.position_m
    return np.array(
        [
            math.degrees(math.atan2(*(v.autopilot.position_m[1::-1] - person[1::-1])))
            for v in snap.vehicles
            if v.autopilot is not None and v.vehicle_id in ids
        ]
    )


# ---- reading -----------------------------------------------------------------------------------------------


async def test_state_lists_vehicles_trees_person_and_formation(station):
    state = (await client_for(station).get("/api/state")).json()
    assert [v["vehicle_id"] for v in state["vehicles"]] == [1, 2, 3]
    assert all(v["phase"] == "takeoff" for v in state["vehicles"])
    assert len([o for o in state["obstacles"] if o["kind"] == "tree"]) == 13
    assert state["person_truth_m"] == pytest.approx([0.0, 0.0, 0.9], abs=1e-6)
    assert state["formation"]["d_des_m"] == 8.0 and state["formation_enabled"] is True
    assert state["arena_min_m"] == [-20.0, -20.0, 3.0]
    assert state["time_s"] == pytest.approx(1.0 / RATE_HZ)


async def test_state_of_a_flying_team_has_plans_estimate_and_solver_times(flying):
    run_for(flying, 3.0)
    state = (await client_for(flying).get("/api/state")).json()
    for v in state["vehicles"]:
        assert v["in_air"] and v["mode"] == "offboard" and not v["link_stale"]
        assert len(v["plan_positions_m"]) == 17
        # the solver's own time: 0 when the exact MPC's closed form solved the tick (no solver ran)
        assert 0.0 <= v["solver_time_s"] < 0.05
    estimate = state["person_estimate"]
    assert np.array(estimate["cov"]).shape == (6, 6)
    assert estimate["position_m"] == pytest.approx(flying.scene_view().person_estimate.position_m)
    assert state["tracking_error_m"] < 1.5


async def test_get_formation_gives_values_and_allowed_ranges(station):
    body = (await client_for(station).get("/api/formation")).json()
    assert body == {
        "d_des_m": 8.0,
        "h_des_m": 8.0,
        "enabled": True,
        "d_des_range_m": {"low": 1.8, "high": 18.5},
        "h_des_range_m": {"low": 2.1, "high": 9.1},
    }


async def test_get_obstacles_lists_the_paper_trees(station):
    obstacles = (await client_for(station).get("/api/obstacles")).json()
    assert len(obstacles) == 13
    assert obstacles[0]["kind"] == "tree" and obstacles[0]["center_m"] == [-14.0, -7.0]


async def test_landing_page_embeds_the_operator_view_from_the_same_origin():
    s = make_station()
    page = await client_for(s).get("/", headers={"host": "127.0.0.1:8000"})
    assert page.status_code == 200
    assert '<iframe id="operator-view" src="/operator/"' in page.text
    assert 'href="/docs"' in page.text
    assert "frame-ancestors 'self'" in page.headers["content-security-policy"]


@pytest.mark.parametrize(
    ("query", "src"),
    [
        ("?fixedDpr=0.5", "/operator/?fixedDpr=0.5"),
        ("?fixedDpr=0.50&x=1", "/operator/?fixedDpr=0.5"),
        ("?fixedDpr=0", "/operator/"),
        ("?fixedDpr=%22%3E%3Cscript%3E", "/operator/"),
    ],
)
async def test_landing_page_hands_a_valid_pixel_ratio_to_the_embedded_view_and_nothing_else(query, src):
    page = await client_for(make_station()).get("/" + query, headers={"host": "127.0.0.1:8000"})
    assert f'<iframe id="operator-view" src="{src}"' in page.text


async def test_docs_page_loads_swagger_from_this_server_only():
    client = client_for(make_station())
    page = await client.get("/docs")
    assert page.status_code == 200
    assert "/static/swagger/swagger-ui-bundle.js" in page.text
    assert "cdn" not in page.text.lower()
    script = await client.get("/static/swagger/swagger-ui-bundle.js")
    assert script.status_code == 200 and len(script.content) > 100_000


async def test_openapi_documents_every_endpoint():
    paths = (await client_for(make_station()).get("/openapi.json")).json()["paths"]
    assert {
        "/api/state",
        "/api/formation",
        "/api/formation/start",
        "/api/formation/stop",
        "/api/obstacles",
        "/api/obstacles/{obstacle_id}",
        "/api/vehicles/{vehicle_id}/land",
        "/api/vehicles/{vehicle_id}/release",
        "/api/land_all",
    } <= set(paths)


# ---- formation ---------------------------------------------------------------------------------------------


async def test_put_formation_reaches_the_mission_at_once(station):
    response = await client_for(station).put("/api/formation", json={"d_des_m": 10.0, "h_des_m": 6.5})
    assert response.status_code == 200
    assert response.json()["d_des_m"] == 10.0 and response.json()["h_des_m"] == 6.5
    assert station.mission.formation.d_des_m == 10.0 and station.mission.formation.h_des_m == 6.5


@pytest.mark.slow  # flies the team for tens of simulated seconds
async def test_a_new_d_des_moves_the_team_to_it(flying):
    assert abs(horizontal_distances(flying).mean() - 10.0) > 1.0  # the team has to move to pass
    await client_for(flying).put("/api/formation", json={"d_des_m": 10.0, "h_des_m": 8.0})
    took = run_until(flying, lambda _: abs(horizontal_distances(flying).mean() - 10.0) < 1.0, limit_s=30.0)
    assert took < 30.0


@pytest.mark.parametrize(
    ("body", "match"),
    [
        ('{"d_des_m": NaN, "h_des_m": 8.0}', "d_des_m must be a finite number"),
        ('{"d_des_m": 8.0, "h_des_m": Infinity}', "h_des_m must be a finite number"),
        ('{"d_des_m": 1.0, "h_des_m": 8.0}', "choose a value between 1.8 and 18.5 m"),
        ('{"d_des_m": 25.0, "h_des_m": 8.0}', "outside what the arena and safety distances allow"),
        ('{"d_des_m": 8.0, "h_des_m": 12.0}', "between 2.1 and 9.1 m"),
        ('{"d_des_m": 8.0, "h_des_m": 0.5}', "outside the arena's height band"),
    ],
)
async def test_bad_formation_is_refused_and_changes_nothing(station, body, match):
    await assert_refused(
        client_for(station),
        "PUT",
        "/api/formation",
        content=body,
        headers={"content-type": "application/json"},
        match=match,
    )
    assert station.mission.formation.d_des_m == 8.0 and station.mission.formation.h_des_m == 8.0


async def test_malformed_formation_body_is_refused_with_the_field_named(station):
    client = client_for(station)
    response = await client.put("/api/formation", json={"d_des_m": "far"})
    assert response.status_code == 422
    body = response.json()
    assert "body.d_des_m" in body["detail"] and "body.h_des_m: Field required" in body["detail"]
    assert {tuple(e["loc"]) for e in body["errors"]} == {("body", "d_des_m"), ("body", "h_des_m")}
    assert station.mission.formation.d_des_m == 8.0


@pytest.mark.parametrize(
    "body",
    [
        {"d_des_m": "9", "h_des_m": 8.0},
        {"d_des_m": 9.0, "h_des_m": True},
        {"d_des_m": 9.0, "h_des_m": 8.0, "speed": 3},
    ],
)
async def test_strings_booleans_and_unknown_fields_are_not_coerced_but_refused(station, body):
    response = await client_for(station).put("/api/formation", json=body)
    assert response.status_code == 422, response.text
    assert response.json()["errors"]
    assert station.mission.formation.d_des_m == 8.0


async def test_the_422_body_is_the_one_openapi_advertises(station):
    client = client_for(station)
    spec = (await client.get("/openapi.json")).json()
    ref = spec["paths"]["/api/formation"]["put"]["responses"]["422"]["content"]["application/json"]["schema"]
    schema = spec["components"]["schemas"][ref["$ref"].rsplit("/", 1)[1]]
    for body in ({"d_des_m": "far"}, {"d_des_m": 99.0, "h_des_m": 8.0}):  # malformed, and refused
        got = (await client.put("/api/formation", json=body)).json()
        assert set(got) <= set(schema["properties"]) and set(schema["required"]) <= set(got)
        assert isinstance(got["detail"], str) and isinstance(got["errors"], list)


async def test_stop_formation_makes_every_mav_hold_and_start_resumes(flying):
    client = client_for(flying)
    assert (await client.post("/api/formation/stop")).json()["enabled"] is False
    run_for(flying, 0.5)
    assert {v.autopilot.mode.value for v in flying.snapshot().vehicles} == {"hold"}
    assert (await client.post("/api/formation/start")).json()["enabled"] is True
    run_for(flying, 0.5)
    assert {v.autopilot.mode.value for v in flying.snapshot().vehicles} == {"offboard"}


# ---- obstacles ---------------------------------------------------------------------------------------------


async def test_post_obstacle_adds_a_virtual_obstacle_everyone_sees(station):
    client = client_for(station)
    response = await client.post("/api/obstacles", json={"x_m": 15.0, "y_m": -15.0, "radius_m": 1.2})
    assert response.status_code == 201
    assert response.json() == {
        "obstacle_id": "v1",
        "kind": "virtual",
        "center_m": [15.0, -15.0],
        "radius_m": 1.2,
        "height_m": 12.0,
    }
    assert response.json() in (await client.get("/api/obstacles")).json()
    assert "v1" in [o.obstacle_id for o in station.mission.obstacles()]


async def test_a_virtual_obstacle_reaches_the_agents_within_one_control_period(flying):
    await client_for(flying).post("/api/obstacles", json={"x_m": 15.0, "y_m": -15.0, "radius_m": 1.0})
    flying.tick()
    assert "v1" in [o.obstacle_id for o in flying.snapshot().obstacles]


async def test_obstacle_ids_are_not_reused_after_removal(station):
    client = client_for(station)
    body = {"x_m": 15.0, "y_m": -15.0, "radius_m": 1.0}
    first = (await client.post("/api/obstacles", json=body)).json()["obstacle_id"]
    await client.delete(f"/api/obstacles/{first}")
    second = (await client.post("/api/obstacles", json=body)).json()
    assert (first, second["obstacle_id"]) == ("v1", "v2")


@pytest.mark.parametrize(
    ("body", "match"),
    [
        ({"x_m": 25.0, "y_m": 0.0, "radius_m": 1.0}, "outside the arena"),
        ({"x_m": 15.0, "y_m": -15.0, "radius_m": 0.0}, "radius_m must be positive"),
        ({"x_m": 15.0, "y_m": -15.0, "radius_m": -2.0}, "radius_m must be positive"),
        ({"x_m": 15.0, "y_m": -15.0, "radius_m": 50.0}, "cover a large area with several obstacles"),
        ({"x_m": 1.0, "y_m": 1.0, "radius_m": 1.0}, "would cover the person"),
        ({"x_m": 8.0, "y_m": 0.5, "radius_m": 1.0}, "would cover MAV 1"),
    ],
)
async def test_bad_obstacle_is_refused_and_changes_nothing(station, body, match):
    await assert_refused(client_for(station), "POST", "/api/obstacles", json=body, match=match)
    assert all(o.kind == "tree" for o in station.mission.obstacles())


async def test_non_finite_obstacle_is_refused_and_changes_nothing(station):
    await assert_refused(
        client_for(station),
        "POST",
        "/api/obstacles",
        content='{"x_m": NaN, "y_m": 0, "radius_m": 1}',
        headers={"content-type": "application/json"},
        match="x_m must be a finite number",
    )


async def test_delete_obstacle_removes_it(station):
    client = client_for(station)
    await client.post("/api/obstacles", json={"x_m": 15.0, "y_m": -15.0, "radius_m": 1.0})
    assert (await client.delete("/api/obstacles/v1")).status_code == 204
    obstacles = (await client.get("/api/obstacles")).json()
    assert [o["obstacle_id"] for o in obstacles if o["kind"] == "virtual"] == []


async def test_deleting_an_unknown_obstacle_is_404_and_changes_nothing(station):
    await assert_refused(
        client_for(station), "DELETE", "/api/obstacles/v9", status=404, match="no obstacle with id 'v9'"
    )


async def test_deleting_a_tree_is_refused_and_changes_nothing(station):
    tree = station.mission.obstacles()[0].obstacle_id
    await assert_refused(
        client_for(station), "DELETE", f"/api/obstacles/{tree}", match="only virtual obstacles"
    )


# ---- landing override --------------------------------------------------------------------------------------


@pytest.mark.slow  # flies the team for tens of simulated seconds
async def test_land_takes_one_mav_out_and_its_teammates_respace_to_180_degrees(flying):
    client = client_for(flying)
    response = await client.post("/api/vehicles/2/land")
    assert response.status_code == 200 and response.json()["phase"] == "landing"
    assert response.headers["x-command-id"]
    run_until(flying, lambda s: s.vehicles[1].phase == Phase.LANDED, limit_s=30.0)
    assert not flying.snapshot().vehicles[1].autopilot.in_air

    def spaced(_) -> bool:
        b = bearings_deg(flying, {1, 3})
        return abs(abs((b[0] - b[1] + 180.0) % 360.0 - 180.0) - 180.0) < 10.0

    run_until(flying, spaced, limit_s=60.0)
    assert flying.snapshot().vehicles[1].phase == Phase.LANDED  # stays out until released


async def test_landing_an_unknown_vehicle_is_404_and_changes_nothing(flying):
    await assert_refused(
        client_for(flying), "POST", "/api/vehicles/7/land", status=404, match="vehicles are [1, 2, 3]"
    )


@pytest.mark.slow  # flies the team for tens of simulated seconds
async def test_landing_a_mav_that_is_down_already_is_refused_and_changes_nothing(flying):
    client = client_for(flying)
    await client.post("/api/vehicles/2/land")
    run_until(flying, lambda s: s.vehicles[1].phase == Phase.LANDED, limit_s=30.0)
    await assert_refused(client, "POST", "/api/vehicles/2/land", match="on the ground already")


@pytest.mark.slow  # flies the team for tens of simulated seconds
async def test_land_all_brings_every_mav_to_the_ground(flying):
    response = await client_for(flying).post("/api/land_all")
    assert response.json() == {"landing": [1, 2, 3]}
    run_until(flying, lambda s: all(v.phase == Phase.LANDED for v in s.vehicles), limit_s=40.0)
    assert all(not v.autopilot.in_air for v in flying.snapshot().vehicles)


@pytest.mark.slow  # flies the team for tens of simulated seconds
async def test_release_returns_a_landed_mav_to_the_formation(flying):
    client = client_for(flying)
    await client.post("/api/vehicles/3/land")
    run_until(flying, lambda s: s.vehicles[2].phase == Phase.LANDED, limit_s=30.0)
    assert (await client.post("/api/vehicles/3/release")).status_code == 200
    run_until(flying, all_in_formation, limit_s=30.0)


async def test_releasing_a_flying_mav_is_refused_and_changes_nothing(flying):
    await assert_refused(
        client_for(flying),
        "POST",
        "/api/vehicles/1/release",
        match="only a landed or holding vehicle, or an airborne one skyring does not fly, can be released",
    )


@pytest.mark.slow  # flies the team for tens of simulated seconds
async def test_release_is_refused_when_d_des_is_too_small_for_the_bigger_team():
    s = make_station(vehicles=8)
    run_until(s, all_in_formation, limit_s=40.0)
    client = client_for(s)
    await client.post("/api/vehicles/8/land")
    run_until(s, lambda snap: snap.vehicles[7].phase == Phase.LANDED, limit_s=30.0)
    assert (await client.put("/api/formation", json={"d_des_m": 3.6, "h_des_m": 8.0})).status_code == 200
    await assert_refused(client, "POST", "/api/vehicles/8/release", match="needs d_des between 4 and 18.5 m")


# ---- stream ------------------------------------------------------------------------------------------------


async def test_websocket_streams_the_state_at_least_10_times_a_second_and_takes_commands(flying):
    app = create_app(flying, viser_port=VISER_PORT)
    config = uvicorn.Config(app, host="127.0.0.1", port=0, log_level="warning", lifespan="off")
    server = uvicorn.Server(config)
    task = asyncio.create_task(server.serve())
    try:
        while not server.started:
            await asyncio.sleep(0.01)
        port = server.servers[0].sockets[0].getsockname()[1]
        async with websockets.connect(f"ws://127.0.0.1:{port}/ws") as ws:
            first = json.loads(await ws.recv())
            start = time.monotonic()
            for _ in range(10):
                await ws.recv()
            elapsed = time.monotonic() - start
            await ws.send(
                json.dumps({"id": "c1", "command": "set_formation", "d_des_m": 9.0, "h_des_m": 8.0})
            )
            await ws.send(
                json.dumps({"id": "c2", "command": "set_formation", "d_des_m": 99.0, "h_des_m": 8.0})
            )
            replies = {}
            while len(replies) < 2:
                message = json.loads(await ws.recv())
                if "reply_to" in message:
                    replies[message["reply_to"]] = message
    finally:
        server.should_exit = True
        await task
    assert [v["vehicle_id"] for v in first["vehicles"]] == [1, 2, 3]
    assert first["time_s"] == pytest.approx(flying.time_s)
    assert elapsed <= 1.0  # 10 messages at the 20 Hz default take 0.5 s
    assert replies["c1"]["accepted"] and flying.mission.formation.d_des_m == 9.0
    assert not replies["c2"]["accepted"] and "choose a value between" in replies["c2"]["detail"]
    audit = [r for r in flying.recent_audit if r.surface == "ws"]
    assert [(r.command_id, r.accepted) for r in audit] == [("c1", True), ("c2", False)]

"""The pre-take-off checks at the operator's commands: the formation's start and Release are refused, naming
the MAV, while one stands inside the person's keep-out or within d_min of a teammate; the override lets it go
and is logged (server/station/ground_station.py, server/station/commands.py)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from log_headers import log_header
from test_api import assert_refused, client_for, run_until

from controller.messages import PersonEstimate
from server.flightlog.log import FlightLog
from server.flightlog.reader import read_flight_log
from server.station.ground_station import GroundStation, takeoff_checks
from vehicles.mission import Phase
from vehicles.sim.scenario import Scenario, build_sim

RATE_HZ = 20.0


def grounded_station(flight_log: FlightLog | None = None) -> GroundStation:
    """Three simulated MAVs on the ground about the still person, formation stopped, d_des 10 m: the person's
    keep-out (8.75 m) reaches the MAVs' start ring (about 8 m)."""
    setup = build_sim(Scenario(vehicles=3, seed=3, person="still", trees="none"))
    setup.mission.set_formation_enabled(False)
    station = GroundStation(mission=setup.mission, control_period_s=1.0 / RATE_HZ)
    if flight_log is not None:
        station.attach_log(flight_log)
    station.tick()
    station.set_formation(d_des_m=10.0, h_des_m=8.0)
    return station


def distances_to_person(station: GroundStation) -> dict[int, float]:
    snap = station.snapshot()
    assert snap.person_truth is not None
    person = snap.person_truth.position_m[:2]
    return {
        v.vehicle_id: float(np.hypot(*(v.autopilot.position_m[:2] - person)))
        for v in snap.vehicles
        if v.autopilot is not None
    }


async def test_start_is_refused_naming_each_mav_inside_the_keep_out_and_nothing_changes():
    station = grounded_station()
    inside = sorted(vid for vid, d in distances_to_person(station).items() if d < 8.75)
    assert inside  # the set-up puts at least one there
    await assert_refused(client_for(station), "POST", "/api/formation/start", match=f"MAV {inside[0]} stands")
    assert not station.snapshot().formation_enabled


async def test_the_view_says_why_each_waiting_mav_may_not_take_off_where_it_stands():
    station = grounded_station()
    vehicles = (await client_for(station).get("/api/state")).json()["vehicles"]
    for v in vehicles:
        d = distances_to_person(station)[v["vehicle_id"]]
        assert (v["takeoff_check"] is not None) == (d < 8.75)
        if v["takeoff_check"] is not None:
            assert f"{d:.1f} m from the person, inside the 8.8 m keep-out" in v["takeoff_check"]


async def test_the_override_starts_the_formation_and_the_flight_log_keeps_it(tmp_path):
    header = log_header(trees="none", person="still")
    flight_log = FlightLog.create(tmp_path / "flight.mcap", header=header)
    station = grounded_station(flight_log)
    client = client_for(station)
    assert (await client.post("/api/formation/start")).status_code == 422
    response = await client.post("/api/formation/start", params={"override": "true"})
    assert response.status_code == 200, response.text
    run_until(station, lambda snap: all(v.phase != Phase.IDLE for v in snap.vehicles), limit_s=2.0)
    flight_log.close()
    commands = [
        a for a in read_flight_log(tmp_path / "flight.mcap").audit if a.command == "set_formation_enabled"
    ]
    assert [(c.accepted, c.arguments["override"]) for c in commands] == [(False, False), (True, True)]
    assert "keep-out" in commands[0].message
    assert commands[1].result is not None and "keep-out" in commands[1].result


async def test_release_of_a_landed_mav_inside_the_keep_out_is_refused_until_overridden():
    setup = build_sim(Scenario(vehicles=3, seed=3, person="still", trees="none"))
    station = GroundStation(mission=setup.mission, control_period_s=1.0 / RATE_HZ)
    run_until(station, lambda snap: all(v.phase == Phase.FORMATION for v in snap.vehicles), limit_s=30.0)
    client = client_for(station)
    await client.post("/api/vehicles/1/land")
    run_until(station, lambda snap: snap.vehicles[0].phase == Phase.LANDED, limit_s=30.0)
    # MAV 1 landed about 8 m from the person; at d_des 10 m the keep-out (8.75 m) covers it
    assert (await client.put("/api/formation", json={"d_des_m": 10.0, "h_des_m": 8.0})).status_code == 200
    assert distances_to_person(station)[1] < 8.75
    await assert_refused(client, "POST", "/api/vehicles/1/release", match="MAV 1 stands")
    response = await client.post("/api/vehicles/1/release", params={"override": "true"})
    assert response.status_code == 200, response.text
    assert response.json()["phase"] == "idle"


def test_a_landed_mavs_drifted_estimate_does_not_refuse_it_when_the_true_person_stands_clear():
    station = grounded_station()
    station.set_formation(d_des_m=6.0, h_des_m=8.0)  # keep-out 5.25 m: every MAV stands clear (about 8 m)
    snap = station.snapshot()
    here = snap.vehicles[0].autopilot
    assert here is not None
    drifted = PersonEstimate(
        stamp_s=snap.stamp_s, position_m=here.position_m, velocity_mps=np.zeros(3), cov=np.eye(6)
    )
    vehicles = (replace(snap.vehicles[0], person=drifted), *snap.vehicles[1:])
    assert takeoff_checks(replace(snap, vehicles=vehicles), limits=station.limits) == {}
    no_truth = replace(snap, vehicles=vehicles, person_truth=None)  # in the field only estimates count
    assert "stands 0.0 m from the person" in takeoff_checks(no_truth, limits=station.limits)[1]


PX4_FIELDS = ("autopilot_mode", "failsafe", "failsafe_reason", "can_arm", "arming_refusal", "takeoff_check")


async def test_the_autopilots_own_words_and_the_takeoff_check_are_in_the_api_its_schema_and_the_log(tmp_path):
    header = log_header(trees="none", person="still")
    flight_log = FlightLog.create(tmp_path / "flight.mcap", header=header)
    station = grounded_station(flight_log)
    for _ in range(round(RATE_HZ)):  # a second: samples after the new d_des
        station.tick()
    client = client_for(station)
    spec = (await client.get("/openapi.json")).json()
    assert set(PX4_FIELDS) <= set(spec["components"]["schemas"]["VehicleView"]["properties"])
    api = (await client.get("/api/state")).json()["vehicles"]
    flight_log.close()
    logged = read_flight_log(tmp_path / "flight.mcap").samples[-1].vehicles
    view = station.scene_view().vehicles
    for in_api, in_log, now in zip(api, logged, view, strict=True):
        assert in_api["autopilot_mode"] == in_log.autopilot_mode == now.autopilot_mode != ""
        assert in_api["failsafe"] is in_log.failsafe is now.failsafe is False
        assert in_api["takeoff_check"] == in_log.takeoff_check == now.takeoff_check
    assert any(v.takeoff_check is not None and "keep-out" in v.takeoff_check for v in logged)


async def test_openapi_offers_the_override_on_start_and_release_and_says_when_they_are_refused():
    spec = (await client_for(grounded_station()).get("/openapi.json")).json()
    for path in ("/api/formation/start", "/api/vehicles/{vehicle_id}/release"):
        operation = spec["paths"][path]["post"]
        override = next(p for p in operation["parameters"] if p["name"] == "override")
        assert override["in"] == "query" and override["schema"]["type"] == "boolean"
        assert "keep-out" in operation["responses"]["422"]["description"]
        assert operation["responses"]["422"]["content"]["application/json"]["schema"] == {
            "$ref": "#/components/schemas/Problem"
        }

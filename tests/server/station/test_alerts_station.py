"""Alerts and per-vehicle Hold through the ground station: injected conditions raise their alert within a tick
of the alert period, in the view, in /api/state and on the WebSocket; acknowledging keeps them in the list;
Hold stops one MAV. A real simulated mission stepped by the test."""

from __future__ import annotations

import asyncio
import json

import httpx
import numpy as np
import pytest
import uvicorn
import websockets
from log_headers import log_header

from server.flightlog.log import FlightLog
from server.flightlog.reader import read_flight_log
from server.station.api.app import create_app
from server.station.ground_station import GroundStation
from vehicles.mission import Phase
from vehicles.sim.scenario import Scenario, SimSetup, build_sim
from webui.view import PaceView

RATE_HZ = 20.0


class Flying:
    """A ground station over three simulated MAVs flying formation, with its simulated parts."""

    def __init__(self) -> None:
        self.setup: SimSetup = build_sim(Scenario(vehicles=3, seed=3))
        self.station = GroundStation(
            mission=self.setup.mission, control_period_s=1.0 / RATE_HZ, wall_clock=lambda: 1.7e9
        )
        while not all(v.phase == Phase.FORMATION for v in self.station.snapshot().vehicles):
            assert self.station.time_s < 30.0
            self.station.tick()

    def run(self, seconds: float) -> None:
        for _ in range(round(seconds * RATE_HZ)):
            self.station.tick()

    def alerts(self, kind: str):
        return [a for a in self.station.alerts if a.kind == kind]

    def client(self) -> httpx.AsyncClient:
        app = create_app(self.station, viser_port=18080)
        return httpx.AsyncClient(transport=httpx.ASGITransport(app=app), base_url="http://127.0.0.1:8000")


@pytest.fixture
def flying() -> Flying:
    return Flying()


def place_beside(f: Flying, mover: int, other: int, offset_m) -> None:
    """Move MAV `mover` so that its *reported* position is MAV `other`'s reported position plus offset_m
    (the alert rules see reported positions, GPS drift included)."""
    ap = {a.vehicle_id: a for a in f.setup.autopilots}
    drift = ap[mover].state().position_m - ap[mover].true_position_m
    target = ap[other].state().position_m + np.asarray(offset_m, dtype=float)
    ap[mover].place_at(target - drift)


def test_a_battery_at_20_percent_raises_a_low_battery_alert_within_one_alert_period(flying):
    flying.setup.autopilots[0].set_battery(0.20)
    flying.run(0.1)
    (alert,) = flying.alerts("battery")
    assert alert.vehicle_id == 1 and alert.severity == "warning" and alert.active
    assert "20 %" in alert.message and alert.first_utc_s == 1.7e9


def test_two_mavs_forced_within_1_4_m_raise_a_critical_separation_alert(flying):
    place_beside(flying, 2, 1, (1.2, 0.0, 0.0))
    flying.run(0.1)
    (alert,) = flying.alerts("separation")
    assert (alert.vehicle_id, alert.subject, alert.severity) == (1, "MAV 2", "critical")


def test_a_cut_link_raises_a_link_alert_within_a_second_of_mission_time(flying):
    flying.setup.autopilots[2].cut_link()
    flying.run(1.0)
    (alert,) = flying.alerts("link")
    assert alert.vehicle_id == 3 and alert.severity == "critical"


def test_a_slow_loop_reported_by_the_runner_raises_a_realtime_alert(flying):
    flying.station.set_pace(PaceView(requested_speed=1.0, realtime_factor=0.5))
    flying.run(0.1)
    (alert,) = flying.alerts("realtime")
    assert alert.vehicle_id is None and "0.50x achieved, 1x asked" in alert.message


def test_an_alert_whose_condition_ended_stays_in_the_list_inactive(flying):
    flying.setup.autopilots[0].set_battery(0.20)
    flying.run(0.1)
    flying.setup.autopilots[0].set_battery(0.90)
    flying.run(1.5)
    (alert,) = flying.alerts("battery")
    assert not alert.active


def test_the_battery_failsafe_shows_as_a_critical_failsafe_alert_and_the_mav_lands(flying):
    flying.setup.autopilots[1].set_battery(0.15)
    flying.run(0.2)
    assert [a.vehicle_id for a in flying.alerts("failsafe")] == [2]
    assert flying.station.snapshot().vehicles[1].phase == Phase.LANDING


async def test_api_state_lists_the_alerts_and_acknowledging_keeps_them_there(flying):
    flying.setup.autopilots[0].set_battery(0.20)
    flying.run(0.1)
    async with flying.client() as client:
        (alert,) = [a for a in (await client.get("/api/state")).json()["alerts"] if a["kind"] == "battery"]
        assert alert["active"] and not alert["acknowledged"] and alert["vehicle_id"] == 1
        acked = await client.post(f"/api/alerts/{alert['alert_id']}/acknowledge")
        assert acked.status_code == 200 and acked.json()["acknowledged"]
        listed = (await client.get("/api/alerts")).json()
    assert [a for a in listed if a["alert_id"] == alert["alert_id"]][0]["acknowledged"]


async def test_acknowledging_an_unknown_alert_is_404_and_counted(flying):
    async with flying.client() as client:
        before = (await client.get("/api/state")).json()["counters"]["refused_commands"]
        response = await client.post("/api/alerts/a999/acknowledge")
        after = (await client.get("/api/state")).json()["counters"]["refused_commands"]
    assert response.status_code == 404 and "no alert with id 'a999'" in response.json()["detail"]
    assert after == before + 1


async def test_acknowledge_all_marks_every_alert_as_seen(flying):
    flying.setup.autopilots[0].set_battery(0.20)
    flying.setup.autopilots[1].set_battery(0.22)
    flying.run(0.1)
    async with flying.client() as client:
        assert (await client.post("/api/alerts/acknowledge")).json() == {"acknowledged": 2}
        alerts = (await client.get("/api/alerts")).json()
    assert alerts and all(a["acknowledged"] for a in alerts)


async def test_hold_stops_one_mav_and_release_returns_it_to_the_formation(flying):
    async with flying.client() as client:
        held = await client.post("/api/vehicles/2/hold")
        assert held.status_code == 200 and held.json()["phase"] == "holding"
        flying.run(1.0)
        assert flying.station.snapshot().vehicles[1].autopilot.mode == "hold"
        released = await client.post("/api/vehicles/2/release")
    assert released.json()["phase"] == "formation"


async def test_land_all_lands_a_holding_mav_too(flying):
    async with flying.client() as client:
        await client.post("/api/vehicles/1/hold")
        landing = (await client.post("/api/land_all")).json()["landing"]
    assert landing == [1, 2, 3]


async def test_holding_a_mav_on_the_ground_is_refused():
    station = GroundStation(
        mission=build_sim(Scenario(vehicles=3, seed=3)).mission, control_period_s=1.0 / RATE_HZ
    )
    station.mission.set_formation_enabled(False)
    station.tick()
    app = create_app(station, viser_port=18080)
    transport = httpx.ASGITransport(app=app)
    async with httpx.AsyncClient(transport=transport, base_url="http://127.0.0.1:8000") as client:
        response = await client.post("/api/vehicles/1/hold")
    assert response.status_code == 422 and "can be held" in response.json()["detail"]
    assert station.snapshot().vehicles[0].phase == Phase.IDLE


async def test_the_websocket_stream_carries_the_same_alerts(flying):
    flying.setup.autopilots[0].set_battery(0.20)
    flying.run(0.1)
    app = create_app(flying.station, viser_port=18080)
    server = uvicorn.Server(
        uvicorn.Config(app, host="127.0.0.1", port=0, log_level="warning", lifespan="off")
    )
    task = asyncio.create_task(server.serve())
    try:
        while not server.started:
            await asyncio.sleep(0.01)
        port = server.servers[0].sockets[0].getsockname()[1]
        async with websockets.connect(f"ws://127.0.0.1:{port}/ws") as ws:
            message = json.loads(await ws.recv())
    finally:
        server.should_exit = True
        await task
    streamed = [(a["alert_id"], a["kind"], a["vehicle_id"]) for a in message["alerts"]]
    assert streamed == [(a.alert_id, a.kind, a.vehicle_id) for a in flying.station.alerts]
    assert any(kind == "battery" and vehicle == 1 for _, kind, vehicle in streamed)


def test_an_acknowledgement_is_recorded_in_the_flight_log_as_a_command(flying, tmp_path):
    header = log_header()
    log = FlightLog.create(tmp_path / "flight.mcap", header=header)
    flying.station.attach_log(log)
    flying.setup.autopilots[0].set_battery(0.20)
    flying.run(0.1)
    alert_id = flying.alerts("battery")[0].alert_id
    flying.station.acknowledge_alert(alert_id)
    log.close()
    (audit,) = read_flight_log(tmp_path / "flight.mcap").audit
    assert (audit.command, audit.arguments, audit.accepted) == (
        "acknowledge_alert",
        {"alert_id": alert_id},
        True,
    )

"""Per-vehicle separation in the state (`GET /api/state`): the nearest airborne teammate (3-D, by the
positions the station knows) and the nearest trunk or obstacle surface below its top; null when not
applicable."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from test_api import client_for

from controller.messages import Obstacle
from server.station.ground_station import GroundStation
from vehicles.mission import Mission, MissionSnapshot
from vehicles.sim.scenario import Scenario, build_sim

TREE = Obstacle(obstacle_id="t", center_m=np.array((0.0, -6.0)), radius_m=0.5, height_m=12.0)
LOW = Obstacle(obstacle_id="v1", center_m=np.array((3.0, 6.0)), radius_m=1.0, height_m=2.0, kind="virtual")


class PlacedMission:
    """A real simulated mission whose snapshot shows each vehicle's telemetry at a given position, in the air
    or on the ground: the station's view of known positions."""

    def __init__(self, mission: Mission, placed: dict[int, tuple[tuple[float, float, float], bool]]) -> None:
        self._mission = mission
        self._placed = placed

    def __getattr__(self, name: str):
        return getattr(self._mission, name)

    def snapshot(self) -> MissionSnapshot:
        snap = self._mission.snapshot()
        vehicles = []
        for v in snap.vehicles:
            position, in_air = self._placed[v.vehicle_id]
            assert v.autopilot is not None
            autopilot = replace(v.autopilot, position_m=np.array(position), in_air=in_air)
            vehicles.append(replace(v, autopilot=autopilot))
        return replace(snap, vehicles=tuple(vehicles), obstacles=(TREE, LOW))


def placed_station(placed) -> GroundStation:
    setup = build_sim(Scenario(vehicles=len(placed), seed=3, trees="none", person="still"))
    setup.mission.set_formation_enabled(False)
    station = GroundStation(mission=PlacedMission(setup.mission, placed), control_period_s=0.05)  # type: ignore[arg-type]
    station.tick()  # the autopilots' first telemetry
    return station


async def test_two_airborne_vehicles_get_their_distance_and_their_clearance_to_the_trunk():
    station = placed_station({1: ((0.0, 0.0, 3.0), True), 2: ((3.0, 4.0, 3.0), True)})
    one, two = (await client_for(station).get("/api/state")).json()["vehicles"]
    assert one["nearest_teammate_m"] == pytest.approx(5.0, abs=1e-6) and one["nearest_teammate_id"] == 2
    assert two["nearest_teammate_m"] == pytest.approx(5.0, abs=1e-6) and two["nearest_teammate_id"] == 1
    assert one["nearest_obstacle_m"] == pytest.approx(5.5, abs=1e-6)
    # MAV 2 is above the low virtual obstacle (1 m from its surface): only the trunk counts
    assert two["nearest_obstacle_m"] == pytest.approx(math.hypot(3.0, 10.0) - 0.5, abs=1e-6)


async def test_a_landed_vehicle_has_null_separation_and_is_not_a_teammate_to_keep_clear_of():
    station = placed_station(
        {1: ((0.0, 0.0, 3.0), True), 2: ((3.0, 4.0, 3.0), True), 3: ((1.0, 0.0, 0.0), False)}
    )
    one, _, landed = (await client_for(station).get("/api/state")).json()["vehicles"]
    assert landed["nearest_teammate_m"] is None and landed["nearest_teammate_id"] is None
    assert landed["nearest_obstacle_m"] is None
    assert one["nearest_teammate_id"] == 2  # not MAV 3 on the ground 3.2 m away
    assert one["nearest_teammate_m"] == pytest.approx(5.0, abs=1e-6)


async def test_a_vehicle_alone_in_the_air_has_null_teammate_distance():
    station = placed_station({1: ((0.0, 0.0, 3.0), True), 2: ((3.0, 4.0, 0.0), False)})
    one, _ = (await client_for(station).get("/api/state")).json()["vehicles"]
    assert one["nearest_teammate_m"] is None and one["nearest_teammate_id"] is None
    assert one["nearest_obstacle_m"] == pytest.approx(5.5, abs=1e-6)


async def test_a_flying_team_reports_separation_from_the_positions_it_shows():
    setup = build_sim(Scenario(vehicles=3, seed=3))
    station = GroundStation(mission=setup.mission, control_period_s=0.05)
    for _ in range(100):
        station.tick()
    vehicles = (await client_for(station).get("/api/state")).json()["vehicles"]
    position = {v["vehicle_id"]: np.array(v["position_m"]) for v in vehicles}
    for v in vehicles:
        assert v["in_air"]
        mate = v["nearest_teammate_id"]
        others = [
            np.linalg.norm(position[v["vehicle_id"]] - p) for k, p in position.items() if k != v["vehicle_id"]
        ]
        assert v["nearest_teammate_m"] == pytest.approx(min(others), abs=1e-6)
        assert v["nearest_teammate_m"] == pytest.approx(
            np.linalg.norm(position[v["vehicle_id"]] - position[mate]), abs=1e-6
        )
        assert v["nearest_obstacle_m"] is not None and v["nearest_obstacle_m"] > 0.0  # the paper's trees

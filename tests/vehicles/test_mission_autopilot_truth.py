"""The mission under what an autopilot says of itself: a take-off it refuses, its own failsafes and landings,
and vehicles found flying (vehicles/mission.py). The simulated MAVs are wrapped so a test can make one read
as PX4 would (refusing to arm, in a failsafe, landing by itself, airborne before the mission began)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from server.lab.metrics import spacing_error_deg
from vehicles.autopilot import AutopilotState, FlightMode, Setpoint
from vehicles.mission import Mission, MissionError, Phase
from vehicles.sim.autopilot import SimAutopilot
from vehicles.sim.scenario import Scenario, build_sim

RATE_HZ = 10.0


class Told:
    """A simulated MAV whose readings a test may override, and that can refuse to take off."""

    def __init__(self, sim: SimAutopilot) -> None:
        self.sim = sim
        self.vehicle_id = sim.vehicle_id
        self.overrides: dict[str, object] = {}
        self.refuse_takeoff = False
        self.takeoffs = 0
        self.holds = 0
        self.lands = 0

    def state(self) -> AutopilotState | None:
        s = self.sim.state()
        return dataclasses.replace(s, **self.overrides) if self.overrides else s

    def send_setpoint(self, setpoint: Setpoint) -> None:
        self.sim.send_setpoint(setpoint)

    def takeoff(self, height_m: float) -> None:
        self.takeoffs += 1
        if self.refuse_takeoff:
            self.overrides.setdefault("arming_refusal", "Arming denied: Resolve system health failures first")
            return
        self.sim.takeoff(height_m)

    def hold(self) -> None:
        self.holds += 1
        self.sim.hold()

    def land(self) -> None:
        self.lands += 1
        self.sim.land()


def team(formation_enabled: bool = True) -> tuple[Mission, list[Told]]:
    setup = build_sim(Scenario(vehicles=3, seed=2, person="still", trees="none"))
    told = [Told(a) for a in setup.autopilots]
    mission = Mission(
        autopilots=told,
        world=setup.world,
        links=setup.links,
        controller_params=setup.mission.controller_params,
        formation_enabled=formation_enabled,
    )
    return mission, told


def run(mission: Mission, t0: float, seconds: float) -> float:
    t = t0
    for _ in range(round(seconds * RATE_HZ)):
        t = round(t + 1.0 / RATE_HZ, 6)
        mission.step(t)
    return t


def flying(mission: Mission) -> float:
    t = run(mission, 0.0, 15.0)
    assert all(v.phase == Phase.FORMATION and v.in_formation for v in mission.snapshot().vehicles)
    return t


def test_a_mav_whose_takeoff_is_refused_leaves_the_roster_and_its_teammates_space_for_two():
    mission, told = team()
    told[2].refuse_takeoff = True
    run(mission, 0.0, 25.0)
    snap = mission.snapshot()
    assert snap.slot_count == 2
    assert [v.in_formation for v in snap.vehicles] == [True, True, False]
    grounded = snap.vehicles[2].autopilot
    assert snap.vehicles[2].phase == Phase.TAKEOFF and grounded is not None and not grounded.in_air
    xy = np.array([a.sim.true_position_m[:2] for a in told[:2]])
    assert spacing_error_deg(positions_xy_m=xy, person_xy_m=np.zeros(2)) < 10.0  # pi apart


def test_a_mav_in_its_autopilots_failsafe_is_out_of_the_roster_and_not_steered():
    mission, told = team()
    t = flying(mission)
    told[0].overrides = {"failsafe": True, "failsafe_reason": "Failsafe activated", "mode": FlightMode.HOLD}
    run(mission, t, 0.2)
    snap = mission.snapshot()
    assert snap.slot_count == 2 and not snap.vehicles[0].in_formation
    assert snap.vehicles[0].phase == Phase.FORMATION  # still up: the autopilot decides what happens next
    assert snap.vehicles[0].setpoint is not None
    before = snap.vehicles[0].setpoint
    run(mission, t + 0.2, 1.0)
    assert mission.snapshot().vehicles[0].setpoint is before  # no new set-points to a vehicle PX4 flies


def test_a_mav_its_autopilot_lands_by_itself_is_landing_and_ends_landed_without_a_command():
    mission, told = team()
    t = flying(mission)
    told[1].overrides = {"mode": FlightMode.LAND}
    run(mission, t, 0.2)
    assert mission.snapshot().vehicles[1].phase == Phase.LANDING
    assert told[1].lands == 0  # PX4 lands it: nothing sent while it shows Land
    told[1].overrides = {}
    told[1].sim.land()  # (the simulated MAV lands for real)
    run(mission, t + 0.2, 15.0)
    assert mission.snapshot().vehicles[1].phase == Phase.LANDED


def test_a_land_read_right_after_the_takeoff_command_is_the_old_mode_not_a_landing():
    mission, told = team()
    t = run(mission, 0.0, 0.1)
    assert {v.phase for v in mission.snapshot().vehicles} == {Phase.TAKEOFF}
    for a in told:  # climbing, but PX4's heartbeat (1 Hz) still shows the Land of the previous flight
        a.overrides = {"mode": FlightMode.LAND, "in_air": True}
    t = run(mission, t, 1.0)
    assert {v.phase for v in mission.snapshot().vehicles} == {Phase.TAKEOFF}
    assert [a.lands for a in told] == [0, 0, 0]


def test_a_mav_found_flying_is_avoided_not_steered_until_the_operator_starts_the_formation():
    mission, told = team(formation_enabled=False)
    up = told[0]
    up.sim.takeoff(8.9)
    t = run(mission, 0.0, 8.0)
    snap = mission.snapshot()
    found = snap.vehicles[0].autopilot
    assert snap.vehicles[0].phase == Phase.IDLE and found is not None and found.in_air
    assert snap.vehicles[0].plan is not None and not snap.vehicles[0].plan.in_formation  # teammates avoid it
    assert up.takeoffs == 0 and [a.takeoffs for a in told[1:]] == [0, 0]
    mission.set_formation_enabled(True)
    run(mission, t, 0.2)
    assert mission.snapshot().vehicles[0].phase == Phase.FORMATION
    assert up.takeoffs == 1  # re-engaged from the air


def test_a_mav_found_in_its_autopilots_failsafe_is_left_to_it_after_the_start():
    mission, told = team(formation_enabled=False)
    told[0].sim.takeoff(8.9)
    t = run(mission, 0.0, 8.0)
    told[0].overrides = {"failsafe": True, "mode": FlightMode.LAND}
    mission.set_formation_enabled(True)
    run(mission, t, 1.0)
    assert mission.snapshot().vehicles[0].phase == Phase.IDLE


def test_release_is_refused_while_the_autopilot_runs_its_failsafe():
    mission, told = team()
    t = flying(mission)
    told[2].overrides = {"failsafe": True, "failsafe_reason": "Critical battery", "mode": FlightMode.HOLD}
    run(mission, t, 0.2)
    with pytest.raises(MissionError, match="failsafe.*Critical battery"):
        mission.release(3)


def test_release_of_a_holding_mav_is_refused_while_its_autopilot_runs_a_failsafe():
    mission, told = team()
    t = flying(mission)
    mission.hold(2)
    run(mission, t, 0.2)
    told[1].overrides = {"failsafe": True, "failsafe_reason": "Critical battery", "mode": FlightMode.HOLD}
    run(mission, t + 0.2, 0.2)
    with pytest.raises(MissionError, match="failsafe.*Critical battery"):
        mission.release(2)
    assert mission.phase(2) == Phase.HOLDING


def test_a_holding_mav_its_autopilot_lands_is_landing_and_skyring_does_not_fight_it_with_hold():
    mission, told = team()
    t = flying(mission)
    mission.hold(2)
    assert told[1].holds == 1
    told[1].overrides = {"mode": FlightMode.LAND, "failsafe": True}  # e.g. PX4's low-battery landing
    t = run(mission, t, 1.5)  # within the mode grace: the Land might still be an old reading
    assert mission.phase(2) == Phase.HOLDING and told[1].holds == 1  # the hold is not re-sent over Land
    run(mission, t, 1.0)
    assert mission.phase(2) == Phase.LANDING and told[1].lands == 0  # its landing stands


def test_a_holding_mav_released_rejoins_from_the_air_and_is_re_engaged_only_if_a_pilot_took_it():
    mission, told = team()
    t = flying(mission)
    mission.hold(1)
    mission.hold(2)
    t = run(mission, t, 0.5)
    told[1].overrides = {"released": True, "mode": FlightMode.MANUAL}  # a pilot took MAV 2 while it held
    t = run(mission, t, 0.2)
    takeoffs = [a.takeoffs for a in told]
    mission.release(1)
    told[1].overrides = {"mode": FlightMode.HOLD}  # the pilot gives it back, hovering
    mission.release(2)
    run(mission, t, 0.5)
    assert [mission.phase(1), mission.phase(2)] == [Phase.FORMATION, Phase.FORMATION]
    assert [a.takeoffs - n for a, n in zip(told, takeoffs, strict=True)] == [0, 1, 0]


def test_land_all_lands_a_mav_found_flying_too():
    mission, told = team(formation_enabled=False)
    told[0].sim.takeoff(8.9)
    t = run(mission, 0.0, 8.0)
    assert mission.phase(1) == Phase.IDLE and told[0].sim.in_air
    mission.land_all()
    assert mission.phase(1) == Phase.LANDING and told[0].lands == 1
    assert [a.lands for a in told[1:]] == [0, 0]  # the ones on the ground are left alone
    run(mission, t, 15.0)
    assert mission.phase(1) == Phase.LANDED and not told[0].sim.in_air


def test_the_roster_slots_follow_the_vehicles_in_it():
    mission, told = team()
    told[1].refuse_takeoff = True
    t = run(mission, 0.0, 0.1)
    assert mission.snapshot().slot_count == 0  # take-offs asked for, nobody airborne yet
    run(mission, t, 20.0)
    assert mission.snapshot().slot_count == 2
    assert math.isclose(2 * math.pi / mission.snapshot().slot_count, math.pi)

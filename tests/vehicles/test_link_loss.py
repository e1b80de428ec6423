"""A silent teammate as an obstacle (vehicles/link_loss.py), and the mission leaving it alone."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from controller.messages import HorizonPlan
from vehicles.autopilot import AutopilotState, FlightMode
from vehicles.link_loss import SilentVehicleParams, silent_vehicle_obstacle
from vehicles.mission import Mission, Phase
from vehicles.sim.scenario import Scenario, build_sim

P = SilentVehicleParams(body_radius_m=0.5, drift_mps=0.5, max_radius_m=6.0, headroom_m=2.0)


def state(position, stamp=10.0, vehicle_id=2):
    return AutopilotState(
        vehicle_id=vehicle_id,
        stamp_s=stamp,
        position_m=position,
        velocity_mps=np.array((0, 0, 0)),
        yaw_rad=0.0,
        armed=True,
        in_air=True,
        mode=FlightMode.OFFBOARD,
        link_lost=True,
    )


def plan(positions):
    p = np.asarray(positions, dtype=float)
    return HorizonPlan(vehicle_id=2, stamp_s=9.9, dt_s=0.1, positions_m=p, velocities_mps=np.zeros_like(p))


def test_just_silent_vehicle_is_its_body_at_its_last_position():
    o = silent_vehicle_obstacle(state=state([3.0, 4.0, 8.0]), plan=None, now_s=10.0, params=P)
    np.testing.assert_allclose(o.center_m, [3.0, 4.0])
    assert o.radius_m == pytest.approx(0.5)
    assert o.height_m == pytest.approx(10.0)
    assert (o.obstacle_id, o.kind) == ("silent-2", "vehicle")


def test_radius_grows_with_the_silence_at_the_drift_rate():
    o = silent_vehicle_obstacle(state=state([0.0, 0.0, 8.0]), plan=None, now_s=14.0, params=P)
    assert o.radius_m == pytest.approx(0.5 + 0.5 * 4.0)


def test_growth_is_bounded():
    o = silent_vehicle_obstacle(state=state([0.0, 0.0, 8.0]), plan=None, now_s=1000.0, params=P)
    assert o.radius_m == pytest.approx(0.5 + 6.0)


def test_cylinder_covers_the_last_plan():
    positions = [[0.0, 0.0, 8.0], [1.0, 0.5, 8.2], [2.0, 1.0, 8.4], [3.0, 1.5, 8.6]]
    o = silent_vehicle_obstacle(state=state([0.0, 0.0, 8.0]), plan=plan(positions), now_s=10.0, params=P)
    distances = np.linalg.norm(np.asarray(positions)[:, :2] - o.center_m, axis=1)
    assert np.all(distances <= o.radius_m - P.body_radius_m + 1e-9)
    assert o.height_m == pytest.approx(8.6 + 2.0)


def test_params_reject_a_non_positive_body_radius():
    with pytest.raises(ValueError):
        SilentVehicleParams(body_radius_m=0.0)


class Silenceable:
    """Wraps an autopilot; once silenced, its telemetry freezes and reads link-lost, and set-points are
    counted (they would go nowhere)."""

    def __init__(self, autopilot) -> None:
        self.inner = autopilot
        self.vehicle_id = autopilot.vehicle_id
        self.frozen = None
        self.setpoints_while_silent = 0

    def silence(self) -> None:
        self.frozen = dataclasses.replace(self.inner.state(), link_lost=True)

    def state(self):
        return self.frozen if self.frozen is not None else self.inner.state()

    def send_setpoint(self, setpoint) -> None:
        if self.frozen is not None:
            self.setpoints_while_silent += 1
        else:
            self.inner.send_setpoint(setpoint)

    def takeoff(self, height_m) -> None:
        self.inner.takeoff(height_m)

    def hold(self) -> None:
        self.inner.hold()

    def land(self) -> None:
        self.inner.land()


@pytest.mark.slow  # flies the team for tens of simulated seconds
def test_mission_stops_steering_a_silent_vehicle_and_its_teammates_keep_clear_of_it():
    setup = build_sim(Scenario(vehicles=3, seed=2, person="still", trees="none"))
    wrapped = Silenceable(setup.autopilots[1])
    mission = Mission(
        autopilots=[setup.autopilots[0], wrapped, setup.autopilots[2]], world=setup.world, links=setup.links
    )  # the simulated world, with vehicle 2 reached through the wrapper
    t = 0.0
    for _ in range(150):  # 15 s at 10 Hz: in formation
        t = round(t + 0.1, 6)
        mission.step(t)
    assert mission.phase(2) == Phase.FORMATION
    wrapped.silence()
    silent_xy = setup.autopilots[1].true_position_m[:2].copy()
    closest = np.inf
    for _ in range(200):  # 20 s of silence
        t = round(t + 0.1, 6)
        mission.step(t)
        for a in (setup.autopilots[0], setup.autopilots[2]):
            closest = min(closest, float(np.linalg.norm(a.true_position_m[:2] - silent_xy)))
    assert wrapped.setpoints_while_silent == 0
    assert closest > 2.0

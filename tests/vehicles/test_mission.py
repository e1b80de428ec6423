"""The mission: phases, operator actions (and their refusals), landing override and re-spacing, snapshots."""

import math

import numpy as np
import pytest

from controller.messages import Obstacle
from controller.params import FormationParams
from server.lab.metrics import spacing_error_deg
from vehicles.autopilot import FlightMode
from vehicles.mission import MissionError, MissionParams, Phase
from vehicles.sim.scenario import Scenario, build_sim

RATE_HZ = 10.0  # the controller's own step; keeps these closed-loop tests fast


def _setup(vehicles=3, person="still", trees="none", formation_enabled=True, **kw):
    setup = build_sim(Scenario(vehicles=vehicles, seed=2, person=person, trees=trees, **kw))
    setup.mission.set_formation_enabled(formation_enabled)
    return setup


def _run(setup, t0, seconds):
    t = t0
    for _ in range(round(seconds * RATE_HZ)):
        t = round(t + 1.0 / RATE_HZ, 6)
        setup.mission.step(t)
    return t


def _in_formation(setup, seconds=15.0):
    t = _run(setup, 0.0, seconds)
    assert all(v.phase == Phase.FORMATION for v in setup.mission.snapshot().vehicles)
    return t


def _true_xy(setup, ids):
    return np.array([a.true_position_m[:2] for a in setup.autopilots if a.vehicle_id in ids])


def test_vehicles_take_off_and_join_the_formation_at_the_formation_height():
    setup = _setup()
    _run(setup, 0.0, 0.1)
    assert {v.phase for v in setup.mission.snapshot().vehicles} == {Phase.TAKEOFF}
    _in_formation(setup)
    for v in setup.mission.snapshot().vehicles:
        assert v.autopilot is not None
        assert v.autopilot.mode == FlightMode.OFFBOARD
        assert v.setpoint is not None and v.plan is not None and v.plan.in_formation
    assert setup.mission.takeoff_height_m() == pytest.approx(8.9)


def test_with_formation_disabled_idle_vehicles_stay_on_the_ground():
    setup = _setup(formation_enabled=False)
    _run(setup, 0.0, 5.0)
    snap = setup.mission.snapshot()
    assert {v.phase for v in snap.vehicles} == {Phase.IDLE}
    assert not any(v.autopilot is not None and v.autopilot.in_air for v in snap.vehicles)


def test_stopping_the_formation_makes_flying_vehicles_hold_within_one_period():
    setup = _setup()
    t = _in_formation(setup)
    setup.mission.set_formation_enabled(False)
    _run(setup, t, 0.1)
    assert {a.state().mode for a in setup.autopilots} == {FlightMode.HOLD}
    assert not setup.mission.snapshot().formation_enabled


@pytest.mark.slow  # flies the team for tens of simulated seconds
def test_land_takes_effect_within_one_control_period_and_ends_landed():
    setup = _setup()
    t = _in_formation(setup)
    setup.mission.land(2)
    assert setup.mission.phase(2) == Phase.LANDING
    t = _run(setup, t, 0.1)
    landing = setup.mission.snapshot().vehicles[1].autopilot
    assert landing is not None and landing.mode == FlightMode.LAND
    _run(setup, t, 20.0)
    v = setup.mission.snapshot().vehicles[1]
    assert v.autopilot is not None
    assert v.phase == Phase.LANDED and not v.autopilot.in_air and not v.autopilot.armed


@pytest.mark.slow  # flies the team for tens of simulated seconds
def test_teammates_of_a_landed_mav_respace_to_half_a_circle():
    setup = _setup()
    t = _in_formation(setup, 20.0)
    setup.mission.land(3)
    _run(setup, t, 40.0)
    person = np.asarray(setup.world.person_truth().position_m[:2])
    gap = spacing_error_deg(positions_xy_m=_true_xy(setup, {1, 2}), person_xy_m=person)
    assert gap < 10.0
    assert setup.mission.snapshot().slot_count == 2


def test_land_all_and_release_one():
    setup = _setup()
    t = _in_formation(setup)
    setup.mission.land_all()
    t = _run(setup, t, 20.0)
    assert {v.phase for v in setup.mission.snapshot().vehicles} == {Phase.LANDED}
    setup.mission.release(1)
    _run(setup, t, 15.0)
    phases = [v.phase for v in setup.mission.snapshot().vehicles]
    assert phases == [Phase.FORMATION, Phase.LANDED, Phase.LANDED]


def test_hold_stops_one_mav_where_it_is_out_of_formation_and_release_brings_it_back():
    setup = _setup()
    t = _in_formation(setup)
    setup.mission.hold(2)
    assert setup.mission.phase(2) == Phase.HOLDING
    t = _run(setup, t, 0.1)
    held = setup.autopilots[1]
    assert held.state().mode == FlightMode.HOLD
    where = held.true_position_m
    t = _run(setup, t, 5.0)
    assert np.linalg.norm(held.true_position_m - where) < 0.5  # hovering where it was stopped
    snap = setup.mission.snapshot()
    plan = snap.vehicles[1].plan
    assert (
        plan is not None and not plan.in_formation and snap.slot_count == 2
    )  # teammates re-space without it
    setup.mission.release(2)
    _run(setup, t, 0.2)
    assert setup.mission.phase(2) == Phase.FORMATION and held.state().mode == FlightMode.OFFBOARD


@pytest.mark.slow  # flies the team for tens of simulated seconds
def test_land_all_lands_a_holding_mav_too():
    setup = _setup()
    t = _in_formation(setup)
    setup.mission.hold(1)
    setup.mission.land_all()
    assert {v.phase for v in setup.mission.snapshot().vehicles} == {Phase.LANDING}
    _run(setup, t, 20.0)
    assert {v.phase for v in setup.mission.snapshot().vehicles} == {Phase.LANDED}


def test_holding_a_mav_on_the_ground_is_refused():
    setup = _setup(formation_enabled=False)
    _run(setup, 0.0, 0.2)
    with pytest.raises(MissionError, match="only a vehicle taking off or flying formation can be held"):
        setup.mission.hold(1)


@pytest.mark.slow  # flies the team for tens of simulated seconds
def test_a_battery_failsafe_landing_takes_the_mav_out_of_formation_and_ends_landed():
    setup = _setup()
    t = _in_formation(setup)
    setup.autopilots[2].set_battery(0.15)
    t = _run(setup, t, 0.3)
    snap = setup.mission.snapshot()
    assert snap.vehicles[2].phase == Phase.LANDING and snap.slot_count == 2
    _run(setup, t, 20.0)
    assert setup.mission.phase(3) == Phase.LANDED


@pytest.mark.slow
def test_changing_d_des_moves_the_team_to_the_new_distance():
    setup = _setup()
    t = _in_formation(setup, 20.0)
    setup.mission.set_formation(FormationParams(d_des_m=6.0, h_des_m=8.0))
    _run(setup, t, 20.0)
    person = np.asarray(setup.world.person_truth().position_m[:2])
    rho = np.hypot(*(_true_xy(setup, {1, 2, 3}) - person).T)
    assert np.mean(rho) == pytest.approx(6.0, abs=0.8)


@pytest.mark.parametrize(
    ("action", "match"),
    [
        (lambda m: m.land(99), "no vehicle with id 99"),
        (lambda m: m.release(1), "only a landed or holding vehicle"),
        (lambda m: m.remove_obstacle("tree-1"), "static obstacle"),
        (lambda m: m.remove_obstacle("nope"), "no virtual obstacle"),
        (
            lambda m: m.add_obstacle(
                Obstacle(obstacle_id="tree-2", center_m=np.array([1.0, 1.0]), radius_m=1)
            ),
            "exists already",
        ),
        (lambda m: m.add_obstacle("a box"), "expected an Obstacle"),
        (lambda m: m.set_formation(FormationParams(d_des_m=math.nan)), "d_des_m"),
        (lambda m: m.set_formation(FormationParams(h_des_m=-1.0)), "h_des_m"),
    ],
)
def test_refused_operator_actions_say_why_are_counted_and_change_nothing(action, match):
    setup = _setup(trees="paper")
    t = _run(setup, 0.0, 12.0)
    before = setup.mission.snapshot()
    with pytest.raises(MissionError, match=match):
        action(setup.mission)
    after = setup.mission.snapshot()
    assert after.counters.rejected_actions == before.counters.rejected_actions + 1
    assert after.formation == before.formation
    assert [o.obstacle_id for o in after.obstacles] == [o.obstacle_id for o in before.obstacles]
    assert [v.phase for v in after.vehicles] == [v.phase for v in before.vehicles]
    _run(setup, t, 0.5)  # the mission keeps running


def test_virtual_obstacles_are_added_shown_and_removed():
    setup = _setup(trees="paper")
    box = Obstacle(obstacle_id="v1", center_m=np.array([5.0, 5.0]), radius_m=1.0, kind="virtual")
    setup.mission.add_obstacle(box)
    snap = setup.mission.snapshot()
    assert snap.virtual_obstacle_ids == ("v1",)
    assert len(snap.obstacles) == 14 and snap.obstacles[-1] is box
    setup.mission.remove_obstacle("v1")
    assert len(setup.mission.snapshot().obstacles) == 13


def test_a_virtual_obstacle_is_avoided():
    setup = _setup(vehicles=1)
    t = _in_formation(setup)
    xy = setup.autopilots[0].true_position_m[:2]
    setup.mission.add_obstacle(Obstacle(obstacle_id="v", center_m=xy, radius_m=0.5, kind="virtual"))
    _run(setup, t, 15.0)
    assert np.hypot(*(setup.autopilots[0].true_position_m[:2] - xy)) > 1.5


def test_snapshot_has_what_a_display_needs():
    setup = _setup(trees="paper")
    _in_formation(setup)
    snap = setup.mission.snapshot()
    assert snap.stamp_s == pytest.approx(15.0)
    assert snap.person_truth is not None and len(snap.obstacles) == 13
    assert snap.formation == FormationParams() and snap.formation_enabled and snap.slot_count == 3
    for v in snap.vehicles:
        assert v.person is not None and v.person.position_cov_m2.shape == (3, 3)
        assert v.status is not None and v.solver_time_s >= 0.0
        assert v.link_age_s == pytest.approx(0.0)
        assert v.tracker.accepted > 0 and v.teammates_known == 2


def test_time_going_backwards_is_refused():
    setup = _setup()
    _run(setup, 0.0, 1.0)
    with pytest.raises(ValueError, match="non-decreasing"):
        setup.mission.step(0.5)


def test_takeoff_height_follows_h_des_and_stays_inside_the_arena():
    setup = _setup(formation=FormationParams(d_des_m=8.0, h_des_m=20.0))
    assert setup.mission.takeoff_height_m() == pytest.approx(9.5)
    assert (
        build_sim(
            Scenario(vehicles=1), mission_params=MissionParams(takeoff_height_m=5.0)
        ).mission.takeoff_height_m()
        == 5.0
    )


def test_no_agent_hears_a_plan_sent_in_the_same_tick_whatever_its_place_in_the_vehicle_order():
    """With instant links, every teammate's newest plan is the previous tick's, for the first vehicle as for
    the last: the whole team takes in before any of it sends (Mission.step)."""
    setup = _setup(latency_s=0.0, jitter_s=0.0)
    t = _in_formation(setup)
    previous = round(t - 1.0 / RATE_HZ, 6)
    pilots = setup.mission._vehicles.values()  # noqa: SLF001 - what each agent heard is inside it
    newest = {v.vehicle_id: sorted(round(p.stamp_s, 6) for p in v.agent.teammate_plans(t)) for v in pilots}
    assert newest == {vid: [previous, previous] for vid in newest}

"""Specification of one MAV's formation controller (controller/formation.py): its outputs, its reference and
way-point choices, the three methods, and how it treats bad input."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from numpy.typing import ArrayLike

from controller.formation import FormationController
from controller.messages import HorizonPlan, Obstacle, PersonEstimate, SolveStatus, VehicleState
from controller.mpc import MpcParams
from controller.params import ControllerParams, FormationParams, Method
from controller.reference import ReferenceParams
from controller.separation import SeparationParams

FORMATION = FormationParams(d_des_m=8.0, h_des_m=8.0)
PERSON_AT = np.array([0.0, 0.0, 0.9])
FIELDS_ALONE = SeparationParams(enabled=False)  # the paper's fields without the separation rows


def person(
    position: ArrayLike = PERSON_AT, velocity: ArrayLike = (0.0, 0.0, 0.0), stamp_s=0.0
) -> PersonEstimate:
    return PersonEstimate(
        stamp_s=stamp_s,
        position_m=np.asarray(position),
        velocity_mps=np.asarray(velocity),
        cov=np.eye(6) * 0.01,
    )


def state(position, velocity=(0.0, 0.0, 0.0), *, vehicle_id=0, stamp_s=0.0, yaw_rad=0.0) -> VehicleState:
    return VehicleState(
        vehicle_id=vehicle_id, stamp_s=stamp_s, position_m=position, velocity_mps=velocity, yaw_rad=yaw_rad
    )


def on_circle(bearing_deg: float, radius_m: float = 8.0, height_m: float = 8.9) -> np.ndarray:
    b = np.radians(bearing_deg)
    return np.array([radius_m * np.cos(b), radius_m * np.sin(b), height_m])


def hold_plan(position, *, vehicle_id=1, stamp_s=0.0, in_formation=True) -> HorizonPlan:
    positions = np.repeat(np.asarray(position, dtype=float)[None, :], 17, axis=0)
    return HorizonPlan(
        vehicle_id=vehicle_id,
        stamp_s=stamp_s,
        dt_s=0.1,
        positions_m=positions,
        velocities_mps=np.zeros((17, 3)),
        in_formation=in_formation,
    )


def controller(method=Method.ACTIVE, **changes) -> FormationController:
    return FormationController(vehicle_id=0, params=replace(ControllerParams(method=method), **changes))


def step(ctrl, own, *, now_s=0.0, who=None, teammates=(), obstacles=(), formation=FORMATION, **kw):
    return ctrl.step(
        now_s=now_s,
        own=own,
        person=person() if who is None else who,
        teammates=teammates,
        obstacles=obstacles,
        formation=formation,
        **kw,
    )


def assert_finite_output(out):
    assert np.all(np.isfinite(out.waypoint_position_m)) and np.all(np.isfinite(out.waypoint_velocity_mps))
    assert np.isfinite(out.yaw_rad)
    assert np.all(np.isfinite(out.plan.positions_m)) and np.all(np.isfinite(out.plan.velocities_mps))


# ------------------------------------------------------------------------------------------- outputs
def test_solved_step_sends_the_plans_next_state_as_way_point():
    out = step(controller(), state(on_circle(30.0, 10.0, 5.0)))
    assert out.status == SolveStatus.SOLVED and out.fault is None
    np.testing.assert_array_equal(out.waypoint_position_m, out.plan.positions_m[1])
    np.testing.assert_array_equal(out.waypoint_velocity_mps, out.plan.velocities_mps[1])


def test_solved_step_feeds_forward_the_plans_acceleration_on_the_step_from_the_way_point():
    """What the plan does next from x(1): (v(2) - v(1)) / dt, so the autopilot brakes when the plan does."""
    out = step(controller(), state(on_circle(30.0, 10.0, 5.0), velocity=(3.0, -2.0, 0.0)))
    v = out.plan.velocities_mps
    np.testing.assert_allclose(out.waypoint_acceleration_mps2, (v[2] - v[1]) / out.plan.dt_s, atol=1e-12)
    assert np.linalg.norm(out.waypoint_acceleration_mps2) > 0.5  # the plan does turn the vehicle


def test_yaw_faces_the_person_from_the_way_point():
    out = step(controller(), state(on_circle(120.0, 10.0, 5.0)))
    to_person = PERSON_AT[:2] - out.waypoint_position_m[:2]
    assert out.yaw_rad == pytest.approx(np.arctan2(to_person[1], to_person[0]), abs=1e-12)


def test_plan_heads_for_d_des_and_h_des_along_the_current_bearing():
    own = on_circle(-60.0, 11.0, 5.0)
    ctrl = controller()
    out = step(ctrl, state(own))
    for tick in range(1, 120):  # the climb of 3.9 m at the 0.5 m/s bound takes 8 s
        own = out.plan.positions_m[1]
        out = step(ctrl, state(own), now_s=0.1 * tick)
    end = out.plan.positions_m[-1]
    assert np.hypot(end[0], end[1]) == pytest.approx(8.0, abs=0.3)
    assert end[2] == pytest.approx(0.9 + 8.0, abs=0.2)
    assert np.degrees(np.arctan2(end[1], end[0])) == pytest.approx(-60.0, abs=0.5)


def test_published_plan_carries_identity_stamp_and_role():
    ctrl = FormationController(vehicle_id=4, params=ControllerParams())
    out = ctrl.step(
        now_s=12.5,
        own=state(on_circle(0.0), vehicle_id=4),
        person=person(),
        teammates=(),
        obstacles=(),
        formation=FORMATION,
        in_formation=False,
    )
    plan = out.plan
    assert (plan.vehicle_id, plan.stamp_s, plan.dt_s, plan.in_formation) == (4, 12.5, 0.1, False)
    assert out.plan.positions_m.shape == (17, 3)


def test_way_point_step_is_a_parameter():
    out = step(controller(reference=ReferenceParams(waypoint_step=4)), state(on_circle(10.0, 10.0, 5.0)))
    np.testing.assert_array_equal(out.waypoint_position_m, out.plan.positions_m[4])


# ------------------------------------------------------------------------------------ reference choices
def test_plan_starts_from_the_previous_plan_when_the_vehicle_is_on_it():
    ctrl = controller()
    first = step(ctrl, state(on_circle(0.0, 10.0, 5.0)))
    lagging = first.plan.positions_m[1] + np.array([0.4, 0.0, 0.0])  # within the 1 m leash
    second = step(ctrl, state(lagging, first.plan.velocities_mps[1]), now_s=0.1)
    np.testing.assert_allclose(second.plan.positions_m[0], first.plan.positions_m[1], atol=1e-12)


def test_plan_start_is_pulled_onto_the_leash_towards_a_distant_vehicle():
    ctrl = controller()
    first = step(ctrl, state(on_circle(0.0, 10.0, 5.0)))
    measured = first.plan.positions_m[1] + np.array([0.0, 5.0, 0.0])
    second = step(ctrl, state(measured, first.plan.velocities_mps[1]), now_s=0.1)
    np.testing.assert_allclose(second.plan.positions_m[0], measured - np.array([0.0, 1.0, 0.0]), atol=1e-9)


def test_pass_through_lets_the_inputs_act_uncancelled():
    own = state(on_circle(0.0))  # at its reference point, at rest; a neighbour 20 deg away pushes sideways
    mate = [hold_plan(on_circle(20.0))]
    free = step(controller(), own, teammates=mate)
    fought = step(controller(reference=ReferenceParams(pass_through=False)), own, teammates=mate)
    f0 = free.external_inputs[0, :2]
    assert np.linalg.norm(f0) > 0.5
    free_accel = (free.plan.velocities_mps[1, :2] - 0.0) / 0.1
    fought_accel = (fought.plan.velocities_mps[1, :2] - 0.0) / 0.1
    np.testing.assert_allclose(free_accel, f0, atol=1e-3)
    assert np.linalg.norm(fought_accel) < 0.2 * np.linalg.norm(f0)


def test_preferred_bearing_sets_the_terminal_reference():
    ctrl = controller()
    own = on_circle(0.0)
    for tick in range(100):
        out = step(ctrl, state(own), now_s=0.1 * tick, preferred_bearing_rad=np.radians(45.0))
        own = out.plan.positions_m[1]
    assert np.degrees(np.arctan2(own[1], own[0])) == pytest.approx(45.0, abs=3.0)
    assert np.hypot(own[0], own[1]) == pytest.approx(8.0, abs=0.5)


def test_non_finite_preferred_bearing_is_ignored_and_counted():
    ctrl = controller()
    out = step(ctrl, state(on_circle(0.0)), preferred_bearing_rad=float("nan"))
    assert out.status == SolveStatus.SOLVED
    assert ctrl.stats.ignored_bearings == 1


# ---------------------------------------------------------------------------------------- team size
def test_only_in_formation_teammates_steer_the_spacing():
    own = state(on_circle(0.0))
    near_bearing = on_circle(25.0, 8.0)  # 3.5 m away: outside the teammate repulsion's 3 m
    left = step(controller(), own, teammates=[hold_plan(near_bearing, in_formation=False)])
    spaced = step(controller(), own, teammates=[hold_plan(near_bearing, in_formation=True)])
    np.testing.assert_array_equal(left.external_inputs, 0.0)
    assert np.linalg.norm(spaced.external_inputs[0]) > 0.1


def test_the_fields_push_away_from_an_out_of_formation_teammate():
    """The paper's fields alone (rows off: with them this tick is an escape, which flies without fields)."""
    own = state(on_circle(0.0))
    close = on_circle(0.0) + np.array([0.0, 2.0, 0.0])
    out = step(controller(separation=FIELDS_ALONE), own, teammates=[hold_plan(close, in_formation=False)])
    assert out.external_inputs[0, 1] == pytest.approx(-1.20, abs=0.01)


def test_an_escape_opens_the_gap_to_an_out_of_formation_teammate():
    """2 m from a teammate outside the formation, inside the rows' 2.6 m: the escape plan ends 3.57 m off."""
    close = on_circle(0.0) + np.array([0.0, 2.0, 0.0])
    out = step(controller(), state(on_circle(0.0)), teammates=[hold_plan(close, in_formation=False)])
    assert out.status == SolveStatus.ESCAPE
    assert np.linalg.norm(out.plan.positions_m[-1] - close) == pytest.approx(3.57, abs=0.01)


def _gap_to_a_teammate_4_m_north_as_reported(ours, theirs) -> np.ndarray:
    """(N+2,) distances of our plan from a holding teammate reported 4 m north, placed by both GPS offsets."""
    own = replace(state(on_circle(0.0)), gps_offset_m=np.array(ours, dtype=float))
    reported = on_circle(0.0) + np.array([0.0, 4.0, 0.0])
    mate = replace(hold_plan(reported, in_formation=False), gps_offset_m=np.array(theirs, dtype=float))
    out = step(controller(), own, teammates=[mate])
    return np.linalg.norm(out.plan.positions_m - (reported + np.array(ours) - np.array(theirs)), axis=1)


def test_the_separation_rows_place_a_teammate_by_both_gps_offsets():
    # our GPS reads 0.8 m south of where we are among the team, the teammate's 0.8 m north: it is 2.4 m away
    gaps = _gap_to_a_teammate_4_m_north_as_reported((0.0, -0.8, 0.0), (0.0, 0.8, 0.0))
    assert gaps[0] == pytest.approx(2.4, abs=1e-9)
    assert gaps[-1] > 2.9  # the plan opens the whole gap (2.6 m) to where the teammate is


def test_without_gps_offsets_the_same_teammate_4_m_away_moves_nothing():
    np.testing.assert_allclose(_gap_to_a_teammate_4_m_north_as_reported((0, 0, 0), (0, 0, 0)), 4.0, atol=1e-6)


# ------------------------------------------------------------------------------------------- methods
@pytest.mark.parametrize("method", list(Method))
def test_each_method_solves_with_teammates_and_trees(method):
    ctrl = controller(method)
    mates = [hold_plan(on_circle(b), vehicle_id=i + 1) for i, b in enumerate((15.0, 100.0, -90.0))]
    trees = [Obstacle(obstacle_id="t", center_m=np.array([8.5, 2.0]), radius_m=0.3)]
    own = on_circle(0.0, 9.0, 6.0)
    for tick in range(20):
        out = step(ctrl, state(own), now_s=0.1 * tick, teammates=mates, obstacles=trees)
        # the teammate at 15 degrees is 2.4 m away, inside the separation rows' 2.6 m: solved or escaping,
        # never a braking plan
        assert out.status in (SolveStatus.SOLVED, SolveStatus.ESCAPE)
        assert_finite_output(out)
        own = out.plan.positions_m[1]


def test_dqmpc_does_not_steer_the_spacing():
    own = state(on_circle(0.0))
    out = step(controller(Method.DQMPC), own, teammates=[hold_plan(on_circle(30.0))])
    np.testing.assert_array_equal(out.external_inputs, 0.0)  # 4.1 m away: beyond DQMPC's 4 m


def test_price_avoids_only_the_teammates_current_position():
    """The methods' fields alone (rows off: with them a plan crossing ours is an escape, without fields)."""
    own = state(on_circle(0.0))
    crossing = np.repeat(on_circle(90.0)[None, :], 17, axis=0)
    crossing[5:] = on_circle(0.0) + np.array([0.0, 1.0, 0.0])  # its plan later crosses our position
    plan = HorizonPlan(
        vehicle_id=1, stamp_s=0.0, dt_s=0.1, positions_m=crossing, velocities_mps=np.zeros((17, 3))
    )
    price = step(controller(Method.PRICE, separation=FIELDS_ALONE), own, teammates=[plan])
    active = step(controller(Method.ACTIVE, separation=FIELDS_ALONE), own, teammates=[plan])
    np.testing.assert_allclose(price.external_inputs[:, :2], 0.0, atol=1e-12)
    assert np.abs(active.external_inputs[5:, 1]).max() > 1.0


def test_price_aims_at_zero_terminal_velocity():
    walking = person(velocity=(1.0, 0.0, 0.0))
    ctrl = controller(Method.PRICE)
    out = step(ctrl, state(on_circle(90.0)), who=walking)
    for tick in range(1, 30):
        out = step(ctrl, state(out.plan.positions_m[1]), now_s=0.1 * tick, who=walking)
    np.testing.assert_allclose(out.plan.velocities_mps[-1], 0.0, atol=0.05)


# ----------------------------------------------------------------------------------------------- hold
def hold_from_6_m(ctrl: FormationController, ticks: int = 20, teammates=()):
    """Hold for `ticks` ticks, from 6 m (the formation height is 8.9 m), the vehicle on its plans."""
    out = step(ctrl, state(on_circle(0.0, 8.0, 6.0)), hold=True, teammates=teammates)
    for tick in range(1, ticks):
        out = step(ctrl, state(out.plan.positions_m[1]), now_s=0.1 * tick, hold=True, teammates=teammates)
    return out


def test_a_hold_before_formation_flight_climbs_to_the_formation_height():
    """After take-off: climbing towards 8.9 m at up to the 0.5 m/s vertical bound, 0.83 m in 1.9 s."""
    out = hold_from_6_m(controller())
    assert out.status == SolveStatus.HOLD
    assert out.plan.positions_m[0, 2] == pytest.approx(6.83, abs=0.02)


def test_a_hold_before_formation_flight_climbs_as_if_alone():
    """The climb after take-off keeps no teammate rows: a teammate 1.2 m aside and 0.5 m above, inside the
    1.6 m gap, leaves the plan exactly as it is with no teammate at all."""
    beside = [hold_plan(on_circle(0.0, 8.0, 6.5) + np.array([0.0, 1.2, 0.0]), in_formation=False)]
    alone = hold_from_6_m(controller()).plan.positions_m
    np.testing.assert_array_equal(hold_from_6_m(controller(), teammates=beside).plan.positions_m, alone)


def test_a_price_hold_feels_no_teammates_field():
    """A hold flies without the fields a silent teammate cannot foresee, PRICE's repulsion included: a
    teammate 1.2 m away leaves the resting plan as it is with no teammate at all."""
    mate = [hold_plan(on_circle(0.0) + np.array([0.0, 1.2, 0.0]), in_formation=False)]
    plans = []
    for teammates in (mate, ()):
        ctrl = controller(Method.PRICE)
        step(ctrl, state(on_circle(0.0)))  # formation flight has begun
        plans.append(step(ctrl, state(on_circle(0.0)), now_s=0.1, teammates=teammates, hold=True).plan)
    np.testing.assert_allclose(plans[0].positions_m, plans[1].positions_m, atol=1e-9)


def test_a_hold_after_formation_flight_rests_at_its_height():
    """A holding MAV must not climb into the height a teammate escaped to (its rows do not make room)."""
    ctrl = controller()
    step(ctrl, state(on_circle(0.0, 8.0, 6.0)))  # one tick of formation flight
    out = hold_from_6_m(ctrl)
    np.testing.assert_allclose(out.plan.positions_m[:, 2], 6.0, atol=0.01)


def test_reset_makes_the_next_hold_climb_again():
    ctrl = controller()
    step(ctrl, state(on_circle(0.0, 8.0, 6.0)))
    ctrl.reset()  # landed
    assert hold_from_6_m(ctrl).plan.positions_m[0, 2] > 6.8


def hold_closing_on(mate_position, *, speed_mps: float, ticks: int = 40) -> float:
    """Enter a hold at speed_mps north, after a tick of formation flight, towards a teammate holding at
    mate_position; fly on the plans for `ticks` ticks; return the closest the plan start came to it (m)."""
    ctrl = controller()
    here = on_circle(0.0)
    step(ctrl, state(here))  # formation flight has begun
    mate = [hold_plan(mate_position, in_formation=False)]
    out = step(ctrl, state(here, (0.0, speed_mps, 0.0)), teammates=mate, hold=True)
    closest = np.inf
    for tick in range(1, ticks):
        p, v = out.plan.positions_m[1], out.plan.velocities_mps[1]
        out = step(ctrl, state(p, v), now_s=0.1 * tick, teammates=mate, hold=True)
        closest = min(closest, float(np.linalg.norm(out.plan.positions_m[0] - mate_position)))
    return closest


def test_a_hold_entered_fast_brakes_short_of_a_resting_teammate():
    """At 3.6 m/s towards a teammate 4.5 m ahead: the eased rows let the plan close no further than braking
    at 3 m/s^2 must (2.16 m), and it stops 3.25 m short; the MPC's rest plan alone, which weighs effort,
    stopped 2.21 m short."""
    mate = on_circle(0.0) + np.array([0.0, 4.5, 0.0])
    assert hold_closing_on(mate, speed_mps=3.6) == pytest.approx(3.25, abs=0.1)


def test_a_resting_teammate_inside_the_gap_does_not_push_a_hold_about():
    """A teammate 1.2 m away, well inside the 1.6 m gap: the holding MAV stays where it rests."""
    mate = on_circle(0.0) + np.array([0.0, 1.2, 0.0])
    assert hold_closing_on(mate, speed_mps=0.0, ticks=20) == pytest.approx(1.2, abs=0.01)


def test_a_hold_entered_fast_towards_a_trunk_stops_three_sigma_off_its_bark():
    """At 4.5 m/s towards a trunk whose bark is 4 m ahead: the hold's trunk rows keep 0.2 m plus 3
    covariance radii (0.5 m each), 1.7 m; with the formation's 1.5 radii the plan stopped 0.95 m off."""
    ctrl = controller()
    here = on_circle(0.0)
    trunk = Obstacle(obstacle_id="t", center_m=here[:2] + np.array([0.0, 4.3]), radius_m=0.3)
    step(ctrl, state(here), obstacles=(trunk,))  # formation flight has begun
    out = step(ctrl, state(here, (0.0, 4.5, 0.0)), obstacles=(trunk,), hold=True)
    closest = np.inf
    for tick in range(1, 60):
        p, v = out.plan.positions_m[1], out.plan.velocities_mps[1]
        out = step(ctrl, state(p, v), now_s=0.1 * tick, obstacles=(trunk,), hold=True)
        closest = min(closest, float(np.linalg.norm(out.plan.positions_m[0, :2] - trunk.center_m)) - 0.3)
    assert closest == pytest.approx(1.7, abs=0.05)


@pytest.mark.parametrize(("bounded", "most_mps2"), [(True, 3.0), (False, 5.2)])
def test_a_plan_backing_off_a_close_teammate_asks_no_more_than_the_input_box(bounded, most_mps2):
    """At 3.8 m/s towards a teammate resting 2 m ahead, the fields push back hard: the plan's horizontal
    acceleration stays within the input box's 3 m/s^2 with the fields included; with the paper's bound (u
    alone) it reaches 5.2 m/s^2, more than the vehicle's 4 (run 413 of the safety sweep, docs/safety.md).
    The fields alone: with the rows this tick is an escape, which flies without fields."""
    mpc = ControllerParams().mpc
    if not bounded:
        mpc = replace(mpc, plan_acceleration_min_mps2=None, plan_acceleration_max_mps2=None)
    ctrl = controller(mpc=mpc, separation=FIELDS_ALONE)
    here = on_circle(0.0)
    out = step(ctrl, state(here, (0.0, 3.8, 0.0)), teammates=[hold_plan(here + np.array([0.0, 2.0, 0.0]))])
    acceleration = np.diff(out.plan.velocities_mps, axis=0) / out.plan.dt_s
    assert np.max(np.abs(acceleration[:, :2])) == pytest.approx(most_mps2, abs=0.01)


def test_an_escape_from_a_silent_teammate_above_does_not_sink_below_the_floor():
    """A teammate 0.8 m aside and 1.2 m above, its plan 0.6 s old: its gap has grown past what any plan
    can keep (the rows are missed by 2.6 m), and its row's normal points down. The escape's plan gives way
    to it, but not through the arena's 3 m floor: its lowest step is at 3.0 m (without the floor rows the
    rows drove such plans through the soft height bound to below the ground: run 277 of the safety sweep,
    docs/safety.md)."""
    ctrl = controller()
    here = np.array([0.0, -8.0, 4.0])
    out = step(ctrl, state(here))
    for tick in range(1, 8):
        now = 0.1 * tick
        mate = hold_plan(here + np.array([0.8, 0.0, 1.2]), stamp_s=now - 0.6)
        own = state(out.plan.positions_m[1], out.plan.velocities_mps[1]) if tick > 1 else state(here)
        out = step(ctrl, own, now_s=now, teammates=[mate])
        assert out.status == SolveStatus.ESCAPE
        assert out.plan.positions_m[:, 2].min() == pytest.approx(3.0, abs=1e-3)


def test_an_escape_flies_without_the_fields_even_where_a_trunks_push_exceeds_the_input_box():
    """A trunk 1.5 m behind pushes at 8 m/s^2, beyond the input box's 3 (the tick without a teammate shows
    it); with a silent teammate above forcing an escape, the escape's plan has no external inputs: with
    them it was pushed on at the box's limit, whatever the rows asked, into the next trunk (run 360 of the
    safety sweep, docs/safety.md)."""
    here = np.array([0.0, -8.0, 6.0])
    trunk = Obstacle(obstacle_id="t", center_m=here[:2] + np.array([0.0, -1.8]), radius_m=0.3)
    moving = state(here, (0.0, 3.0, 0.0))
    alone = step(controller(), moving, obstacles=(trunk,))
    assert alone.status == SolveStatus.SOLVED
    assert alone.external_inputs[0, 1] == pytest.approx(8.0, abs=0.01)
    ctrl = controller()
    step(ctrl, state(here), obstacles=(trunk,))
    mate = hold_plan(here + np.array([0.8, 0.0, 1.2]), stamp_s=-0.5)
    out = step(ctrl, moving, now_s=0.1, teammates=[mate], obstacles=(trunk,))
    assert out.status == SolveStatus.ESCAPE
    np.testing.assert_array_equal(out.external_inputs, 0.0)


# ------------------------------------------------------------------------------------------ bad input
def test_no_person_brakes_to_rest():
    ctrl = controller()
    out = ctrl.step(
        now_s=0.0,
        own=state(on_circle(0.0), (2.0, 1.0, 0.0)),
        person=None,
        teammates=(),
        obstacles=(),
        formation=FORMATION,
    )
    assert out.status == SolveStatus.NO_PERSON
    np.testing.assert_allclose(out.plan.velocities_mps[-1], 0.0, atol=1e-9)
    assert np.linalg.norm(out.waypoint_velocity_mps) < np.hypot(2.0, 1.0)


@pytest.mark.parametrize(
    "field, value", [("position_m", (np.nan, 0.0, 5.0)), ("velocity_mps", (0.0, np.inf, 0.0))]
)
def test_non_finite_own_state_brakes_with_a_finite_way_point(field, value):
    ctrl = controller()
    good = step(ctrl, state(on_circle(0.0, 10.0, 5.0)))
    bad = {"position_m": good.plan.positions_m[1], "velocity_mps": good.plan.velocities_mps[1], field: value}
    out = step(ctrl, state(bad["position_m"], bad["velocity_mps"]), now_s=0.1)
    assert out.fault is not None
    assert out.status == SolveStatus.BRAKING and "own state" in out.fault
    assert_finite_output(out)
    assert ctrl.stats.rejected_inputs == 1


def test_non_finite_own_state_on_the_first_tick_still_gives_a_finite_way_point():
    out = step(controller(), state((np.nan, np.nan, np.nan), (np.nan, 0.0, 0.0)))
    assert out.status == SolveStatus.BRAKING
    assert_finite_output(out)


def test_non_finite_person_estimate_brakes():
    out = step(controller(), state(on_circle(0.0)), who=person(position=(np.nan, 0.0, 0.9)))
    assert out.fault is not None
    assert out.status == SolveStatus.BRAKING and "person" in out.fault
    assert_finite_output(out)


@pytest.mark.parametrize(
    "formation",
    [
        FormationParams(d_des_m=float("nan")),
        FormationParams(d_des_m=-3.0),
        FormationParams(h_des_m=float("inf")),
    ],
)
def test_invalid_formation_parameters_brake(formation):
    out = step(controller(), state(on_circle(0.0)), formation=formation)
    assert out.fault is not None
    assert out.status == SolveStatus.BRAKING and "formation parameters" in out.fault
    assert_finite_output(out)


def test_non_finite_time_brakes():
    out = step(controller(), state(on_circle(0.0)), now_s=float("nan"))
    assert out.fault is not None
    assert out.status == SolveStatus.BRAKING and "time" in out.fault
    assert_finite_output(out)


def test_garbage_teammate_plans_are_dropped_and_counted():
    ctrl = controller()
    nan_plan = hold_plan((np.nan, 1.0, 8.0), vehicle_id=1)
    own_echo = hold_plan(on_circle(10.0), vehicle_id=0)
    late_nan = HorizonPlan(
        vehicle_id=2,
        stamp_s=float("nan"),
        dt_s=0.1,
        positions_m=np.ones((17, 3)),
        velocities_mps=np.zeros((17, 3)),
    )
    out = step(ctrl, state(on_circle(0.0)), teammates=[nan_plan, own_echo, late_nan])
    assert out.status == SolveStatus.SOLVED
    assert ctrl.stats.rejected_plans == 3
    np.testing.assert_array_equal(out.external_inputs, 0.0)


def test_obstacle_with_non_finite_centre_is_counted():
    ctrl = controller()
    bad = Obstacle(obstacle_id="x", center_m=np.array([np.nan, 1.0]), radius_m=0.3)
    out = step(ctrl, state(on_circle(0.0)), obstacles=[bad])
    assert out.status == SolveStatus.SOLVED and ctrl.stats.rejected_obstacles == 1


@pytest.mark.parametrize("solver", ["osqp", "exact"])
def test_solver_failure_falls_back_to_braking(solver):
    stubborn = MpcParams(solver=solver, max_iterations=1, accept_inaccurate=False, polishing=False)
    ctrl = controller(mpc=stubborn)
    out = step(ctrl, state(on_circle(0.0, 12.0, 4.0), (3.0, -2.0, 0.0)))
    assert out.fault is not None
    assert out.status == SolveStatus.BRAKING and out.fault.startswith("MPC:")
    assert_finite_output(out)
    assert ctrl.stats.braking == 1


def test_random_garbage_never_yields_a_non_finite_way_point():
    rng = np.random.default_rng(2024)
    specials = np.array([np.nan, np.inf, -np.inf, 1e300, -1e300, 0.0])

    def vec(n=3):
        v = rng.normal(0.0, 10.0, n)
        mask = rng.random(n) < 0.3
        v[mask] = rng.choice(specials, mask.sum())
        return v

    for method in Method:
        ctrl = controller(method)
        for tick in range(60):
            mates = [
                HorizonPlan(
                    vehicle_id=int(rng.integers(0, 4)),
                    stamp_s=float(vec(1)[0]),
                    dt_s=float(rng.choice([0.1, 0.0, -1.0, np.nan])),
                    positions_m=np.stack([vec() for _ in range(17)]),
                    velocities_mps=np.zeros((17, 3)),
                )
                for _ in range(int(rng.integers(0, 4)))
            ]
            who = None if rng.random() < 0.1 else person(position=vec(), velocity=vec())
            formation = FormationParams(
                d_des_m=float(rng.choice([8.0, 8.0, np.nan, -1.0, 1e9])),
                h_des_m=float(rng.choice([8.0, 8.0, np.inf])),
            )
            bearing = float(rng.choice([np.nan, 1.0])) if rng.random() < 0.2 else None
            now_s = float(rng.choice([0.1 * tick, 0.1 * tick, np.nan]))
            out = ctrl.step(
                now_s=now_s,
                own=state(vec(), vec()),
                person=who,
                teammates=mates,
                obstacles=(),
                formation=formation,
                preferred_bearing_rad=bearing,
            )
            assert_finite_output(out)
        stats = ctrl.stats
        assert stats.ticks == 60 == stats.solved + stats.braking + stats.no_person


def test_a_mav_closing_on_a_trunk_at_speed_is_braked_before_the_trunks_d_max():
    # The simulator's case: a MAV catching up at 2.9 m/s went through a trunk. The trunk's surface is 4 m
    # ahead, beyond d_max = 3 m: at rest there is no obstacle input, at 3 m/s its braking distance (2.25 m)
    # brings the trunk inside the field and the input opposes the motion from the first step.
    own_p = on_circle(180.0)
    trunk = Obstacle(obstacle_id="t", center_m=own_p[:2] + np.array([0.0, 4.3]), radius_m=0.3)
    at_rest = step(controller(), state(own_p), obstacles=(trunk,))
    closing = step(controller(), state(own_p, velocity=(0.0, 3.0, 0.0)), obstacles=(trunk,))
    np.testing.assert_allclose(at_rest.external_inputs[:, 1], 0.0, atol=1e-12)
    assert closing.external_inputs[0, 1] < -3.0

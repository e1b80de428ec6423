"""One MAV's loop: tracker fusion, message handling, roles, plan publishing, roster slot, robustness."""

import math
from typing import cast

import numpy as np
import pytest

from controller.formation import FormationController
from controller.messages import Detection, HorizonPlan
from controller.params import ControllerParams
from vehicles.agent import Agent, AgentInputs, AgentParams, AgentRole, hold_plan
from vehicles.autopilot import AutopilotState, FlightMode

PERSON = np.array([0.0, 0.0, 0.9])


def _state(vid=1, t=0.0, pos=(8.0, 0.0, 8.9)):
    return AutopilotState(
        vehicle_id=vid,
        stamp_s=t,
        position_m=pos,
        velocity_mps=np.array((0, 0, 0)),
        yaw_rad=math.pi,
        armed=True,
        in_air=True,
        mode=FlightMode.OFFBOARD,
    )


def _det(source, t, pos=PERSON):
    return Detection(source_id=source, stamp_s=t, position_m=pos, cov_m2=np.eye(3) * 0.5)


def _plan(vid, t, pos, in_formation=True):
    n = ControllerParams().mpc.horizon_steps + 2
    return HorizonPlan(
        vehicle_id=vid,
        stamp_s=t,
        dt_s=0.1,
        positions_m=np.tile(pos, (n, 1)),
        velocities_mps=np.zeros((n, 3)),
        in_formation=in_formation,
    )


def _inputs(t, **kw):
    kw.setdefault("own", _state(t=t))
    return AgentInputs(**kw)


def test_own_detections_are_fused_and_broadcast():
    agent = Agent(vehicle_id=1)
    dets = (_det(1, 0.0),)
    out = agent.tick(0.0, _inputs(0.0, detections=dets, role=AgentRole.GROUND))
    assert out.person is not None
    np.testing.assert_allclose(out.person.position_m, PERSON, atol=1e-9)
    assert out.counters.own_detections_fused == 1
    assert out.outbox == dets


def test_teammate_detections_are_fused_and_not_rebroadcast():
    agent = Agent(vehicle_id=1)
    out = agent.tick(0.1, _inputs(0.1, received=(_det(2, 0.05),), role=AgentRole.GROUND))
    assert out.counters.teammate_detections_fused == 1
    assert out.person is not None
    assert out.outbox == ()


def test_a_ticks_detections_are_fused_in_capture_time_order_whatever_order_they_arrive_in():
    """Teammates' detections arriving newest first and an own detection older than them: fused oldest first,
    so nothing is re-filtered out of order, and the estimate is the one of an in-order arrival."""
    arrived = (_det(4, 0.30, PERSON + [0.2, 0, 0]), _det(3, 0.25, PERSON + [0.1, 0, 0]), _det(2, 0.20))
    own = (_det(1, 0.15, PERSON - [0.1, 0, 0]),)
    shuffled, ordered = Agent(vehicle_id=1), Agent(vehicle_id=1)
    shuffled.tick(0.0, _inputs(0.0, detections=(_det(1, 0.0),), role=AgentRole.GROUND))
    ordered.tick(0.0, _inputs(0.0, detections=(_det(1, 0.0),), role=AgentRole.GROUND))
    out = shuffled.tick(0.35, _inputs(0.35, received=arrived, detections=own, role=AgentRole.GROUND))
    ordered.tick(0.35, _inputs(0.35, detections=own, role=AgentRole.GROUND))
    want = ordered.tick(0.35, _inputs(0.35, received=arrived[::-1], role=AgentRole.GROUND))
    assert out.tracker.out_of_order == 0 and out.tracker.accepted == 5
    assert out.counters.own_detections_fused == 2 and out.counters.teammate_detections_fused == 3
    assert out.person is not None and want.person is not None
    np.testing.assert_allclose(out.person.position_m, want.person.position_m, atol=1e-12)
    np.testing.assert_allclose(out.person.cov, want.person.cov, atol=1e-12)


def test_echoes_of_its_own_messages_and_unknown_messages_are_rejected_and_counted():
    agent = Agent(vehicle_id=1)
    bad_plan = _plan(2, 0.0, [np.nan, 0.0, 8.9])
    received = (_det(1, 0.0), _plan(1, 0.0, [8.0, 0, 8.9]), "garbage", bad_plan)
    out = agent.tick(0.1, _inputs(0.1, received=received, detections=(_det(3, 0.0),), role=AgentRole.GROUND))
    assert out.counters.rejected_messages == 5
    assert out.person is None
    assert agent.teammate_plans(0.1) == ()


def test_formation_role_sends_a_finite_setpoint_and_publishes_an_in_formation_plan():
    agent = Agent(vehicle_id=1)
    out = agent.tick(0.0, _inputs(0.0, detections=(_det(1, 0.0),), role=AgentRole.FORMATION))
    assert out.setpoint is not None and out.control is not None
    assert np.all(np.isfinite(out.setpoint.position_m)) and np.isfinite(out.setpoint.yaw_rad)
    plans = [m for m in out.outbox if isinstance(m, HorizonPlan)]
    assert len(plans) == 1 and plans[0].in_formation and plans[0].vehicle_id == 1


def test_ground_role_sends_no_setpoint_and_no_plan_but_keeps_tracking():
    agent = Agent(vehicle_id=1)
    out = agent.tick(0.0, _inputs(0.0, detections=(_det(1, 0.0),), role=AgentRole.GROUND))
    assert out.setpoint is None and out.plan is None
    assert not any(isinstance(m, HorizonPlan) for m in out.outbox)
    assert out.person is not None


def test_airborne_role_publishes_a_hold_plan_out_of_formation():
    agent = Agent(vehicle_id=1)
    out = agent.tick(0.0, _inputs(0.0, role=AgentRole.AIRBORNE))
    assert out.setpoint is None
    assert out.plan is not None and not out.plan.in_formation
    np.testing.assert_allclose(out.plan.positions_m, np.tile([8.0, 0.0, 8.9], (17, 1)))


def test_plans_go_out_at_10_hz_when_ticked_at_100_hz():
    agent = Agent(vehicle_id=1)
    sent = 0
    for i in range(100):
        t = i * 0.01
        out = agent.tick(t, _inputs(t, role=AgentRole.AIRBORNE))
        sent += sum(isinstance(m, HorizonPlan) for m in out.outbox)
    assert sent == 10


def test_teammate_plans_are_kept_until_the_timeout():
    agent = Agent(vehicle_id=1)
    agent.tick(0.0, _inputs(0.0, received=(_plan(2, 0.0, [-8.0, 0.0, 8.9]),), role=AgentRole.GROUND))
    assert [p.vehicle_id for p in agent.teammate_plans(2.9)] == [2]
    assert agent.teammate_plans(3.1) == ()


def test_a_newer_plan_replaces_an_older_one_but_not_the_reverse():
    agent = Agent(vehicle_id=1)
    new, old = _plan(2, 1.0, [-8.0, 0.0, 8.9]), _plan(2, 0.5, [-7.0, 0.0, 8.9])
    agent.tick(1.1, _inputs(1.1, received=(new, old), role=AgentRole.GROUND))
    assert agent.teammate_plans(1.1)[0].stamp_s == 1.0


ROSTER = ((1, 0.0), (2, 2.0 * math.pi / 3.0), (3, 4.0 * math.pi / 3.0))


def test_the_roster_slot_is_used_only_while_teammates_are_not_in_formation():
    agent = Agent(vehicle_id=1)
    climbing = (_plan(2, 0.0, [-4.0, 6.9, 5.0], False), _plan(3, 0.0, [-4.0, -6.9, 5.0], False))
    taking_off = agent.tick(0.0, _inputs(0.0, detections=(_det(1, 0.0),), received=climbing, roster=ROSTER))
    assert taking_off.used_slot and taking_off.teammates_known == 0
    mates = (_plan(2, 0.05, [-4.0, 6.9, 8.9]), _plan(3, 0.05, [-4.0, -6.9, 8.9]))
    heard = agent.tick(0.1, _inputs(0.1, received=mates, roster=ROSTER))
    assert not heard.used_slot and heard.teammates_known == 2
    assert heard.counters.slot_ticks == 1


def test_a_roster_teammate_never_heard_makes_the_mav_hold_where_it_is():
    agent = Agent(vehicle_id=1)
    heard = (_plan(2, 0.0, [-4.0, 6.9, 8.9]),)
    out = agent.tick(0.0, _inputs(0.0, detections=(_det(1, 0.0),), received=heard, roster=ROSTER))
    assert out.control is not None and out.control.status.value == "hold"
    assert out.fault == "hold: teammate 3 unheard for more than 1.5 s"
    assert out.counters.hold_ticks == 1 and not out.used_slot
    assert out.plan is not None and not out.plan.in_formation  # the others keep their whole distance
    assert not out.control.external_inputs.any()  # no field pushes a holding MAV
    assert out.setpoint is not None  # at rest, at h_des above the person, where it is horizontally
    np.testing.assert_allclose(out.plan.positions_m[-1], [8.0, 0.0, 8.9], atol=0.05)
    np.testing.assert_allclose(out.setpoint.velocity_mps, 0.0, atol=0.05)


def test_a_holding_mav_is_not_pushed_about_by_a_teammate_close_by():
    agent = Agent(vehicle_id=1)
    close = (_plan(2, 0.0, [7.0, 0.0, 8.9]),)  # 1 m away, heard; 3 unheard: hold
    out = agent.tick(0.0, _inputs(0.0, detections=(_det(1, 0.0),), received=close, roster=ROSTER))
    assert out.control is not None and out.control.status.value == "hold"
    assert out.plan is not None
    np.testing.assert_allclose(out.plan.positions_m[-1], [8.0, 0.0, 8.9], atol=0.05)


def test_the_hold_starts_when_a_teammate_is_silent_for_longer_than_blind_after_s():
    agent = Agent(vehicle_id=1)
    mates = (_plan(2, 0.0, [-4.0, 6.9, 8.9]), _plan(3, 0.0, [-4.0, -6.9, 8.9]))
    agent.tick(0.0, _inputs(0.0, detections=(_det(1, 0.0),), received=mates, roster=ROSTER))
    statuses = {}
    for t in (1.0, 1.5, 1.6):
        only_2 = (_plan(2, t, [-4.0, 6.9, 8.9]),)  # 3 falls silent after its plan stamped 0.0
        out = agent.tick(t, _inputs(t, received=only_2, roster=ROSTER))
        assert out.control is not None
        statuses[t] = out.control.status.value
    assert statuses == {1.0: "solved", 1.5: "solved", 1.6: "hold"}


def test_the_hold_ends_as_soon_as_every_teammate_is_heard_again():
    agent = Agent(vehicle_id=1)
    agent.tick(0.0, _inputs(0.0, detections=(_det(1, 0.0),), roster=ROSTER))
    mates = (_plan(2, 0.1, [-4.0, 6.9, 8.9]), _plan(3, 0.1, [-4.0, -6.9, 8.9]))
    out = agent.tick(0.1, _inputs(0.1, received=mates, roster=ROSTER))
    assert out.control is not None and out.control.status.value == "solved"
    assert out.plan is not None and out.plan.in_formation and out.counters.hold_ticks == 1


def test_a_hold_ends_only_when_every_teammate_is_heard_within_resume_within_s():
    agent = Agent(vehicle_id=1)
    agent.tick(0.0, _inputs(0.0, detections=(_det(1, 0.0),), roster=ROSTER))  # nobody heard yet: hold
    statuses = []
    for t, stamp_3 in ((0.1, 0.05), (0.2, None), (1.0, None), (1.1, 1.05)):
        mates = [_plan(2, t - 0.05, [-4.0, 6.9, 8.9])]
        if stamp_3 is not None:
            mates.append(_plan(3, stamp_3, [-4.0, -6.9, 8.9]))
        out = agent.tick(t, _inputs(t, received=tuple(mates), roster=ROSTER))
        assert out.control is not None
        statuses.append(out.control.status.value)
    # 0.1: both heard afresh, flying; 1.0: 3 silent for 0.95 s, within blind_after_s, still flying
    assert statuses == ["solved", "solved", "solved", "solved"]
    out = agent.tick(1.7, _inputs(1.7, received=(_plan(2, 1.65, [-4.0, 6.9, 8.9]),), roster=ROSTER))
    assert out.control is not None and out.control.status.value == "solved"  # 3 last heard 0.65 s ago
    out = agent.tick(2.6, _inputs(2.6, received=(_plan(2, 2.55, [-4.0, 6.9, 8.9]),), roster=ROSTER))
    assert out.control is not None and out.control.status.value == "hold"  # 3 silent for 1.55 s
    late = (_plan(2, 2.65, [-4.0, 6.9, 8.9]), _plan(3, 2.0, [-4.0, -6.9, 8.9]))
    out = agent.tick(2.7, _inputs(2.7, received=late, roster=ROSTER))
    assert out.control is not None and out.control.status.value == "hold"  # 3 heard, but 0.7 s ago
    assert out.fault == "hold: waiting to hear teammate 3 within 0.5 s"
    fresh = (_plan(2, 2.75, [-4.0, 6.9, 8.9]), _plan(3, 2.75, [-4.0, -6.9, 8.9]))
    out = agent.tick(2.8, _inputs(2.8, received=fresh, roster=ROSTER))
    assert out.control is not None and out.control.status.value == "solved"


def test_holds_are_off_with_blind_after_s_zero():
    agent = Agent(vehicle_id=1, agent_params=AgentParams(blind_after_s=0.0))
    out = agent.tick(0.0, _inputs(0.0, detections=(_det(1, 0.0),), roster=ROSTER))
    assert out.control is not None and out.control.status.value == "solved"
    assert out.counters.hold_ticks == 0


class _Recorder:
    """Stands in for the controller to see what the agent hands it (and hold where it is)."""

    def __init__(self, inner):
        self.inner, self.calls = inner, []

    def step(self, **kwargs):
        self.calls.append(kwargs)
        return self.inner.step(**kwargs)


def test_teammates_not_in_formation_are_stood_in_for_by_phantoms_at_their_slots():
    agent = Agent(vehicle_id=1)
    spy = _Recorder(agent._controller)
    agent._controller = cast(FormationController, spy)
    heard = (_plan(2, 0.0, [-4.0, 6.9, 8.9]), _plan(3, 0.0, [-4.0, -6.9, 5.0], False))
    agent.tick(0.0, _inputs(0.0, detections=(_det(1, 0.0),), received=heard, roster=ROSTER))
    call = spy.calls[-1]
    assert call["preferred_bearing_rad"] == pytest.approx(0.0)
    phantom = next(p for p in call["teammates"] if p.vehicle_id == 3 and p.in_formation)
    expected = PERSON + [8.0 * math.cos(4.0 * math.pi / 3.0), 8.0 * math.sin(4.0 * math.pi / 3.0), 8.0]
    np.testing.assert_allclose(phantom.positions_m[0], expected, atol=1e-9)  # at its slot, not climbing


def test_no_phantom_stands_at_a_slot_the_mav_is_within_phantom_clearance_of():
    """The MAV is 1.2 m from teammate 3's slot (inside the gap its rows would keep): no phantom there, so no
    escape from it; the climbing teammate itself is still handed on (its own plan, not in formation)."""
    slot_3 = PERSON + [8.0 * math.cos(4.0 * math.pi / 3.0), 8.0 * math.sin(4.0 * math.pi / 3.0), 8.0]
    heard = (_plan(2, 0.0, [-4.0, 6.9, 8.9]), _plan(3, 0.0, [-4.0, -6.9, 5.0], False))
    calls = []
    for clearance in (2.0, 1.0):
        agent = Agent(vehicle_id=1, agent_params=AgentParams(phantom_clearance_m=clearance))
        spy = _Recorder(agent._controller)
        agent._controller = cast(FormationController, spy)
        own = _state(t=0.0, pos=tuple(slot_3 + [1.2, 0.0, 0.0]))
        agent.tick(0.0, _inputs(0.0, own=own, detections=(_det(1, 0.0),), received=heard, roster=ROSTER))
        calls.append([(p.vehicle_id, p.in_formation) for p in spy.calls[-1]["teammates"]])
    assert sorted(calls[0]) == [(2, True), (3, False)]
    assert sorted(calls[1]) == [(2, True), (3, False), (3, True)]  # 1.2 m is beyond a 1 m clearance


def test_with_holds_off_unheard_teammates_are_stood_in_for_by_phantoms_at_their_slots():
    agent = Agent(vehicle_id=1, agent_params=AgentParams(blind_after_s=0.0))
    spy = _Recorder(agent._controller)
    agent._controller = cast(FormationController, spy)
    heard = (_plan(2, 0.0, [-4.0, 6.9, 8.9]),)
    agent.tick(0.0, _inputs(0.0, detections=(_det(1, 0.0),), received=heard, roster=ROSTER))
    call = spy.calls[-1]
    assert call["preferred_bearing_rad"] == pytest.approx(0.0)
    by_id = {p.vehicle_id: p for p in call["teammates"]}
    assert by_id[2] is heard[0]  # a heard teammate is used as it is
    phantom = by_id[3]  # the unheard one stands at its slot, d_des from the estimate, h_des above it
    expected = PERSON + [8.0 * math.cos(4.0 * math.pi / 3.0), 8.0 * math.sin(4.0 * math.pi / 3.0), 8.0]
    np.testing.assert_allclose(phantom.positions_m[0], expected, atol=1e-9)
    assert phantom.in_formation


def test_no_phantoms_and_no_slot_when_every_teammate_is_heard():
    agent = Agent(vehicle_id=1)
    spy = _Recorder(agent._controller)
    agent._controller = cast(FormationController, spy)
    mates = (_plan(2, 0.0, [-4.0, 6.9, 8.9]), _plan(3, 0.0, [-4.0, -6.9, 8.9]))
    agent.tick(0.0, _inputs(0.0, detections=(_det(1, 0.0),), received=mates, roster=ROSTER))
    assert spy.calls[-1]["preferred_bearing_rad"] is None
    assert tuple(spy.calls[-1]["teammates"]) == mates


def test_a_mav_that_lost_the_person_turns_on_the_spot_to_search():
    agent = Agent(vehicle_id=1)
    yaws = []
    for i in range(11):
        t = i * 0.1
        out = agent.tick(t, _inputs(t, role=AgentRole.FORMATION))
        assert out.control is not None
        assert out.control.status.value == "no_person"
        assert out.setpoint is not None
        yaws.append(out.setpoint.yaw_rad)
    # the command advances at 0.5 rad/s from the MAV's heading (pi), wrapped into [-pi, pi)
    assert np.unwrap(yaws)[-1] - np.unwrap(yaws)[0] == pytest.approx(0.5, abs=1e-9)
    assert yaws[0] == pytest.approx(-math.pi, abs=1e-9)


def test_a_controller_exception_is_caught_counted_and_the_mav_holds_where_it_is():
    class Broken:
        def step(self, **kwargs):
            raise RuntimeError("boom")

    agent = Agent(vehicle_id=1)
    agent._controller = cast(FormationController, Broken())
    out = agent.tick(0.0, _inputs(0.0, detections=(_det(1, 0.0),)))
    assert out.counters.controller_errors == 1
    assert out.fault is not None
    assert "boom" in out.fault
    assert out.setpoint is not None
    np.testing.assert_allclose(out.setpoint.position_m, [8.0, 0.0, 8.9])
    np.testing.assert_allclose(out.setpoint.velocity_mps, 0.0)


def test_with_a_replan_period_the_mpc_is_solved_that_often_and_followed_in_between():
    agent = Agent(vehicle_id=1, agent_params=AgentParams(replan_period_s=0.1))
    spy = _Recorder(agent._controller)
    agent._controller = cast(FormationController, spy)
    outs = []
    for i in range(20):
        t = round(i * 0.01, 6)
        outs.append(agent.tick(t, _inputs(t, detections=(_det(1, t),) if i == 0 else ())))
    assert len(spy.calls) == 2  # at 0.0 and 0.1 s
    plan = outs[0].plan
    # 0.05 s after the plan: its state waypoint_step (1) steps ahead of now, i.e. at step 1.5, interpolated
    expected = 0.5 * (plan.positions_m[1] + plan.positions_m[2])
    np.testing.assert_allclose(outs[5].setpoint.position_m, expected, atol=1e-9)
    np.testing.assert_allclose(
        outs[5].setpoint.velocity_mps, 0.5 * (plan.velocities_mps[1] + plan.velocities_mps[2]), atol=1e-9
    )
    # and the acceleration of the step it is on, from 1 to 2
    np.testing.assert_allclose(
        outs[5].setpoint.acceleration_mps2,
        (plan.velocities_mps[2] - plan.velocities_mps[1]) / plan.dt_s,
        atol=1e-9,
    )
    np.testing.assert_allclose(outs[0].setpoint.acceleration_mps2, outs[0].control.waypoint_acceleration_mps2)


def test_hold_plan_stays_at_the_reported_position():
    plan = hold_plan(state=_state(pos=(1.0, 2.0, 5.0)), params=ControllerParams())
    assert plan.positions_m.shape == (17, 3)
    assert plan.position_at(0.7) == pytest.approx(np.array([1.0, 2.0, 5.0]))

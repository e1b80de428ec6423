"""The agent learns its GPS offset relative to the team from its detections and publishes it with its plans;
its separation rows place its teammates by both offsets."""

import math
from dataclasses import replace

import numpy as np
import pytest
from test_agent import _plan as still_plan

from controller.messages import Detection, HorizonPlan
from vehicles.agent import Agent, AgentInputs, AgentOutputs, AgentParams, AgentRole
from vehicles.autopilot import AutopilotState, FlightMode

PERSON = np.array([0.0, 0.0, 0.9])
OFFSET = np.array([0.8, -0.5, 0.3])  # MAV 1's GPS error: everything it places in the world lands this far off


def _state(t):
    return AutopilotState(
        vehicle_id=1,
        stamp_s=t,
        position_m=np.array([8.0, 0.0, 8.9]),
        velocity_mps=np.zeros(3),
        yaw_rad=math.pi,
        armed=True,
        in_air=True,
        mode=FlightMode.OFFBOARD,
    )


def _det(source, t, pos):
    return Detection(source_id=source, stamp_s=t, position_m=pos, cov_m2=np.eye(3) * 0.5)


def _fly(agent, *, seconds, teammates=(2, 3, 4), seed=1, t0=0.0) -> AgentOutputs:
    """Tick `agent` (MAV 1) at 4 Hz from t0: its own detections carry OFFSET and noise; the teammates' see
    the person where it is, with the same noise. Returns the last tick's outputs."""
    rng = np.random.default_rng(seed)
    out = None
    for k in range(int(seconds * 4)):
        t = t0 + k * 0.25
        own = (_det(1, t, PERSON + OFFSET + rng.normal(0.0, 0.3, 3)),)
        heard = tuple(_det(j, t, PERSON + rng.normal(0.0, 0.3, 3)) for j in teammates)
        out = agent.tick(t, AgentInputs(own=_state(t), detections=own, received=heard, role=AgentRole.GROUND))
    assert out is not None
    return out


def _plan(vid, t, pos, offset):
    """test_agent's still plan, carrying the sender's GPS offset."""
    return replace(still_plan(vid, t, pos), gps_offset_m=np.asarray(offset, dtype=float))


def test_with_three_teammates_it_learns_three_quarters_of_its_offset():
    # its own detections weigh a quarter of the fused estimate it is compared with
    out = _fly(Agent(vehicle_id=1), seconds=60)
    np.testing.assert_allclose(out.gps_offset_m, 0.75 * OFFSET, atol=0.1)


def test_alone_it_has_nothing_to_compare_with_and_learns_nothing():
    out = _fly(Agent(vehicle_id=1), seconds=60, teammates=())
    np.testing.assert_array_equal(out.gps_offset_m, np.zeros(3))


def test_the_offset_learns_only_while_a_teammates_detections_come_in():
    agent = Agent(vehicle_id=1)
    _fly(agent, seconds=30)
    # the teammates' links are lost: their last detections (29.75 s) serve for teammate_within_s (1 s)
    learnt = _fly(agent, seconds=1.25, teammates=(), seed=2, t0=30.0).gps_offset_m
    alone = _fly(agent, seconds=10, teammates=(), seed=3, t0=31.25)
    np.testing.assert_array_equal(alone.gps_offset_m, learnt)


def test_its_detections_are_fused_and_sent_as_measured():
    out = _fly(Agent(vehicle_id=1), seconds=5)
    (sent,) = out.outbox
    assert isinstance(sent, Detection)
    assert np.linalg.norm(sent.position_m - PERSON - OFFSET) < 1.5  # its own, GPS error and all


def test_its_plans_carry_its_offset():
    agent = Agent(vehicle_id=1)
    learnt = _fly(agent, seconds=30).gps_offset_m
    out = agent.tick(30.0, AgentInputs(own=_state(30.0), role=AgentRole.AIRBORNE))
    assert out.plan is not None and isinstance(out.outbox[-1], HorizonPlan)
    np.testing.assert_array_equal(out.plan.gps_offset_m, learnt)
    np.testing.assert_array_equal(out.outbox[-1].gps_offset_m, learnt)
    np.testing.assert_allclose(out.plan.positions_m[0], _state(30.0).position_m)  # flown as reported


def test_a_teammates_plan_is_kept_as_sent_with_its_offset():
    agent = Agent(vehicle_id=1)
    _fly(agent, seconds=30)
    theirs = np.array([-0.4, 0.2, 0.0])
    agent.tick(30.0, AgentInputs(own=_state(30.0), received=(_plan(2, 30.0, (0.0, 8.0, 8.9), theirs),)))
    (kept,) = agent.teammate_plans(30.0)
    np.testing.assert_array_equal(kept.positions_m[0], (0.0, 8.0, 8.9))
    np.testing.assert_array_equal(kept.gps_offset_m, theirs)


@pytest.mark.parametrize("offset", [(np.nan, 0.0, 0.0), (3.5, 0.0, 0.0)])
def test_a_plan_with_a_non_finite_or_absurd_offset_is_rejected_and_counted(offset):
    agent = Agent(vehicle_id=1)
    out = agent.tick(0.0, AgentInputs(own=_state(0.0), received=(_plan(2, 0.0, (0.0, 8.0, 8.9), offset),)))
    assert out.counters.rejected_messages == 1
    assert agent.teammate_plans(0.0) == ()


def test_with_the_estimate_off_nothing_is_learnt_and_plans_go_without_an_offset():
    agent = Agent(vehicle_id=1, agent_params=AgentParams(gps_offset=None))
    out = _fly(agent, seconds=20)
    np.testing.assert_array_equal(out.gps_offset_m, np.zeros(3))
    flying = agent.tick(20.1, AgentInputs(own=_state(20.1), role=AgentRole.AIRBORNE))
    assert flying.plan is not None
    np.testing.assert_array_equal(flying.plan.gps_offset_m, np.zeros(3))

"""The wire format and the guard every received message passes: what is admitted, and every refusal counted
under its reason without raising."""

from __future__ import annotations

import msgspec
import numpy as np
import pytest

from controller.messages import Detection, HorizonPlan
from vehicles.autopilot import AutopilotState, FlightMode
from vehicles.net import wire
from vehicles.net.guard import MessageGuard, Reason
from vehicles.net.keys import agent_key, parse_key, station_key

TEAM = "alpha"


def plan(vid: int = 2, stamp: float = 100.0) -> HorizonPlan:
    positions = np.cumsum(np.full((17, 3), 0.1), axis=0)
    return HorizonPlan(
        vehicle_id=vid,
        stamp_s=stamp,
        dt_s=0.1,
        positions_m=positions,
        velocities_mps=np.ones((17, 3)),
        gps_offset_m=np.array([0.25, -0.5, 0.125]),
    )


def message(*, sender=2, seq=1, boot=10, team=TEAM, body=None) -> bytes:
    body = body if body is not None else wire.plan_to_wire(plan(sender), phase="formation")
    return wire.encode(team=team, sender=sender, boot=boot, seq=seq, stamp=1.0, body=body)


@pytest.fixture
def guard() -> MessageGuard:
    return MessageGuard(team=TEAM, is_member=lambda s: 0 <= s <= 3, clock=lambda: 5.0)


def test_a_plan_round_trips_through_the_wire_exactly():
    original = plan()
    body = msgspec.msgpack.decode(msgspec.msgpack.encode(wire.plan_to_wire(original)), type=wire.PlanBody)
    back = wire.plan_from_wire(body, vehicle_id=2)
    assert np.array_equal(back.positions_m, original.positions_m)
    assert np.array_equal(back.velocities_mps, original.velocities_mps)
    assert back.stamp_s == original.stamp_s and back.dt_s == original.dt_s
    assert np.array_equal(back.gps_offset_m, original.gps_offset_m)


def test_telemetry_and_detections_round_trip():
    state = AutopilotState(
        vehicle_id=1,
        stamp_s=3.5,
        position_m=np.array([1.0, 2.0, 3.0]),
        velocity_mps=np.array([0.1, 0.2, 0.3]),
        yaw_rad=0.4,
        armed=True,
        in_air=True,
        mode=FlightMode.OFFBOARD,
        battery_fraction=0.5,
    )
    back = wire.telemetry_from_wire(wire.telemetry_to_wire(state), vehicle_id=1)
    assert np.allclose(back.position_m, state.position_m) and back.mode is FlightMode.OFFBOARD
    det = Detection(source_id=1, stamp_s=2.0, position_m=np.array([4.0, 5.0, 0.9]), cov_m2=np.eye(3) * 0.3)
    again = wire.detection_from_wire(wire.detection_to_wire(det), source_id=1)
    assert np.allclose(again.cov_m2, det.cov_m2) and again.stamp_s == 2.0


def test_a_state_message_stays_well_under_the_size_bound():
    body = wire.StateBody(
        phase="formation",
        settings=wire.SettingsBody(obstacles=[wire.ObstacleBody("v1", (1.0, 2.0), 1.0, 10.0)] * 13),
        plan=wire.plan_to_wire(plan()),
        person=wire.PersonBody(stamp_s=1.0, position_m=(0, 0, 0), velocity_mps=(0, 0, 0), cov=[0.1] * 36),
    )
    size = len(wire.encode(team=TEAM, sender=1, boot=1, seq=1, stamp=1.0, body=body))
    assert size < wire.MAX_MESSAGE_BYTES / 3


def test_a_good_plan_is_admitted_with_its_header(guard):
    got = guard.admit(agent_key(TEAM, 2, "plan"), message())
    assert got is not None and isinstance(got.body, wire.PlanBody)
    assert (got.header.sender, got.header.seq, got.received_s) == (2, 1, 5.0)
    assert guard.accepted == 1 and guard.rejected == 0


@pytest.mark.parametrize(
    ("key", "payload", "reason"),
    [
        (agent_key(TEAM, 2, "plan"), b"\x00" * (wire.MAX_MESSAGE_BYTES + 1), Reason.OVERSIZED),
        (agent_key(TEAM, 2, "plan"), b"\x93garbage", Reason.MALFORMED),
        (agent_key(TEAM, 2, "plan"), message(team="bravo"), Reason.TEAM),
        (agent_key(TEAM, 9, "plan"), message(sender=9), Reason.UNKNOWN_SENDER),
        (agent_key(TEAM, 3, "plan"), message(sender=2), Reason.MISMATCHED),
        (agent_key(TEAM, 2, "detection"), message(sender=2), Reason.MISMATCHED),
        (station_key(TEAM, "command"), message(sender=2), Reason.MISMATCHED),
    ],
    ids=["oversized", "malformed", "other-team", "unknown-id", "key-id", "key-topic", "station-key"],
)
def test_a_bad_message_is_refused_and_counted_under_its_reason(guard, key, payload, reason):
    assert guard.admit(key, payload) is None
    assert guard.counts()[reason.value] == 1
    assert guard.rejected == 1


def test_another_wire_version_is_refused_as_such(guard):
    header = msgspec.msgpack.decode(message())
    header["v"] = wire.WIRE_VERSION + 1
    assert guard.admit(agent_key(TEAM, 2, "plan"), msgspec.msgpack.encode(header)) is None
    assert guard.counts()["version"] == 1


def test_a_body_that_does_not_match_its_kind_is_malformed(guard):
    det = wire.DetectionBody(stamp_s=1.0, position_m=(0, 0, 0), cov_m2=[1.0] * 9)
    header = msgspec.msgpack.decode(message(body=det))
    header["kind"] = "plan"
    assert guard.admit(agent_key(TEAM, 2, "plan"), msgspec.msgpack.encode(header)) is None
    assert guard.counts()["malformed"] == 1


def test_a_replayed_or_reordered_sequence_number_is_refused(guard):
    key = agent_key(TEAM, 2, "plan")
    assert guard.admit(key, message(seq=5)) is not None
    assert guard.admit(key, message(seq=5)) is None  # the same message again
    assert guard.admit(key, message(seq=4)) is None  # an older one
    assert guard.admit(key, message(seq=6)) is not None
    assert guard.counts()["replayed"] == 2


def test_a_restarted_sender_is_heard_again_but_its_old_incarnation_is_not(guard):
    key = agent_key(TEAM, 2, "plan")
    assert guard.admit(key, message(boot=10, seq=900)) is not None
    assert guard.admit(key, message(boot=20, seq=1)) is not None  # a new process: new boot stamp
    assert guard.admit(key, message(boot=10, seq=901)) is None  # the old one, replayed
    assert guard.counts()["replayed"] == 1


def test_sequence_numbers_are_per_kind(guard):
    det = wire.DetectionBody(stamp_s=1.0, position_m=(0, 0, 0), cov_m2=[1.0] * 9)
    assert guard.admit(agent_key(TEAM, 2, "plan"), message(seq=7)) is not None
    assert guard.admit(agent_key(TEAM, 2, "detection"), message(seq=1, body=det)) is not None


def test_non_finite_plan_values_are_refused_by_the_conversion():
    body = wire.plan_to_wire(plan())
    bad = msgspec.structs.replace(body, positions_m=[(float("nan"), 0.0, 0.0)] * 17)
    with pytest.raises(ValueError):
        wire.plan_from_wire(bad, vehicle_id=2)
    with pytest.raises(ValueError):
        wire.plan_from_wire(
            msgspec.structs.replace(body, gps_offset_m=(0.0, float("inf"), 0.0)), vehicle_id=2
        )


def test_keys_parse_back_and_reject_strangers():
    agent, station = parse_key("skyring/alpha/agent/12/plan"), parse_key("skyring/alpha/station/heartbeat")
    assert agent is not None and agent.vehicle_id == 12
    assert station is not None and station.role == "station"
    assert parse_key("skyring/alpha/agent/x/plan") is None
    assert parse_key("other/alpha/agent/1/plan") is None

"""The onboard agent over real Zenoh sessions on 127.0.0.1 (multicast scouting off, free ports): bad messages
are refused and counted while the loop keeps its period; commands are acknowledged once and applied once;
the station's loss lands the MAV; teammates heard make the roster."""

from __future__ import annotations

import contextlib
import os
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import msgspec
import numpy as np
import pytest
from fifo_probe import fifo_allowed

from controller.messages import HorizonPlan
from vehicles.net import wire
from vehicles.net.guard import Received
from vehicles.net.keys import agent_key, all_agents_key, station_key
from vehicles.net.onboard import OnboardAgent, OnboardParams
from vehicles.net.ports import free_port
from vehicles.net.realtime import handler_priority, policy
from vehicles.net.session import Bus, NetConfig
from vehicles.pilot import Phase

sys.path.insert(0, str(Path(__file__).resolve().parent))
from net_stubs import StubAutopilot  # noqa: E402

TEAM = "unit"


def ack_of(received: Received) -> wire.AckBody:
    """The acknowledgement a received message carries (anything else on the ack key is a test failure)."""
    assert isinstance(received.body, wire.AckBody), received.body
    return received.body


@contextlib.contextmanager
def bus_pair(**agent_bus_options) -> Iterator[tuple[Bus, Bus]]:
    """The agent's bus listening on a free port and another process's bus connected to it, peered."""
    port = free_port()
    agent_bus = Bus(
        NetConfig(team=TEAM, listen=(f"tcp/127.0.0.1:{port}",), multicast_scouting=False),
        sender=1,
        is_member=lambda s: 0 <= s <= 3,
        **agent_bus_options,
    )
    other = Bus(
        NetConfig(team=TEAM, connect=(f"tcp/127.0.0.1:{port}",), multicast_scouting=False),
        sender=0,
        is_member=lambda s: 0 <= s <= 3,
    )
    deadline = time.monotonic() + 10
    while not agent_bus.peers() and time.monotonic() < deadline:
        time.sleep(0.05)
    time.sleep(0.3)  # let the subscriptions propagate
    try:
        yield agent_bus, other
    finally:
        other.close()
        agent_bus.close()


@pytest.fixture
def buses():
    with bus_pair() as pair:
        yield pair


def make_agent(bus: Bus, **params) -> tuple[OnboardAgent, StubAutopilot]:
    autopilot = StubAutopilot()
    return OnboardAgent(vehicle_id=1, autopilot=autopilot, bus=bus, params=OnboardParams(**params)), autopilot


def wait_for(condition, timeout_s: float = 5.0, *, resend=None) -> None:
    """Poll condition(); with `resend`, call it every 0.2 s meanwhile (a fresh subscription takes a moment to
    reach the publishing peer, as a station's re-sending covers in real use)."""
    deadline = time.monotonic() + timeout_s
    next_send = 0.0
    while not condition():
        assert time.monotonic() < deadline, "condition not met in time"
        if resend is not None and time.monotonic() >= next_send:
            resend()
            next_send = time.monotonic() + 0.2
        time.sleep(0.02)


def teammate_plan(stamp: float) -> wire.PlanBody:
    positions = np.tile([-8.0, 0.0, 8.9], (17, 1))
    return wire.plan_to_wire(
        HorizonPlan(
            vehicle_id=2, stamp_s=stamp, dt_s=0.1, positions_m=positions, velocities_mps=np.zeros((17, 3))
        ),
        phase="formation",
    )


@pytest.mark.alone  # its tick p99 is a wall-clock bound: beside the parallel suite it read 0.166 s once
def test_forged_malformed_oversized_and_replayed_messages_are_counted_and_the_loop_keeps_its_period(buses):
    agent_bus, other = buses
    agent, _ = make_agent(agent_bus, rate_hz=20.0)
    states: list[wire.StateBody] = []
    other.subscribe(agent_key(TEAM, 1, "state"), lambda m: states.append(m.body))
    agent.start()
    key = agent_key(TEAM, 2, "plan")
    genuine = wire.encode(
        team=TEAM, sender=2, boot=1, seq=1, stamp=time.time(), body=teammate_plan(time.time())
    )
    forged = wire.encode(team="intruder", sender=2, boot=1, seq=2, stamp=time.time(), body=teammate_plan(1.0))
    wait_for(lambda: 2 in agent.links.heard(), resend=lambda: other.put_raw(key, genuine))
    replays = agent_bus.guard.counts()["replayed"]  # re-sent while the subscription was on its way
    started = time.monotonic()
    for _ in range(5):
        other.put_raw(key, forged)
        other.put_raw(key, b"\xc1 not msgpack")
        other.put_raw(key, b"\x00" * (wire.MAX_MESSAGE_BYTES + 10))
        time.sleep(0.1)
    other.put_raw(key, genuine)  # a replay
    time.sleep(1.5)
    agent.stop()
    ran = time.monotonic() - started
    counts = agent_bus.guard.counts()
    assert counts["team"] == 5
    assert counts["malformed"] == 5
    assert counts["oversized"] == 5
    assert counts["replayed"] == replays + 1
    assert 2 in agent.links.heard()  # the genuine plan got through
    assert states and states[-1].rejected["team"] == 5  # and the station is told
    assert agent.loop_errors == 0
    assert agent.tick_stats.ticks >= 0.8 * 20.0 * ran  # it kept its rate (generous for a shared machine)
    p99 = agent.tick_stats.p99_error_s()
    # Bad traffic costs the loop nothing it would notice: p99 below one period (20 Hz); `skyring bench agents`
    # measures the figure.
    assert p99 is not None and p99 < 0.05


def command(command_id: int, action: str, *, settings=None) -> wire.CommandBody:
    return wire.CommandBody(command_id=command_id, action=action, targets=[1], settings=settings)


def test_commands_are_acknowledged_each_time_but_applied_once_and_bad_settings_are_refused(buses):
    agent_bus, station = buses
    agent, autopilot = make_agent(agent_bus)
    acks: list[Received] = []
    station.subscribe(all_agents_key(TEAM, "ack"), acks.append)
    bad = wire.SettingsBody(rev=5, d_des_m=1e6, h_des_m=8.0, enabled=True)
    good = wire.SettingsBody(rev=6, d_des_m=6.0, h_des_m=7.0, enabled=True)

    def send() -> None:
        for body in (command(1, "configure", settings=bad), command(2, "configure", settings=good)):
            station.publish(station_key(TEAM, "command"), body)

    now = time.time()
    wait_for(lambda: (agent.step(now), {ack_of(a).command_id for a in acks} == {1, 2})[1], resend=send)
    count = len(acks)
    outcome = {ack_of(a).command_id: (ack_of(a).accepted, ack_of(a).message) for a in acks}
    assert outcome[1][0] is False and "d_des_m" in outcome[1][1]
    assert outcome[2] == (True, "")
    assert agent.settings.d_des_m == 6.0 and agent.refused_commands == 1
    # The station re-sends command 2 (its ack was lost, say): acknowledged again, applied once.
    station.publish(station_key(TEAM, "command"), command(2, "configure", settings=good))
    wait_for(lambda: (agent.step(now), len(acks) > count)[1])
    assert ack_of(acks[-1]).accepted and agent.refused_commands == 1
    assert agent.phase in (Phase.TAKEOFF, Phase.FORMATION) and autopilot.height > 0  # enabled: it took off


def test_losing_the_station_for_the_timeout_lands_the_mav(buses):
    agent_bus, station = buses
    agent, autopilot = make_agent(agent_bus, station_timeout_s=2.0)
    settings = wire.SettingsBody(rev=2, enabled=True)

    def send() -> None:
        station.publish(station_key(TEAM, "heartbeat"), wire.HeartbeatBody())
        station.publish(station_key(TEAM, "command"), command(1, "configure", settings=settings))

    t0 = time.time()
    wait_for(lambda: (agent.step(t0), agent.settings.enabled)[1], resend=send)
    t0 = agent._heartbeat[1] if agent._heartbeat is not None else t0
    for i in range(10):
        agent.step(t0 + 0.1 * i)
    assert agent.phase is Phase.FORMATION and not agent.station_lost
    agent.step(t0 + 1.9)
    assert agent.phase is Phase.FORMATION  # still inside the timeout: it flies on
    agent.step(t0 + 2.5)
    assert agent.station_lost and agent.phase in (Phase.LANDING, Phase.LANDED) and autopilot.landings == 1


def test_a_hold_command_stops_a_flying_mav_and_release_brings_it_back(buses):
    agent_bus, station = buses
    agent, _ = make_agent(agent_bus)
    acks: list[Received] = []
    station.subscribe(all_agents_key(TEAM, "ack"), acks.append)
    settings = wire.SettingsBody(rev=2, enabled=True)
    now = time.time()

    def acked(command_id: int) -> bool:
        agent.step(now)
        return any(ack_of(a).command_id == command_id for a in acks)

    wait_for(
        lambda: acked(1),
        resend=lambda: station.publish(
            station_key(TEAM, "command"), command(1, "configure", settings=settings)
        ),
    )
    for _ in range(3):
        agent.step(now)
    assert agent.phase is Phase.FORMATION
    wait_for(
        lambda: acked(2), resend=lambda: station.publish(station_key(TEAM, "command"), command(2, "hold"))
    )
    assert agent.phase is Phase.HOLDING and [ack_of(a).accepted for a in acks if ack_of(a).command_id == 2][0]
    wait_for(
        lambda: acked(3), resend=lambda: station.publish(station_key(TEAM, "command"), command(3, "release"))
    )
    assert agent.phase is Phase.FORMATION


def test_teammates_heard_in_formation_join_the_roster_and_silent_ones_become_obstacles(buses):
    agent_bus, teammate = buses
    agent, _ = make_agent(agent_bus, silent_after_s=1.0)
    payload = wire.encode(
        team=TEAM, sender=2, boot=1, seq=1, stamp=time.time(), body=teammate_plan(time.time())
    )
    teammate.put_raw(agent_key(TEAM, 2, "plan"), payload)
    wait_for(lambda: 2 in agent.links.heard())
    now = agent.links.heard()[2].received_s
    members, silent = agent._teammates(now + 0.5)
    assert members == [2] and silent == ()
    members, silent = agent._teammates(now + 3.0)
    assert members == [] and [o.obstacle_id for o in silent] == ["silent-2"]
    assert np.allclose(silent[0].center_m, [-8.0, 0.0])


def test_a_real_time_priority_the_system_refuses_is_reported_to_the_station(buses, monkeypatch):
    """The kernel's refusal (no CAP_SYS_NICE) is played by os.sched_setscheduler raising EPERM."""

    def refuse(*_args):
        raise PermissionError(1, "Operation not permitted")

    monkeypatch.setattr("os.sched_setscheduler", refuse)
    agent_bus, _ = buses
    agent, _ = make_agent(agent_bus, realtime_priority=10)
    assert agent.state_body().scheduler == "SCHED_FIFO priority 10"  # asked, not yet refused
    agent.start()
    try:
        wait_for(lambda: "refused" in agent.state_body().scheduler)
    finally:
        agent.stop()
    again = msgspec.msgpack.decode(msgspec.msgpack.encode(agent.state_body()), type=wire.StateBody)
    assert again.scheduler == "normal scheduler (SCHED_FIFO priority 10 refused: Operation not permitted)"


def test_a_state_message_decodes_into_what_the_station_shows(buses):
    agent_bus, _ = buses
    agent, _ = make_agent(agent_bus)
    agent.step(time.time())
    body = agent.state_body()
    again = msgspec.msgpack.decode(msgspec.msgpack.encode(body), type=wire.StateBody)
    assert again.phase == "idle" and again.autopilot is not None
    assert again.autopilot.position_m == (8.0, 0.0, 0.0)


def test_message_handlers_run_under_sched_fifo_one_below_the_control_loop():
    """With handler_priority set, Zenoh's thread takes SCHED_FIFO at its first message, so that normal work
    cannot preempt a handler holding the interpreter lock the control loop waits for (where the system
    refuses SCHED_FIFO, the handlers run on under the normal scheduler)."""
    assert handler_priority(10) == 9 and handler_priority(1) == 1 and handler_priority(0) == 0
    seen: list[tuple[int, int]] = []
    key = station_key(TEAM, "heartbeat")
    with bus_pair(handler_priority=handler_priority(10)) as (agent_bus, other):
        agent_bus.subscribe(key, lambda _msg: seen.append((policy(), os.sched_getparam(0).sched_priority)))
        wait_for(lambda: bool(seen), resend=lambda: other.publish(key, wire.HeartbeatBody()))
    assert seen[0] == ((os.SCHED_FIFO, 9) if fifo_allowed(9) else (os.SCHED_OTHER, 0))
    assert agent_bus.handler_errors == 0

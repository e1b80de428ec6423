"""The station side of onboard agents (`AgentFleet`) against a real onboard agent over Zenoh on 127.0.0.1:
commands acknowledged per vehicle, a silent agent shown lost, unanswered commands failed, settings adopted
from the agents, and the clock offset measured from the heartbeat round trip."""

from __future__ import annotations

import sys
import time
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "vehicles" / "net"))

from net_stubs import StubAutopilot  # noqa: E402

from controller.params import FormationParams  # noqa: E402
from server.station.fleet import AgentFleet, FleetParams  # noqa: E402
from server.station.ground_station import GroundStation, agent_view  # noqa: E402
from vehicles.mission import MissionError, Phase  # noqa: E402
from vehicles.net import wire  # noqa: E402
from vehicles.net.keys import agent_key  # noqa: E402
from vehicles.net.onboard import OnboardAgent, OnboardParams  # noqa: E402
from vehicles.net.ports import free_port  # noqa: E402
from vehicles.net.session import Bus, NetConfig  # noqa: E402
from webui.cards import AGENT_LOST_FLAG, SKEW_FLAG, vehicle_detail_markdown  # noqa: E402

TEAM = "fleet"
SKEW_S = 0.2


def wait_for(condition, timeout_s: float = 10.0) -> float:
    t0 = time.monotonic()
    while not condition():
        assert time.monotonic() - t0 < timeout_s, "condition not met in time"
        time.sleep(0.02)
    return time.monotonic() - t0


def _buses(agent: int, agent_clock=time.time) -> tuple[Bus, Bus]:
    """The station's bus (sender 0, listening on a free port of 127.0.0.1) and agent `agent`'s, connected."""
    port = free_port()
    member = lambda s: 0 <= s <= 2  # noqa: E731
    station_bus = Bus(
        NetConfig(team=TEAM, listen=(f"tcp/127.0.0.1:{port}",), multicast_scouting=False),
        sender=0,
        is_member=member,
    )
    agent_bus = Bus(
        NetConfig(team=TEAM, connect=(f"tcp/127.0.0.1:{port}",), multicast_scouting=False),
        sender=agent,
        is_member=member,
        clock=agent_clock,
    )
    return station_bus, agent_bus


@pytest.fixture
def setup():
    skewed = lambda: time.time() + SKEW_S  # noqa: E731 - the agent's clock runs 200 ms ahead
    station_bus, agent_bus = _buses(1, skewed)
    fleet = AgentFleet(
        bus=station_bus,
        vehicle_ids=[1, 2],  # vehicle 2's agent never runs
        formation=FormationParams(d_des_m=7.0, h_des_m=8.0),
        params=FleetParams(command_timeout_s=1.5),
    )
    agent = OnboardAgent(
        vehicle_id=1,
        autopilot=StubAutopilot(),
        bus=agent_bus,
        params=OnboardParams(rate_hz=20.0),
        clock=skewed,
    )
    fleet.start()
    agent.start()
    yield fleet, agent
    agent.stop()
    fleet.close(settle_s=0.0)
    agent_bus.close()
    station_bus.close()


def link(fleet: AgentFleet, vid: int):
    v = next(v for v in fleet.snapshot().vehicles if v.vehicle_id == vid)
    assert v.agent is not None
    return v, v.agent


def test_a_fresh_agent_is_configured_with_the_station_settings_and_acknowledges(setup):
    fleet, agent = setup
    wait_for(lambda: agent.settings.rev >= 1 and agent.settings.d_des_m == 7.0)
    wait_for(lambda: link(fleet, 1)[1].commands and link(fleet, 1)[1].commands[-1][2] == "acked")
    # the ack and the next state report travel separately: wait for the report that shows the takeoff
    wait_for(lambda: link(fleet, 1)[0].phase in (Phase.TAKEOFF, Phase.FORMATION))
    assert not link(fleet, 1)[1].lost


def test_an_operator_change_is_acknowledged_by_the_agent_and_fails_for_a_silent_one(setup):
    fleet, agent = setup
    wait_for(lambda: agent.settings.rev >= 1)
    fleet.set_formation(FormationParams(d_des_m=6.0, h_des_m=8.0))
    took = wait_for(lambda: link(fleet, 1)[1].commands[-1][1:3] == ("configure", "acked"))
    assert took < 1.0
    assert agent.settings.d_des_m == 6.0
    wait_for(lambda: link(fleet, 2)[1].commands[-1][2] == "failed", timeout_s=5.0)
    assert "no acknowledgement" in link(fleet, 2)[1].commands[-1][3]


def test_an_agent_that_stops_is_shown_lost_within_one_second(setup):
    fleet, agent = setup
    wait_for(lambda: not link(fleet, 1)[1].lost)
    agent.stop()
    stopped = time.monotonic()
    wait_for(lambda: link(fleet, 1)[1].lost, timeout_s=3.0)
    assert time.monotonic() - stopped < 1.0
    vehicle, _ = link(fleet, 1)
    assert AGENT_LOST_FLAG in vehicle_detail_markdown(_vehicle_view(vehicle), ())


def test_the_clock_offset_is_measured_and_a_skew_over_50_ms_is_flagged_on_the_card(setup):
    fleet, _ = setup
    wait_for(lambda: link(fleet, 1)[1].clock_offset_s is not None)
    vehicle, status = link(fleet, 1)
    assert status.clock_offset_s == pytest.approx(SKEW_S, abs=0.02)
    view = agent_view(status)
    assert view.clock_skew
    assert SKEW_FLAG in vehicle_detail_markdown(_vehicle_view(vehicle), ())


def test_what_the_agents_control_loop_runs_under_reaches_the_card(setup):
    fleet, _ = setup
    wait_for(lambda: link(fleet, 1)[1].scheduler != "")
    vehicle, status = link(fleet, 1)
    assert status.scheduler == "normal scheduler"
    assert "control loop: normal scheduler" in vehicle_detail_markdown(_vehicle_view(vehicle), ())


def test_landing_a_vehicle_on_the_ground_is_refused_and_release_needs_a_landed_one(setup):
    fleet, agent = setup
    with pytest.raises(MissionError, match="no vehicle"):
        fleet.land(7)
    wait_for(lambda: link(fleet, 1)[0].phase in (Phase.TAKEOFF, Phase.FORMATION))
    with pytest.raises(MissionError, match="only a landed or holding vehicle"):
        fleet.release(1)
    fleet.land(1)
    wait_for(lambda: link(fleet, 1)[0].phase in (Phase.LANDING, Phase.LANDED))


def test_hold_reaches_the_agent_and_is_refused_for_a_vehicle_that_is_not_flying(setup):
    fleet, _ = setup
    wait_for(lambda: link(fleet, 1)[0].phase == Phase.FORMATION)
    fleet.hold(1)
    wait_for(lambda: link(fleet, 1)[0].phase == Phase.HOLDING)
    fleet.land(1)
    wait_for(lambda: link(fleet, 1)[0].phase in (Phase.LANDING, Phase.LANDED))
    with pytest.raises(MissionError, match="can be held"):
        fleet.hold(1)


def test_a_station_adopts_newer_settings_an_agent_already_flies(setup):
    fleet, agent = setup
    wait_for(lambda: agent.settings.rev >= 1)
    newer = wire.SettingsBody(rev=time.time_ns() + 10**9, d_des_m=5.0, h_des_m=7.5, enabled=True)
    agent._settings = newer  # as if a previous station had set it
    wait_for(lambda: fleet.formation.d_des_m == 5.0)
    assert fleet.formation.h_des_m == 7.5


def test_the_ground_station_runs_over_the_fleet(setup):
    fleet, _ = setup
    station = GroundStation(mission=fleet, control_period_s=0.05, clock=time.monotonic)
    station.tick()
    view = station.scene_view()
    assert [v.vehicle_id for v in view.vehicles] == [1, 2]
    assert all(v.agent is not None for v in view.vehicles)
    assert station.counters()["refused_commands"] == 0


def _vehicle_view(vehicle):
    from server.station.ground_station import vehicle_view

    return vehicle_view(vehicle, link_stale_s=1.0)


@pytest.fixture
def reporter():
    """A station fleet and a bare bus publishing as vehicle 2's agent, for hand-made state reports."""
    station_bus, agent_bus = _buses(2)
    fleet = AgentFleet(bus=station_bus, vehicle_ids=[2])
    yield fleet, lambda body: agent_bus.publish(agent_key(TEAM, 2, "state"), body)
    fleet.close(settle_s=0.0)
    agent_bus.close()
    station_bus.close()


def _report(offset):
    telemetry = wire.TelemetryBody(
        stamp_s=time.time(),
        position_m=(5.0, 1.0, 8.0),
        velocity_mps=(0.0, 0.0, 0.0),
        yaw_rad=0.0,
        armed=True,
        in_air=True,
        mode="offboard",
    )
    return wire.StateBody(
        phase="formation", settings=wire.SettingsBody(rev=1), autopilot=telemetry, gps_offset_m=offset
    )


def _published_until(publish, body, condition):
    """Publish body every 20 ms until condition() holds (the first may go out before the link is up)."""
    wait_for(lambda: publish(body) > 0 and condition())


def test_an_agents_gps_offset_reaches_the_station_which_places_it_where_its_controller_believes(reporter):
    fleet, publish = reporter
    vehicle = lambda: fleet.snapshot().vehicles[0]  # noqa: E731
    _published_until(publish, _report((0.5, -0.25, 0.125)), lambda: vehicle().autopilot is not None)
    assert tuple(vehicle().gps_offset_m) == (0.5, -0.25, 0.125)
    assert tuple(vehicle().believed_position_m) == (4.5, 1.25, 7.875)


def test_a_non_finite_gps_offset_is_counted_as_a_bad_report_and_not_used(reporter):
    fleet, publish = reporter
    _published_until(
        publish, _report((float("nan"), 0.0, 0.0)), lambda: fleet.snapshot() and fleet.bad_reports > 0
    )
    assert tuple(fleet.snapshot().vehicles[0].gps_offset_m) == (0.0, 0.0, 0.0)

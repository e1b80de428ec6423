"""The PX4 back-end against the MAVLink test peer over real UDP: parameters, takeoff and offboard, the
set-point watchdog, link loss, pilot takeover, frames, and PX4's own offboard-loss failsafe."""

from __future__ import annotations

import asyncio
import contextlib
import math
import sys
import time
from pathlib import Path

import mavsdk
import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # tests/, for the peer

from px4_peer import PeerMode, Px4Peer, free_udp_port, setpoint_problems  # noqa: E402

from vehicles.autopilot import AutopilotState, FlightMode, Setpoint  # noqa: E402
from vehicles.px4.autopilot import Px4Autopilot, Px4Config, Px4Error, Px4Fleet  # noqa: E402
from vehicles.px4.geodesy import GeodeticPoint, geodetic_to_enu  # noqa: E402
from vehicles.px4.supervisor import SupervisorParams  # noqa: E402

pytestmark = pytest.mark.slow

REF = GeodeticPoint(47.397742, 8.545594, 488.0)
# Quicker than PX4's defaults so the suite stays short; the logic is the same.
FAST = {"MPC_TKO_SPEED": 3.0, "MPC_LAND_SPEED": 2.0, "COM_DISARM_LAND": 0.5, "COM_FAIL_ACT_T": 1.0}
CONFIG = Px4Config(
    connect_timeout_s=10.0,
    health_timeout_s=10.0,
    supervisor=SupervisorParams(land_after_s=2.0, prestream_s=1.0, mode_grace_s=1.5),
)


def home_at(east_m: float, north_m: float, up_m: float = 0.0) -> tuple[float, float, float]:
    """A geodetic home east_m / north_m / up_m from REF (small offsets, spherical approximation)."""
    lat = REF.latitude_deg + north_m / 111_195.0
    lon = REF.longitude_deg + east_m / (111_195.0 * math.cos(math.radians(REF.latitude_deg)))
    return lat, lon, REF.altitude_m + up_m


def state_of(autopilot: Px4Autopilot) -> AutopilotState:
    """The autopilot's latest state; a connected vehicle always has one."""
    state = autopilot.state()
    assert state is not None, f"vehicle {autopilot.vehicle_id} has no state"
    return state


def truth_enu(peer: Px4Peer) -> np.ndarray:
    return geodetic_to_enu(GeodeticPoint(*peer.geodetic()), reference=REF)


@contextlib.asynccontextmanager
async def px4_fleet(homes, *, team_origin: GeodeticPoint | None = REF, config=CONFIG, **peer_kw):
    mavsdk.log_subscribe(lambda *a: True)
    ports = [free_udp_port() for _ in homes]
    peers = [
        Px4Peer(gcs_port=port, system_id=i + 1, home=home, params=FAST, **peer_kw).start()
        for i, (port, home) in enumerate(zip(ports, homes, strict=True))
    ]
    try:
        fleet = await Px4Fleet.open(
            [f"udpin://127.0.0.1:{p}" for p in ports], origin=team_origin, config=config
        )
        try:
            yield fleet, peers
        finally:
            await fleet.close()
    finally:
        for peer in peers:
            peer.stop()


async def wait_until(condition, *, timeout_s: float, what: str) -> float:
    """Poll condition every 20 ms; seconds it took, or fail saying what did not happen."""
    t0 = time.monotonic()
    while not condition():
        if time.monotonic() - t0 > timeout_s:
            raise AssertionError(f"{what} did not happen within {timeout_s} s")
        await asyncio.sleep(0.02)
    return time.monotonic() - t0


class StandInAgent:
    """Stands in for a formation agent: one set-point to a fixed ENU target every period_s until frozen."""

    def __init__(
        self, autopilot, target_m, *, yaw_rad: float = 0.0, period_s: float = 0.1, acceleration_mps2=(0, 0, 0)
    ) -> None:
        self.autopilot, self.target_m, self.yaw_rad, self.period_s = autopilot, target_m, yaw_rad, period_s
        self.acceleration_mps2 = np.asarray(acceleration_mps2, dtype=float)
        self.frozen = False
        self._task = asyncio.get_running_loop().create_task(self._run())

    async def _run(self) -> None:
        while True:
            if not self.frozen:
                self.autopilot.send_setpoint(
                    Setpoint(
                        stamp_s=time.monotonic(),
                        position_m=self.target_m,
                        velocity_mps=np.array((0.0, 0.0, 0.0)),
                        yaw_rad=self.yaw_rad,
                        acceleration_mps2=self.acceleration_mps2,
                    )
                )
            await asyncio.sleep(self.period_s)

    def stop(self) -> None:
        self._task.cancel()


async def engaged(autopilot, target_m, *, yaw_rad: float = 0.0, acceleration_mps2=(0, 0, 0)) -> StandInAgent:
    """Take off and follow a stand-in agent; returns once the vehicle flies in offboard."""
    autopilot.takeoff(4.0)
    agent = StandInAgent(autopilot, target_m, yaw_rad=yaw_rad, acceleration_mps2=acceleration_mps2)
    await wait_until(
        lambda: autopilot.status().engagement == "following", timeout_s=20.0, what="engaging offboard"
    )
    return agent


async def test_the_setpoints_acceleration_feed_forward_reaches_the_vehicle_in_ned():
    async with px4_fleet([home_at(0, 0)]) as (fleet, (peer,)):
        agent = await engaged(
            fleet.autopilots[0], np.array([0.0, 0.0, 4.0]), acceleration_mps2=(0.5, -0.25, 0.1)
        )
        await asyncio.sleep(0.5)
        agent.stop()
        seen = peer.setpoints()
        assert [p for sp in seen for p in setpoint_problems(sp, system_id=1)] == []
        np.testing.assert_allclose(
            seen[-1].acceleration_ned, [-0.25, 0.5, -0.1], atol=1e-6
        )  # float32 on the wire


async def test_connect_sets_the_failsafe_parameters_on_the_vehicle():
    async with px4_fleet([home_at(0, 0)]) as (fleet, (peer,)):
        assert peer.param("COM_OF_LOSS_T") == pytest.approx(1.0)
        assert peer.param("COM_OBL_RC_ACT") == 4  # Land
        assert peer.param("NAV_DLL_ACT") == 3  # Land
        assert fleet.autopilots[0].status().frame_source == "origin"


async def test_setpoints_fly_the_vehicle_to_the_enu_target_in_offboard():
    target = np.array([6.0, -4.0, 6.0])
    async with px4_fleet([home_at(15.0, 10.0, 1.5)]) as (fleet, (peer,)):
        a = fleet.autopilots[0]
        agent = await engaged(a, target, yaw_rad=math.pi / 2)  # face north
        await wait_until(
            lambda: np.linalg.norm(truth_enu(peer) - target) < 0.2, timeout_s=15.0, what="reaching the target"
        )
        state = a.state()
        agent.stop()
        assert peer.mode is PeerMode.OFFBOARD
        assert state is not None
        assert state.mode is FlightMode.OFFBOARD
        np.testing.assert_allclose(state.position_m, truth_enu(peer), atol=0.1)
        assert state.yaw_rad == pytest.approx(math.pi / 2, abs=0.05)
        seen = peer.setpoints()
        assert len(seen) > 20
        assert [p for sp in seen for p in setpoint_problems(sp, system_id=1)] == []
        # the set-point is the ENU target in the vehicle's own NED frame (it booted 15 m east, 10 m north)
        np.testing.assert_allclose(seen[-1].position_ned, [-14.0, -9.0, -4.5], atol=0.05)
        assert seen[-1].yaw_rad == pytest.approx(0.0, abs=1e-3)


async def test_a_takeoff_waits_in_hold_for_px4s_arming_checks_instead_of_being_refused():
    # PX4 cannot arm for a moment (here COM_ARMABLE 0 for 0.5 s; on PX4 v1.16: until its arming checks have
    # seen a ground station that just came back): skyring asks for Hold and arms once PX4 says it can.
    config = Px4Config(
        connect_timeout_s=10.0, health_timeout_s=10.0, armable_wait_s=6.0, supervisor=CONFIG.supervisor
    )
    async with px4_fleet([home_at(0, 0)], config=config) as (fleet, (peer,)):
        a = fleet.autopilots[0]
        peer.set_param("COM_ARMABLE", 0)
        await wait_until(lambda: state_of(a).can_arm is False, timeout_s=5.0, what="PX4 saying it cannot arm")
        a.takeoff(4.0)
        await asyncio.sleep(0.5)
        peer.set_param("COM_ARMABLE", 1)
        await wait_until(lambda: state_of(a).in_air, timeout_s=15.0, what="the take-off")
        assert not [text for _, _, text in peer.texts() if "Arming denied" in text]
        assert a.status().takeoff_failures == 0 and state_of(a).arming_refusal is None


async def test_frozen_agent_puts_the_vehicle_in_hold_within_a_second_then_lands():
    async with px4_fleet([home_at(0, 0)]) as (fleet, (peer,)):
        a = fleet.autopilots[0]
        agent = await engaged(a, np.array([2.0, 0.0, 5.0]))
        await asyncio.sleep(1.0)
        agent.frozen = True
        frozen_at = peer.now()
        await wait_until(lambda: peer.mode is PeerMode.HOLD, timeout_s=2.0, what="hold")
        await wait_until(lambda: peer.landed and not peer.armed, timeout_s=10.0, what="landing")
        agent.stop()
        log = [(t - frozen_at, mode) for t, mode in peer.mode_log() if t >= frozen_at]
        # Hold, Land; after the disarm PX4 returns to Hold, the last mode asked for that allows arming
        assert [mode for _, mode in log] == ["HOLD", "LAND", "HOLD"]
        assert log[0][0] < 1.0
        assert log[1][0] == pytest.approx(2.0, abs=0.3)  # land_after_s
        assert a.status().watchdog_holds == 1 and a.status().watchdog_landings == 1


async def test_silent_vehicle_is_flagged_link_lost_within_1_5_s_and_recovers():
    async with px4_fleet([home_at(0, 0)]) as (fleet, (peer,)):
        a = fleet.autopilots[0]
        assert not state_of(a).link_lost
        before = state_of(a).position_m
        peer.silence()
        took = await wait_until(lambda: state_of(a).link_lost, timeout_s=3.0, what="LINK_LOST")
        assert 0.9 < took < 1.5
        np.testing.assert_allclose(state_of(a).position_m, before, atol=0.01)  # the last known position
        peer.silence(False)
        await wait_until(lambda: not state_of(a).link_lost, timeout_s=2.0, what="link recovery")


async def test_pilot_taking_over_is_respected_and_shown():
    async with px4_fleet([home_at(0, 0)]) as (fleet, (peer,)):
        a = fleet.autopilots[0]
        agent = await engaged(a, np.array([0.0, 3.0, 5.0]))
        peer.pilot_takeover(PeerMode.POSCTL)
        taken_at = peer.now()
        await wait_until(lambda: state_of(a).released, timeout_s=3.0, what="release")
        assert state_of(a).mode is FlightMode.MANUAL
        assert "manual" in str(a.status().released_reason)
        await asyncio.sleep(5.0)  # the agent keeps sending; skyring must not take control back
        agent.stop()
        assert peer.mode is PeerMode.POSCTL
        offboard_requests = [c for c in peer.commands() if c[0] > taken_at and c[1] == 176 and c[3] == 6]
        assert offboard_requests == []
        late = [sp for sp in peer.setpoints() if sp.t_s > taken_at + 4.0]
        assert late == []  # MAVSDK stopped streaming once skyring released the vehicle
        assert a.status().ignored_setpoints > 20


async def test_vehicles_with_different_homes_share_one_enu_frame():
    homes = [home_at(0.0, 0.0), home_at(40.0, -25.0, 3.0), home_at(-60.0, 35.0, -2.0)]
    async with px4_fleet(homes, team_origin=GeodeticPoint(*home_at(5.0, 5.0, 1.0))) as (fleet, peers):
        ref = fleet.reference
        for a, peer in zip(fleet.autopilots, peers, strict=True):
            truth = geodetic_to_enu(GeodeticPoint(*peer.geodetic()), reference=ref)
            np.testing.assert_allclose(state_of(a).position_m, truth, atol=0.1)


async def test_team_origin_defaults_to_vehicle_1_home():
    homes = [home_at(10.0, 20.0, 2.0), home_at(-30.0, 5.0)]
    async with px4_fleet(homes, team_origin=None) as (fleet, peers):
        home1 = GeodeticPoint(*peers[0].geodetic())
        assert (fleet.reference.latitude_deg, fleet.reference.longitude_deg, fleet.reference.altitude_m) == (
            pytest.approx(home1.latitude_deg, abs=1e-6),
            pytest.approx(home1.longitude_deg, abs=1e-6),
            pytest.approx(home1.altitude_m, abs=0.01),
        )
        np.testing.assert_allclose(state_of(fleet.autopilots[0]).position_m, [0.0, 0.0, 0.0], atol=0.05)
        truth2 = geodetic_to_enu(GeodeticPoint(*peers[1].geodetic()), reference=home1)
        np.testing.assert_allclose(state_of(fleet.autopilots[1]).position_m, truth2, atol=0.1)
        np.testing.assert_allclose(truth2, [-40.0, -15.0, -2.0], atol=0.5)


async def test_vehicle_that_booted_away_from_home_is_placed_by_its_estimator_origin():
    # origin (where the estimator started) differs from home (where it stands now)
    booted = home_at(-20.0, 30.0, -1.0)
    async with px4_fleet([home_at(12.0, -7.0, 0.5)], origin=booted) as (fleet, (peer,)):
        assert np.linalg.norm(peer.position_ned) > 40.0  # far from its local origin
        np.testing.assert_allclose(state_of(fleet.autopilots[0]).position_m, truth_enu(peer), atol=0.1)


async def test_ground_station_loss_lands_the_vehicle_by_px4s_offboard_failsafe():
    async with px4_fleet([home_at(0, 0)]) as (fleet, (peer,)):
        agent = await engaged(fleet.autopilots[0], np.array([0.0, 0.0, 5.0]))
        agent.stop()
        await fleet.close()  # the ground station is gone: no more set-points, no MAVSDK re-sending
        lost_at = peer.now()
        await wait_until(lambda: peer.mode is PeerMode.LAND, timeout_s=5.0, what="PX4's failsafe landing")
        log = [(t - lost_at, mode) for t, mode in peer.mode_log() if t >= lost_at]
        # straight to COM_OBL_RC_ACT (Land) after COM_OF_LOSS_T, no Hold first: PX4 v1.16 (docs/px4.md)
        assert [mode for _, mode in log] == ["LAND"]
        assert log[0][0] == pytest.approx(1.0, abs=0.3)
        assert peer.failsafe and any("Failsafe activated" in text for _, _, text in peer.texts())


async def test_connecting_to_a_silent_port_fails_with_the_url_in_the_message():
    port = free_udp_port()
    config = Px4Config(connect_timeout_s=1.0)
    with pytest.raises(Px4Error, match=f"udpin://127.0.0.1:{port}"):
        await Px4Fleet.open([f"udpin://127.0.0.1:{port}"], origin=REF, config=config)


async def test_vehicle_that_hides_its_origin_is_placed_from_a_position_fix():
    async with px4_fleet([home_at(25.0, -15.0, 2.0)], answers_origin=False) as (fleet, (peer,)):
        a = fleet.autopilots[0]
        assert a.status().frame_source == "fix"
        np.testing.assert_allclose(state_of(a).position_m, truth_enu(peer), atol=0.1)

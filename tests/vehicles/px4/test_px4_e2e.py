"""End to end: three PX4 test peers and the ground station of `skyring serve --px4`, in-process through the
same code path as the command (server/station/px4.py, `serve_px4`), driven through its REST API."""

from __future__ import annotations

import asyncio
import contextlib
import math
import sys
import time
from pathlib import Path

import httpx
import mavsdk
import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # tests/, for the peer

from px4_peer import PeerMode, Px4Peer, free_udp_port, setpoint_problems  # noqa: E402

from server.lab.metrics import spacing_error_deg  # noqa: E402
from server.station.px4 import serve_px4  # noqa: E402
from vehicles.px4.autopilot import Px4Config  # noqa: E402
from vehicles.px4.geodesy import GeodeticPoint, geodetic_to_enu  # noqa: E402
from vehicles.px4.supervisor import SupervisorParams  # noqa: E402
from webui.cards import team_table_html  # noqa: E402

pytestmark = pytest.mark.e2e

REF = GeodeticPoint(47.397742, 8.545594, 488.0)
D_DES_M = 8.0  # the formation default; the still person stands at the team origin
FAST = {"MPC_TKO_SPEED": 3.0, "MPC_LAND_SPEED": 2.0, "COM_DISARM_LAND": 0.5, "COM_FAIL_ACT_T": 1.0}
CONFIG = Px4Config(
    connect_timeout_s=10.0, health_timeout_s=10.0, supervisor=SupervisorParams(land_after_s=2.0)
)


def ring_home(i: int, k: int = 3) -> tuple[tuple[float, float, float], float]:
    """Spawn point i of k on a ring of radius d_des about the origin (from the south), and the NED yaw that
    faces the person."""
    bearing = -math.pi / 2 + 2 * math.pi * i / k
    e, n = D_DES_M * math.cos(bearing), D_DES_M * math.sin(bearing)
    lat = REF.latitude_deg + n / 111_195.0
    lon = REF.longitude_deg + e / (111_195.0 * math.cos(math.radians(REF.latitude_deg)))
    return (lat, lon, REF.altitude_m), math.atan2(-e, -n)


def truth_xyz(peers) -> np.ndarray:
    return np.array([geodetic_to_enu(GeodeticPoint(*p.geodetic()), reference=REF) for p in peers])


@contextlib.asynccontextmanager
async def px4_ground_station(k: int = 3):
    """k peers on a ring, and the ground station serving them; yields (station, fleet, peers, api url)."""
    mavsdk.log_subscribe(lambda *a: True)
    ports = [free_udp_port() for _ in range(k)]
    peers = []
    for i, port in enumerate(ports):
        home, yaw = ring_home(i, k)
        peers.append(
            Px4Peer(gcs_port=port, system_id=i + 1, home=home, start_yaw_ned_rad=yaw, params=FAST).start()
        )
    stop, ready = asyncio.Event(), {}
    task = asyncio.create_task(
        serve_px4(
            [f"udpin://127.0.0.1:{p}" for p in ports],
            origin=REF,
            config=CONFIG,
            person="still",
            trees="none",
            rate_hz=20.0,
            port=0,
            viser_port=0,
            stop=stop,
            handle_signals=False,
            on_ready=lambda urls, ui: ready.update(api=urls.api),
            on_station=lambda station, fleet: ready.update(station=station, fleet=fleet),
        )
    )
    try:
        while "api" not in ready:
            if task.done():
                task.result()
            await asyncio.sleep(0.05)
        yield ready["station"], ready["fleet"], peers, ready["api"]
    finally:
        stop.set()
        with contextlib.suppress(Exception):
            await asyncio.wait_for(task, timeout=15.0)
        for peer in peers:
            peer.stop()


async def wait_until(condition, *, timeout_s: float, what: str, every=None) -> float:
    t0 = time.monotonic()
    while not condition():
        if every is not None:
            every()
        if time.monotonic() - t0 > timeout_s:
            raise AssertionError(f"{what} did not happen within {timeout_s} s")
        await asyncio.sleep(0.05)
    return time.monotonic() - t0


def in_formation(peers) -> bool:
    """All airborne in offboard, 2 pi / 3 apart about the person within 10 degrees, d_des within 1 m."""
    if not all(p.mode is PeerMode.OFFBOARD and not p.landed for p in peers):
        return False
    xyz = truth_xyz(peers)
    distances = np.hypot(xyz[:, 0], xyz[:, 1])
    return spacing_error_deg(positions_xy_m=xyz[:, :2], person_xy_m=np.zeros(2)) < 10.0 and bool(
        np.all(np.abs(distances - D_DES_M) < 1.0)
    )


async def test_team_takes_off_forms_up_and_lands_on_land_all():
    t0 = time.monotonic()
    async with px4_ground_station() as (station, fleet, peers, api):
        took = await wait_until(lambda: in_formation(peers), timeout_s=60.0, what="the 2 pi / 3 formation")
        assert time.monotonic() - t0 < 60.0
        async with httpx.AsyncClient(base_url=api) as client:
            state = (await client.get("/api/state")).json()
            assert [v["phase"] for v in state["vehicles"]] == ["formation"] * 3
            response = await client.post("/api/land_all")
            assert response.status_code == 200
            assert sorted(response.json()["landing"]) == [1, 2, 3]
        await wait_until(
            lambda: all(p.landed and not p.armed for p in peers), timeout_s=20.0, what="landing all"
        )
        # landed through PX4's Land; after the disarm PX4 returns to the last mode that allows arming
        assert all([m for _, m in p.mode_log()][-2:] == ["LAND", "OFFBOARD"] for p in peers)
        for i, peer in enumerate(peers):
            seen = peer.setpoints()
            assert len(seen) > 20
            assert [q for sp in seen for q in setpoint_problems(sp, system_id=i + 1)] == []
    assert took < 60.0


async def test_frozen_agent_holds_within_a_second_then_lands_clear_of_its_teammates(monkeypatch):
    async with px4_ground_station() as (station, fleet, peers, api):
        await wait_until(lambda: in_formation(peers), timeout_s=60.0, what="the formation")
        frozen = fleet.autopilots[1]
        monkeypatch.setattr(frozen, "send_setpoint", lambda setpoint: None)  # its controller's output stops
        frozen_at = peers[1].now()
        closest = [math.inf]

        def watch() -> None:
            xyz = truth_xyz(peers)
            closest[0] = min(closest[0], *(float(np.linalg.norm(xyz[j] - xyz[1])) for j in (0, 2)))

        await wait_until(
            lambda: peers[1].landed and not peers[1].armed, timeout_s=20.0, what="its landing", every=watch
        )
        log = [(t - frozen_at, mode) for t, mode in peers[1].mode_log() if t >= frozen_at]
        assert [mode for _, mode in log][:2] == ["HOLD", "LAND"]
        assert log[0][0] < 1.0
        assert closest[0] > 3.0
        assert all(p.mode is PeerMode.OFFBOARD for p in (peers[0], peers[2]))  # the others fly on


async def test_silent_vehicle_is_flagged_in_the_api_and_on_its_card_within_1_5_s():
    async with px4_ground_station() as (station, fleet, peers, api):
        async with httpx.AsyncClient(base_url=api) as client:
            await wait_until(  # the API answers before every peer's first telemetry has come
                lambda: not any(v.link_stale for v in station.scene_view().vehicles),
                timeout_s=10.0,
                what="fresh telemetry from every vehicle",
            )
            peers[2].silence()
            silenced = time.monotonic()

            async def flagged() -> bool:
                vehicles = (await client.get("/api/state")).json()["vehicles"]
                return vehicles[2]["link_stale"] and not vehicles[0]["link_stale"]

            while not await flagged():
                assert time.monotonic() - silenced < 3.0, "LINK_LOST never reached the API"
                await asyncio.sleep(0.05)
            api_took = time.monotonic() - silenced
            row = team_table_html(station.scene_view(), {}).split('data-vehicle="3"')[1].split("</tr>")[0]

            async def alerted() -> bool:
                alerts = (await client.get("/api/state")).json()["alerts"]
                return any(a["kind"] == "link" and a["vehicle_id"] == 3 and a["active"] for a in alerts)

            while not await alerted():  # read off the view every 0.1 s of mission time
                assert time.monotonic() - silenced < 3.0, "no link alert for the silent vehicle"
                await asyncio.sleep(0.05)
            alert_took = time.monotonic() - silenced
            while not fleet.autopilots[2].state().link_lost:  # the back-end's own flag, after its 1 s
                assert time.monotonic() - silenced < 3.0, "the PX4 back-end never flagged LINK_LOST"
                await asyncio.sleep(0.05)
            lost_took = time.monotonic() - silenced
        assert api_took < 1.5 and alert_took < 1.5 and lost_took < 1.5
        assert ">STALE</span>" in row  # the team table flags it

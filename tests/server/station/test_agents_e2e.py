"""End to end over real Zenoh on 127.0.0.1: three `skyring agent` processes, each flying its own PX4 test
peer through MAVSDK (real MAVLink over UDP), supervised by a `skyring serve --agents zenoh` process that also
holds a direct MAVLink link to every peer. Processes are killed with SIGKILL, as a crash or a power cut would.
"""

from __future__ import annotations

import math
import sys
import time
from pathlib import Path

import httpx
import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # tests/, for the peer
sys.path.insert(0, str(Path(__file__).resolve().parent))

from agents_harness import Team, wait_until  # noqa: E402
from px4_peer import PeerMode  # noqa: E402

pytestmark = [pytest.mark.e2e, pytest.mark.slow]

NAV_LAND = 21


@pytest.fixture
def team(tmp_path):
    t = Team(k=3, logs=tmp_path).start()
    try:
        yield t
    finally:
        t.stop()


def acked_by_all(state: dict | None, command_ids: set[int]) -> bool:
    if state is None:
        return False
    for v in state["vehicles"]:
        outcomes = {c["command_id"]: c["outcome"] for c in v["agent"]["commands"]}
        if not any(outcomes.get(c) == "acked" for c in command_ids):
            return False
    return True


def newest_command(state: dict) -> int:
    return max(c["command_id"] for v in state["vehicles"] for c in v["agent"]["commands"])


@pytest.mark.alone  # bounds the acks at 0.5 s of wall time: beside the parallel suite CI measured 0.85 s
def test_team_forms_up_takes_a_new_d_des_and_survives_losing_agents(team):
    # Take-off and the 2 pi / 3 formation at d_des within 60 s of starting the processes.
    took = wait_until(lambda: team.in_formation(range(3)), timeout_s=60.0, what="the 2 pi / 3 formation")
    assert took < 60.0
    # A d_des change from the API: acknowledged by all three agents within 0.5 s, flown within 30 s.
    before = team.state()
    assert before is not None and all(not v["agent"]["lost"] for v in before["vehicles"])
    sent = time.monotonic()
    response = httpx.put(f"{team.api}/api/formation", json={"d_des_m": 7.0, "h_des_m": 8.0}, timeout=5.0)
    assert response.status_code == 200
    command = newest_command(team.state())
    acked = wait_until(
        lambda: acked_by_all(team.state(), {command}), timeout_s=5.0, what="the acks", poll_s=0.02
    )
    assert time.monotonic() - sent < 0.5 + 0.3, "acks slower than 0.5 s (0.3 s allowed for polling the API)"
    assert acked < 0.5 + 0.3
    wait_until(lambda: team.in_formation(range(3), d_des_m=7.0), timeout_s=30.0, what="flying d_des = 7 m")

    # kill -9 agent 3: shown lost within 1 s; its failsafe lands it; agents 1 and 2 re-space to pi.
    team.kill_agent(2)
    killed = time.monotonic()
    lost = wait_until(
        lambda: (s := team.state(0.5)) is not None and s["vehicles"][2]["agent"]["lost"],
        timeout_s=5.0,
        what="agent 3 shown lost",
        poll_s=0.05,
    )
    assert lost < 1.0
    closest = [math.inf]

    def watch() -> None:
        xyz = team.truth_xyz()
        closest[0] = min(closest[0], float(np.linalg.norm(xyz[0] - xyz[1])), *(
            float(np.linalg.norm(xyz[j] - xyz[2])) for j in (0, 1)
        ))  # fmt: skip

    wait_until(
        lambda: team.peers[2].landed, timeout_s=30.0, what="the failsafe landing of MAV 3", every=watch
    )
    modes = [m for t, m in team.peers[2].mode_log() if t >= team.peers[2].now() - (time.monotonic() - killed)]
    assert modes[:1] == ["LAND"]  # offboard loss: straight to Land, as PX4 v1.16 does (docs/px4.md)
    wait_until(
        lambda: team.in_formation([0, 1], d_des_m=7.0), timeout_s=40.0, what="1 and 2 at pi", every=watch
    )
    assert closest[0] > 1.5

    # kill -9 agent 2 as well, then LAND ALL: its vehicle lands through the station's own MAVLink link.
    team.kill_agent(1)
    killed_at = team.peers[1].now()
    response = httpx.post(f"{team.api}/api/land_all", timeout=5.0)
    assert response.status_code == 200
    wait_until(lambda: team.peers[1].mode is PeerMode.LAND, timeout_s=3.0, what="MAV 2 landing")
    assert any(cmd == NAV_LAND and t > killed_at for t, cmd, *_ in team.peers[1].commands())
    assert team.peers[1].now() - killed_at < 3.0  # long before its own failsafe (>= 6 s)
    wait_until(lambda: all(p.landed for p in team.peers), timeout_s=30.0, what="every MAV down")


def test_agents_fly_on_without_the_station_then_land_and_a_restarted_station_finds_them(team):
    wait_until(lambda: team.in_formation(range(3)), timeout_s=60.0, what="the 2 pi / 3 formation")
    # The agents count the timeout from the last heartbeat they heard, which is up to one heartbeat period
    # (0.5 s) before the kill, more when the station is slow under load: watch until 1.5 s short of it.
    killed = time.monotonic()
    team.kill_station()
    hold_s = team.station_timeout_s - 1.5
    worst = [0.0]
    dropped: list[int] = []

    def watch() -> None:
        if time.monotonic() - killed < hold_s:
            worst[0] = max(worst[0], team.spacing_deg(range(3)))
            dropped.extend(i for i, p in enumerate(team.peers) if p.mode is not PeerMode.OFFBOARD or p.landed)

    # Until the station timeout the formation holds; then every agent lands its MAV.
    wait_until(lambda: time.monotonic() - killed > hold_s, timeout_s=30, what="", every=watch)
    assert not dropped, f"MAVs {sorted(set(dropped))} left the formation {hold_s:g} s after the station went"
    assert worst[0] < 10.0
    wait_until(lambda: all(p.landed for p in team.peers), timeout_s=30.0, what="every MAV landed")

    team.start_station()
    found = wait_until(
        lambda: (
            (s := team.state()) is not None
            and all(not v["agent"]["lost"] and v["phase"] == "landed" for v in s["vehicles"])
        ),
        timeout_s=40.0,
        what="the restarted station showing every agent",
        poll_s=0.2,
    )
    assert found < 40.0
    state = team.state()
    assert state is not None
    assert all(v["agent"]["station_lost"] is False for v in state["vehicles"])
    assert all(abs(v["position_m"][2]) < 1.0 for v in state["vehicles"])

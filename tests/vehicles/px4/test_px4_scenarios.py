"""End to end against PX4 as it behaves after a first mission: `skyring serve --px4` in its own process, three
vehicles, driven through the REST API and watched through the vehicles' own telemetry.

Each scenario runs twice over: on `Px4Peer` MAVLink peers in `make test` (the peer models what these
scenarios hinge on, as measured on PX4 v1.16 SITL: the return to Offboard after a disarm and the arming
refusal without a set-point stream, PX4's failsafe modes and system status, COM_ARMABLE), and on real PX4
SITL in `make test-px4 PX4_SITL=path/to/bin/px4` (several SIH instances started and stopped by the test;
tests/px4_team.py). The times each scenario measured are printed (`-rP` shows them).
"""

from __future__ import annotations

import math
import os
import time
from functools import partial
from pathlib import Path

import numpy as np
import pytest
from px4_team import (
    D_DES_M,
    PeerTeam,
    Sampler,
    SitlTeam,
    Station,
    Team,
    describe,
    home_at,
    ring_homes,
    wait_for,
)

from server.flightlog.reader import read_flight_log
from server.lab.metrics import spacing_error_deg

pytestmark = [pytest.mark.slow, pytest.mark.e2e]

# The peer's take-off and disarm-after-landing quicker than PX4's defaults; its landing speed stays PX4's
# (0.7 m/s) where a scenario must see a vehicle still in the air.
FAST_TAKEOFF = {"MPC_TKO_SPEED": 3.0, "COM_DISARM_LAND": 0.5}
FAST = {**FAST_TAKEOFF, "MPC_LAND_SPEED": 2.0}
MIN_SEPARATION_M = 1.5
# A second station is meant to serve within 30 s of its start (it used to give up after 60 s). The bound is
# looser because it counts the whole process start on a shared 2-core machine: on real PX4 the station served
# after 6-23 s, its connection to the three vehicles itself took 2 s, and its Python imports alone 2-12 s, so
# a busy machine (load average 15, the test run under `nice`) once took longer than 30 s. Each run prints the
# time it measured (docs/px4.md, "Times measured by make test-px4").
SECOND_STATION_BOUND_S = 60.0


@pytest.fixture(params=["peer", pytest.param("sitl", marks=pytest.mark.px4_sitl)])
def make_team(request, tmp_path):
    """make_team(homes, peer_params=..., per_vehicle=...) -> a started team of the parametrised kind; every
    team made is closed (peers stopped, PX4 processes stopped by pid) at the end."""
    teams: list[Team] = []
    kind = request.param
    binary = os.environ.get("PX4_SITL", "")
    if kind == "sitl" and not binary:
        pytest.skip("needs a PX4 SITL build: make test-px4 PX4_SITL=path/to/build/px4_sitl_default/bin/px4")

    def make(homes, *, peer_params=FAST, px4_params=None, per_vehicle=None) -> Team:
        """peer_params: the peers' own speed-ups; px4_params: PX4 parameters for every vehicle of either kind;
        per_vehicle: PX4 parameters for one (1-based)."""
        if kind == "peer":
            merged = {**peer_params, **(px4_params or {})}
            team: Team = PeerTeam(homes, params=merged, per_vehicle=per_vehicle)
        else:
            team = SitlTeam(binary, homes, params=px4_params, per_vehicle=per_vehicle)
        teams.append(team)
        return team

    yield make
    for team in teams:
        team.close()


@pytest.fixture
def stations(tmp_path):
    """start(team) -> a running `skyring serve --px4` over the team; every station is stopped at the end."""
    started: list[Station] = []

    def start(team: Team) -> Station:
        station = Station(team.urls, log_path=tmp_path / f"flight-{len(started) + 1}.mcap")
        started.append(station)
        return station

    yield start
    for station in started:
        if station.proc.poll() is None:
            station.stop()


def flies_formation(
    team: Team, ids=(1, 2, 3), *, d_des_m: float = D_DES_M, distance_tolerance_m: float = 1.0
) -> bool:
    """The vehicles `ids` fly offboard, evenly spaced about the person (within 10 deg), d_des +- 1 m away
    (or +- distance_tolerance_m)."""
    truth = [team.truth()[i - 1] for i in ids]
    if not all(t.mode == "OFFBOARD" and t.enu_m[2] > 1.0 for t in truth):
        return False
    xy = np.array([t.enu_m[:2] for t in truth])
    distance = np.hypot(xy[:, 0], xy[:, 1])
    spacing = spacing_error_deg(positions_xy_m=xy, person_xy_m=np.zeros(2))
    return bool(spacing < 10.0 and np.all(np.abs(distance - d_des_m) < distance_tolerance_m))


def view_in_formation(station: Station, ids=(1, 2, 3)) -> bool:
    vehicles = {v["vehicle_id"]: v for v in station.state()["vehicles"]}
    return all(vehicles[i]["in_formation"] for i in ids)


def fly_formation(team: Team, station: Station, times: dict[str, float]) -> None:
    """Start the station, wait for take-off and the 2 pi / 3 formation; record connect/take-off/formation."""
    times["connect_s"] = station.wait_ready(60.0)
    shown = partial(describe, team, station)  # what a failure message shows
    times["takeoff_s"] = wait_for(
        lambda: all(team.airborne()), timeout_s=60.0, what="all three airborne", detail=shown
    )
    times["formation_s"] = times["takeoff_s"] + wait_for(
        lambda: flies_formation(team) and view_in_formation(station),
        timeout_s=90.0,
        what="the 2 pi / 3 formation",
        detail=shown,
    )


def report(kind: str, name: str, times: dict[str, float]) -> None:
    print(f"{kind} {name}: " + ", ".join(f"{k} {v:.2f}" for k, v in times.items()))


def test_after_land_all_every_released_mav_is_airborne_and_in_formation_within_60_s(make_team, stations):
    team = make_team(ring_homes())
    sampler = Sampler(team)
    station = stations(team)
    times: dict[str, float] = {}
    fly_formation(team, station, times)
    assert station.post("/api/land_all").status_code == 200
    times["land_all_s"] = wait_for(lambda: all(team.on_ground_disarmed()), timeout_s=60.0, what="LAND ALL")
    wait_for(
        lambda: [v["phase"] for v in station.state()["vehicles"]] == ["landed"] * 3,
        timeout_s=10.0,
        what="every card saying landed",
    )
    # PX4 went back to Offboard after the disarm: where it refuses to arm without a set-point stream.
    assert team.modes() == ["OFFBOARD"] * 3
    released = time.monotonic()
    for vid in (1, 2, 3):
        response = station.post(f"/api/vehicles/{vid}/release")
        if response.status_code == 422 and "keep-out" in response.text:
            # The person's keep-out (0.875 d_des = 7 m) lies inside the formation's d_des +- 1 m, and the
            # station checks it against the person's estimates too: a MAV landed from the formation's inner
            # edge (measured: 6.6-7.0 m, with and without acceleration feed-forward) is refused, as it should
            # be, and the operator overrides. Anything else refused fails.
            response = station.post(f"/api/vehicles/{vid}/release", override="true")
        assert response.status_code == 200, response.text
    shown = partial(describe, team, station)  # what a failure message shows
    times["retakeoff_s"] = wait_for(
        lambda: all(team.airborne()), timeout_s=60.0, what="re-takeoff", detail=shown
    )
    wait_for(
        lambda: flies_formation(team) and view_in_formation(station),
        timeout_s=60.0 - (time.monotonic() - released),
        what="the formation again within 60 s of the release",
        detail=shown,
    )
    times["release_to_formation_s"] = time.monotonic() - released
    sampler.close()
    assert sampler.closest_m >= MIN_SEPARATION_M, sampler.closest_at
    report(team.kind, "land all, release", {**times, "closest_pair_m": sampler.closest_m})


def test_a_second_station_adopts_landed_vehicles_and_flies_the_formation(make_team, stations):
    team = make_team(ring_homes())
    first = stations(team)
    fly_formation(team, first, {})
    first.stop()  # SIGTERM: it lands every vehicle before it exits
    wait_for(lambda: all(team.on_ground_disarmed()), timeout_s=60.0, what="the landing at shutdown")
    assert team.modes() == ["OFFBOARD"] * 3  # the state a second mission used to fail on
    second = stations(team)
    times = {"second_station_s": second.wait_ready(SECOND_STATION_BOUND_S)}
    # its view shows PX4's own mode for every vehicle (it changes once the take-off starts)
    wait_for(
        lambda: [v["autopilot_mode"] for v in second.state()["vehicles"]] == team.modes(),
        timeout_s=5.0,
        what="the view showing PX4's modes",
    )
    shown = partial(describe, team, second)  # what a failure message shows
    times["takeoff_s"] = wait_for(lambda: all(team.airborne()), timeout_s=60.0, what="take-off", detail=shown)
    times["formation_s"] = times["takeoff_s"] + wait_for(
        lambda: flies_formation(team) and view_in_formation(second),
        timeout_s=90.0,
        what="the formation",
        detail=shown,
    )
    report(team.kind, "second station, landed team", times)


def test_a_second_station_adopts_vehicles_still_flying_after_the_first_was_killed(make_team, stations):
    # PX4 lands them at 0.3 m/s, not 0.7: still flying when the second station is up, even on a busy machine
    team = make_team(ring_homes(), peer_params=FAST_TAKEOFF, px4_params={"MPC_LAND_SPEED": 0.3})
    sampler = Sampler(team)
    first = stations(team)
    fly_formation(team, first, {})
    first.kill()  # SIGKILL: no landing command; PX4's offboard-loss failsafe takes over
    second = stations(team)
    times = {"second_station_s": second.wait_ready(SECOND_STATION_BOUND_S)}
    state = second.state()
    assert not state["formation_enabled"]  # found flying: nothing is commanded until the operator acts
    vehicles = state["vehicles"]
    assert not any(v["in_formation"] for v in vehicles)
    flying = [v for v in vehicles if v["in_air"]]
    assert flying, "every vehicle had landed before the second station was up: nothing adopted in flight"
    for v in flying:  # PX4 lands them in its failsafe, and the view says so
        assert v["phase"] == "idle" and v["autopilot_mode"] == "LAND" and v["failsafe"], v
        assert v["failsafe_reason"]
    assert set(team.modes()) <= {"LAND", "OFFBOARD"}  # OFFBOARD: already down and disarmed
    wait_for(lambda: all(team.on_ground_disarmed()), timeout_s=60.0, what="PX4's failsafe landing")
    response = second.post("/api/formation/start")
    assert response.status_code == 200, response.text
    started = time.monotonic()
    wait_for(
        lambda: flies_formation(team) and view_in_formation(second),
        timeout_s=120.0,
        what="the formation",
        detail=lambda: describe(team, second),
    )
    times["start_to_formation_s"] = time.monotonic() - started
    sampler.close()
    assert sampler.closest_m >= MIN_SEPARATION_M, sampler.closest_at
    times["adopted_flying"] = len(flying)
    times["closest_pair_m"] = sampler.closest_m
    report(team.kind, "second station, team killed in flight", times)


def test_a_stalled_station_shows_px4s_failsafe_and_no_vehicle_in_formation_while_px4_lands_it(
    make_team, stations
):
    team = make_team(ring_homes(), peer_params=FAST_TAKEOFF)
    sampler = Sampler(team)
    station = stations(team)
    fly_formation(team, station, {})
    wait_for(lambda: team.modes() == ["OFFBOARD"] * 3, timeout_s=20.0, what="all three in Offboard")
    station.freeze()  # SIGSTOP: the whole ground station stalls, MAVSDK's threads too
    frozen = time.monotonic()
    time.sleep(6.0)
    landed_by_px4 = [t.mode == "LAND" and t.failsafe for t in team.truth()]  # PX4's offboard-loss failsafe
    station.thaw()
    thawed = time.monotonic()
    # (a vehicle skyring had put in Hold just before, its loop starved, has no set-points to lose)
    assert sum(landed_by_px4) >= 2, team.modes()
    seen: list[tuple[float, list[dict], list[str]]] = []  # (time, API vehicles, PX4's modes)
    down = [i for i in range(3) if landed_by_px4[i]]
    while not all(team.on_ground_disarmed()[i] for i in down):
        vehicles = station.state()["vehicles"]
        seen.append((time.monotonic(), vehicles, team.modes()))
        assert time.monotonic() - frozen < 90.0, "the vehicles did not land"
        time.sleep(0.1)
    sampler.close()
    for i in down:
        # no vehicle is shown in formation while PX4 is landing it, from the first answer after the stall
        shown = [
            (round(t - thawed, 2), vs[i]["phase"])
            for t, vs, modes in seen
            if modes[i] == "LAND" and vs[i]["in_formation"]
        ]
        assert not shown, (i, shown)  # (seconds after the thaw, phase) of every answer that said so
        # it is shown landing in a failsafe, with the reason, until it is down (PX4's heartbeat comes once a
        # second: the view may take that long to catch up with the stall)
        landing = [vs[i] for t, vs, modes in seen if modes[i] == "LAND" and t - thawed >= 1.5]
        assert landing and sum(v["failsafe"] for v in landing) >= 0.9 * len(landing), landing[:3]
        assert all(v["failsafe_reason"] for v in landing if v["failsafe"])
        assert any(v["phase"] == "landing" and v["autopilot_mode"] == "LAND" for v in landing)
    assert sampler.closest_m >= MIN_SEPARATION_M, sampler.closest_at
    report(
        team.kind,
        "stall 6 s",
        {
            "landed_by_px4": len(down),
            "landed_after_thaw_s": seen[-1][0] - frozen - 6.0,
            "closest_pair_m": sampler.closest_m,
        },
    )


def test_a_vehicle_refused_arming_shows_px4s_reason_within_2_s_and_its_teammates_space_for_two(
    make_team, stations
):
    team = make_team(ring_homes(), per_vehicle={3: {"COM_ARMABLE": 0}})
    station = stations(team)
    station.wait_ready(60.0)
    refused = wait_for(
        lambda: any("Arming denied" in text for _, text in team.truth()[2].texts),
        timeout_s=30.0,
        what="PX4 refusing to arm vehicle 3",
    )
    refused_at = next(t for t, text in team.truth()[2].texts if "Arming denied" in text)

    def shown() -> bool:
        refusal = station.state()["vehicles"][2]["arming_refusal"]
        return refusal is not None and "Arming denied" in refusal

    wait_for(shown, timeout_s=5.0, what="the refusal on the card", every_s=0.05)
    shown_after_s = time.monotonic() - refused_at
    assert shown_after_s < 2.0
    vehicle3 = station.state()["vehicles"][2]
    if team.kind == "sitl":  # PX4's events protocol names the failing check
        assert "safety configuration" in vehicle3["arming_refusal"]
    assert not vehicle3["in_formation"] and not vehicle3["in_air"] and vehicle3["can_arm"] is False
    wait_for(
        lambda: flies_formation(team, ids=(1, 2)) and view_in_formation(station, ids=(1, 2)),
        timeout_s=90.0,
        what="MAVs 1 and 2 at pi apart",
        detail=lambda: describe(team, station),
    )
    assert not team.airborne()[2] and not station.state()["vehicles"][2]["in_formation"]
    refusals = sum("Arming denied" in text for _, text in team.truth()[2].texts)
    assert refusals <= 3  # retried when PX4 says it can arm, not hammered (84 refusals in 83 s before)
    report(
        team.kind, "refused arming", {"refusal_after_ready_s": refused, "card_after_refusal_s": shown_after_s}
    )


def test_a_vehicle_inside_the_person_keep_out_is_refused_by_name_until_overridden(
    make_team, stations, tmp_path
):
    homes = ring_homes()[:2] + [home_at(0.0, -3.0)]  # MAV 3 stands 3 m from the person (keep-out 7 m)
    team = make_team(homes)
    station = stations(team)
    station.wait_ready(60.0)
    state = station.state()
    assert not state["formation_enabled"]  # nothing took off on its own
    assert "keep-out" in state["vehicles"][2]["takeoff_check"]
    response = station.post("/api/formation/start")
    assert response.status_code == 422
    assert "MAV 3" in response.json()["detail"] and "keep-out" in response.json()["detail"]
    time.sleep(2.0)
    assert not any(t.armed for t in team.truth())
    response = station.post("/api/formation/start", override="true")
    assert response.status_code == 200, response.text
    wait_for(
        lambda: all(team.airborne()),
        timeout_s=60.0,
        what="take-off after the override",
        detail=lambda: describe(team, station),
    )
    station.stop()
    commands = [
        a for a in read_flight_log(Path(station.log_path)).audit if a.command == "set_formation_enabled"
    ]
    assert [(c.accepted, c.arguments["override"]) for c in commands] == [(False, False), (True, True)]
    result = commands[1].result
    assert result is not None and "MAV 3" in result and "keep-out" in result
    assert math.isfinite(commands[1].time_s)

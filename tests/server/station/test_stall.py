"""A real-time ground station whose control loop stalls (the process stopped or starved): a reader never sees
the team as it was before the stall. It waits for the first tick after it, and if the loop still stands it is
shown no vehicle in formation."""

from __future__ import annotations

import threading
import time

import pytest
from test_live import FakeClock

from server.station.ground_station import STALL_AFTER_S, STALL_WAIT_S, GroundStation
from vehicles.mission import Phase
from vehicles.sim.scenario import Scenario, build_sim

RATE_HZ = 20.0


@pytest.fixture
def flying() -> tuple[GroundStation, FakeClock]:
    """Three simulated MAVs in formation, ticked by this thread on a clock that moves one period per tick."""
    clock = FakeClock()
    setup = build_sim(Scenario(vehicles=3, seed=3))
    station = GroundStation(mission=setup.mission, control_period_s=1.0 / RATE_HZ, clock=clock)
    station.set_formation_enabled(True)
    while not all(v.phase == Phase.FORMATION for v in station.snapshot().vehicles):
        assert clock.now < 60.0, "the team did not form up"
        clock.now += 1.0 / RATE_HZ
        station.tick()
    return station, clock


def view_from_another_thread(station: GroundStation):
    box = {}

    def read() -> None:
        started = time.monotonic()
        box["view"] = station.scene_view()
        box["waited_s"] = time.monotonic() - started

    reader = threading.Thread(target=read)
    reader.start()
    return reader, box


def test_a_view_read_after_a_stall_is_the_first_ticks_after_it(flying):
    station, clock = flying
    assert all(v.in_formation for v in station.scene_view().vehicles)
    clock.now += 3.0  # the loop stood for 3 s
    reader, box = view_from_another_thread(station)
    time.sleep(0.2)
    assert reader.is_alive()  # it waits for the tick rather than answer with the team before the stall
    station.tick()
    reader.join(timeout=5.0)
    assert box["view"].time_s == pytest.approx(clock.now, abs=1e-9)
    assert box["waited_s"] < STALL_WAIT_S


def test_a_view_read_while_the_loop_still_stands_shows_no_vehicle_in_formation(flying):
    station, clock = flying
    clock.now += 3.0
    reader, box = view_from_another_thread(station)
    reader.join(timeout=5.0)
    assert box["waited_s"] == pytest.approx(STALL_WAIT_S, abs=0.5)
    assert [v.in_formation for v in box["view"].vehicles] == [False] * 3
    assert all("control loop has not run for 3.0 s" in v.fault for v in box["view"].vehicles)


def test_a_short_pause_below_the_stall_limit_is_answered_at_once_as_it_is(flying):
    station, clock = flying
    clock.now += 0.5 * STALL_AFTER_S
    reader, box = view_from_another_thread(station)
    reader.join(timeout=5.0)
    assert box["waited_s"] < 0.2
    assert all(v.in_formation for v in box["view"].vehicles)


def test_the_ticking_thread_itself_never_waits_for_its_own_tick(flying):
    station, clock = flying
    clock.now += 3.0
    started = time.monotonic()
    view = station.scene_view()
    assert time.monotonic() - started < 0.2
    assert all(v.in_formation for v in view.vehicles)

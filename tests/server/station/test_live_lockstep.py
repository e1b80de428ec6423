"""Physics and control in lockstep under overload: the live station (`LiveRunner` pacing a `GroundStation`
over the embedded simulation, as `skyring serve` runs it) never advances the simulated vehicles on a stale
set-point. Each tick runs the world one control period on the set-points computed at its start, then every
agent; a controller slower than the control period slows simulated time as a whole, which the state's
real-time factor reports.

The controller is made slow on purpose (its tick sleeps); the runner runs on the real clock. The bounds
asserted only get safer on a slower machine.
"""

from __future__ import annotations

import asyncio
import time
from collections import defaultdict

import pytest
from test_api import client_for, run_until

from server.station.ground_station import GroundStation
from server.station.live import LiveRunner
from vehicles.agent import Agent
from vehicles.mission import Phase
from vehicles.sim.scenario import Scenario, SimSetup, build_sim

RATE_HZ = 20.0
PERIOD_S = 1.0 / RATE_HZ
WALL_S = 2.0  # wall seconds each live run lasts


class Recorder:
    """What the live run did: MAV 1's agent ticks (vehicle, mission time, wall time), the world's advances
    (start, end: one per station tick) and every physics step of every simulated vehicle (start, end, and the
    autopilot time its latest set-point arrived at; the world steps the vehicles on a finer grid)."""

    def __init__(self) -> None:
        self.ticks: list[tuple[int, float, float]] = []
        self.advances: list[tuple[float, float]] = []
        self.steps: dict[int, list[tuple[float, float, float]]] = defaultdict(list)


def flying(monkeypatch, setup: SimSetup, *, slow_s) -> tuple[GroundStation, Recorder]:
    """A station over `setup` with its team flying formation (stepped as fast as it goes), then watched: from
    here MAV 1's agent sleeps slow_s(tick number) seconds in every tick."""
    station = GroundStation(mission=setup.mission, control_period_s=PERIOD_S)
    run_until(station, lambda s: all(v.phase == Phase.FORMATION for v in s.vehicles), limit_s=30.0)
    rec = Recorder()
    tick = Agent.tick

    def slow_tick(agent: Agent, now_s, inputs, **kwargs):
        if agent.vehicle_id == 1:
            time.sleep(slow_s(len(rec.ticks)))
            rec.ticks.append((agent.vehicle_id, now_s, time.monotonic()))
        return tick(agent, now_s, inputs, **kwargs)

    monkeypatch.setattr(Agent, "tick", slow_tick)
    for autopilot in setup.autopilots:
        setpoint_at = {"t": autopilot.time_s}  # the set-point of the tick that just ran
        send, advance = autopilot.send_setpoint, autopilot.advance

        def sent(setpoint, *, _ap=autopilot, _at=setpoint_at, _send=send):
            _at["t"] = _ap.time_s
            _send(setpoint)

        def advanced(now_s, *, _ap=autopilot, _at=setpoint_at, _advance=advance):
            start = _ap.time_s
            _advance(now_s)
            rec.steps[_ap.vehicle_id].append((start, _ap.time_s, _at["t"]))

        monkeypatch.setattr(autopilot, "send_setpoint", sent)
        monkeypatch.setattr(autopilot, "advance", advanced)
    world_advance = setup.world.advance

    def world_advanced(now_s):
        start = setup.world.time_s
        world_advance(now_s)
        rec.advances.append((start, setup.world.time_s))

    monkeypatch.setattr(setup.world, "advance", world_advanced)
    return station, rec


async def run_live(station: GroundStation) -> LiveRunner:
    """Run the live loop at real time for WALL_S, handing the station its pace as `serve_station` does."""
    runner: LiveRunner

    def frame() -> None:
        station.set_pace(runner.pace())

    runner = LiveRunner(station=station, speed=1.0, on_frame=frame)
    stop = asyncio.Event()
    asyncio.get_running_loop().call_later(WALL_S, stop.set)
    await runner.run(stop)
    frame()
    return runner


def assert_every_period_flown_on_a_fresh_setpoint(rec: Recorder, vehicles: int) -> None:
    """The world advanced exactly one control period per control tick, and every simulated vehicle flew
    every physics step of that period on the set-point its agent computed at the period's start (never on
    one from an earlier tick)."""
    assert len(rec.advances) == len(rec.ticks)
    assert all(end - start == pytest.approx(PERIOD_S, abs=1e-9) for start, end in rec.advances)
    # each tick: the world to t, then the agents at t
    assert [end for _, end in rec.advances] == pytest.approx([now for _, now, _ in rec.ticks], abs=1e-9)
    assert sorted(rec.steps) == list(range(1, vehicles + 1))
    for vid, steps in rec.steps.items():
        assert steps[0][0] == pytest.approx(rec.advances[0][0], abs=1e-9)
        assert steps[-1][1] == pytest.approx(rec.advances[-1][1], abs=1e-9)
        period = 0
        for start, end, setpoint_at in steps:
            while start >= rec.advances[period][1] - 1e-9:
                period += 1
            assert end <= rec.advances[period][1] + 1e-9, (vid, start)
            assert setpoint_at == pytest.approx(rec.advances[period][0], abs=1e-9), (vid, start)


async def test_an_overloaded_controller_slows_simulated_time_one_period_per_control_tick(monkeypatch):
    setup = build_sim(Scenario(vehicles=3, seed=3))
    station, rec = flying(monkeypatch, setup, slow_s=lambda _: 1.5 * PERIOD_S)
    start_s = station.time_s
    runner = await run_live(station)

    ticks = len(rec.ticks)
    assert ticks == runner.stats.ticks and ticks >= 10
    assert station.time_s - start_s == pytest.approx(ticks * PERIOD_S, abs=1e-9)
    times = [now for _, now, _ in rec.ticks]
    assert all(b - a == pytest.approx(PERIOD_S, abs=1e-9) for a, b in zip(times, times[1:], strict=False))
    assert_every_period_flown_on_a_fresh_setpoint(rec, 3)
    # each tick takes at least 1.5 periods of wall time: simulated time runs at most 1/1.5 of real time
    pace = (await client_for(station).get("/api/state")).json()["pace"]
    assert pace["requested_speed"] == 1.0
    assert 0.0 < pace["realtime_factor"] < 0.7
    assert runner.stats.achieved_speed < 0.7


async def test_catching_up_after_stalls_runs_control_before_every_physics_step(monkeypatch):
    setup = build_sim(Scenario(vehicles=3, seed=3))
    # every 8th tick stalls for 5 periods: the runner then runs several ticks back to back to catch up
    station, rec = flying(monkeypatch, setup, slow_s=lambda n: 5 * PERIOD_S if n % 8 == 0 else 0.0)
    await run_live(station)

    walls = [wall for _, _, wall in rec.ticks]
    back_to_back = sum(b - a < 0.5 * PERIOD_S for a, b in zip(walls[1:], walls[2:], strict=False))
    assert back_to_back >= 3  # it did catch up in bursts
    assert_every_period_flown_on_a_fresh_setpoint(rec, 3)

"""Pacing of the live runner, on a simulated clock: speed, falling behind, failing ticks, frames."""

from __future__ import annotations

import asyncio

import pytest

from server.station.live import LiveRunner, bind_port


class FakeClock:
    """Wall time that advances only when the runner sleeps or a tick costs time."""

    def __init__(self) -> None:
        self.now = 0.0

    def __call__(self) -> float:
        return self.now

    async def sleep(self, seconds: float) -> None:
        self.now += seconds
        await asyncio.sleep(0)


class CountingStation:
    """A station whose tick costs `tick_cost_s` of wall time and may raise."""

    def __init__(
        self, clock: FakeClock, *, period_s: float = 0.05, tick_cost_s: float = 0.0, fail_every: int = 0
    ) -> None:
        self.clock = clock
        self.control_period_s = period_s
        self.time_s = 0.0
        self.tick_cost_s = tick_cost_s
        self.fail_every = fail_every
        self.calls = 0

    def tick(self) -> None:
        self.calls += 1
        self.clock.now += self.tick_cost_s
        self.time_s += self.control_period_s
        if self.fail_every and self.calls % self.fail_every == 0:
            raise RuntimeError("a failing tick")


async def run_for(runner: LiveRunner, clock: FakeClock, wall_s: float) -> None:
    stop = asyncio.Event()

    async def stopper() -> None:
        while clock.now < wall_s:
            await asyncio.sleep(0)
        stop.set()

    await asyncio.gather(runner.run(stop), stopper())


@pytest.mark.parametrize("speed", [1.0, 4.0])
async def test_simulated_time_runs_at_speed_times_wall_time(speed):
    clock = FakeClock()
    station = CountingStation(clock)
    runner = LiveRunner(station=station, speed=speed, clock=clock, sleep=clock.sleep)
    await run_for(runner, clock, 10.0)
    assert station.time_s == pytest.approx(speed * 10.0, abs=2 * station.control_period_s)
    assert runner.stats.lagged == 0


async def test_a_runner_that_cannot_keep_up_slows_down_instead_of_bursting():
    clock = FakeClock()
    station = CountingStation(clock, tick_cost_s=0.1)  # each 0.05 s tick costs 0.1 s of wall time
    runner = LiveRunner(station=station, speed=1.0, clock=clock, sleep=clock.sleep)
    await run_for(runner, clock, 10.0)
    assert runner.stats.achieved_speed == pytest.approx(0.5, abs=0.05)
    assert runner.stats.lagged > 0


async def test_failing_ticks_are_counted_and_the_loop_goes_on():
    clock = FakeClock()
    station = CountingStation(clock, fail_every=3)
    runner = LiveRunner(station=station, speed=1.0, clock=clock, sleep=clock.sleep)
    await run_for(runner, clock, 3.0)
    assert runner.stats.ticks == station.calls == pytest.approx(60, abs=2)
    assert runner.stats.tick_errors == station.calls // 3


async def test_frames_are_published_every_frame_period_even_if_publishing_fails():
    clock = FakeClock()
    frames: list[float] = []

    def publish() -> None:
        frames.append(clock.now)
        raise RuntimeError("a drawing bug")

    runner = LiveRunner(
        station=CountingStation(clock),
        speed=1.0,
        on_frame=publish,
        frame_period_s=0.1,
        clock=clock,
        sleep=clock.sleep,
    )
    await run_for(runner, clock, 2.0)
    assert len(frames) == pytest.approx(20, abs=1)


def test_a_non_positive_speed_is_refused():
    with pytest.raises(ValueError, match="speed must be a positive factor"):
        LiveRunner(station=CountingStation(FakeClock()), speed=0.0)


def test_a_busy_port_falls_back_to_a_free_one():
    taken, _ = bind_port("127.0.0.1", 0)
    try:
        port = taken.getsockname()[1]
        sock, fell_back = bind_port("127.0.0.1", port)
        assert fell_back and sock.getsockname()[1] not in (0, port)
        sock.close()
    finally:
        taken.close()


async def test_pace_reports_the_real_time_factor_of_the_last_second_and_the_speed_asked():
    clock = FakeClock()
    station = CountingStation(clock)
    runner = LiveRunner(station=station, speed=4.0, clock=clock, sleep=clock.sleep)
    assert runner.pace().realtime_factor is None  # nothing measured yet
    await run_for(runner, clock, 3.0)
    pace = runner.pace()
    assert pace.requested_speed == 4.0
    assert pace.realtime_factor == pytest.approx(4.0, rel=0.05)
    assert pace.fell_behind == 0


async def test_pace_and_capacity_drop_when_the_ticks_get_slow():
    clock = FakeClock()
    station = CountingStation(clock)
    runner = LiveRunner(station=station, speed=1.0, clock=clock, sleep=clock.sleep)
    await run_for(runner, clock, 3.0)
    station.tick_cost_s = 0.2  # each 0.05 s tick now costs 0.2 s: a quarter of real time
    await run_for(runner, clock, 4.2)
    pace = runner.pace()
    assert pace.realtime_factor == pytest.approx(0.25, abs=0.06)
    assert pace.capacity == pytest.approx(0.25, rel=0.01)  # 0.05 s of mission per 0.2 s of computing
    assert pace.fell_behind > 0


async def test_a_loop_slowed_to_half_speed_shows_below_the_alert_floor_after_its_second_slow_tick():
    clock = FakeClock()
    station = CountingStation(clock, tick_cost_s=0.005)
    runner = LiveRunner(station=station, speed=1.0, clock=clock, sleep=clock.sleep)
    await run_for(runner, clock, 1.0)
    capacity_before: list[float | None] = []  # [k]: the capacity reported after k slow ticks
    normal_tick = station.tick

    def slow_tick() -> None:  # each 0.05 s tick now costs 0.1 s: half of real time
        capacity_before.append(runner.pace().capacity)
        station.tick_cost_s = 0.1
        normal_tick()

    station.tick = slow_tick
    await run_for(runner, clock, 1.5)
    assert len(capacity_before) >= 3
    assert capacity_before[1] == pytest.approx(3 * 0.05 / 0.11, rel=0.01)  # one slow tick: still above 0.8
    assert capacity_before[2] == pytest.approx(3 * 0.05 / 0.205, rel=0.01)  # two: 0.73, below the floor


async def test_capacity_shows_the_speed_the_ticks_computing_time_allows():
    clock = FakeClock()
    station = CountingStation(clock, tick_cost_s=0.01)  # a 0.05 s tick computed in 0.01 s: 5x at most
    runner = LiveRunner(station=station, speed=1.0, clock=clock, sleep=clock.sleep)
    await run_for(runner, clock, 2.0)
    assert runner.pace().capacity == pytest.approx(5.0, rel=0.01)

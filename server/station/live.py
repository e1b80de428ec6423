"""Running the ground station live: pacing control ticks against the wall clock, and serving the API and the
operator page beside them.

`LiveRunner` advances the station `speed` simulated seconds per wall second in short batches; when the CPU
cannot keep up it re-anchors instead of spiralling and counts it, so simulated time as a whole slows down
(each tick is control and physics together: docs/architecture.md#pacing-physics-and-control-in-lockstep);
`LiveRunner.pace` tells how it keeps up (the real-time factor over the last `PACE_WINDOW_S` of wall time),
which every frame hands the station for the operator's header and the "behind real time" alert.
`serve_station` runs it on a thread of its own with its own event loop and clock (`ControlThread`), so neither
request bodies nor WebSocket clients on the web's event loop can delay a control tick; viser, uvicorn and the
frame publisher share the web's loop. It serves until stopped (SIGINT/SIGTERM or an event), then lands every
MAV and closes the back-ends in a `finally`, whatever stopped it. (With `--agents zenoh|spawn` the control
loops are in the agents' own processes and the station's tick only gathers their state.)
"""

from __future__ import annotations

import asyncio
import contextlib
import errno
import logging
import signal
import socket
import threading
import time
from collections import deque
from collections.abc import Awaitable, Callable
from dataclasses import dataclass
from typing import Protocol

import uvicorn

from webui.view import PaceView

log = logging.getLogger(__name__)

PACE_WINDOW_S = 1.0  # wall seconds the reported real-time factor is measured over
CAPACITY_TICKS = 3
"""Ticks whose computing time the reported capacity is measured over: a loop slowed to half of real time shows
after its second slow tick (0.2 s at 20 Hz), which leaves room for the operator's alert within a second on a
busy machine; a single slow tick shows only if it takes more than 3 / 0.8 periods (the alert's floor)."""


class Steppable(Protocol):
    """What the runner paces: a fixed control period and one tick at a time."""

    @property
    def control_period_s(self) -> float: ...

    @property
    def time_s(self) -> float: ...

    def tick(self) -> None:
        """Advance by one control period."""


@dataclass
class PaceStats:
    """How the live run kept up: ticks run, times the runner fell behind by more than max_lag_s and
    re-anchored, and the achieved simulated seconds per wall second since the start."""

    ticks: int = 0
    lagged: int = 0
    tick_errors: int = 0
    achieved_speed: float = 0.0


class LiveRunner:
    """Paces `station.tick()` at `speed` x real time and calls `on_frame` every frame_period_s of wall time.

    max_batch_s: the longest stretch of ticks between two yields to the event loop; max_lag_s: simulated
    seconds the run may fall behind before it gives up catching up (it then runs slower than asked, never in
    bursts). clock and sleep are injectable for tests.
    """

    def __init__(
        self,
        *,
        station: Steppable,
        speed: float = 1.0,
        on_frame: Callable[[], None] | None = None,
        frame_period_s: float = 0.1,
        max_batch_s: float = 0.02,
        max_lag_s: float = 0.5,
        clock: Callable[[], float] = time.monotonic,
        sleep: Callable[[float], Awaitable[None]] = asyncio.sleep,
    ) -> None:
        if not (speed > 0.0 and speed < 1e6):
            raise ValueError(f"speed must be a positive factor of real time, got {speed}")
        self._station = station
        self._speed = speed
        self._on_frame = on_frame
        self._frame_period_s = frame_period_s
        self._max_batch_s = max_batch_s
        self._max_lag_s = max_lag_s
        self._clock = clock
        self._sleep = sleep
        self.stats = PaceStats()
        self._window: deque[tuple[float, float]] = deque()  # (wall, simulated) seconds, last PACE_WINDOW_S
        self._tick_costs: deque[float] = deque(maxlen=CAPACITY_TICKS)  # wall seconds of the last ticks
        self._pace = PaceView(requested_speed=speed)

    def pace(self) -> PaceView:
        """The requested speed, the real-time factor achieved over the last PACE_WINDOW_S of wall time (None
        until half a window has passed), the speed the last CAPACITY_TICKS ticks' computing time allows, and
        the times the loop fell behind so far. Safe to call from any thread (the control loop replaces the
        value; it never changes one)."""
        return self._pace

    def _measure(self, wall: float) -> None:
        window = self._window
        window.append((wall, self._station.time_s))
        while len(window) > 2 and wall - window[1][0] >= PACE_WINDOW_S:
            window.popleft()
        (w0, s0), (w1, s1) = window[0], window[-1]
        factor = (s1 - s0) / (w1 - w0) if w1 - w0 >= 0.5 * PACE_WINDOW_S else None
        costs = self._tick_costs
        capacity = None
        if len(costs) == costs.maxlen and sum(costs) > 0.0:
            capacity = len(costs) * self._station.control_period_s / sum(costs)
        self._pace = PaceView(
            requested_speed=self._speed,
            realtime_factor=factor,
            fell_behind=self.stats.lagged,
            capacity=capacity,
        )

    async def run(self, stop: asyncio.Event) -> None:
        """Tick until `stop` is set."""
        period = self._station.control_period_s
        wall0 = start_wall = self._clock()
        sim0 = start_sim = self._station.time_s
        next_frame = wall0
        while not stop.is_set():
            target = sim0 + self._speed * (self._clock() - wall0)
            batch_start = self._clock()
            while self._station.time_s + period <= target + 1e-9:
                self._tick()
                if self._clock() - batch_start > self._max_batch_s:
                    break
            if target - self._station.time_s > self._max_lag_s:
                wall0, sim0 = self._clock(), self._station.time_s
                self.stats.lagged += 1
            now = self._clock()
            if now - start_wall > 0:
                self.stats.achieved_speed = (self._station.time_s - start_sim) / (now - start_wall)
            self._measure(now)
            if now >= next_frame:
                self._frame()
                next_frame = now + self._frame_period_s
            next_tick = wall0 + (self._station.time_s + period - sim0) / self._speed
            await self._sleep(max(0.0, min(next_tick, next_frame) - self._clock()))

    def _tick(self) -> None:
        start = self._clock()
        try:
            self._station.tick()
        except Exception:  # noqa: BLE001 - the live loop must survive a failing tick; it is counted and logged
            self.stats.tick_errors += 1
            if self.stats.tick_errors <= 10 or self.stats.tick_errors % 1000 == 0:
                log.exception("control tick failed (%d so far)", self.stats.tick_errors)
        self._tick_costs.append(self._clock() - start)
        self.stats.ticks += 1

    def _frame(self) -> None:
        if self._on_frame is None:
            return
        try:
            self._on_frame()
        except Exception:  # noqa: BLE001 - a drawing problem must not stop the MAVs' control
            log.exception("publishing a frame failed")


class ControlThread:
    """A `LiveRunner` on its own thread, with its own asyncio loop and the monotonic clock."""

    def __init__(self, runner: LiveRunner) -> None:
        self.runner = runner
        self.error: BaseException | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._stop: asyncio.Event | None = None
        self._started = threading.Event()
        self._thread = threading.Thread(target=self._main, name="control-loop", daemon=True)

    def start(self) -> None:
        self._thread.start()
        self._started.wait(5.0)

    def is_alive(self) -> bool:
        return self._thread.is_alive()

    def stop(self, timeout_s: float = 10.0) -> None:
        if self._loop is not None and self._stop is not None and self._thread.is_alive():
            self._loop.call_soon_threadsafe(self._stop.set)
        self._thread.join(timeout_s)

    def _main(self) -> None:
        async def main() -> None:
            self._loop = asyncio.get_running_loop()
            self._stop = asyncio.Event()
            self._started.set()
            await self.runner.run(self._stop)

        try:
            asyncio.run(main())
        except BaseException as exc:  # noqa: BLE001 - reported to serve_station
            self.error = exc
        finally:
            self._started.set()


async def _publish_frames(
    publish: Callable[[], None], period_s: float, stop: asyncio.Event, control: ControlThread
) -> None:
    """Draw the operator's view every period_s on the web's loop until stop (or the control loop ended)."""
    while not stop.is_set() and control.is_alive():
        try:
            publish()
        except Exception:  # noqa: BLE001 - a drawing problem must not stop the MAVs' control
            log.exception("publishing a frame failed")
        with contextlib.suppress(TimeoutError):
            await asyncio.wait_for(stop.wait(), timeout=period_s)


def _publish(station, runner: LiveRunner, ui) -> None:
    """One frame: tell the station how the loop keeps up, then draw its view."""
    station.set_pace(runner.pace())
    ui.publish(station.scene_view())


def bind_port(host: str, port: int) -> tuple[socket.socket, bool]:
    """A listening TCP socket on (host, port), or on a free port if that one is taken. Returns (socket,
    fell_back)."""
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    for candidate, fell_back in ((port, False), (0, True)):
        sock = socket.socket(family, socket.SOCK_STREAM)
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            sock.bind((host, candidate))
        except OSError as exc:
            sock.close()
            if exc.errno != errno.EADDRINUSE or candidate == 0:
                raise
            continue
        sock.listen(128)
        sock.setblocking(False)
        return sock, fell_back
    raise AssertionError("unreachable")


class _QuietServer(uvicorn.Server):
    """uvicorn that leaves signals to us: uvicorn 0.54 installs its own handlers and re-raises the signal
    after serve() returns, which would skip our shutdown (landing) and exit with the signal."""

    @contextlib.contextmanager
    def capture_signals(self):  # type: ignore[override]
        yield


@dataclass(frozen=True)
class Urls:
    """Where the operator finds the ground station: the landing page/API and the 3-D page (served by the same
    front at /operator/; viser itself listens on 127.0.0.1 only)."""

    api: str
    operator: str
    api_fell_back: bool = False
    viser_fell_back: bool = False


def url_host(host: str) -> str:
    """The host to print in a URL for a bind address (0.0.0.0 and :: mean this machine)."""
    return "127.0.0.1" if host in ("0.0.0.0", "", "::") else host


async def serve_station(
    station,
    *,
    host: str = "127.0.0.1",
    port: int = 8000,
    viser_port: int = 8080,
    speed: float = 1.0,
    frame_period_s: float = 0.1,
    stop: asyncio.Event | None = None,
    on_ready: Callable[[Urls, object], None] | None = None,
    handle_signals: bool = True,
    gate=None,
    ssl_certfile: str | None = None,
    ssl_keyfile: str | None = None,
) -> PaceStats:
    """Run the ground station (viser page, FastAPI app, paced control ticks) until `stop` is set or
    SIGINT/SIGTERM arrives; then land every MAV and close the back-ends. Returns how the run kept up with
    real time.

    `station` is a `server.station.ground_station.GroundStation` over any list of autopilots (the embedded
    simulation or PX4 vehicles). on_ready(urls, ui) is called once when both servers listen (ui: the
    `webui.app.OperatorUi`, for callers that inspect the scene). gate: sign-in and origin rules
    (`server.station.api.gate.Gate`; default: open mode, allowed on loopback only); ssl_certfile /
    ssl_keyfile: serve HTTPS and WSS (PEM files).
    """
    from server.station.api.app import create_app  # FastAPI/viser load only when serving
    from server.station.api.gate import LOOPBACK_NAMES, Gate
    from server.station.api.operator_page import TicketAccess
    from webui.app import OperatorUi

    gate = gate or Gate(None, secure=ssl_certfile is not None)
    if gate.open and host not in LOOPBACK_NAMES:
        raise ValueError(
            f"listening on {host} needs sign-in: give a users file (--users FILE, or SKYRING_USERS_FILE / "
            "SKYRING_USERS); without one the station listens on 127.0.0.1 only"
        )

    stop = stop or asyncio.Event()
    loop = asyncio.get_running_loop()
    installed: list[int] = []
    if handle_signals and threading.current_thread() is threading.main_thread():
        for sig in (signal.SIGINT, signal.SIGTERM):
            loop.add_signal_handler(sig, stop.set)
            installed.append(sig)
    ui = None
    server = None
    serve_task = None
    try:
        access = TicketAccess(gate)
        ui = OperatorUi(
            actions=station, initial=station.scene_view(), host="127.0.0.1", port=viser_port, access=access
        )
        sock, api_fell_back = bind_port(host, port)
        app = create_app(station, viser_port=ui.port, gate=gate, access=access)
        config = uvicorn.Config(
            app,
            log_level="warning",
            lifespan="off",
            ws="websockets-sansio",
            ws_max_size=1 << 20,
            ssl_certfile=ssl_certfile,
            ssl_keyfile=ssl_keyfile,
        )
        server = _QuietServer(config)
        serve_task = asyncio.create_task(server.serve(sockets=[sock]))
        while not server.started:
            if serve_task.done():
                serve_task.result()
            await asyncio.sleep(0.02)
        api_port = sock.getsockname()[1]
        scheme = "https" if ssl_certfile else "http"
        urls = Urls(
            api=f"{scheme}://{url_host(host)}:{api_port}/",
            operator=f"{scheme}://{url_host(host)}:{api_port}/operator/",
            api_fell_back=api_fell_back,
            viser_fell_back=viser_port not in (0, ui.port),
        )
        if on_ready is not None:
            on_ready(urls, ui)
        runner = LiveRunner(station=station, speed=speed)
        control = ControlThread(runner)
        control.start()
        frames_task = asyncio.create_task(
            _publish_frames(lambda: _publish(station, runner, ui), frame_period_s, stop, control)
        )
        stop_task = asyncio.create_task(stop.wait())
        await asyncio.wait({frames_task, serve_task, stop_task}, return_when=asyncio.FIRST_COMPLETED)
        stop.set()
        await asyncio.to_thread(control.stop)
        await frames_task
        stop_task.cancel()
        if control.error is not None:
            raise control.error
        failed = serve_task.exception() if serve_task.done() and not serve_task.cancelled() else None
        if failed is not None:
            raise failed
        return runner.stats
    finally:
        for sig in installed:
            loop.remove_signal_handler(sig)
        try:
            station.shutdown()
        finally:
            if server is not None:
                server.should_exit = True
            if serve_task is not None:
                with contextlib.suppress(Exception, asyncio.CancelledError):
                    await asyncio.wait_for(serve_task, timeout=5.0)
            if ui is not None:
                ui.stop()

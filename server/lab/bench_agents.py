"""`skyring bench agents`: does web load reach the agents' control loops? (It should not.)

The one-laptop rehearsal (`serve --agents spawn`, 3 MAVs, agents at 20 Hz) runs for a warm-up, then the
agents' tick-period jitter (the 99th percentile of |period - nominal| over the last 10 s, as each agent
reports it) is read once after 10 s without web load and once after 10 s with 50 WebSocket clients on /ws and
ten 10 MB request bodies sent to the API. Twice: with the agents' control loops under the normal scheduler,
and under SCHED_FIFO (`--realtime-priority`, as on a companion computer; where the system refuses it, the
agents log why and the second rehearsal measures the normal scheduler again). Plain asyncio sockets play the
clients, so the bench needs nothing beyond the runtime dependencies.
"""

from __future__ import annotations

import asyncio
import threading
import time

from server.station.agents_mode import build_spawn_station
from server.station.live import Urls, serve_station
from vehicles.net import realtime

VEHICLES = 3
WINDOW_S = 10.0
WARMUP_S = 25.0
CLIENTS = 50
BODIES = 10
BODY_BYTES = 10 * 1024 * 1024


async def _websocket_client(host: str, port: int, stop: asyncio.Event) -> int:
    """A WebSocket client on /ws that reads everything it is sent until stop; returns the bytes read."""
    reader, writer = await asyncio.open_connection(host, port)
    writer.write(
        f"GET /ws HTTP/1.1\r\nHost: {host}:{port}\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
        "Sec-WebSocket-Key: c2t5cmluZy1iZW5jaC0xMg==\r\nSec-WebSocket-Version: 13\r\n\r\n".encode()
    )
    await writer.drain()
    got = 0
    while not stop.is_set():
        try:
            chunk = await asyncio.wait_for(reader.read(65536), timeout=0.5)
        except TimeoutError:
            continue
        if not chunk:
            break
        got += len(chunk)
    writer.close()
    return got


async def _big_request(host: str, port: int) -> str:
    """PUT a 10 MB body to /api/formation; returns the status line."""
    reader, writer = await asyncio.open_connection(host, port)
    writer.write(
        f"PUT /api/formation HTTP/1.1\r\nHost: {host}:{port}\r\nContent-Type: application/json\r\n"
        f"Content-Length: {BODY_BYTES}\r\nConnection: close\r\n\r\n".encode()
    )
    chunk = b" " * 65536
    try:
        for _ in range(BODY_BYTES // len(chunk)):
            writer.write(chunk)
            await writer.drain()
        status = (await asyncio.wait_for(reader.readline(), timeout=60.0)).decode().strip()
    except (ConnectionError, TimeoutError) as exc:
        status = f"connection ended: {type(exc).__name__}"
    writer.close()
    return status


async def _load(host: str, port: int) -> list[str]:
    stop = asyncio.Event()
    clients = [asyncio.create_task(_websocket_client(host, port, stop)) for _ in range(CLIENTS)]
    started = time.monotonic()
    statuses = await asyncio.gather(*(_big_request(host, port) for _ in range(BODIES)))
    await asyncio.sleep(max(0.0, WINDOW_S - (time.monotonic() - started)))
    stop.set()
    await asyncio.gather(*clients, return_exceptions=True)
    return list(statuses)


def _jitter_ms(agents) -> list[float]:
    out = []
    for v in agents.station.snapshot().vehicles:
        p99 = v.agent.tick_period_p99_error_s if v.agent is not None else None
        out.append(float("nan") if p99 is None else p99 * 1e3)
    return out


REALTIME_PRIORITY = 10


def run(*, repeats: int) -> None:
    """Two rehearsals (normal scheduler, SCHED_FIFO): jitter without and with web load (repeats is not
    used: the windows are fixed)."""
    print(
        f"agents: {VEHICLES} agent processes at 20 Hz (rehearsal); tick period p99 |error| over "
        f"{WINDOW_S:g} s windows, per agent"
    )
    for priority in (0, REALTIME_PRIORITY):
        print(f"  control loops: {realtime.describe(priority)}")
        _rehearsal(priority)
    print("  target: within 2 ms of nominal at p99")


def _rehearsal(realtime_priority: int) -> None:
    """One rehearsal with the agents at this real-time priority: prints the jitter without and with load."""
    agents = build_spawn_station(
        vehicles=VEHICLES,
        seed=1,
        trees="paper",
        person="paper",
        agent_realtime_priority=realtime_priority,
    )
    box: dict[str, Urls] = {}
    ready = threading.Event()
    loop = asyncio.new_event_loop()
    stop = asyncio.Event()

    def on_ready(urls: Urls, _ui: object) -> None:
        box.update(urls=urls)
        ready.set()

    def serve() -> None:
        asyncio.set_event_loop(loop)
        loop.run_until_complete(
            serve_station(
                agents.station,
                port=0,
                viser_port=0,
                stop=stop,
                handle_signals=False,
                on_ready=on_ready,
            )
        )
        loop.close()

    thread = threading.Thread(target=serve, daemon=True)
    thread.start()
    try:
        ready.wait(30.0)
        url = box["urls"].api.rstrip("/").removeprefix("http://")
        host, port = url.rsplit(":", 1)
        time.sleep(WARMUP_S + WINDOW_S)
        idle = _jitter_ms(agents)
        statuses = asyncio.run(_load(host, int(port)))
        loaded = _jitter_ms(agents)
        print(f"    no web load:                        {'  '.join(f'{x:6.2f} ms' for x in idle)}")
        print(
            f"    {CLIENTS} WebSocket clients + {BODIES} x 10 MB: {'  '.join(f'{x:6.2f} ms' for x in loaded)}"
            f"   (answers: {', '.join(sorted(set(statuses)))})"
        )
    finally:
        loop.call_soon_threadsafe(stop.set)
        thread.join(20.0)
        agents.close()

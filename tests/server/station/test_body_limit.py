"""Request bodies are capped at 64 KiB: a 20 MB body gets 413 (the client receives it) and the station process
does not grow by more than 50 MB (measured on a real `skyring serve` process, with and without a declared
length)."""

from __future__ import annotations

import signal
from pathlib import Path

import httpx
from serve_process import start_serve
from starlette.types import Message, Receive, Scope, Send

from server.station.api.gate import Gate
from server.station.api.guard import DRAIN_LIMIT_BYTES, Guard

BODY_BYTES = 20 * 1024 * 1024


def rss_bytes(pid: int) -> int:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) * 1024
    raise AssertionError("no VmRSS")


def test_a_20_mb_body_gets_413_and_the_process_grows_by_less_than_50_mb():
    proc, api = start_serve("--no-log")
    try:
        assert httpx.get(f"{api}api/state", timeout=10).status_code == 200
        before = rss_bytes(proc.pid)
        body = b"{" + b" " * (BODY_BYTES - 2) + b"}"
        declared = httpx.post(
            f"{api}api/obstacles", content=body, headers={"content-type": "application/json"}, timeout=30
        )

        def chunks():
            for i in range(0, BODY_BYTES, 1 << 20):
                yield body[i : i + (1 << 20)]

        streamed = httpx.post(f"{api}api/land_all", content=chunks(), timeout=30)
        grown = rss_bytes(proc.pid) - before
        state = httpx.get(f"{api}api/state", timeout=10).json()
    finally:
        proc.send_signal(signal.SIGINT)
        proc.communicate(timeout=60)
    assert declared.status_code == 413 and "larger than 65536 bytes" in declared.json()["detail"]
    assert streamed.status_code == 413  # the client gets the answer, not a reset connection
    assert grown < 50 * 1024 * 1024, f"grew by {grown / 1e6:.1f} MB"
    assert all(v["phase"] != "landing" for v in state["vehicles"])  # nothing was commanded


async def _guarded_post(declared_bytes: int, chunk_bytes: int = 1 << 20) -> tuple[int, int, bool]:
    """POST `declared_bytes` through the Guard alone: (status, body bytes it read, whether the app ran)."""
    reached = False

    async def app(scope: Scope, receive: Receive, send: Send) -> None:
        nonlocal reached
        reached = True

    sent = 0

    async def receive() -> Message:
        nonlocal sent
        n = min(chunk_bytes, declared_bytes - sent)
        sent += n
        return {"type": "http.request", "body": b"x" * n, "more_body": sent < declared_bytes}

    answer: list[Message] = []

    async def send(message: Message) -> None:
        answer.append(message)

    guard = Guard(app, gate=Gate(None), on_refused=lambda *_: None)
    scope: Scope = {
        "type": "http",
        "method": "POST",
        "path": "/api/land_all",
        "scheme": "http",
        "headers": [(b"host", b"127.0.0.1:8000"), (b"content-length", str(declared_bytes).encode())],
    }
    await guard(scope, receive, send)
    return answer[0]["status"], sent, reached


async def test_an_oversized_body_is_read_and_dropped_before_the_413_up_to_the_drain_limit():
    status, read, reached = await _guarded_post(5 * 1024 * 1024)
    assert (status, read, reached) == (413, 5 * 1024 * 1024, False)


async def test_a_body_declared_beyond_the_drain_limit_is_answered_without_reading_it():
    status, read, reached = await _guarded_post(DRAIN_LIMIT_BYTES + 1)
    assert (status, read, reached) == (413, 0, False)

"""Request bodies are capped at 64 KiB: a 20 MB body gets 413 and the station process does not grow by more
than 50 MB (measured on a real `skyring serve` process, with and without a declared length)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from pathlib import Path

import httpx

ROOT = Path(__file__).resolve().parents[3]
BODY_BYTES = 20 * 1024 * 1024


def rss_bytes(pid: int) -> int:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) * 1024
    raise AssertionError("no VmRSS")


def test_a_20_mb_body_gets_413_and_the_process_grows_by_less_than_50_mb():
    proc = subprocess.Popen(
        [sys.executable, "-m", "server.cli", "serve", "--port", "0", "--rate", "20", "--no-log"],
        cwd=ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        env={**os.environ, "PYTHONUNBUFFERED": "1"},
    )
    try:
        seen = ""
        assert proc.stdout is not None
        for line in proc.stdout:
            seen += line
            if line.startswith("Ctrl-C"):
                break
        api = next(w for w in seen.split() if w.startswith("http://127.0.0.1:") and w.endswith("/"))
        assert httpx.get(f"{api}api/state", timeout=10).status_code == 200
        before = rss_bytes(proc.pid)
        body = b"{" + b" " * (BODY_BYTES - 2) + b"}"
        declared = httpx.post(
            f"{api}api/obstacles", content=body, headers={"content-type": "application/json"}, timeout=30
        )

        offered = 0

        def chunks():
            nonlocal offered
            for i in range(0, BODY_BYTES, 1 << 20):
                offered += 1 << 20
                yield body[i : i + (1 << 20)]

        try:
            streamed = httpx.post(f"{api}api/land_all", content=chunks(), timeout=30).status_code
        except httpx.HTTPError:  # the station answered and closed while the client was still sending:
            streamed = None  # it stopped reading (checked below), the answer was lost with the connection
        grown = rss_bytes(proc.pid) - before
        state = httpx.get(f"{api}api/state", timeout=10).json()
    finally:
        proc.send_signal(signal.SIGINT)
        proc.communicate(timeout=60)
    assert declared.status_code == 413 and "larger than 65536 bytes" in declared.json()["detail"]
    assert streamed == 413 or (streamed is None and offered < BODY_BYTES)
    assert grown < 50 * 1024 * 1024, f"grew by {grown / 1e6:.1f} MB"
    assert all(v["phase"] != "landing" for v in state["vehicles"])  # nothing was commanded

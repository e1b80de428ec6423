"""`skyring serve` as a user runs it: URLs printed and working, a busy port announced, Ctrl-C handled."""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import httpx
import pytest

from server.station.live import bind_port

pytestmark = pytest.mark.e2e  # starts `skyring serve` as a process and talks to it over HTTP

ROOT = Path(__file__).resolve().parents[3]


def start_serve(*args: str) -> subprocess.Popen:
    command = [sys.executable, "-m", "server.cli", "serve", "--viser-port", "0", "--no-log", *args]
    return subprocess.Popen(
        command,
        cwd=ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        env={**os.environ, "PYTHONUNBUFFERED": "1"},
    )


def read_until(proc: subprocess.Popen, pattern: str, *, timeout_s: float) -> tuple[re.Match, str]:
    """Read the command's output until a line matches; fail after timeout_s."""
    seen = ""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        assert proc.stdout is not None
        line = proc.stdout.readline()
        if not line:
            break
        seen += line
        match = re.search(pattern, line)
        if match:
            return match, seen
    pytest.fail(f"no line matching {pattern!r} within {timeout_s} s; output so far:\n{seen}")


def stop(proc: subprocess.Popen) -> tuple[int, str]:
    proc.send_signal(signal.SIGINT)
    out, _ = proc.communicate(timeout=30)
    return proc.returncode, out


def test_serve_prints_working_urls_and_stops_cleanly_on_ctrl_c():
    proc = start_serve("--port", "0", "--speed", "2")
    try:
        operator, _ = read_until(proc, r"operator view:\s+(http://\S+)", timeout_s=60)
        api, _ = read_until(proc, r"API and docs:\s+(http://\S+/)", timeout_s=10)
        assert "skyring ground station" in httpx.get(api.group(1), timeout=10).text
        state = httpx.get(f"{api.group(1)}api/state", timeout=10).json()
        assert [v["vehicle_id"] for v in state["vehicles"]] == [1, 2, 3]
        assert httpx.get(operator.group(1), timeout=10).status_code == 200
    finally:
        code, out = stop(proc)
    assert code == 0, out
    assert re.search(r"stopped after \d+ control ticks", out)


def test_serve_uses_a_free_port_when_the_api_port_is_busy_and_says_so():
    taken, _ = bind_port("127.0.0.1", 0)
    port = taken.getsockname()[1]
    proc = start_serve("--port", str(port))
    try:
        busy, _ = read_until(proc, rf"port {port} is busy: the API uses (http://\S+) instead", timeout_s=60)
        assert f":{port}/" not in busy.group(1)
        assert httpx.get(f"{busy.group(1)}api/formation", timeout=10).status_code == 200
    finally:
        stop(proc)
        taken.close()


@pytest.mark.parametrize(
    ("args", "option"),
    [(["--vehicles", "0"], "--vehicles"), (["--speed", "-1"], "--speed"), (["--trees", "lots"], "--trees")],
)
def test_serve_refuses_bad_arguments_with_a_message_naming_them(args, option):
    proc = start_serve(*args)
    out, _ = proc.communicate(timeout=60)
    assert proc.returncode != 0
    assert option in out

"""`skyring serve` as a user runs it: URLs printed and working, a busy port announced, Ctrl-C handled."""

from __future__ import annotations

import asyncio
import json
import os
import re
import signal
import struct
import subprocess
import sys
import time
from pathlib import Path

import httpx
import pytest
import websockets
from websockets.typing import Subprotocol

from server.station.api.users import user_line
from server.station.live import bind_port
from webui.access import Role

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
    assert proc.stdout is not None
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


def test_serve_refuses_to_listen_beyond_loopback_without_a_users_file():
    env_without_users = {k: v for k, v in os.environ.items() if not k.startswith("SKYRING_USERS")}
    proc = subprocess.Popen(
        [sys.executable, "-m", "server.cli", "serve", "--host", "0.0.0.0", "--port", "0", "--no-log"],
        cwd=ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        env=env_without_users,
    )
    out, _ = proc.communicate(timeout=60)
    assert proc.returncode != 0
    assert "needs sign-in" in out and "--users" in out
    assert "operator view" not in out  # refused before anything listens or flies


def test_serve_with_a_users_file_requires_sign_in_on_every_surface(tmp_path):
    users = tmp_path / "users.txt"
    users.write_text(user_line("carol", Role.OPERATOR, "carol-secret-3") + "\n")
    proc = start_serve("--port", "0", "--users", str(users))
    try:
        api, _ = read_until(proc, r"API and docs:\s+(http://\S+/)", timeout_s=60)
        required, _ = read_until(proc, r"sign-in:\s+(.*)", timeout_s=10)
        base = api.group(1)
        assert required.group(1).startswith("required")
        assert httpx.get(f"{base}api/state", timeout=10).status_code == 401
        assert httpx.post(f"{base}api/land_all", timeout=10).status_code == 401
        assert httpx.get(f"{base}operator/", timeout=10, follow_redirects=False).status_code == 303
        signed = httpx.post(
            f"{base}auth/login", json={"name": "carol", "secret": "carol-secret-3"}, timeout=10
        )
        token = signed.json()["token"]
        state = httpx.get(f"{base}api/state", headers={"authorization": f"Bearer {token}"}, timeout=10)
        assert state.status_code == 200 and len(state.json()["vehicles"]) == 3
    finally:
        code, out = stop(proc)
    assert code == 0, out
    assert "carol-secret-3" not in out


def test_serve_foxglove_streams_the_flight_log_channels_on_loopback():
    proc = start_serve("--port", "0", "--speed", "2", "--foxglove", "0")
    try:
        fox, _ = read_until(proc, r"foxglove:\s+ws://127\.0\.0\.1:(\d+)", timeout_s=60)
        _, announced = read_until(proc, r"^Ctrl-C", timeout_s=30)
        topics, frame = asyncio.run(foxglove_state(int(fox.group(1))))
    finally:
        code, out = stop(proc)
    assert code == 0, out
    assert topics == {
        "/scene": "foxglove.SceneUpdate",
        "/skyring/state": "skyring.SceneView",
        "/skyring/audit": "skyring.AuditRecord",
        "/skyring/header": "skyring.LogHeader",
        "/skyring/end": "skyring.LogEnd",
    }
    assert [v["vehicle_id"] for v in frame["vehicles"]] == [1, 2, 3]
    assert "flight log:     off" in announced  # --no-log: published live, nothing written


async def foxglove_state(port: int) -> tuple[dict[str, str], dict]:
    """Connect as a Foxglove client (the SDK's WebSocket protocol), list the advertised channels and subscribe
    to /skyring/state: (topic -> schema name, the first state message)."""
    async with websockets.connect(
        f"ws://127.0.0.1:{port}", subprotocols=[Subprotocol("foxglove.sdk.v1")]
    ) as ws:
        channels: dict[str, dict] = {}
        while "/skyring/state" not in channels or len(channels) < 5:
            message = await asyncio.wait_for(ws.recv(), 30)
            if isinstance(message, str) and json.loads(message)["op"] == "advertise":
                channels.update({c["topic"]: c for c in json.loads(message)["channels"]})
        subscribe = {"id": 1, "channelId": channels["/skyring/state"]["id"]}
        await ws.send(json.dumps({"op": "subscribe", "subscriptions": [subscribe]}))
        while True:
            message = await asyncio.wait_for(ws.recv(), 30)
            if isinstance(message, bytes) and message[0] == 1:  # message data: op, subscription, log time
                op, subscription, _log_time_ns = struct.unpack_from("<BIQ", message)
                assert subscription == 1
                frame = json.loads(message[13:])
                break
    return {topic: c["schemaName"] for topic, c in channels.items()}, frame

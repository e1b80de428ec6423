"""End to end on 127.0.0.1: `skyring detect --camera vtest.avi` and a `skyring agent` (flying a PX4 test peer
over real MAVLink/UDP) talk over real Zenoh; the agent converts the camera's pixel detections with its own
pose, fuses them, and its state message shows it, with the capture-to-conversion latency.

The calibration says what vtest.avi's camera is (768 x 576, f = 800 px, 30 degrees down, 8 m above the body
origin: the footage was filmed from a raised position and the peer's vehicle stands on the ground), so the
detections become plausible world positions 10-30 m in front of the vehicle.
"""

from __future__ import annotations

import math
import subprocess
import sys
import threading
import time

import numpy as np
import pytest
from detect_footage import footage
from px4_peer import Px4Peer, free_udp_port

from vehicles.detect.calibration import Calibration, mount_rotation
from vehicles.net.ports import free_port

pytestmark = [pytest.mark.e2e, pytest.mark.slow]

ORIGIN = "47.397742,8.545594,488.0"


def _vtest_calibration(path) -> None:
    Calibration(
        width_px=768,
        height_px=576,
        camera_matrix=np.array([[800.0, 0.0, 383.5], [0.0, 800.0, 287.5], [0.0, 0.0, 1.0]]),
        distortion=np.zeros(5),
        camera_to_body_rotation=mount_rotation(math.radians(30.0)),
        camera_to_body_translation_m=np.array([0.0, 0.0, 8.0]),
    ).save(path)


DETECT_FOR_S = 150
"""How long `skyring detect` runs and the test waits for the counts. It stops waiting once they are reached
(the whole test takes 17 s on an idle 2-core machine). With the CPU starved (2026-12-07: the parallel suite
and two more simulations on 2 cores) the detector made 25 detections in 60 s, below the 30 asked, and the
test failed on the detector's exit, not on anything it checks."""


def test_detections_from_skyring_detect_are_fused_by_the_agent_over_zenoh(tmp_path):
    from vehicles.net import wire
    from vehicles.net.guard import Received
    from vehicles.net.keys import agent_key
    from vehicles.net.session import Bus, NetConfig

    video = footage("vtest.avi")
    calibration = tmp_path / "vtest.yaml"
    _vtest_calibration(calibration)
    team = f"det{int(time.time() * 1000) % 1_000_000}"
    udp = free_udp_port()
    agent_port = free_port()
    endpoint = f"tcp/127.0.0.1:{agent_port}"
    peer = Px4Peer(gcs_port=udp, system_id=1).start()
    logs = {name: open(tmp_path / f"{name}.log", "w") for name in ("agent", "detect")}  # noqa: SIM115
    agent = subprocess.Popen(
        [
            sys.executable, "-m", "server.cli", "agent", "--id", "1", "--px4", f"udpin://127.0.0.1:{udp}",
            "--team", team, "--team-size", "1", "--no-multicast", "--listen", endpoint,
            "--origin", ORIGIN, "--rate", "20", "--calibration", str(calibration),
        ],
        stdout=logs["agent"], stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
    )  # fmt: skip
    detect = None
    states: list[wire.StateBody] = []
    lock = threading.Lock()

    def on_state(msg: Received) -> None:
        assert isinstance(msg.body, wire.StateBody)
        with lock:
            states.append(msg.body)

    bus = Bus(
        NetConfig(team=team, connect=(endpoint,), multicast_scouting=False),
        sender=0,
        is_member=lambda s: s == 1,
    )
    try:
        bus.subscribe(agent_key(team, 1, "state"), on_state)
        deadline = time.time() + 90
        while time.time() < deadline and not states:
            time.sleep(0.2)
        assert states, "the agent published no state within 90 s"
        detect = subprocess.Popen(
            [
                sys.executable, "-m", "server.cli", "detect", "--id", "1", "--camera", str(video),
                "--calibration", str(calibration), "--team", team, "--no-multicast", "--connect", endpoint,
                "--duration", str(DETECT_FOR_S),
            ],
            stdout=logs["detect"], stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
        )  # fmt: skip
        deadline = time.time() + DETECT_FOR_S
        last = states[-1]
        while time.time() < deadline:
            with lock:
                last = states[-1]
            if last.camera.get("converted", 0) >= 30 and last.counters.get("own_detections_fused", 0) >= 20:
                break
            assert detect.poll() is None, (tmp_path / "detect.log").read_text()[-2000:]
            time.sleep(0.5)
        print(f"agent camera counts: {last.camera}, counters: {last.counters}")
        assert last.camera.get("converted", 0) >= 30, (
            last.camera,
            (tmp_path / "detect.log").read_text()[-2000:],
        )
        assert last.counters.get("own_detections_fused", 0) >= 20
        latency_ms = last.camera["latency_p50_ms"]
        assert 0 < latency_ms < 1000  # capture to conversion, median of the last 200
        assert last.person is not None  # the agent's fused estimate of the person
    finally:
        for proc in (detect, agent):
            if proc is not None and proc.poll() is None:
                proc.terminate()
        for proc in (detect, agent):
            if proc is not None:
                try:
                    proc.wait(20)
                except subprocess.TimeoutExpired:
                    proc.kill()
                    proc.wait(5)
        bus.close()
        peer.stop()
        for f in logs.values():
            f.close()

"""Harness for the end-to-end tests of onboard agents: K PX4 test peers (real MAVLink over UDP), K
`skyring agent` processes (each flying its own peer through MAVSDK) and a `skyring serve --agents zenoh`
process, all on Zenoh over 127.0.0.1 with multicast scouting off and free ports; every process is started
and stopped (or killed with SIGKILL) by the test."""

from __future__ import annotations

import math
import os
import signal
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import httpx
import numpy as np
from px4_peer import PeerMode, Px4Peer, free_udp_port
from serve_process import UNBUFFERED, printed_api_url

from server.lab.metrics import spacing_error_deg
from vehicles.net.ports import free_port
from vehicles.px4.geodesy import GeodeticPoint, geodetic_to_enu

REF = GeodeticPoint(47.397742, 8.545594, 488.0)
D_DES_M = 8.0
ORIGIN = f"{REF.latitude_deg},{REF.longitude_deg},{REF.altitude_m}"
# Quick climbs and landings; COM_FAIL_ACT_T stays PX4's 5 s, so an offboard-loss landing starts >= 6 s after
# the set-points stop (COM_OF_LOSS_T 1 s + 5 s of Hold) and a landing seen sooner came from a command.
FAST = {"MPC_TKO_SPEED": 3.0, "MPC_LAND_SPEED": 2.0, "COM_DISARM_LAND": 0.5}


def ring_home(i: int, k: int) -> tuple[tuple[float, float, float], float]:
    bearing = -math.pi / 2 + 2 * math.pi * i / k
    e, n = D_DES_M * math.cos(bearing), D_DES_M * math.sin(bearing)
    lat = REF.latitude_deg + n / 111_195.0
    lon = REF.longitude_deg + e / (111_195.0 * math.cos(math.radians(REF.latitude_deg)))
    return (lat, lon, REF.altitude_m), math.atan2(-e, -n)


@dataclass
class Team:
    """The processes of one end-to-end run and the helpers to watch them."""

    k: int
    logs: Path
    station_timeout_s: float = 6.0
    team: str = field(default_factory=lambda: f"e2e{os.getpid()}x{time.monotonic_ns() % 100000}")
    peers: list[Px4Peer] = field(default_factory=list)
    agents: list[subprocess.Popen | None] = field(default_factory=list)
    station: subprocess.Popen | None = None
    station_endpoint: str = ""
    agent_ports: list[int] = field(default_factory=list)
    agent_udp: list[int] = field(default_factory=list)
    station_udp: list[int] = field(default_factory=list)
    _station_starts: int = 0
    _api: str = ""  # the newest station's printed API URL, once read (`api`)

    def start(self) -> Team:
        self.station_endpoint = f"tcp/127.0.0.1:{free_port()}"
        self.agent_udp = [free_udp_port() for _ in range(self.k)]
        self.station_udp = [free_udp_port() for _ in range(self.k)]
        for i in range(self.k):
            home, yaw = ring_home(i, self.k)
            self.peers.append(
                Px4Peer(
                    gcs_port=self.agent_udp[i],
                    extra_gcs_ports=(self.station_udp[i],),
                    system_id=i + 1,
                    home=home,
                    start_yaw_ned_rad=yaw,
                    params=FAST,
                ).start()
            )
        self.start_station()
        self.agent_ports = [free_port() for _ in range(self.k)]
        for i in range(self.k):
            self.agents.append(self._spawn_agent(i))
        return self

    def _spawn_agent(self, i: int) -> subprocess.Popen:
        own = f"tcp/127.0.0.1:{self.agent_ports[i]}"
        others = [f"tcp/127.0.0.1:{p}" for j, p in enumerate(self.agent_ports) if j < i]
        cmd = [
            sys.executable, "-m", "server.cli", "agent", "--id", str(i + 1),
            "--px4", f"udpin://127.0.0.1:{self.agent_udp[i]}",
            "--team", self.team, "--team-size", str(self.k), "--no-multicast",
            "--listen", own, "--connect", self.station_endpoint,
            *[a for e in others for a in ("--connect", e)],
            "--origin", ORIGIN, "--emulate-camera", "still", "--rate", "20",
            "--station-timeout", f"{self.station_timeout_s:g}",
        ]  # fmt: skip
        return self._popen(cmd, f"agent{i + 1}")

    def start_station(self) -> None:
        self._station_starts += 1
        listen = self.station_endpoint
        cmd = [
            sys.executable, "-m", "server.cli", "serve", "--agents", "zenoh", "--team", self.team,
            "--no-multicast", "--listen", listen,
            *[a for p in self.agent_ports for a in ("--connect", f"tcp/127.0.0.1:{p}")],
            "--px4", ",".join(f"udpin://127.0.0.1:{p}" for p in self.station_udp),
            "--origin", ORIGIN, "--trees", "none", "--person", "still",
            "--host", "127.0.0.1", "--port", "0", "--viser-port", "0", "--no-log",
        ]  # fmt: skip
        self.station = self._popen(cmd, f"station{self._station_starts}")
        self._api = ""

    @property
    def api(self) -> str:
        """The newest station's API URL as it printed it; "" while it has not (its state() is then None).
        Read from its log until found, then kept: state() is polled several times a second."""
        if not self._api:
            self._api = printed_api_url(self.logs / f"station{self._station_starts}.log") or ""
        return self._api

    def _popen(self, cmd: list[str], name: str) -> subprocess.Popen:
        out = open(self.logs / f"{name}.log", "w")  # noqa: SIM115 - closed with the process
        return subprocess.Popen(
            cmd, stdout=out, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL, env=UNBUFFERED
        )

    def kill_agent(self, i: int) -> None:
        proc = self.agents[i]
        assert proc is not None
        proc.send_signal(signal.SIGKILL)
        proc.wait(5.0)

    def kill_station(self) -> None:
        assert self.station is not None
        self.station.send_signal(signal.SIGKILL)
        self.station.wait(5.0)

    def stop(self) -> None:
        for proc in [self.station, *self.agents]:
            if proc is not None and proc.poll() is None:
                proc.terminate()
        for proc in [self.station, *self.agents]:
            if proc is not None:
                try:
                    proc.wait(10.0)
                except subprocess.TimeoutExpired:
                    proc.kill()
                    proc.wait(5.0)
        for peer in self.peers:
            peer.stop()

    # ---- observing ----------------------------------------------------------------------------------------
    def state(self, timeout_s: float = 2.0) -> dict | None:
        """GET /api/state, or None while the station does not answer."""
        if not self.api:
            return None
        try:
            return httpx.get(f"{self.api}/api/state", timeout=timeout_s).json()
        except (httpx.HTTPError, ValueError):
            return None

    def truth_xyz(self, indices=None) -> np.ndarray:
        peers = [self.peers[i] for i in (indices if indices is not None else range(self.k))]
        return np.array([geodetic_to_enu(GeodeticPoint(*p.geodetic()), reference=REF) for p in peers])

    def in_formation(self, indices, *, d_des_m: float = D_DES_M, tol_deg: float = 10.0) -> bool:
        """The peers `indices` all airborne in offboard, evenly spaced about the person (at the origin) within
        tol_deg, each d_des from it within 1 m."""
        peers = [self.peers[i] for i in indices]
        if not all(p.mode is PeerMode.OFFBOARD and not p.landed for p in peers):
            return False
        xyz = self.truth_xyz(indices)
        distances = np.hypot(xyz[:, 0], xyz[:, 1])
        spacing = spacing_error_deg(positions_xy_m=xyz[:, :2], person_xy_m=np.zeros(2))
        return spacing < tol_deg and bool(np.all(np.abs(distances - d_des_m) < 1.0))

    def spacing_deg(self, indices) -> float:
        xyz = self.truth_xyz(indices)
        return spacing_error_deg(positions_xy_m=xyz[:, :2], person_xy_m=np.zeros(2))


def wait_until(condition, *, timeout_s: float, what: str, every=None, poll_s: float = 0.1) -> float:
    """Seconds until condition() held; AssertionError after timeout_s."""
    t0 = time.monotonic()
    while True:
        if every is not None:
            every()
        if condition():
            return time.monotonic() - t0
        if time.monotonic() - t0 > timeout_s:
            raise AssertionError(f"{what} did not happen within {timeout_s} s")
        time.sleep(poll_s)

"""PX4 vehicles for end-to-end scenarios, and `skyring serve --px4` run against them in its own process.

Two kinds of team answer the same questions (where is each vehicle really, which mode does PX4 show, is it in
a failsafe, did it say something):
- `PeerTeam`: `Px4Peer` MAVLink peers (tests/px4_peer.py) in this process, over real UDP on 127.0.0.1;
- `SitlTeam`: real PX4 SITL instances (SIH quadrotor, airframe 10040), one process each, started from the
  binary given in PX4_SITL, each in its own temporary working directory and stopped by its pid. PX4 numbers
  its ports by instance (14540 + i for the API link, 14550 for the GCS link); the team gives each instance
  free ports instead, through PX4's own startup file for its MAVLink links (etc/init.d-posix/px4-rc.mavlink,
  in a copy of the build's etc folder per instance). The instance number itself (MAV_SYS_ID = i + 1, and
  PX4's lock file and shell socket under /tmp) is picked among those no running PX4 holds. The test listens
  to each instance's GCS link (it sends nothing there, so PX4 does not take it for a ground station) for the
  truth: position, mode, system status, STATUSTEXT.

`Station` runs `python -m server.cli serve --px4 ...` on free ports, reads its API, and can be stopped,
frozen (SIGSTOP) and killed (SIGKILL) by its pid like a real ground station.
"""

from __future__ import annotations

import contextlib
import fcntl
import math
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import httpx
import numpy as np
from px4_peer import PeerMode, Px4Peer, free_udp_port
from pymavlink.dialects.v20 import common as mavlink
from serve_process import UNBUFFERED, printed_api_url

from vehicles.px4.geodesy import GeodeticPoint, geodetic_to_enu

REF = GeodeticPoint(47.397742, 8.545594, 488.0)  # the team origin; the still person stands here
D_DES_M = 8.0  # the formation's default distance
REPO = Path(__file__).resolve().parents[1]

# PX4 custom main modes / AUTO sub-modes -> the names MAVSDK (and skyring's view) use.
_PX4_MODES = {
    (1, 0): "MANUAL",
    (2, 0): "ALTCTL",
    (3, 0): "POSCTL",
    (4, 1): "READY",
    (4, 2): "TAKEOFF",
    (4, 3): "HOLD",
    (4, 4): "MISSION",
    (4, 5): "RETURN_TO_LAUNCH",
    (4, 6): "LAND",
    (5, 0): "ACRO",
    (6, 0): "OFFBOARD",
    (7, 0): "STABILIZED",
}
_PEER_NAMES = {PeerMode.RTL: "RETURN_TO_LAUNCH", PeerMode.STABILIZED: "STABILIZED"}


def home_at(east_m: float, north_m: float) -> tuple[float, float, float]:
    """A geodetic spawn point east_m / north_m from REF (spherical approximation, fine within 100 m)."""
    lat = REF.latitude_deg + north_m / 111_195.0
    lon = REF.longitude_deg + east_m / (111_195.0 * math.cos(math.radians(REF.latitude_deg)))
    return lat, lon, REF.altitude_m


def ring_homes(k: int = 3, radius_m: float = D_DES_M) -> list[tuple[float, float, float]]:
    """k spawn points on a ring about the origin, the first due south."""
    out = []
    for i in range(k):
        bearing = -math.pi / 2 + 2 * math.pi * i / k
        out.append(home_at(radius_m * math.cos(bearing), radius_m * math.sin(bearing)))
    return out


@dataclass
class VehicleTruth:
    """One vehicle as the autopilot itself has it, on this process's monotonic clock."""

    enu_m: np.ndarray = field(default_factory=lambda: np.full(3, np.nan))
    mode: str = "UNKNOWN"
    armed: bool = False
    failsafe: bool = False
    system_status: str = "UNKNOWN"  # PX4's heartbeat: STANDBY (can arm), UNINIT (cannot), ACTIVE, CRITICAL
    texts: list[tuple[float, str]] = field(default_factory=list)


class Team:
    """What every team offers the scenarios. Subclasses fill `urls` and `truth()`."""

    urls: list[str]
    kind: str

    def truth(self) -> list[VehicleTruth]:
        raise NotImplementedError

    def positions(self) -> np.ndarray:
        """(K, 3) true ENU positions in the team frame about REF."""
        return np.array([t.enu_m for t in self.truth()])

    def modes(self) -> list[str]:
        return [t.mode for t in self.truth()]

    def airborne(self) -> list[bool]:
        """More than 1 m up (PX4's own altitude estimate drifts by tens of centimetres on the ground)."""
        return [bool(t.enu_m[2] > 1.0) for t in self.truth()]

    def on_ground_disarmed(self) -> list[bool]:
        return [bool(t.enu_m[2] < 1.0 and not t.armed) for t in self.truth()]

    def close(self) -> None:
        raise NotImplementedError


class PeerTeam(Team):
    """Px4Peer vehicles; params override PX4's defaults for all (e.g. a faster take-off), per_vehicle for
    one (1-based)."""

    kind = "peer"

    def __init__(
        self,
        homes: Sequence[tuple[float, float, float]],
        *,
        params: dict[str, float] | None = None,
        per_vehicle: dict[int, dict[str, float]] | None = None,
    ) -> None:
        self.peers: list[Px4Peer] = []
        self.urls = []
        for i, home in enumerate(homes):
            port = free_udp_port()
            merged = {**(params or {}), **(per_vehicle or {}).get(i + 1, {})}
            self.peers.append(Px4Peer(gcs_port=port, system_id=i + 1, home=home, params=merged).start())
            self.urls.append(f"udpin://127.0.0.1:{port}")

    def truth(self) -> list[VehicleTruth]:
        out = []
        for p in self.peers:
            mode = p.mode
            out.append(
                VehicleTruth(
                    enu_m=geodetic_to_enu(GeodeticPoint(*p.geodetic()), reference=REF),
                    mode=_PEER_NAMES.get(mode, mode.name),
                    armed=p.armed,
                    failsafe=p.failsafe,
                    texts=[(t + time.monotonic() - p.now(), text) for t, _, text in p.texts()],
                )
            )
        return out

    def close(self) -> None:
        for p in self.peers:
            p.stop()


_RC_MAVLINK = """#!/bin/sh
# Written by skyring's test harness: PX4's two MAVLink links on ports the test chose (free ones), instead of
# 18570 + i -> 14550 (GCS) and 14580 + i -> 14540 + i (API/offboard). Streams at PX4's default rates.
mavlink start -x -u {gcs_local} -r 4000000 -f -o {gcs_remote}
mavlink start -x -u {api_local} -r 4000000 -f -m onboard -o {api_remote}
"""


# PX4's console goes to a file; line-buffered, its lines arrive as PX4 prints them (stdbuf execs px4).
_LINE_BUFFERED = ["stdbuf", "-oL", "-eL"] if shutil.which("stdbuf") else []


def _instance_free(instance: int) -> bool:
    """No PX4 runs as `instance`: none holds its lock file (/tmp/px4_lock-N, locked while a PX4 server runs,
    removed when it exits) and nothing answers on its shell socket (/tmp/px4-sock-N; PX4 leaves it behind
    when killed, and a new server replaces it)."""
    lock = Path(f"/tmp/px4_lock-{instance}")
    if lock.exists():
        try:
            with open(lock, "a") as f:
                fcntl.lockf(f, fcntl.LOCK_EX | fcntl.LOCK_NB)
                fcntl.lockf(f, fcntl.LOCK_UN)
        except OSError:
            return False
    sock = Path(f"/tmp/px4-sock-{instance}")
    if not sock.exists():
        return True
    with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as s:
        try:
            s.connect(str(sock))
        except OSError:
            return True  # a stale socket: nobody listens
    return False


class _GcsListener:
    """Hears one PX4 instance's GCS link (sends nothing): position, mode, armed, failsafe; and follows its
    console for what it says. (PX4 sends STATUSTEXT only to a link that a ground station's heartbeat reached,
    and the test must not pose as one; PX4 prints every such line on its console too.)"""

    def __init__(self, port: int, console: Path) -> None:
        self.truth = VehicleTruth()
        self._console = console
        self._sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self._sock.bind(("127.0.0.1", port))
        self._sock.settimeout(0.2)
        self._mav = mavlink.MAVLink(None)
        self._mav.robust_parsing = True
        self._stop = threading.Event()
        self._lock = threading.Lock()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        offset = 0
        while not self._stop.is_set():
            offset = self._follow_console(offset)
            try:
                data = self._sock.recv(65535)
            except (TimeoutError, OSError):
                continue
            try:
                messages = self._mav.parse_buffer(data) or []
            except mavlink.MAVError:
                continue
            for msg in messages:
                self._handle(msg)

    def _follow_console(self, offset: int) -> int:
        """New complete lines of PX4's console (WARN/ERROR lines carry its STATUSTEXT), stamped on arrival."""
        with contextlib.suppress(OSError), open(self._console, "rb") as f:
            f.seek(offset)
            chunk = f.read()
            end = chunk.rfind(b"\n") + 1
            now = time.monotonic()
            with self._lock:
                for line in chunk[:end].decode(errors="replace").splitlines():
                    if line.startswith(("WARN", "ERROR")):
                        self.truth.texts.append((now, line.split("] ", 1)[-1].strip()))
            return offset + end
        return offset

    def _handle(self, msg) -> None:
        kind = msg.get_type()
        with self._lock:
            t = self.truth
            if kind == "HEARTBEAT" and msg.autopilot == mavlink.MAV_AUTOPILOT_PX4:
                main, sub = (msg.custom_mode >> 16) & 0xFF, (msg.custom_mode >> 24) & 0xFF
                t.mode = _PX4_MODES.get((main, sub if main == 4 else 0), f"{main}/{sub}")
                t.armed = bool(msg.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED)
                t.failsafe = t.armed and msg.system_status == mavlink.MAV_STATE_CRITICAL
                t.system_status = mavlink.enums["MAV_STATE"][msg.system_status].name.removeprefix(
                    "MAV_STATE_"
                )
            elif kind == "GLOBAL_POSITION_INT":
                point = GeodeticPoint(msg.lat * 1e-7, msg.lon * 1e-7, msg.alt * 1e-3)
                t.enu_m = geodetic_to_enu(point, reference=REF)
            elif kind == "STATUSTEXT":
                t.texts.append((time.monotonic(), msg.text.strip()))

    def snapshot(self) -> VehicleTruth:
        with self._lock:
            t = self.truth
            return VehicleTruth(
                enu_m=t.enu_m.copy(),
                mode=t.mode,
                armed=t.armed,
                failsafe=t.failsafe,
                system_status=t.system_status,
                texts=list(t.texts),
            )

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=2.0)
        self._sock.close()


class SitlTeam(Team):
    """Real PX4 SITL instances (binary: PX4_SITL), SIH quadrotor; params: PX4 parameters for every instance
    (set at boot through PX4_PARAM_<name>), per_vehicle: for one (1-based)."""

    kind = "sitl"

    def __init__(
        self,
        binary: str | os.PathLike,
        homes: Sequence[tuple[float, float, float]],
        *,
        params: dict[str, float] | None = None,
        per_vehicle: dict[int, dict[str, float]] | None = None,
        ready_timeout_s: float = 90.0,
    ) -> None:
        self.binary = Path(binary).resolve()
        etc = self.binary.parent.parent / "etc"
        if not (etc / "init.d-posix" / "rcS").exists():
            raise FileNotFoundError(f"{self.binary} is not in a PX4 SITL build (no {etc}/init.d-posix/rcS)")
        self.dir = Path(tempfile.mkdtemp(prefix="skyring-px4-"))
        self.processes: list[subprocess.Popen] = []
        self.listeners: list[_GcsListener] = []
        self.urls = []
        self.logs: list[Path] = []
        try:
            instances = [i for i in range(20, 200) if _instance_free(i)][: len(homes)]
            if len(instances) < len(homes):
                raise RuntimeError(
                    f"only {len(instances)} free PX4 instance numbers in 20..199 for {len(homes)}"
                )
            for n, (instance, home) in enumerate(zip(instances, homes, strict=False)):
                self._start(n, instance, home, etc, {**(params or {}), **(per_vehicle or {}).get(n + 1, {})})
            self._wait_ready(ready_timeout_s)
        except BaseException:
            self.close()
            raise

    def _start(self, n: int, instance: int, home, etc: Path, params: dict[str, float]) -> None:
        root = self.dir / f"px4-{n + 1}"
        shutil.copytree(etc, root / "etc", symlinks=True)
        gcs_remote, api_remote = free_udp_port(), free_udp_port()
        (root / "etc" / "init.d-posix" / "px4-rc.mavlink").write_text(
            _RC_MAVLINK.format(
                gcs_local=free_udp_port(),
                gcs_remote=gcs_remote,
                api_local=free_udp_port(),
                api_remote=api_remote,
            )
        )
        work = root / "work"
        work.mkdir()
        env = {
            **os.environ,
            "PX4_SYS_AUTOSTART": "10040",
            "PX4_SIM_MODEL": "sihsim_quadx",
            "PX4_SIMULATOR": "sihsim",
            "PX4_HOME_LAT": f"{home[0]:.7f}",
            "PX4_HOME_LON": f"{home[1]:.7f}",
            "PX4_HOME_ALT": f"{home[2]:.1f}",
            **{f"PX4_PARAM_{name}": str(value) for name, value in params.items()},
        }
        log = root / "px4.log"
        self.logs.append(log)
        self.listeners.append(_GcsListener(gcs_remote, log))
        with open(log, "wb") as out:
            self.processes.append(
                subprocess.Popen(
                    [
                        *_LINE_BUFFERED,
                        str(self.binary),
                        "-d",
                        str(root / "etc"),
                        "-i",
                        str(instance),
                        "-w",
                        str(work),
                    ],
                    stdin=subprocess.DEVNULL,
                    stdout=out,
                    stderr=subprocess.STDOUT,
                    env=env,
                    cwd=work,
                )
            )
        self.urls.append(f"udpin://127.0.0.1:{api_remote}")

    def _wait_ready(self, timeout_s: float) -> None:
        deadline = time.monotonic() + timeout_s
        # Not "Ready for takeoff": a vehicle set up to refuse arming never says it.
        for proc, log, listener in zip(self.processes, self.logs, self.listeners, strict=True):
            while not (
                b"Startup script returned successfully" in (text := log.read_bytes())
                and b"home set" in text
                and np.all(np.isfinite(listener.snapshot().enu_m))
            ):
                if proc.poll() is not None:
                    raise RuntimeError(f"PX4 exited with {proc.returncode}; its log: {log}")
                if time.monotonic() > deadline:
                    raise TimeoutError(f"PX4 not up with a home within {timeout_s:.0f} s; its log: {log}")
                time.sleep(0.2)

    def truth(self) -> list[VehicleTruth]:
        return [listener.snapshot() for listener in self.listeners]

    def close(self) -> None:
        for proc in self.processes:
            stop_process(proc)
        for listener in self.listeners:
            listener.close()
        if os.environ.get("SKYRING_KEEP_PX4_LOGS"):
            print(f"PX4 working directories kept in {self.dir}")
        else:
            shutil.rmtree(self.dir, ignore_errors=True)


def stop_process(proc: subprocess.Popen, *, timeout_s: float = 10.0) -> None:
    """SIGTERM by its pid (waking it first if it was stopped), then SIGKILL if it does not exit in time."""
    if proc.poll() is not None:
        return
    with contextlib.suppress(ProcessLookupError):
        os.kill(proc.pid, signal.SIGCONT)
        os.kill(proc.pid, signal.SIGTERM)
    try:
        proc.wait(timeout=timeout_s)
    except subprocess.TimeoutExpired:
        with contextlib.suppress(ProcessLookupError):
            os.kill(proc.pid, signal.SIGKILL)
        proc.wait(timeout=5.0)


class Station:
    """`skyring serve --px4 URLS` in its own process, on ports the kernel picks; `api` once it has printed it.

    started_s / ready_s: monotonic times of the process start and of the API answering."""

    def __init__(self, urls: Sequence[str], *, log_path: Path, extra: Sequence[str] = ()) -> None:
        self.log_path = log_path
        self.out_path = log_path.with_suffix(".out")
        cmd = [
            sys.executable,
            "-m",
            "server.cli",
            "serve",
            "--px4",
            ",".join(urls),
            "--origin",
            f"{REF.latitude_deg},{REF.longitude_deg},{REF.altitude_m}",
            "--person",
            "still",
            "--trees",
            "none",
            "--rate",
            "20",
            "--port",
            "0",
            "--viser-port",
            "0",
            "--log",
            str(log_path),
            *extra,
        ]
        self.started_s = time.monotonic()
        self.ready_s: float | None = None
        self._api: str | None = None
        self._out = open(self.out_path, "wb")  # noqa: SIM115 - closed in stop()
        self.proc = subprocess.Popen(
            cmd, stdout=self._out, stderr=subprocess.STDOUT, cwd=REPO, env=UNBUFFERED
        )
        self.client = httpx.Client(timeout=15.0)  # generous: a loaded machine, a thawed process

    @property
    def api(self) -> str:
        """The API's URL, as the station printed it (AssertionError before it has)."""
        self._api = self._api or printed_api_url(self.out_path)
        assert self._api is not None, f"skyring serve has printed no URL yet:\n{self.output()[-3000:]}"
        return self._api

    def output(self) -> str:
        return self.out_path.read_text(errors="replace")

    def _assert_running(self) -> None:
        """AssertionError with the station's exit code and output if its process has ended."""
        if self.proc.poll() is not None:
            raise AssertionError(
                f"skyring serve exited with {self.proc.returncode}:\n{self.output()[-3000:]}"
            )

    def wait_ready(self, timeout_s: float) -> float:
        """Wait until /api/state answers after the first control tick (the vehicles' telemetry is in the
        view); seconds since the process started."""
        deadline = self.started_s + timeout_s
        while True:
            self._assert_running()
            with contextlib.suppress(httpx.HTTPError, AssertionError):
                response = self.client.get(f"{self.api}/api/state")
                if response.status_code == 200 and response.json()["time_s"] > 0.0:
                    self.ready_s = time.monotonic()
                    return self.ready_s - self.started_s
            if time.monotonic() > deadline:
                raise AssertionError(f"skyring serve not up within {timeout_s} s:\n{self.output()[-3000:]}")
            time.sleep(0.2)

    def state(self) -> dict:
        self._assert_running()
        response = self.client.get(f"{self.api}/api/state")
        response.raise_for_status()
        return response.json()

    def post(self, path: str, **params) -> httpx.Response:
        return self.client.post(f"{self.api}{path}", params=params)

    def freeze(self) -> None:
        os.kill(self.proc.pid, signal.SIGSTOP)

    def thaw(self) -> None:
        os.kill(self.proc.pid, signal.SIGCONT)

    def kill(self) -> None:
        """SIGKILL: the ground station dies without a word (no landing command)."""
        os.kill(self.proc.pid, signal.SIGKILL)
        self.proc.wait(timeout=5.0)
        self.client.close()
        self._out.close()

    def stop(self) -> None:
        """SIGTERM: the ground station lands every vehicle and exits."""
        stop_process(self.proc, timeout_s=20.0)
        self.client.close()
        self._out.close()


class Sampler:
    """Samples a team's truth (and optionally the station's view) every period_s in a thread: the closest
    pair ever seen, and callbacks a scenario adds (`watch`)."""

    def __init__(self, team: Team, *, period_s: float = 0.1) -> None:
        self.team = team
        self.closest_m = math.inf
        self.closest_at: tuple[int, int] | None = None
        self._watchers: list[Callable[[list[VehicleTruth]], None]] = []
        self._stop = threading.Event()
        self._period = period_s
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def watch(self, fn: Callable[[list[VehicleTruth]], None]) -> None:
        self._watchers.append(fn)

    def _run(self) -> None:
        while not self._stop.is_set():
            truth = self.team.truth()
            xyz = np.array([t.enu_m for t in truth])
            for i in range(len(xyz)):
                for j in range(i + 1, len(xyz)):
                    d = float(np.linalg.norm(xyz[i] - xyz[j]))
                    if np.isfinite(d) and d < self.closest_m:
                        self.closest_m, self.closest_at = d, (i + 1, j + 1)
            for fn in list(self._watchers):
                fn(truth)
            self._stop.wait(self._period)

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=2.0)


def wait_for(
    condition: Callable[[], bool],
    *,
    timeout_s: float,
    what: str,
    every_s: float = 0.2,
    detail: Callable[[], str] | None = None,
) -> float:
    """Poll until condition() holds; seconds it took, or AssertionError naming what did not happen (and
    detail(), e.g. what the station and PX4 showed then)."""
    t0 = time.monotonic()
    while True:
        if condition():
            return time.monotonic() - t0
        if time.monotonic() - t0 > timeout_s:
            shown = f"\n{detail()}" if detail is not None else ""
            raise AssertionError(f"{what} did not happen within {timeout_s:.0f} s{shown}")
        time.sleep(every_s)


def describe(team: Team, station: Station | None = None) -> str:
    """What PX4 and (if given) the station show for each vehicle: for a failing scenario's message."""
    lines = []
    truth = team.truth()
    vehicles = []
    if station is not None and station.proc.poll() is None:
        with contextlib.suppress(httpx.HTTPError):
            vehicles = station.state()["vehicles"]
    for i, t in enumerate(truth):
        line = (
            f"MAV {i + 1}: PX4 {t.mode} armed={t.armed} status={t.system_status} "
            f"height={t.enu_m[2]:.1f} m; last said: {[text for _, text in t.texts[-3:]]}"
        )
        if i < len(vehicles):
            v = vehicles[i]
            line += (
                f"; view: phase={v['phase']} mode={v['autopilot_mode']} can_arm={v['can_arm']} "
                f"in_formation={v['in_formation']} failsafe={v['failsafe']} refusal={v['arming_refusal']!r}"
            )
        lines.append(line)
    return "\n".join(lines)

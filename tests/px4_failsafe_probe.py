"""Measures what real PX4 SITL does when the ground station goes away or the battery runs down: the facts
docs/px4.md states in "What PX4 v1.16 does".

    PYTHONPATH=tests .venv/bin/python -m px4_failsafe_probe path/to/bin/px4 [situation ...]

Each situation starts one PX4 SIH instance (tests/px4_team.py: its own working directory, free ports,
stopped by its pid), plays the ground station over raw MAVLink on the vehicle's API link (GCS heartbeats,
commands, position set-points), flies it to 5 m and then makes the situation happen. It prints, on one time
axis from the moment the situation began, every change of PX4's mode, armed state and system status heard
on the vehicle's GCS link, the height, and every WARN/ERROR line of PX4's console (PX4's STATUSTEXT).

Situations:
- offboard-loss: in Offboard the set-points stop, heartbeats go on (COM_OF_LOSS_T 1 s, COM_OBL_RC_ACT 4);
- offboard-loss-default: the same with PX4's default COM_OBL_RC_ACT (0, Position) and no RC;
- station-gone-offboard: in Offboard the ground station goes silent (set-points and heartbeats);
- station-gone-hold: in Hold the ground station goes silent (NAV_DLL_ACT 3, COM_DL_LOSS_T 10 s);
- battery: in Hold, the simulated battery drains (SIM_BAT_DRAIN 60 s) and stops at 6 %, below the critical
  level (7 %) and above the emergency level (5 %) (COM_LOW_BAT_ACT 2);
- battery-sitl-default: the same with the COM_LOW_BAT_ACT PX4's SITL start-up script sets (3) and the
  battery allowed to run empty.
"""

from __future__ import annotations

import math
import sys
import threading
import time
from dataclasses import dataclass

from px4_team import SitlTeam, ring_homes, wait_for
from pymavlink import mavutil
from pymavlink.dialects.v20 import common as mavlink

TAKEOFF_M = 5.0
COMMON = {"MIS_TAKEOFF_ALT": TAKEOFF_M, "COM_OF_LOSS_T": 1.0, "COM_DISARM_LAND": 2.0}


@dataclass(frozen=True)
class Situation:
    """params: PX4 parameters at boot; offboard: fly in Offboard (else Hold) before it begins;
    stop_setpoints / stop_heartbeats: what the ground station stops when it begins; watch_s: how long to
    watch after."""

    params: dict[str, float]
    offboard: bool
    stop_setpoints: bool
    stop_heartbeats: bool
    watch_s: float


SITUATIONS = {
    "offboard-loss": Situation({"COM_OBL_RC_ACT": 4}, True, True, False, 30.0),
    "offboard-loss-default": Situation({"COM_OBL_RC_ACT": 0}, True, True, False, 30.0),
    "station-gone-offboard": Situation({"COM_OBL_RC_ACT": 4, "NAV_DLL_ACT": 3}, True, True, True, 30.0),
    "station-gone-hold": Situation({"NAV_DLL_ACT": 3, "COM_DL_LOSS_T": 10}, False, False, True, 45.0),
    "battery": Situation(
        {"COM_LOW_BAT_ACT": 2, "SIM_BAT_DRAIN": 60.0, "SIM_BAT_MIN_PCT": 6.0}, False, False, False, 90.0
    ),
    "battery-sitl-default": Situation(
        {"COM_LOW_BAT_ACT": 3, "SIM_BAT_DRAIN": 60.0, "SIM_BAT_MIN_PCT": 0.0}, False, False, False, 100.0
    ),
}


class GroundStation:
    """Raw MAVLink on one vehicle's API link: heartbeats at 1 Hz and (when given) a position set-point at
    20 Hz from a thread; commands with their acknowledgement."""

    def __init__(self, url: str) -> None:
        port = int(url.rsplit(":", 1)[1])
        self.link = mavutil.mavlink_connection(
            f"udpin:127.0.0.1:{port}", source_system=255, source_component=190
        )
        self.link.wait_heartbeat(timeout=30)
        self.heartbeats = True
        self.setpoint_ned: tuple[float, float, float] | None = None
        self.local_ned = (math.nan, math.nan, math.nan)
        self._acks: dict[int, int] = {}
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._threads = [threading.Thread(target=f, daemon=True) for f in (self._send, self._receive)]
        for thread in self._threads:
            thread.start()

    def _send(self) -> None:
        n = 0
        while not self._stop.is_set():
            if self.heartbeats and n % 20 == 0:
                self.link.mav.heartbeat_send(mavlink.MAV_TYPE_GCS, mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 0)
            target = self.setpoint_ned
            if target is not None:
                self.link.mav.set_position_target_local_ned_send(
                    0, self.link.target_system, 1, mavlink.MAV_FRAME_LOCAL_NED, 0b110111111000, *target,
                    0, 0, 0, 0, 0, 0, 0, 0,
                )  # fmt: skip
            n += 1
            self._stop.wait(0.05)

    def _receive(self) -> None:
        while not self._stop.is_set():
            msg = self.link.recv_match(blocking=True, timeout=0.2)
            if msg is None:
                continue
            if msg.get_type() == "COMMAND_ACK":
                with self._lock:
                    self._acks[msg.command] = msg.result
            elif msg.get_type() == "LOCAL_POSITION_NED":
                self.local_ned = (msg.x, msg.y, msg.z)

    def command(self, command: int, *params: float, timeout_s: float = 5.0) -> int:
        """COMMAND_LONG, re-sent each second until acknowledged; PX4's MAV_RESULT."""
        padded = [*params, *[0.0] * (7 - len(params))]
        deadline = time.monotonic() + timeout_s
        with self._lock:
            self._acks.pop(command, None)
        while time.monotonic() < deadline:
            self.link.mav.command_long_send(self.link.target_system, 1, command, 0, *padded)
            for _ in range(10):
                time.sleep(0.1)
                with self._lock:
                    if command in self._acks:
                        return self._acks.pop(command)
        raise TimeoutError(f"no COMMAND_ACK for {command}")

    def set_mode(self, main: int, sub: int = 0) -> int:
        custom = mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
        return self.command(mavlink.MAV_CMD_DO_SET_MODE, custom, main, sub)

    def close(self) -> None:
        self._stop.set()
        for thread in self._threads:
            thread.join(timeout=2.0)
        self.link.close()


def fly_to_height(team: SitlTeam, gcs: GroundStation, situation: Situation) -> None:
    wait_for(
        lambda: b"Ready for takeoff" in team.logs[0].read_bytes(), timeout_s=60, what="Ready for takeoff"
    )
    assert gcs.set_mode(4, 3) == mavlink.MAV_RESULT_ACCEPTED  # Hold first: arming is allowed there
    assert gcs.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1) == mavlink.MAV_RESULT_ACCEPTED
    assert gcs.command(mavlink.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, math.nan, math.nan, math.nan, math.nan) == 0
    wait_for(lambda: team.truth()[0].mode == "HOLD" and team.truth()[0].enu_m[2] > TAKEOFF_M - 0.5,
             timeout_s=60, what="Hold at height")  # fmt: skip
    if situation.offboard:
        gcs.setpoint_ned = gcs.local_ned
        time.sleep(1.5)
        assert gcs.set_mode(6) == mavlink.MAV_RESULT_ACCEPTED
        wait_for(lambda: team.truth()[0].mode == "OFFBOARD", timeout_s=5, what="Offboard")
        time.sleep(5.0)


def watch(team: SitlTeam, since: float, watch_s: float) -> None:
    """Print every change of PX4's mode / armed / failsafe, every warning PX4 prints and every line of its
    commander and navigator, with the time since `since`, until watch_s have passed or the vehicle is down
    and disarmed for 3 s."""
    last: tuple | None = None
    console = team.logs[0]
    offset = console.stat().st_size
    down_since: float | None = None
    while time.monotonic() - since < watch_s:
        t = team.truth()[0]
        state = (t.mode, t.armed, t.failsafe)
        now = time.monotonic() - since
        if state != last:
            print(f"{now:6.1f} s  mode {t.mode:<17} armed {t.armed!s:<5} failsafe {t.failsafe!s:<5} "
                  f"height {t.enu_m[2]:5.1f} m")  # fmt: skip
            last = state
        with open(console, "rb") as f:
            f.seek(offset)
            chunk = f.read()
        offset += chunk.rfind(b"\n") + 1
        for line in chunk[: chunk.rfind(b"\n") + 1].decode(errors="replace").splitlines():
            if line.startswith(("WARN", "ERROR")) or any(
                f"[{m}]" in line for m in ("commander", "navigator")
            ):
                print(f"{now:6.1f} s  PX4: {line.strip()}")
        if not t.armed and t.enu_m[2] < 1.0:
            down_since = down_since or time.monotonic()
            if time.monotonic() - down_since > 3.0:
                break
        time.sleep(0.05)


def probe(binary: str, name: str) -> None:
    situation = SITUATIONS[name]
    print(f"== {name}: {situation.params}")
    team = SitlTeam(binary, ring_homes()[:1], params={**COMMON, **situation.params})
    try:
        gcs = GroundStation(team.urls[0])
        try:
            fly_to_height(team, gcs, situation)
            since = time.monotonic()
            if situation.stop_setpoints:
                gcs.setpoint_ned = None
            if situation.stop_heartbeats:
                gcs.heartbeats = False
            watch(team, since, situation.watch_s)
        finally:
            gcs.close()
    finally:
        team.close()


if __name__ == "__main__":
    if len(sys.argv) < 2:
        sys.exit(__doc__)
    for situation_name in sys.argv[2:] or list(SITUATIONS):
        probe(sys.argv[1], situation_name)

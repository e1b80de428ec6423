"""A MAVLink peer that behaves like PX4 for what skyring uses, over real UDP on 127.0.0.1, for tests.

One `Px4Peer` is one multicopter autopilot: it sends to the ground station's port (MAVSDK listens with
`udpin://127.0.0.1:PORT`; the peer plays PX4's `udpout` side from its own ephemeral port) and runs its loop
in a daemon thread in real time, as MAVSDK needs.

What it does, the way PX4 v1.16 does it:
- HEARTBEAT (1 Hz) with autopilot PX4, armed flag, the PX4 custom mode (main mode in bits 16-23, AUTO
  sub-mode in bits 24-31, e.g. Hold = AUTO/LOITER = 4/3, Offboard = 6/0, Position = 3/0) and PX4's system
  status: STANDBY disarmed and able to arm, UNINIT disarmed and unable to, ACTIVE armed, CRITICAL armed in a
  failsafe;
- modes as PX4 keeps them: the mode asked for (the user's intention) and, on top of it, a failsafe's mode; a
  mode change by the ground station or a pilot ends a failsafe; after every disarm the vehicle returns to the
  last mode asked for that allows arming (Offboard after an offboard flight, never Land or Return);
- arming checks: arming is denied, with PX4's STATUSTEXT "Arming denied: Resolve system health failures
  first", when COM_ARMABLE is 0, when the mode asked for is Offboard without a set-point stream, or when
  NAV_DLL_ACT is set and no ground station was heard for COM_DL_LOSS_T (then after "Preflight Fail: No
  connection to the ground control station"); the SYS_STATUS pre-arm bit and the heartbeat say so
  beforehand;
- LOCAL_POSITION_NED, GLOBAL_POSITION_INT, ATTITUDE, ATTITUDE_QUATERNION at `rate_hz`; EXTENDED_SYS_STATE
  (landed state); SYS_STATUS (sensor health bits, pre-arm check, battery); GPS_RAW_INT (accuracy);
  HOME_POSITION (home resets at every arming; the local NED origin stays where it booted); GPS_GLOBAL_ORIGIN
  and AUTOPILOT_VERSION on request;
- COMMAND_LONG / COMMAND_INT with COMMAND_ACK: arm/disarm, NAV_TAKEOFF (Takeoff mode, accepted disarmed too;
  once armed it climbs to MIS_TAKEOFF_ALT, then Hold),
  NAV_LAND (descend at MPC_LAND_SPEED, auto-disarm COM_DISARM_LAND after touch-down), DO_SET_MODE (offboard
  only after >= 1 s of set-points at > 2 Hz, as PX4 >= 1.14), REQUEST_MESSAGE, SET_MESSAGE_INTERVAL; unknown
  commands are answered UNSUPPORTED;
- PARAM_REQUEST_READ / PARAM_REQUEST_LIST / PARAM_SET with PX4's byte-wise int32 encoding, for the parameters
  in `DEFAULT_PARAMS`; unknown names are ignored, as PX4 does;
- SET_POSITION_TARGET_LOCAL_NED in Offboard, honouring the type mask, with simple dynamics: a P position loop
  with velocity feed-forward, speed and acceleration limits, and attitude from the commanded acceleration;
- failsafes, as measured on PX4 v1.16 SITL: offboard loss (no set-point for COM_OF_LOSS_T while Offboard is
  asked for: straight to COM_OBL_RC_ACT, no Hold first; it ends, back to Offboard, as soon as set-points come
  again) and GCS link loss (no GCS heartbeat for COM_DL_LOSS_T while armed and flying: Hold for
  COM_FAIL_ACT_T, then NAV_DLL_ACT), each announced by the STATUSTEXT "Failsafe activated"; the pre-flight
  auto-disarm (COM_DISARM_PRFLT);
- STATUSTEXT lines PX4 sends on arming, take-off and landing detection and disarming.
Every SET_POSITION_TARGET_LOCAL_NED it receives is recorded (`setpoints()`) so tests can check them, every
mode change is logged with its time (`mode_log()`), and so is every STATUSTEXT sent (`texts()`).

What it leaves out: estimator behaviour (position is truth, no drift or noise), wind and real multicopter
dynamics, terrain (ground is flat at the boot altitude), attitude/rate/acceleration-only offboard set-points,
SET_POSITION_TARGET_GLOBAL_INT, missions, geofence, battery failsafes (COM_LOW_BAT_ACT is stored, the battery
never runs low), RC input (a pilot is emulated by `pilot_takeover`), arming checks other than the three above,
PX4's events protocol (the detailed reasons behind its STATUSTEXT lines; MAVSDK's events plugin hears nothing
from the peer), MAVLink signing, FTP and component metadata, most statustext chatter, message-interval
changes (acknowledged but rates stay fixed), COM_RC_OVERRIDE, and PX4's azimuthal projection (local <->
global uses the ellipsoid tangent plane, which differs by < 1 cm within 300 m).
"""

from __future__ import annotations

import math
import socket
import struct
import threading
import time
from dataclasses import dataclass
from enum import Enum

import numpy as np
import pymap3d
from pymavlink.dialects.v20 import common as mavlink

from vehicles.net.ports import free_port

G_MPS2 = 9.81

# PX4 custom main modes and AUTO sub-modes (px4_custom_mode.h).
MAIN_MANUAL, MAIN_ALTCTL, MAIN_POSCTL, MAIN_AUTO = 1, 2, 3, 4
MAIN_ACRO, MAIN_OFFBOARD, MAIN_STABILIZED = 5, 6, 7
SUB_READY, SUB_TAKEOFF, SUB_LOITER, SUB_MISSION, SUB_RTL, SUB_LAND = 1, 2, 3, 4, 5, 6


class PeerMode(Enum):
    """The PX4 flight modes the peer implements, as (main mode, AUTO sub-mode)."""

    MANUAL = (MAIN_MANUAL, 0)
    ALTCTL = (MAIN_ALTCTL, 0)
    POSCTL = (MAIN_POSCTL, 0)
    STABILIZED = (MAIN_STABILIZED, 0)
    HOLD = (MAIN_AUTO, SUB_LOITER)
    TAKEOFF = (MAIN_AUTO, SUB_TAKEOFF)
    LAND = (MAIN_AUTO, SUB_LAND)
    RTL = (MAIN_AUTO, SUB_RTL)
    OFFBOARD = (MAIN_OFFBOARD, 0)

    @property
    def custom_mode(self) -> int:
        main, sub = self.value
        return (main << 16) | (sub << 24)

    @classmethod
    def from_main_sub(cls, main: int, sub: int) -> PeerMode | None:
        for mode in cls:
            if mode.value == (main, sub if main == MAIN_AUTO else 0):
                return mode
        return None


PILOT_MODES = (PeerMode.MANUAL, PeerMode.ALTCTL, PeerMode.POSCTL, PeerMode.STABILIZED)
# Modes PX4 does not return to after a disarm (they prevent arming).
NO_ARMING_MODES = (PeerMode.LAND, PeerMode.RTL)
ARMING_DENIED = "Arming denied: Resolve system health failures first"
NO_GCS = "Preflight Fail: No connection to the ground control station"

# name -> (PX4 default, MAVLink type). Floats are REAL32, ints INT32 (sent byte-wise, as PX4 does).
DEFAULT_PARAMS: dict[str, tuple[float, int]] = {
    "COM_OF_LOSS_T": (1.0, mavlink.MAV_PARAM_TYPE_REAL32),
    "COM_OBL_RC_ACT": (0, mavlink.MAV_PARAM_TYPE_INT32),
    "COM_FAIL_ACT_T": (5.0, mavlink.MAV_PARAM_TYPE_REAL32),
    "COM_DL_LOSS_T": (10, mavlink.MAV_PARAM_TYPE_INT32),
    "NAV_DLL_ACT": (0, mavlink.MAV_PARAM_TYPE_INT32),
    "COM_DISARM_LAND": (2.0, mavlink.MAV_PARAM_TYPE_REAL32),
    "COM_DISARM_PRFLT": (10.0, mavlink.MAV_PARAM_TYPE_REAL32),
    "COM_ARMABLE": (1, mavlink.MAV_PARAM_TYPE_INT32),
    "COM_LOW_BAT_ACT": (0, mavlink.MAV_PARAM_TYPE_INT32),
    "MIS_TAKEOFF_ALT": (2.5, mavlink.MAV_PARAM_TYPE_REAL32),
    "MPC_TKO_SPEED": (1.5, mavlink.MAV_PARAM_TYPE_REAL32),
    "MPC_LAND_SPEED": (0.7, mavlink.MAV_PARAM_TYPE_REAL32),
    "MPC_XY_VEL_MAX": (12.0, mavlink.MAV_PARAM_TYPE_REAL32),
    "MPC_Z_VEL_MAX_UP": (3.0, mavlink.MAV_PARAM_TYPE_REAL32),
    "MPC_Z_VEL_MAX_DN": (1.5, mavlink.MAV_PARAM_TYPE_REAL32),
    "MAV_SYS_ID": (1, mavlink.MAV_PARAM_TYPE_INT32),
}

# COM_OBL_RC_ACT and NAV_DLL_ACT values -> the mode PX4 switches to (None: disabled / disarm).
OFFBOARD_LOSS_ACTIONS = {
    0: PeerMode.POSCTL,
    1: PeerMode.ALTCTL,
    2: PeerMode.STABILIZED,
    3: PeerMode.RTL,
    4: PeerMode.LAND,
    5: PeerMode.HOLD,
}
LINK_LOSS_ACTIONS = {1: PeerMode.HOLD, 2: PeerMode.RTL, 3: PeerMode.LAND}

_SENSORS = (
    mavlink.MAV_SYS_STATUS_SENSOR_3D_GYRO
    | mavlink.MAV_SYS_STATUS_SENSOR_3D_ACCEL
    | mavlink.MAV_SYS_STATUS_SENSOR_3D_MAG
    | mavlink.MAV_SYS_STATUS_SENSOR_ABSOLUTE_PRESSURE
    | mavlink.MAV_SYS_STATUS_SENSOR_GPS
    | mavlink.MAV_SYS_STATUS_PREARM_CHECK
)
_CAPABILITIES = (
    mavlink.MAV_PROTOCOL_CAPABILITY_MAVLINK2
    | mavlink.MAV_PROTOCOL_CAPABILITY_COMMAND_INT
    | mavlink.MAV_PROTOCOL_CAPABILITY_PARAM_FLOAT
    | mavlink.MAV_PROTOCOL_CAPABILITY_MISSION_INT
    | mavlink.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_LOCAL_NED
    | mavlink.MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE
)

IGNORE_POSITION = 0b111  # type-mask bits of SET_POSITION_TARGET_LOCAL_NED
IGNORE_VELOCITY = 0b111 << 3
IGNORE_ACCELERATION = 0b111 << 6
IGNORE_YAW = 1 << 10
IGNORE_YAW_RATE = 1 << 11


@dataclass
class _Failsafe:
    """A failsafe PX4 runs on top of the mode asked for: its cause ("offboard": set-points lost; "gcs": the
    ground station's heartbeat lost), the mode it flies, and when that mode starts (before: Hold)."""

    cause: str
    action: PeerMode
    act_at_t: float


@dataclass(frozen=True)
class SeenSetpoint:
    """One SET_POSITION_TARGET_LOCAL_NED as received: t_s on the peer's monotonic clock, all raw fields."""

    t_s: float
    target_system: int
    target_component: int
    frame: int
    type_mask: int
    position_ned: tuple[float, float, float]
    velocity_ned: tuple[float, float, float]
    acceleration_ned: tuple[float, float, float]
    yaw_rad: float
    yaw_rate_rad_s: float


def int_as_param_float(value: int) -> float:
    """PX4's byte-wise encoding: the int32's bytes carried in the float field."""
    return struct.unpack("<f", struct.pack("<i", int(value)))[0]


def param_float_as_int(value: float) -> int:
    return struct.unpack("<i", struct.pack("<f", value))[0]


def free_udp_port() -> int:
    """A UDP port on 127.0.0.1 for a peer or a GCS link (vehicles/net/ports.py says why not bind(0))."""
    return free_port("udp")


class _UdpOut:
    """The file-like sink pymavlink writes frames to: one datagram per frame to each GCS, unless silenced."""

    def __init__(self, sock: socket.socket, addresses: list[tuple[str, int]]) -> None:
        self.sock, self.addresses, self.silenced = sock, addresses, False

    def write(self, data: bytes) -> None:
        if not self.silenced:
            for address in self.addresses:
                try:
                    self.sock.sendto(data, address)
                except OSError:
                    pass  # the GCS is not listening yet: UDP drops it, as on a real link


class Px4Peer:
    """A simulated PX4 multicopter speaking MAVLink 2 to a ground station at 127.0.0.1:gcs_port.

    home: (lat_deg, lon_deg, alt_m) where it boots, which is also its local NED origin unless `origin` says
    otherwise; start_ned_m: (3,) its boot position in that local frame (when origin is not given);
    extra_gcs_ports: more ground stations it streams to, as PX4 does with one MAVLink instance per link (e.g.
    the onboard agent's and the station's telemetry radio);
    start_yaw_ned_rad: its heading on the ground; params: overrides of DEFAULT_PARAMS; answers_origin: False
    plays an autopilot that does not answer a GPS_GLOBAL_ORIGIN request.
    """

    def __init__(
        self,
        *,
        gcs_port: int,
        system_id: int = 1,
        home: tuple[float, float, float] = (47.397742, 8.545594, 488.0),
        origin: tuple[float, float, float] | None = None,
        start_ned_m=(0.0, 0.0, 0.0),
        start_yaw_ned_rad: float = 0.0,
        rate_hz: float = 20.0,
        params: dict[str, float] | None = None,
        max_accel_mps2: float = 5.0,
        answers_origin: bool = True,
        extra_gcs_ports: tuple[int, ...] = (),
    ) -> None:
        self.system_id = system_id
        self.origin = tuple(origin if origin is not None else home)
        self.rate_hz = rate_hz
        self.max_accel_mps2 = max_accel_mps2
        self.answers_origin = answers_origin
        self._sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self._sock.bind(("127.0.0.1", 0))
        self._sock.setblocking(False)
        self._out = _UdpOut(self._sock, [("127.0.0.1", p) for p in (gcs_port, *extra_gcs_ports)])
        self._mav = mavlink.MAVLink(
            self._out, srcSystem=system_id, srcComponent=mavlink.MAV_COMP_ID_AUTOPILOT1
        )
        self._mav.robust_parsing = True
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._t0 = time.monotonic()
        self._deaf = False
        # parameters: name -> [value, type]
        self._params = {name: [value, ptype] for name, (value, ptype) in DEFAULT_PARAMS.items()}
        self._params["MAV_SYS_ID"][0] = system_id
        for name, value in (params or {}).items():
            self._params[name][0] = value
        # vehicle state, local NED
        start = np.array(start_ned_m, dtype=float)
        if origin is not None:
            # home is given explicitly: place the vehicle there in the origin's frame
            lat0, lon0, alt0 = self.origin
            n, e, d = pymap3d.geodetic2ned(home[0], home[1], home[2], lat0, lon0, alt0)
            start = np.array([n, e, d], dtype=float)
        self._ground_down_m = float(start[2])
        self._p = start
        self._v = np.zeros(3)
        self._accel = np.zeros(3)
        self._yaw = float(start_yaw_ned_rad)
        self._yaw_rate = 0.0
        self._armed = False
        self._mode = PeerMode.HOLD  # what the heartbeat shows: the failsafe's mode, else the one asked for
        self._intended = PeerMode.HOLD  # the mode asked for (PX4's user intention)
        self._after_disarm = PeerMode.HOLD  # the last mode asked for that allows arming
        self._failsafe: _Failsafe | None = None
        self._texts: list[tuple[float, int, str]] = []
        self._landed = True
        self._home_ned = start.copy()
        self._battery = 1.0
        self._mode_log: list[tuple[float, str]] = [(0.0, self._mode.name)]
        self._setpoints: list[SeenSetpoint] = []
        self._sp_used: SeenSetpoint | None = None
        self._sp_stream_start = -1.0
        self._last_sp_t = -1e9
        self._last_gcs_heartbeat_t = 0.0
        self._hold_point = start.copy()
        self._land_xy = start[:2].copy()
        self._touchdown_t: float | None = None
        self._flew_since_arming = False
        self._armed_t = 0.0
        self._commands: list[tuple[float, int, float, float, float]] = []

    # ------------------------------------------------------------------ lifecycle
    def start(self) -> Px4Peer:
        self._thread = threading.Thread(target=self._run, name=f"px4-peer-{self.system_id}", daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
        self._sock.close()

    def __enter__(self) -> Px4Peer:
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()

    # ------------------------------------------------------------------ test controls
    def silence(self, silent: bool = True) -> None:
        """Cut (or restore) the radio link both ways: nothing is sent, everything received is dropped."""
        with self._lock:
            self._out.silenced = silent
            self._deaf = silent

    def pilot_takeover(self, mode: PeerMode = PeerMode.POSCTL) -> None:
        """A pilot flips the RC mode switch: the vehicle leaves whatever mode it was in for `mode`."""
        with self._lock:
            self._request_mode(mode, self._now())

    def set_param(self, name: str, value: float) -> None:
        """Change a parameter on the vehicle itself (e.g. COM_ARMABLE from a maintenance laptop)."""
        with self._lock:
            self._params[name][0] = value

    def place_airborne(self, height_m: float, mode: PeerMode = PeerMode.HOLD) -> None:
        """Put the vehicle in the air, armed, height_m above its ground, in `mode`: as an earlier ground
        station would have left it."""
        with self._lock:
            now = self._now()
            self._armed, self._armed_t, self._flew_since_arming = True, now, True
            self._landed, self._touchdown_t = False, None
            self._p[2] = self._ground_down_m - float(height_m)
            self._v[:] = 0.0
            self._request_mode(mode, now)

    # ------------------------------------------------------------------ observations (thread-safe copies)
    def now(self) -> float:
        return self._now()

    @property
    def mode(self) -> PeerMode:
        with self._lock:
            return self._mode

    @property
    def armed(self) -> bool:
        with self._lock:
            return self._armed

    @property
    def landed(self) -> bool:
        with self._lock:
            return self._landed

    @property
    def position_ned(self) -> np.ndarray:
        with self._lock:
            return self._p.copy()

    @property
    def velocity_ned(self) -> np.ndarray:
        with self._lock:
            return self._v.copy()

    def geodetic(self) -> tuple[float, float, float]:
        """The true (lat_deg, lon_deg, alt_m) of the vehicle."""
        with self._lock:
            p = self._p.copy()
        lat, lon, alt = pymap3d.ned2geodetic(*p, *self.origin)
        return float(lat), float(lon), float(alt)

    def param(self, name: str) -> float:
        with self._lock:
            return self._params[name][0]

    def setpoints(self) -> list[SeenSetpoint]:
        with self._lock:
            return list(self._setpoints)

    @property
    def failsafe(self) -> bool:
        """PX4 runs a failsafe now (its heartbeat's system status is CRITICAL)."""
        with self._lock:
            return self._failsafe is not None and self._armed

    def texts(self) -> list[tuple[float, int, str]]:
        """[(t_s, MAV_SEVERITY, text)] of every STATUSTEXT sent, t_s on the peer clock."""
        with self._lock:
            return list(self._texts)

    def mode_log(self) -> list[tuple[float, str]]:
        """[(t_s, mode name)] for every mode change, t_s on the peer clock (`now()`)."""
        with self._lock:
            return list(self._mode_log)

    def commands(self) -> list[tuple[float, int, float, float, float]]:
        """[(t_s, MAV_CMD, param1, param2, param3)] for every command received."""
        with self._lock:
            return list(self._commands)

    # ------------------------------------------------------------------ the loop
    def _now(self) -> float:
        return time.monotonic() - self._t0

    def _run(self) -> None:
        period = 1.0 / 100.0  # physics and message handling; telemetry goes out at rate_hz
        last = self._now()
        next_fast = next_hb = next_slow = next_status = 0.0
        while not self._stop.is_set():
            self._receive()
            now = self._now()
            with self._lock:
                self._step(now, max(0.0, min(now - last, 0.05)))
                last = now
                if now >= next_fast:
                    next_fast = now + 1.0 / self.rate_hz
                    self._send_fast(now)
                if now >= next_slow:
                    next_slow = now + 0.2
                    self._send_slow()
                if now >= next_hb:
                    next_hb = now + 1.0
                    self._send_heartbeat()
                if now >= next_status:
                    next_status = now + 2.0
                    self._send_home()
            self._stop.wait(period)

    def _receive(self) -> None:
        while True:
            try:
                data, _ = self._sock.recvfrom(65535)
            except (BlockingIOError, OSError):
                return
            try:
                messages = self._mav.parse_buffer(data) or []
            except mavlink.MAVError:
                continue
            with self._lock:
                if self._deaf:
                    continue
                for msg in messages:
                    self._handle(msg, self._now())

    # ------------------------------------------------------------------ message handling (lock held)
    def _handle(self, msg, now: float) -> None:
        kind = msg.get_type()
        if kind == "HEARTBEAT" and msg.type == mavlink.MAV_TYPE_GCS:
            self._last_gcs_heartbeat_t = now
        elif kind == "SET_POSITION_TARGET_LOCAL_NED":
            self._on_setpoint(msg, now)
        elif kind in ("COMMAND_LONG", "COMMAND_INT"):
            if msg.target_system in (0, self.system_id):
                self._on_command(msg, now)
        elif kind == "PARAM_REQUEST_READ" and msg.target_system in (0, self.system_id):
            name = msg.param_id if msg.param_index < 0 else self._param_name(msg.param_index)
            if name in self._params:
                self._send_param(name)
        elif kind == "PARAM_REQUEST_LIST" and msg.target_system in (0, self.system_id):
            for name in self._params:
                self._send_param(name)
        elif kind == "PARAM_SET" and msg.target_system in (0, self.system_id):
            if msg.param_id in self._params:
                ptype = self._params[msg.param_id][1]
                value = (
                    param_float_as_int(msg.param_value)
                    if ptype == mavlink.MAV_PARAM_TYPE_INT32
                    else float(msg.param_value)
                )
                self._params[msg.param_id][0] = value
                self._send_param(msg.param_id)

    def _param_name(self, index: int) -> str | None:
        names = list(self._params)
        return names[index] if 0 <= index < len(names) else None

    def _send_param(self, name: str) -> None:
        value, ptype = self._params[name]
        wire = int_as_param_float(value) if ptype == mavlink.MAV_PARAM_TYPE_INT32 else float(value)
        index = list(self._params).index(name)
        self._mav.param_value_send(name.encode(), wire, ptype, len(self._params), index)

    def _on_setpoint(self, msg, now: float) -> None:
        sp = SeenSetpoint(
            t_s=now,
            target_system=msg.target_system,
            target_component=msg.target_component,
            frame=msg.coordinate_frame,
            type_mask=msg.type_mask,
            position_ned=(msg.x, msg.y, msg.z),
            velocity_ned=(msg.vx, msg.vy, msg.vz),
            acceleration_ned=(msg.afx, msg.afy, msg.afz),
            yaw_rad=msg.yaw,
            yaw_rate_rad_s=msg.yaw_rate,
        )
        self._setpoints.append(sp)
        if msg.target_system != self.system_id or msg.coordinate_frame != mavlink.MAV_FRAME_LOCAL_NED:
            return
        if now - self._last_sp_t > 0.5:  # the stream restarts: PX4 wants > 2 Hz
            self._sp_stream_start = now
        self._last_sp_t = now
        self._sp_used = sp

    def _ack(self, msg, command: int, result: int) -> None:
        self._mav.command_ack_send(command, result, 0, 0, msg.get_srcSystem(), msg.get_srcComponent())

    def _on_command(self, msg, now: float) -> None:
        cmd = msg.command
        self._commands.append((now, cmd, msg.param1, msg.param2, msg.param3))
        accepted, denied = mavlink.MAV_RESULT_ACCEPTED, mavlink.MAV_RESULT_DENIED
        if cmd == mavlink.MAV_CMD_COMPONENT_ARM_DISARM:
            if msg.param1 >= 0.5:
                if self._armed:
                    self._ack(msg, cmd, accepted)
                elif not self._landed or not self._can_arm(now):
                    self._ack(msg, cmd, denied)
                    if self._gcs_required_but_lost(now):
                        self._text(mavlink.MAV_SEVERITY_CRITICAL, NO_GCS)
                    self._text(mavlink.MAV_SEVERITY_CRITICAL, ARMING_DENIED)
                else:
                    self._armed, self._armed_t, self._flew_since_arming = True, now, False
                    self._home_ned = self._p.copy()  # home resets at every arming
                    self._ack(msg, cmd, accepted)
                    self._text(mavlink.MAV_SEVERITY_INFO, "Armed by external command")
            else:
                ok = self._landed or int(msg.param2) == 21196
                if ok and self._armed:
                    self._disarm(now, "Disarmed by external command")
                self._ack(msg, cmd, accepted if ok else denied)
        elif cmd == mavlink.MAV_CMD_NAV_TAKEOFF:
            self._request_mode(PeerMode.TAKEOFF, now)  # disarmed too: it climbs once armed
            self._ack(msg, cmd, accepted)
        elif cmd == mavlink.MAV_CMD_NAV_LAND:
            self._request_mode(PeerMode.LAND, now)
            self._ack(msg, cmd, accepted)
        elif cmd == mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH:
            self._request_mode(PeerMode.RTL, now)
            self._ack(msg, cmd, accepted)
        elif cmd == mavlink.MAV_CMD_DO_SET_MODE:
            mode = PeerMode.from_main_sub(int(msg.param2), int(msg.param3))
            if mode is None:
                self._ack(msg, cmd, mavlink.MAV_RESULT_UNSUPPORTED)
            elif mode is PeerMode.OFFBOARD and not self._offboard_signal_ok(now):
                self._ack(msg, cmd, denied)
            else:
                self._request_mode(mode, now)
                self._ack(msg, cmd, accepted)
        elif cmd == mavlink.MAV_CMD_REQUEST_MESSAGE:
            self._ack(
                msg,
                cmd,
                accepted if self._send_requested(int(msg.param1)) else mavlink.MAV_RESULT_UNSUPPORTED,
            )
        elif cmd == mavlink.MAV_CMD_SET_MESSAGE_INTERVAL:
            self._ack(msg, cmd, accepted)
        elif cmd == mavlink.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES:
            self._ack(msg, cmd, accepted)
            self._send_requested(mavlink.MAVLINK_MSG_ID_AUTOPILOT_VERSION)
        else:
            self._ack(msg, cmd, mavlink.MAV_RESULT_UNSUPPORTED)

    def _offboard_signal_ok(self, now: float) -> bool:
        return now - self._last_sp_t < 0.5 and now - self._sp_stream_start >= 1.0

    def _offboard_signal_lost(self, now: float) -> bool:
        return now - self._last_sp_t > self._params["COM_OF_LOSS_T"][0]

    def _gcs_lost(self, now: float) -> bool:
        return now - self._last_gcs_heartbeat_t > self._params["COM_DL_LOSS_T"][0]

    def _gcs_required_but_lost(self, now: float) -> bool:
        """PX4 makes a ground-station connection an arming check when NAV_DLL_ACT acts on its loss."""
        return int(self._params["NAV_DLL_ACT"][0]) != 0 and self._gcs_lost(now)

    def _can_arm(self, now: float) -> bool:
        """PX4's arming checks as modelled: COM_ARMABLE, an offboard signal when Offboard is asked for, and a
        ground station heard within COM_DL_LOSS_T when NAV_DLL_ACT is set."""
        if int(self._params["COM_ARMABLE"][0]) < 1 or self._gcs_required_but_lost(now):
            return False
        return not (self._intended is PeerMode.OFFBOARD and self._offboard_signal_lost(now))

    def _text(self, severity: int, text: str) -> None:
        """A STATUSTEXT line as PX4 sends it (with the tab PX4 ends evented lines with)."""
        self._texts.append((self._now(), severity, text))
        self._mav.statustext_send(severity, (text + "\t").encode()[:50])

    def _disarm(self, now: float, why: str) -> None:
        self._armed = False
        self._failsafe = None
        self._intended = self._after_disarm  # PX4 returns to the last mode asked for that allows arming
        self._show_mode(now)
        self._text(mavlink.MAV_SEVERITY_INFO, why)

    def _send_requested(self, message_id: int) -> bool:
        if message_id == mavlink.MAVLINK_MSG_ID_HOME_POSITION:
            self._send_home()
        elif message_id == mavlink.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN and self.answers_origin:
            lat, lon, alt = self.origin
            self._mav.gps_global_origin_send(
                int(round(lat * 1e7)), int(round(lon * 1e7)), int(round(alt * 1e3)), int(self._now() * 1e6)
            )
        elif message_id == mavlink.MAVLINK_MSG_ID_AUTOPILOT_VERSION:
            version = (1 << 24) | (16 << 16) | (0 << 8) | 255  # 1.16.0 release
            self._mav.autopilot_version_send(
                _CAPABILITIES, version, 0, 0, 0, [0] * 8, [0] * 8, [0] * 8, 0, 0, 1000 + self.system_id
            )
        else:
            return False
        return True

    def _request_mode(self, mode: PeerMode, now: float) -> None:
        """A mode asked for (ground station, pilot, or PX4's own step such as take-off done): it becomes the
        user's intention, ends any failsafe, and is where a disarm returns to unless it prevents arming."""
        self._intended = mode
        if mode not in NO_ARMING_MODES:
            self._after_disarm = mode
        self._failsafe = None
        self._show_mode(now)

    def _show_mode(self, now: float) -> None:
        """The mode the heartbeat shows: the failsafe's (Hold during its delay), else the one asked for."""
        fs = self._failsafe
        mode = self._intended if fs is None else (fs.action if now >= fs.act_at_t else PeerMode.HOLD)
        if mode is self._mode:
            return
        self._mode = mode
        self._mode_log.append((now, mode.name))
        if mode in (PeerMode.HOLD, *PILOT_MODES):
            self._hold_point = self._p.copy()
            if self._landed:
                self._hold_point[2] = self._ground_down_m
        elif mode is PeerMode.LAND:
            self._land_xy = self._p[:2].copy()

    # ------------------------------------------------------------------ dynamics and failsafes (lock held)
    def _step(self, now: float, dt: float) -> None:
        self._failsafes(now)
        if not self._armed:
            self._v[:] = 0.0
            self._accel[:] = 0.0
            self._yaw_rate = 0.0
            return
        self._battery = max(0.0, self._battery - 5e-4 * dt)
        target, v_ff, a_ff, yaw_target, vz_fixed = self._guidance(now)
        p_gain = 1.0
        v_cmd = v_ff + p_gain * (target - self._p)
        lim = float(self._params["MPC_XY_VEL_MAX"][0])
        horizontal = np.linalg.norm(v_cmd[:2])
        if horizontal > lim:
            v_cmd[:2] *= lim / horizontal
        if vz_fixed is not None:
            v_cmd[2] = vz_fixed
        v_cmd[2] = float(
            np.clip(v_cmd[2], -self._params["MPC_Z_VEL_MAX_UP"][0], self._params["MPC_Z_VEL_MAX_DN"][0])
        )
        a = a_ff + 3.0 * (v_cmd - self._v)
        norm = np.linalg.norm(a)
        if norm > self.max_accel_mps2:
            a *= self.max_accel_mps2 / norm
        self._accel = a
        self._v = self._v + a * dt
        self._p = self._p + self._v * dt
        if yaw_target is not None:
            err = (yaw_target - self._yaw + math.pi) % (2 * math.pi) - math.pi
            self._yaw_rate = float(np.clip(2.0 * err, -1.0, 1.0))
            self._yaw = (self._yaw + self._yaw_rate * dt + math.pi) % (2 * math.pi) - math.pi
        else:
            self._yaw_rate = 0.0
        self._ground_contact(now)

    def _guidance(self, now: float):
        """(target NED (3,), velocity and acceleration feed-forward (3,), yaw target or None, fixed vertical
        speed or None)."""
        zero = np.zeros(3)
        if self._mode is PeerMode.OFFBOARD and self._sp_used is not None:
            sp = self._sp_used
            mask = sp.type_mask
            pos = np.array(sp.position_ned) if not mask & IGNORE_POSITION else self._p.copy()
            vel = np.array(sp.velocity_ned) if not mask & IGNORE_VELOCITY else zero
            acc = np.array(sp.acceleration_ned) if not mask & IGNORE_ACCELERATION else zero
            yaw = None if mask & IGNORE_YAW else sp.yaw_rad
            return pos, vel, acc, yaw, None
        if self._mode is PeerMode.TAKEOFF:
            alt = float(self._params["MIS_TAKEOFF_ALT"][0])
            target = np.array([self._home_ned[0], self._home_ned[1], self._ground_down_m - alt])
            speed = float(self._params["MPC_TKO_SPEED"][0])
            vz = -speed if self._p[2] - target[2] > 0.5 else None
            if abs(self._p[2] - target[2]) < 0.2:
                self._request_mode(PeerMode.HOLD, now)  # PX4's navigator: take-off done, loiter
            return target, zero, zero, None, vz
        if self._mode is PeerMode.LAND:
            target = np.array([self._land_xy[0], self._land_xy[1], self._p[2]])
            return target, zero, zero, None, float(self._params["MPC_LAND_SPEED"][0])
        if self._mode is PeerMode.RTL:
            cruise_down = min(self._p[2], self._ground_down_m - 5.0)
            target = np.array([self._home_ned[0], self._home_ned[1], cruise_down])
            if np.linalg.norm(self._p[:2] - self._home_ned[:2]) < 1.0:
                if self._failsafe is not None:
                    self._failsafe.action = PeerMode.LAND
                    self._show_mode(now)
                else:
                    self._request_mode(PeerMode.LAND, now)
            return target, zero, zero, None, None
        return self._hold_point.copy(), zero, zero, None, None  # Hold and the pilot modes (sticks centred)

    def _ground_contact(self, now: float) -> None:
        if self._p[2] >= self._ground_down_m and self._v[2] >= 0.0:
            self._p[2] = self._ground_down_m
            self._v[:] = 0.0
            if not self._landed and self._mode is not PeerMode.TAKEOFF:
                self._landed, self._touchdown_t = True, now
                self._text(mavlink.MAV_SEVERITY_INFO, "Landing detected")
        elif self._p[2] < self._ground_down_m - 0.1:
            if self._landed:
                self._text(mavlink.MAV_SEVERITY_INFO, "Takeoff detected")
            self._landed, self._touchdown_t, self._flew_since_arming = False, None, True
        if (
            self._landed
            and self._flew_since_arming
            and self._touchdown_t is not None
            and now - self._touchdown_t > self._params["COM_DISARM_LAND"][0]
        ):
            self._disarm(now, "Disarmed by landing")

    def _failsafes(self, now: float) -> None:
        if (
            self._armed
            and not self._flew_since_arming
            and self._mode is not PeerMode.TAKEOFF
            and now - self._armed_t > self._params["COM_DISARM_PRFLT"][0]
        ):
            self._disarm(now, "Disarmed by auto preflight disarming")  # armed but never took off
        fs = self._failsafe
        gcs_lost = self._gcs_lost(now)
        if fs is not None and fs.cause == "offboard" and not self._offboard_signal_lost(now):
            self._failsafe = None  # a mode fallback: it ends, back to Offboard, once set-points come again
        elif fs is not None and fs.cause == "gcs" and fs.action is PeerMode.HOLD and not gcs_lost:
            self._failsafe = None
        elif fs is None and self._armed:
            dll = int(self._params["NAV_DLL_ACT"][0])
            if self._intended is PeerMode.OFFBOARD and self._offboard_signal_lost(now):
                action = OFFBOARD_LOSS_ACTIONS.get(int(self._params["COM_OBL_RC_ACT"][0]), PeerMode.LAND)
                self._failsafe = _Failsafe(cause="offboard", action=action, act_at_t=now)  # no Hold first
                self._text(mavlink.MAV_SEVERITY_CRITICAL, "Failsafe activated")
            elif (
                not self._landed
                and dll in LINK_LOSS_ACTIONS
                and self._intended is not PeerMode.LAND
                and gcs_lost
            ):
                delay = float(self._params["COM_FAIL_ACT_T"][0])
                self._failsafe = _Failsafe(cause="gcs", action=LINK_LOSS_ACTIONS[dll], act_at_t=now + delay)
                self._text(
                    mavlink.MAV_SEVERITY_CRITICAL, f"Failsafe activated: entering Hold for {delay:g} seconds"
                )
        self._show_mode(now)

    # ------------------------------------------------------------------ telemetry (lock held)
    def _geodetic_now(self) -> tuple[float, float, float]:
        lat, lon, alt = pymap3d.ned2geodetic(*self._p, *self.origin)
        return float(lat), float(lon), float(alt)

    def _send_heartbeat(self) -> None:
        base = mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
        if self._armed:
            base |= mavlink.MAV_MODE_FLAG_SAFETY_ARMED
            status = mavlink.MAV_STATE_CRITICAL if self._failsafe is not None else mavlink.MAV_STATE_ACTIVE
        else:
            can_arm = self._can_arm(self._now())
            status = mavlink.MAV_STATE_STANDBY if can_arm else mavlink.MAV_STATE_UNINIT
        self._mav.heartbeat_send(
            mavlink.MAV_TYPE_QUADROTOR, mavlink.MAV_AUTOPILOT_PX4, base, self._mode.custom_mode, status
        )

    def _send_fast(self, now: float) -> None:
        ms = int(now * 1e3)
        p, v = self._p, self._v
        self._mav.local_position_ned_send(ms, *p, *v)
        lat, lon, alt = self._geodetic_now()
        home_alt = pymap3d.ned2geodetic(*self._home_ned, *self.origin)[2]
        hdg = int(round(math.degrees(self._yaw) % 360.0 * 100)) % 36000
        self._mav.global_position_int_send(
            ms,
            int(round(lat * 1e7)),
            int(round(lon * 1e7)),
            int(round(alt * 1e3)),
            int(round((alt - home_alt) * 1e3)),
            int(round(v[0] * 100)),
            int(round(v[1] * 100)),
            int(round(v[2] * 100)),
            hdg,
        )
        roll, pitch = self._tilt()
        self._mav.attitude_send(ms, roll, pitch, self._yaw, 0.0, 0.0, self._yaw_rate)
        q = _quaternion(roll, pitch, self._yaw)
        self._mav.attitude_quaternion_send(ms, *q, 0.0, 0.0, self._yaw_rate)

    def _tilt(self) -> tuple[float, float]:
        """Roll and pitch that produce the commanded horizontal acceleration at this yaw (FRD body)."""
        cy, sy = math.cos(self._yaw), math.sin(self._yaw)
        forward = cy * self._accel[0] + sy * self._accel[1]
        right = -sy * self._accel[0] + cy * self._accel[1]
        return math.atan2(right, G_MPS2), -math.atan2(forward, G_MPS2)

    def _send_slow(self) -> None:
        if self._landed:
            landed = mavlink.MAV_LANDED_STATE_ON_GROUND
        elif self._mode is PeerMode.TAKEOFF:
            landed = mavlink.MAV_LANDED_STATE_TAKEOFF
        elif self._mode is PeerMode.LAND:
            landed = mavlink.MAV_LANDED_STATE_LANDING
        else:
            landed = mavlink.MAV_LANDED_STATE_IN_AIR
        self._mav.extended_sys_state_send(mavlink.MAV_VTOL_STATE_UNDEFINED, landed)
        healthy = _SENSORS
        if not self._armed and not self._can_arm(self._now()):
            healthy &= ~mavlink.MAV_SYS_STATUS_PREARM_CHECK  # PX4 clears its pre-arm bit: it cannot arm
        self._mav.sys_status_send(
            _SENSORS,
            _SENSORS,
            healthy,
            200,
            int(12600 + 4200 * self._battery),
            1000,
            int(round(self._battery * 100)),
            0,
            0,
            0,
            0,
            0,
            0,
        )
        lat, lon, alt = self._geodetic_now()
        self._mav.gps_raw_int_send(
            int(self._now() * 1e6),
            3,
            int(round(lat * 1e7)),
            int(round(lon * 1e7)),
            int(round(alt * 1e3)),
            80,
            120,
            0,
            0,
            14,
            0,
            300,
            500,
            100,
            0,
            0,
        )

    def _send_home(self) -> None:
        lat, lon, alt = pymap3d.ned2geodetic(*self._home_ned, *self.origin)
        self._mav.home_position_send(
            int(round(lat * 1e7)),
            int(round(lon * 1e7)),
            int(round(alt * 1e3)),
            float(self._home_ned[0]),
            float(self._home_ned[1]),
            float(self._home_ned[2]),
            [1.0, 0.0, 0.0, 0.0],
            0.0,
            0.0,
            0.0,
            int(self._now() * 1e6),
        )


def _quaternion(roll: float, pitch: float, yaw: float) -> tuple[float, float, float, float]:
    """(w, x, y, z) of the ZYX Euler angles."""
    cr, sr = math.cos(roll / 2), math.sin(roll / 2)
    cp, sp = math.cos(pitch / 2), math.sin(pitch / 2)
    cy, sy = math.cos(yaw / 2), math.sin(yaw / 2)
    return (
        cr * cp * cy + sr * sp * sy,
        sr * cp * cy - cr * sp * sy,
        cr * sp * cy + sr * cp * sy,
        cr * cp * sy - sr * sp * cy,
    )


# What skyring's set-points must look like: local NED position + velocity feed-forward + yaw (accelerations
# and yaw rate ignored), as MAVSDK's set_position_velocity_ned sends them.
POSITION_VELOCITY_ACCELERATION_YAW_MASK = IGNORE_YAW_RATE


def setpoint_problems(
    sp: SeenSetpoint, *, system_id: int, max_range_m: float = 1000.0, max_speed_mps: float = 20.0
) -> list[str]:
    """Everything wrong with one received set-point (empty when it is well-formed for vehicle system_id)."""
    problems = []
    if sp.target_system != system_id or sp.target_component != mavlink.MAV_COMP_ID_AUTOPILOT1:
        problems.append(f"addressed to {sp.target_system}/{sp.target_component}")
    if sp.frame != mavlink.MAV_FRAME_LOCAL_NED:
        problems.append(f"frame {sp.frame} is not MAV_FRAME_LOCAL_NED")
    if sp.type_mask != POSITION_VELOCITY_ACCELERATION_YAW_MASK:
        problems.append(f"type mask {sp.type_mask:#x} is not position + velocity + acceleration + yaw")
    values = (*sp.position_ned, *sp.velocity_ned, *sp.acceleration_ned, sp.yaw_rad)
    if not all(math.isfinite(v) for v in values):
        problems.append(f"non-finite values {values}")
    elif np.linalg.norm(sp.position_ned) > max_range_m or np.linalg.norm(sp.velocity_ned) > max_speed_mps:
        problems.append(f"out of range: position {sp.position_ned}, velocity {sp.velocity_ned}")
    elif not -math.pi - 1e-6 <= sp.yaw_rad <= math.pi + 1e-6:
        problems.append(f"yaw {sp.yaw_rad} outside [-pi, pi]")
    return problems

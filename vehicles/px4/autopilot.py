"""PX4 autopilots through MAVSDK 4: the `Autopilot` back-end for PX4 SITL and real vehicles.

One `Px4Autopilot` per vehicle, each with its own `Mavsdk` instance and connection URL. `connect()` waits for
the autopilot and its position, sets the failsafe parameters skyring relies on (`Px4Config.failsafe_params`),
and reads the estimator origin; it adopts the vehicle in whatever state it is found (on the ground in any
mode, flying, in a failsafe) and changes nothing until asked. `start()` then runs, on the event loop it was
connected on, one reader task per telemetry stream into a state cache, a supervisor task
(vehicles/px4/supervisor.py: engagement, the set-point watchdog, respect for a pilot and for PX4's failsafes)
and a set-point streaming task. The `Autopilot` methods are non-blocking requests, safe to call from any
thread.

Frames: the team's ENU frame is converted to the vehicle's local NED frame here and nowhere else
(vehicles/px4/geodesy.py). Telemetry goes the other way. Link loss (no telemetry for `link_lost_after_s`) is
reported in `AutopilotState.link_lost`.

Take-off works from every mode PX4 can be in on the ground: after a disarm PX4 v1.16 returns to the last mode
that allows arming (Offboard after an offboard flight), where it refuses to arm without a set-point stream;
so skyring first asks for Hold (PX4 accepts that disarmed), then arms and takes off. What PX4 says reaches
the state: its own mode name, whether it runs a failsafe (the critical system status of its
heartbeat) and why, whether it can arm, and why it refused (STATUSTEXT and, where the vehicle serves them,
PX4 events; vehicles/px4/notices.py).
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import math
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from controller.messages import frozen_array
from vehicles.autopilot import AutopilotState, FlightMode, Setpoint
from vehicles.px4.geodesy import GeodeticPoint, LocalFrame, geodetic_to_enu
from vehicles.px4.notices import (
    FAILSAFE_ACTION_EVENTS,
    SEVERITY_ERROR,
    Px4Message,
    Px4Notices,
    statustext_severity,
)
from vehicles.px4.supervisor import Command, Engagement, Observation, OffboardSupervisor, SupervisorParams

if TYPE_CHECKING:
    from mavsdk.asyncio import Mavsdk
    from mavsdk.asyncio.plugins.action import ActionAsync
    from mavsdk.asyncio.plugins.events import EventsAsync
    from mavsdk.asyncio.plugins.mavlink_direct import MavlinkDirectAsync
    from mavsdk.asyncio.plugins.offboard import OffboardAsync
    from mavsdk.asyncio.plugins.param import ParamAsync
    from mavsdk.asyncio.plugins.telemetry import TelemetryAsync


log = logging.getLogger(__name__)

# COM_OBL_RC_ACT values skyring accepts for the offboard-loss failsafe, and NAV_DLL_ACT values for GCS loss.
OFFBOARD_LOSS_ACTIONS = {3: "Return", 4: "Land", 5: "Hold"}
DATALINK_LOSS_ACTIONS = {0: "Disabled", 1: "Hold", 2: "Return", 3: "Land"}
# COM_LOW_BAT_ACT values: what PX4 does at critical battery (its default, 0, only warns).
LOW_BATTERY_ACTIONS = {0: "Warning", 2: "Land", 3: "Return at critical, land at emergency"}

# HEARTBEAT system_status values PX4 sends: STANDBY disarmed with its pre-arm checks passing, ACTIVE armed,
# CRITICAL armed and running a failsafe (UNINIT: disarmed and unable to arm in its current mode).
MAV_STATE_STANDBY, MAV_STATE_ACTIVE, MAV_STATE_CRITICAL = 3, 4, 5
MAV_MODE_FLAG_SAFETY_ARMED = 128
MAV_COMP_ID_AUTOPILOT1 = 1

# MAVSDK telemetry flight modes -> skyring's (pilot modes all read as MANUAL; missions are someone else's).
_MODES = {
    "READY": FlightMode.READY,
    "TAKEOFF": FlightMode.TAKEOFF,
    "HOLD": FlightMode.HOLD,
    "RETURN_TO_LAUNCH": FlightMode.RETURN,
    "LAND": FlightMode.LAND,
    "OFFBOARD": FlightMode.OFFBOARD,
    "MANUAL": FlightMode.MANUAL,
    "ALTCTL": FlightMode.MANUAL,
    "POSCTL": FlightMode.MANUAL,
    "ACRO": FlightMode.MANUAL,
    "STABILIZED": FlightMode.MANUAL,
    "RATTITUDE": FlightMode.MANUAL,
}


class Px4Error(RuntimeError):
    """Connecting to or configuring a PX4 vehicle failed; the message says what to check."""


@dataclass(frozen=True)
class Px4Config:
    """How skyring talks to PX4.

    connect_timeout_s: wait for the autopilot's heartbeat; health_timeout_s: wait for global/local/home
    position and calibrated sensors (and pre-arm checks when require_armable); link_lost_after_s: no telemetry
    for this long flags LINK_LOST; offboard_loss_timeout_s and offboard_loss_action: PX4's COM_OF_LOSS_T and
    COM_OBL_RC_ACT (3 Return, 4 Land, 5 Hold): what PX4 does when skyring's set-points stop arriving;
    datalink_loss_action: NAV_DLL_ACT (0 off, 1 Hold, 2 Return, 3 Land) after COM_DL_LOSS_T without a ground
    station heartbeat, which covers a vehicle left hovering in Hold; low_battery_action: COM_LOW_BAT_ACT (0
    warn only, 2 Land, 3 Return then land; None leaves the vehicle's own setting); require_armable: also wait
    for PX4's pre-arm checks at connect (off: a vehicle found in Offboard after an earlier flight cannot arm
    until skyring switches its mode, and must still be adopted); supervise_period_s: supervisor tick;
    max_setpoint_rate_hz: set-points forwarded to MAVSDK at most this often (it re-sends the latest at 20 Hz);
    max_setpoint_range_m: set-points farther than this from the team origin are rejected and counted;
    min_takeoff_altitude_m: the lowest takeoff altitude above home skyring asks for; armable_wait_s: after
    asking for Hold, how long a take-off waits for PX4 to report it can arm before arming (PX4 re-runs its
    arming checks at 10 Hz, after a mode change and after a ground station comes back; an arming request
    before that is refused), then it arms all the same and PX4's refusal, if any, tells why.
    """

    connect_timeout_s: float = 30.0
    health_timeout_s: float = 60.0
    link_lost_after_s: float = 1.0
    offboard_loss_timeout_s: float = 1.0
    offboard_loss_action: int = 4
    datalink_loss_action: int = 3
    low_battery_action: int | None = 2
    require_armable: bool = False
    supervise_period_s: float = 0.05
    max_setpoint_rate_hz: float = 20.0
    max_setpoint_range_m: float = 2000.0
    min_takeoff_altitude_m: float = 1.0
    command_timeout_s: float = 10.0
    armable_wait_s: float = 3.0
    supervisor: SupervisorParams = field(default_factory=SupervisorParams)

    def __post_init__(self) -> None:
        if self.offboard_loss_action not in OFFBOARD_LOSS_ACTIONS:
            raise ValueError(
                f"offboard_loss_action (COM_OBL_RC_ACT) must be one of {OFFBOARD_LOSS_ACTIONS}, "
                f"got {self.offboard_loss_action}"
            )
        if self.datalink_loss_action not in DATALINK_LOSS_ACTIONS:
            raise ValueError(
                f"datalink_loss_action (NAV_DLL_ACT) must be one of {DATALINK_LOSS_ACTIONS}, "
                f"got {self.datalink_loss_action}"
            )
        if self.supervisor.stall_land_after_s <= self.offboard_loss_timeout_s:
            raise ValueError(
                f"supervisor.stall_land_after_s ({self.supervisor.stall_land_after_s} s) must exceed "
                f"offboard_loss_timeout_s ({self.offboard_loss_timeout_s} s): only a stall longer than PX4's "
                "offboard-loss timeout has set off its failsafe"
            )
        if self.low_battery_action is not None and self.low_battery_action not in LOW_BATTERY_ACTIONS:
            raise ValueError(
                f"low_battery_action (COM_LOW_BAT_ACT) must be one of {LOW_BATTERY_ACTIONS} or None, "
                f"got {self.low_battery_action}"
            )
        for name in (
            "connect_timeout_s",
            "health_timeout_s",
            "link_lost_after_s",
            "offboard_loss_timeout_s",
            "supervise_period_s",
            "max_setpoint_rate_hz",
            "max_setpoint_range_m",
            "command_timeout_s",
        ):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be a positive finite number, got {value}")
        if not (math.isfinite(self.armable_wait_s) and 0.0 <= self.armable_wait_s < self.command_timeout_s):
            raise ValueError(
                f"armable_wait_s must be >= 0 and below command_timeout_s ({self.command_timeout_s} s), "
                f"got {self.armable_wait_s}"
            )

    def failsafe_params(self) -> dict[str, float | int]:
        """The PX4 parameters skyring sets on every vehicle it connects to (floats stay floats)."""
        params: dict[str, float | int] = {
            "COM_OF_LOSS_T": float(self.offboard_loss_timeout_s),
            "COM_OBL_RC_ACT": int(self.offboard_loss_action),
            "NAV_DLL_ACT": int(self.datalink_loss_action),
        }
        if self.low_battery_action is not None:
            params["COM_LOW_BAT_ACT"] = int(self.low_battery_action)
        return params


@dataclass(frozen=True, eq=False)
class NedSetpoint:
    """A set-point in one vehicle's local NED frame, as MAVSDK's offboard plugin takes it.

    position_ned_m (3,), velocity_ned_mps (3,) and acceleration_ned_mps2 (3,) feed-forward, yaw_ned_deg (0 =
    north, clockwise; degrees is what MAVSDK's PositionNedYaw wants).
    """

    position_ned_m: np.ndarray
    velocity_ned_mps: np.ndarray
    yaw_ned_deg: float
    acceleration_ned_mps2: np.ndarray = field(default_factory=lambda: np.zeros(3))

    def __post_init__(self) -> None:
        object.__setattr__(self, "position_ned_m", frozen_array(self.position_ned_m, (3,), "position_ned_m"))
        object.__setattr__(
            self, "velocity_ned_mps", frozen_array(self.velocity_ned_mps, (3,), "velocity_ned_mps")
        )
        object.__setattr__(
            self,
            "acceleration_ned_mps2",
            frozen_array(self.acceleration_ned_mps2, (3,), "acceleration_ned_mps2"),
        )


def ned_setpoint(setpoint: Setpoint, frame: LocalFrame) -> NedSetpoint:
    """The team-ENU set-point expressed in the vehicle's local NED frame (position, velocity, acceleration and
    yaw)."""
    return NedSetpoint(
        position_ned_m=frame.to_ned(setpoint.position_m),
        velocity_ned_mps=frame.vector_to_ned(setpoint.velocity_mps),
        yaw_ned_deg=math.degrees(frame.yaw_to_ned(setpoint.yaw_rad)),
        acceleration_ned_mps2=frame.vector_to_ned(setpoint.acceleration_mps2),
    )


def skyring_mode(px4_mode: str, *, armed: bool, in_air: bool) -> FlightMode:
    """skyring's reading of a MAVSDK flight-mode name: READY on the ground disarmed, pilot modes MANUAL."""
    if not armed and not in_air:
        return FlightMode.READY
    return _MODES.get(px4_mode, FlightMode.UNKNOWN)


def check_setpoint(setpoint: object, *, max_range_m: float) -> str | None:
    """Why a set-point must be refused, or None when it is acceptable."""
    if not isinstance(setpoint, Setpoint):
        return f"expected a Setpoint, got {type(setpoint).__name__}"
    distance = float(np.linalg.norm(setpoint.position_m))
    if distance > max_range_m:
        return f"set-point {distance:.0f} m from the team origin is beyond the {max_range_m:.0f} m limit"
    return None


def frozen(gap_s: float, cpu_s: float) -> bool:
    """Whether a process stood frozen through a gap of gap_s seconds in which all its threads used cpu_s of
    CPU: next to none (a stopped process uses none; a busy or starved one keeps using some)."""
    return gap_s > 0.0 and cpu_s < 0.02 + 0.01 * gap_s


def sitl_urls(count: int, *, first_port: int = 14540, host: str = "0.0.0.0") -> list[str]:
    """URLs for `count` local PX4 SITL instances: instance i sends to UDP 14540 + i (from i = 9 on: 14549)."""
    if count < 1:
        raise ValueError(f"need at least one SITL instance, got {count}")
    return [f"udpin://{host}:{first_port + min(i, 9)}" for i in range(count)]


class TelemetryCache:
    """The latest value of every telemetry stream, written by the reader tasks, read by `state()` from any
    thread (guarded by a lock). Local NED position/velocity, attitude (NED yaw), geodetic position and home,
    flags, battery, health, GPS accuracy, PX4's heartbeat system status and messages (`notices`);
    `received_s` holds when each stream last delivered."""

    def __init__(self) -> None:
        self.lock = threading.Lock()
        self.local_ned_m: np.ndarray | None = None
        self.velocity_ned_mps = np.zeros(3)
        self.position: GeodeticPoint | None = None
        self.home: GeodeticPoint | None = None
        self.roll_rad = 0.0
        self.pitch_rad = 0.0
        self.yaw_ned_rad = 0.0
        self.armed = False
        self.in_air = False
        self.px4_mode = "UNKNOWN"
        self.battery_fraction: float | None = None
        self.health: dict[str, bool] = {}
        self.gps_std_m: tuple[float, float] | None = None
        self.system_status: int | None = None
        self.failsafe_since_s: float | None = None
        self.failsafe_reports = 0  # critical heartbeats and Land (EXTENDED_SYS_STATE) readings so far
        self.failsafe_report_s: float | None = None
        self.notices = Px4Notices()
        self.received_s: dict[str, float] = {}
        self.position_stamp_s = -math.inf
        self.malformed = 0

    def last_received_s(self) -> float:
        return max(self.received_s.values(), default=-math.inf)


def _finite(*values: float) -> bool:
    return all(v is not None and math.isfinite(v) for v in values)


def _geodetic(message) -> GeodeticPoint | None:
    """A MAVSDK position or home message (latitude_deg, longitude_deg, absolute_altitude_m) as a point; None
    when a coordinate is not finite."""
    lat, lon, alt = message.latitude_deg, message.longitude_deg, message.absolute_altitude_m
    return GeodeticPoint(lat, lon, alt) if _finite(lat, lon, alt) else None


@dataclass(frozen=True)
class Px4Status:
    """The back-end's own view of one vehicle, for the ground station and logs.

    engagement: `vehicles.px4.supervisor.Engagement` value; setpoint_age_s: age of the agent's last set-point;
    counters: set-points ignored (not engaged) or rejected (malformed), land/hold requests not sent because a
    pilot flies the vehicle, watchdog holds/landings, take-offs that failed (PX4 refused to arm, or no
    answer), commands PX4 refused or that timed out, telemetry readings dropped as malformed; frame_source:
    "origin" (the estimator origin) or "fix" (inferred from one position reading); fault: the last problem.
    """

    vehicle_id: int
    url: str
    engagement: str
    released_reason: str | None
    link_lost: bool
    setpoint_age_s: float
    ignored_setpoints: int
    ignored_requests: int
    rejected_setpoints: int
    watchdog_holds: int
    watchdog_landings: int
    takeoff_failures: int
    failed_commands: int
    malformed_telemetry: int
    frame_source: str | None
    fault: str | None


@dataclass
class _Plugins:
    """The MAVSDK instance and plugins of one connected vehicle."""

    mavsdk: Mavsdk
    telemetry: TelemetryAsync
    action: ActionAsync
    offboard: OffboardAsync
    param: ParamAsync
    events: EventsAsync
    direct: MavlinkDirectAsync

    def destroy(self) -> None:
        for plugin in (self.telemetry, self.action, self.offboard, self.param, self.events, self.direct):
            plugin.destroy()
        self.mavsdk.destroy()


class Px4Autopilot:
    """One PX4 vehicle behind the `Autopilot` protocol. `await connect()`, `set_reference(...)`, `start()`.

    clock: the wall clock the watchdog and link-loss detection run on (seconds, monotonic). AutopilotState
    stamps are on the same clock unless `use_stamp_clock` gives the caller's (e.g. a ground station's mission
    time): a reading's age is then carried over to that clock. cpu_clock: the CPU time of the whole process
    (all its threads, MAVSDK's included), which tells a frozen process from a busy or starved one.
    """

    def __init__(
        self,
        *,
        vehicle_id: int,
        url: str,
        config: Px4Config = Px4Config(),
        clock: Callable[[], float] = time.monotonic,
        cpu_clock: Callable[[], float] = time.process_time,
    ) -> None:
        self.vehicle_id = int(vehicle_id)
        self.url = url
        self.config = config
        self._clock = clock
        self._cpu_clock = cpu_clock
        self._cache = TelemetryCache()
        self._supervisor = OffboardSupervisor(config.supervisor)
        self._loop: asyncio.AbstractEventLoop | None = None
        self._plugins: _Plugins | None = None
        self._tasks: list[asyncio.Task] = []
        self._frame: LocalFrame | None = None
        self._frame_source: str | None = None
        self._origin: GeodeticPoint | None = None
        self._reference: GeodeticPoint | None = None
        self._latest_setpoint: Setpoint | None = None
        self._setpoint_event = asyncio.Event()
        self._rejected_setpoints = 0
        self._failed_commands = 0
        self._fault: str | None = None
        self._refused_at_s: float | None = None  # when PX4 last refused a take-off (arming) skyring asked for
        self._refusal_fallback = ""
        self._failsafe_reports_seen = 0
        self._last_beat_s: float | None = None  # when the event loop last let `_beat` run
        self._last_beat_cpu_s = 0.0  # the process's CPU time then
        self._loop_gap_s = 0.0  # the longest the whole process stood frozen since the supervisor last looked
        self._executing = False
        self._stamp_clock: Callable[[], float] | None = None

    # ---- connection ---------------------------------------------------------------------------------------
    async def connect(self) -> None:
        """Connect, wait for health, set the failsafe parameters and read the estimator origin."""
        from mavsdk import ComponentType, Configuration
        from mavsdk.asyncio import Mavsdk, MavsdkConnectionError
        from mavsdk.asyncio.plugins.action import ActionAsync
        from mavsdk.asyncio.plugins.events import EventsAsync
        from mavsdk.asyncio.plugins.mavlink_direct import MavlinkDirectAsync
        from mavsdk.asyncio.plugins.offboard import OffboardAsync
        from mavsdk.asyncio.plugins.param import ParamAsync
        from mavsdk.asyncio.plugins.telemetry import TelemetryAsync

        self._loop = asyncio.get_running_loop()
        mavsdk = Mavsdk(Configuration.create_with_component_type(ComponentType.GROUND_STATION))
        try:
            await mavsdk.add_any_connection(self.url)
        except MavsdkConnectionError as exc:
            mavsdk.destroy()
            raise Px4Error(f"vehicle {self.vehicle_id}: cannot open {self.url}: {exc}") from exc
        system = await mavsdk.first_autopilot(timeout_s=self.config.connect_timeout_s)
        if system is None:
            mavsdk.destroy()
            raise Px4Error(
                f"vehicle {self.vehicle_id}: no autopilot heard on {self.url} within "
                f"{self.config.connect_timeout_s:.0f} s; is PX4 running and sending to that port?"
            )
        self._plugins = _Plugins(
            mavsdk=mavsdk,
            telemetry=TelemetryAsync(system),
            action=ActionAsync(system),
            offboard=OffboardAsync(system),
            param=ParamAsync(system),
            events=EventsAsync(system),
            direct=MavlinkDirectAsync(system),
        )
        self._start_readers()
        await self._wait_healthy()
        await self._set_failsafe_params()
        await self._read_origin()

    async def _wait_healthy(self) -> None:
        needed = ["is_local_position_ok", "is_global_position_ok", "is_home_position_ok"]
        if self.config.require_armable:
            needed.append("is_armable")
        deadline = self._clock() + self.config.health_timeout_s
        while True:
            with self._cache.lock:
                health = dict(self._cache.health)
                ready = self._cache.local_ned_m is not None and self._cache.home is not None
            missing = [name for name in needed if not health.get(name, False)]
            if not missing and ready:
                return
            if self._clock() > deadline:
                what = ", ".join(missing) or "a local position and a home position"
                raise Px4Error(
                    f"vehicle {self.vehicle_id} ({self.url}) not healthy after "
                    f"{self.config.health_timeout_s:.0f} s: waiting for {what}"
                )
            await asyncio.sleep(0.1)

    async def _set_failsafe_params(self) -> None:
        from mavsdk.asyncio.plugins.param import ParamError

        param = self._p.param
        for name, value in self.config.failsafe_params().items():
            try:
                if isinstance(value, int):
                    await param.set_param_int(name, value)
                    readback = await param.get_param_int(name)
                else:
                    await param.set_param_float(name, value)
                    readback = await param.get_param_float(name)
            except ParamError as exc:
                raise Px4Error(f"vehicle {self.vehicle_id}: could not set {name} = {value}: {exc}") from exc
            if not math.isclose(readback, value, abs_tol=1e-4):
                raise Px4Error(f"vehicle {self.vehicle_id}: {name} reads back {readback}, not {value}")

    async def _read_origin(self) -> None:
        from mavsdk.asyncio.plugins.telemetry import TelemetryError

        try:
            origin = await asyncio.wait_for(self._p.telemetry.get_gps_global_origin(), timeout=5.0)
        except (TimeoutError, TelemetryError) as exc:
            log.warning(
                "vehicle %d: no GPS_GLOBAL_ORIGIN (%s); inferring it from a position fix",
                self.vehicle_id,
                exc,
            )
            return
        if _finite(origin.latitude_deg, origin.longitude_deg, origin.altitude_m):
            self._origin = GeodeticPoint(origin.latitude_deg, origin.longitude_deg, origin.altitude_m)

    @property
    def home(self) -> GeodeticPoint | None:
        """The vehicle's home (where it last armed or booted), geodetic."""
        with self._cache.lock:
            return self._cache.home

    def set_reference(self, reference: GeodeticPoint) -> None:
        """Place this vehicle in the team's ENU frame about `reference`; telemetry and set-points use it."""
        if self._origin is not None:
            self._frame = LocalFrame.from_origin(local_origin=self._origin, reference=reference)
            self._frame_source = "origin"
        else:
            with self._cache.lock:
                position, local = self._cache.position, self._cache.local_ned_m
            if position is None or local is None:
                raise Px4Error(f"vehicle {self.vehicle_id}: no position yet to place it in the team frame")
            self._frame = LocalFrame.from_fix(position=position, local_ned_m=local, reference=reference)
            self._frame_source = "fix"
        self._reference = reference

    def use_stamp_clock(self, stamp_clock: Callable[[], float]) -> None:
        """Stamp `state()` readings on the caller's clock: now on stamp_clock minus the reading's age."""
        self._stamp_clock = stamp_clock

    def start(self) -> None:
        """Run the supervisor and the set-point streamer (after `connect` and `set_reference`)."""
        if self._frame is None or self._loop is None:
            raise Px4Error(f"vehicle {self.vehicle_id}: connect and set_reference before start")
        name = f"px4-{self.vehicle_id}"
        self._tasks.append(self._loop.create_task(self._beat(), name=f"{name}-beat"))
        self._tasks.append(self._loop.create_task(self._supervise(), name=f"{name}-supervisor"))
        self._tasks.append(self._loop.create_task(self._stream(), name=f"{name}-stream"))

    async def settle(self, timeout_s: float = 5.0) -> bool:
        """Wait until every request made so far was acted on and no command is in flight (e.g. the landing
        asked for at shutdown has reached PX4); False if that took longer than timeout_s."""
        deadline = self._clock() + timeout_s
        await asyncio.sleep(0)  # let requests handed over from other threads arrive
        while self._supervisor.pending or self._executing:
            if self._clock() > deadline or not self._tasks:
                return False
            await asyncio.sleep(0.02)
        return True

    async def close(self) -> None:
        """Stop every task and release MAVSDK (the vehicle keeps doing what PX4 last decided)."""
        for task in self._tasks:
            task.cancel()
        for task in self._tasks:
            with contextlib.suppress(asyncio.CancelledError, Exception):
                await task
        self._tasks.clear()
        if self._plugins is not None:
            self._plugins.destroy()
            self._plugins = None

    # ---- the Autopilot protocol ---------------------------------------------------------------------------
    def state(self) -> AutopilotState | None:
        frame = self._frame
        if frame is None:
            return None
        c = self._cache
        now = self._clock()
        with c.lock:
            if c.local_ned_m is None:
                return None
            local, velocity = c.local_ned_m.copy(), c.velocity_ned_mps.copy()
            roll, pitch, yaw_ned = c.roll_rad, c.pitch_rad, c.yaw_ned_rad
            armed, in_air, px4_mode = c.armed, c.in_air, c.px4_mode
            battery, health, gps_std = c.battery_fraction, dict(c.health), c.gps_std_m
            stamp, last = c.position_stamp_s, c.last_received_s()
            failsafe = self._failsafe_locked()
            failsafe_reason = None
            if failsafe and c.failsafe_since_s is not None:
                failsafe_reason = c.notices.failsafe_reason(since_s=c.failsafe_since_s)
            elif self._supervisor.failsafe_landing or self._stalled(now):
                failsafe = True  # PX4's failsafe landing, which skyring keeps going
                failsafe_reason = self._failsafe_landing_reason(now)
            can_arm = self._can_arm_locked()
            refusal = None
            if self._refused_at_s is not None and not (armed or in_air):
                refusal = c.notices.arming_refusal(
                    refused_at_s=self._refused_at_s, fallback=self._refusal_fallback
                )
        cov = np.eye(3) * 0.25
        if gps_std is not None:
            cov = np.diag([gps_std[0] ** 2, gps_std[0] ** 2, gps_std[1] ** 2])
        if self._stamp_clock is not None:
            stamp = self._stamp_clock() - (now - stamp)
        healthy = all(
            health.get(k, False)
            for k in (
                "is_local_position_ok",
                "is_global_position_ok",
                "is_gyrometer_calibration_ok",
                "is_accelerometer_calibration_ok",
            )
        )
        return AutopilotState(
            vehicle_id=self.vehicle_id,
            stamp_s=stamp,
            position_m=frame.to_enu(local),
            velocity_mps=frame.vector_to_enu(velocity),
            yaw_rad=frame.yaw_to_enu(yaw_ned),
            armed=armed,
            in_air=in_air,
            mode=skyring_mode(px4_mode, armed=armed, in_air=in_air),
            roll_rad=roll,
            pitch_rad=pitch,
            battery_fraction=battery,
            healthy=healthy,
            position_cov_m2=cov,
            link_lost=now - last > self.config.link_lost_after_s,
            released=self._supervisor.released,
            autopilot_mode=px4_mode,
            failsafe=failsafe,
            failsafe_reason=failsafe_reason,
            can_arm=can_arm,
            arming_refusal=refusal,
        )

    def _loop_stall_s(self, now: float) -> float:
        """The longest the whole process stood frozen since the supervisor last looked, counting the gap
        since the last beat when the process used next to no CPU in it (it was stopped, not busy)."""
        running = 0.0
        if self._last_beat_s is not None:
            gap = now - self._last_beat_s
            running = gap if frozen(gap, self._cpu_clock() - self._last_beat_cpu_s) else 0.0
        return max(self._loop_gap_s, running)

    def _stalled(self, now: float) -> bool:
        """The whole ground station stalled long enough for PX4's offboard-loss failsafe (the supervisor's
        rule, `OffboardSupervisor.stall_lands`): the supervisor lands it next step (cache lock held)."""
        c = self._cache
        mode = skyring_mode(c.px4_mode, armed=c.armed, in_air=c.in_air)
        return self._supervisor.stall_lands(mode, self._loop_stall_s(now))

    def _failsafe_landing_reason(self, now: float) -> str:
        """Why a vehicle lands for PX4's failsafe that PX4 itself no longer reports (cache lock held)."""
        c = self._cache
        stall = self._supervisor.stall_s
        if stall is None and self._stalled(now):
            stall = self._loop_stall_s(now)
        said = (
            c.notices.failsafe_reason(since_s=c.failsafe_report_s)
            if c.failsafe_report_s is not None
            else None
        )
        if stall is not None and (said is None or said.startswith("PX4 failsafe (PX4 gave no reason)")):
            return (
                f"the ground station stalled {stall:.1f} s, past PX4's offboard-loss timeout "
                f"({self.config.offboard_loss_timeout_s:g} s): PX4 lands it, and skyring keeps it landing"
            )
        return f"{said or 'PX4 failsafe'}; PX4 left it, skyring keeps it landing"

    def _failsafe_locked(self) -> bool:
        """PX4 runs a failsafe: its heartbeat says armed with a critical system status (cache lock held)."""
        return self._cache.failsafe_since_s is not None

    def _can_arm_locked(self) -> bool | None:
        """PX4's pre-arm checks pass in its current mode (None while armed or not yet known; lock held)."""
        c = self._cache
        if c.armed:
            return None
        if "is_armable" in c.health:
            return c.health["is_armable"]
        if c.system_status is None:
            return None
        return c.system_status == MAV_STATE_STANDBY

    def send_setpoint(self, setpoint: Setpoint) -> None:
        reason = check_setpoint(setpoint, max_range_m=self.config.max_setpoint_range_m)
        if reason is None and self._loop is None:
            reason = "not connected"
        if reason is not None:
            self._rejected_setpoints += 1
            self._fault = f"set-point refused: {reason}"
            return
        self._on_loop(self._accept_setpoint, setpoint)

    def takeoff(self, height_m: float) -> None:
        if not (isinstance(height_m, int | float) and math.isfinite(height_m) and 0.5 <= height_m <= 120.0):
            self._failed_commands += 1
            self._fault = f"takeoff refused: height must be within [0.5, 120] m, got {height_m!r}"
            return
        self._on_loop(self._supervisor.request_takeoff, float(height_m))

    def hold(self) -> None:
        self._on_loop(self._supervisor.request_hold)

    def land(self) -> None:
        self._on_loop(self._supervisor.request_land)

    def status(self) -> Px4Status:
        """Engagement, watchdog and link details beyond `AutopilotState`."""
        s = self._supervisor
        with self._cache.lock:
            last = self._cache.last_received_s()
            malformed = self._cache.malformed
        now = self._clock()
        return Px4Status(
            vehicle_id=self.vehicle_id,
            url=self.url,
            engagement=s.engagement.value,
            released_reason=s.released_reason,
            link_lost=now - last > self.config.link_lost_after_s,
            setpoint_age_s=s.setpoint_age_s(now),
            ignored_setpoints=s.ignored_setpoints,
            ignored_requests=s.ignored_requests,
            rejected_setpoints=self._rejected_setpoints,
            watchdog_holds=s.watchdog_holds,
            watchdog_landings=s.watchdog_landings,
            takeoff_failures=s.takeoff_failures,
            failed_commands=self._failed_commands,
            malformed_telemetry=malformed,
            frame_source=self._frame_source,
            fault=self._fault,
        )

    # ---- internals: threading -----------------------------------------------------------------------------
    @property
    def _p(self) -> _Plugins:
        """The connected vehicle's MAVSDK plugins (Px4Error before `connect` or after `close`)."""
        if self._plugins is None:
            raise Px4Error(f"vehicle {self.vehicle_id}: not connected")
        return self._plugins

    def _require_loop(self) -> asyncio.AbstractEventLoop:
        if self._loop is None:
            raise Px4Error(f"vehicle {self.vehicle_id}: not connected")
        return self._loop

    def _on_loop(self, fn: Callable, *args) -> None:
        """Run fn on the back-end's loop: at once when called on it, else handed over thread-safely."""
        if self._loop is None:
            self._failed_commands += 1
            self._fault = f"{getattr(fn, '__name__', 'command')} refused: not connected"
            return
        try:
            running = asyncio.get_running_loop()
        except RuntimeError:
            running = None
        if running is self._loop:
            fn(*args)
        else:
            self._loop.call_soon_threadsafe(fn, *args)

    def _accept_setpoint(self, setpoint: Setpoint) -> None:
        if self._supervisor.note_setpoint(self._clock()):
            self._latest_setpoint = setpoint
            self._setpoint_event.set()

    # ---- internals: telemetry readers ---------------------------------------------------------------------
    def _start_readers(self) -> None:
        t, direct, events = self._p.telemetry, self._p.direct, self._p.events
        streams = {
            "position_velocity_ned": (t.subscribe_position_velocity_ned, self._on_position_velocity_ned),
            "position": (t.subscribe_position, self._on_position),
            "attitude": (t.subscribe_attitude_euler, self._on_attitude),
            "armed": (t.subscribe_armed, self._on_armed),
            "flight_mode": (t.subscribe_flight_mode, self._on_flight_mode),
            "landed_state": (t.subscribe_landed_state, self._on_landed_state),
            "battery": (t.subscribe_battery, self._on_battery),
            "health": (t.subscribe_health, self._on_health),
            "home": (t.subscribe_home, self._on_home),
            "raw_gps": (t.subscribe_raw_gps, self._on_raw_gps),
            "status_text": (t.subscribe_status_text, self._on_status_text),
            "heartbeat": (lambda: direct.subscribe_message("HEARTBEAT"), self._on_heartbeat),
            "events": (events.subscribe_events, self._on_event),
            "arming_checks": (events.subscribe_health_and_arming_checks, self._on_arming_checks),
        }
        loop = self._require_loop()
        for name, (subscribe, apply) in streams.items():
            self._tasks.append(
                loop.create_task(self._read(name, subscribe, apply), name=f"px4-{self.vehicle_id}-{name}")
            )

    async def _read(self, name: str, subscribe: Callable, apply: Callable) -> None:
        """One telemetry stream into the cache; a failing stream is logged and re-subscribed, never fatal."""
        while True:
            try:
                async for item in subscribe():
                    now = self._clock()
                    with self._cache.lock:
                        if apply(item, now) is False:
                            self._cache.malformed += 1
                        self._cache.received_s[name] = now
            except asyncio.CancelledError:
                raise
            except Exception as exc:  # a broken stream must not stop the others
                self._fault = f"telemetry {name}: {exc}"
                log.warning("vehicle %d: telemetry %s failed: %s", self.vehicle_id, name, exc)
                await asyncio.sleep(1.0)

    # Each _on_* runs with the cache lock held; returning False counts the reading as malformed.
    def _on_position_velocity_ned(self, pv, now: float) -> bool:
        p, v = pv.position, pv.velocity
        if not _finite(p.north_m, p.east_m, p.down_m, v.north_m_s, v.east_m_s, v.down_m_s):
            return False
        self._cache.local_ned_m = np.array([p.north_m, p.east_m, p.down_m])
        self._cache.velocity_ned_mps = np.array([v.north_m_s, v.east_m_s, v.down_m_s])
        self._cache.position_stamp_s = now
        return True

    def _on_position(self, p, now: float) -> bool:
        point = _geodetic(p)
        if point is None:
            return False
        self._cache.position = point
        return True

    def _on_attitude(self, a, now: float) -> bool:
        if not _finite(a.roll_deg, a.pitch_deg, a.yaw_deg):
            return False
        c = self._cache
        c.roll_rad, c.pitch_rad, c.yaw_ned_rad = (
            math.radians(a.roll_deg),
            math.radians(a.pitch_deg),
            math.radians(a.yaw_deg),
        )
        return True

    def _on_armed(self, armed, now: float) -> bool:
        self._cache.armed = bool(armed)
        return True

    def _on_flight_mode(self, mode, now: float) -> bool:
        self._cache.px4_mode = getattr(mode, "name", str(mode))
        return True

    def _on_landed_state(self, state, now: float) -> bool:
        name = getattr(state, "name", str(state))
        if name == "ON_GROUND":
            self._cache.in_air = False
        elif name in ("IN_AIR", "TAKING_OFF", "LANDING"):
            self._cache.in_air = True
        if name == "LANDING":  # PX4 lands it (5 Hz: sooner than its 1 Hz heartbeat shows Land)
            self._cache.failsafe_reports += 1
            self._cache.failsafe_report_s = now
        return True

    def _on_battery(self, battery, now: float) -> bool:
        remaining = battery.remaining_percent
        self._cache.battery_fraction = min(max(remaining / 100.0, 0.0), 1.0) if _finite(remaining) else None
        return True

    def _on_health(self, health, now: float) -> bool:
        self._cache.health = {
            name: bool(getattr(health, name))
            for name in (
                "is_gyrometer_calibration_ok",
                "is_accelerometer_calibration_ok",
                "is_magnetometer_calibration_ok",
                "is_local_position_ok",
                "is_global_position_ok",
                "is_home_position_ok",
                "is_armable",
            )
        }
        return True

    def _on_home(self, home, now: float) -> bool:
        point = _geodetic(home)
        if point is None:
            return False
        self._cache.home = point
        return True

    def _on_status_text(self, text, now: float) -> bool:
        severity = statustext_severity(getattr(text.type, "value", 6))
        self._cache.notices.add(Px4Message(t_s=now, text=str(text.text), severity=severity))
        return True

    def _on_heartbeat(self, message, now: float) -> bool:
        """PX4's HEARTBEAT (through MAVSDK's mavlink_direct): its system status tells a failsafe."""
        if message.component_id != MAV_COMP_ID_AUTOPILOT1:
            return True  # another component's heartbeat (a camera, a gimbal): not the autopilot's state
        try:
            fields = json.loads(message.fields_json)
            status = int(fields["system_status"])
            armed = bool(int(fields["base_mode"]) & MAV_MODE_FLAG_SAFETY_ARMED)
        except (ValueError, KeyError, TypeError):
            return False
        c = self._cache
        c.system_status = status
        if not (armed and status == MAV_STATE_CRITICAL):
            c.failsafe_since_s = None
            return True
        if c.failsafe_since_s is None:
            c.failsafe_since_s = now
        c.failsafe_reports += 1
        c.failsafe_report_s = now
        return True

    def _on_event(self, event, now: float) -> bool:
        """A PX4 event (its events protocol): the detailed words behind its STATUSTEXT lines."""
        level = int(getattr(event.log_level, "value", 6))
        name = str(event.event_name)
        self._cache.notices.add(
            Px4Message(t_s=now, text=str(event.message), severity=level, source="event", name=name)
        )
        if name in FAILSAFE_ACTION_EVENTS:
            # Events are PX4's reliable channel (sequenced; MAVSDK asks again for missed ones): a failsafe is
            # known even when the heartbeats of its time were lost, e.g. while the ground station was stalled.
            self._cache.failsafe_reports += 1
            self._cache.failsafe_report_s = now
        return True

    def _on_arming_checks(self, report, now: float) -> bool:
        """PX4's health-and-arming-check report: the errors that stop arming in its current mode."""
        intention = report.current_mode_intention
        problems = tuple(
            str(p.message) for p in intention.problems if getattr(p.log_level, "value", 7) <= SEVERITY_ERROR
        )
        self._cache.notices.set_arming_problems(now, problems if not intention.can_arm_or_run else ())
        return True

    def _on_raw_gps(self, gps, now: float) -> bool:
        h, v = gps.horizontal_uncertainty_m, gps.vertical_uncertainty_m
        if _finite(h, v) and h > 0 and v > 0:
            self._cache.gps_std_m = (float(h), float(v))
        return True

    # ---- internals: supervision and commands --------------------------------------------------------------
    def _observe(self) -> Observation:
        now = self._clock()
        with self._cache.lock:
            c = self._cache
            if c.armed or c.in_air:
                self._refused_at_s = None  # it flies: the last refusal is history
            reported = c.failsafe_reports > self._failsafe_reports_seen
            self._failsafe_reports_seen = c.failsafe_reports
            stalled = self._loop_stall_s(now)
            self._loop_gap_s = 0.0
            return Observation(
                now_s=now,
                mode=skyring_mode(c.px4_mode, armed=c.armed, in_air=c.in_air),
                armed=c.armed,
                in_air=c.in_air,
                link_lost=now - c.last_received_s() > self.config.link_lost_after_s,
                failsafe=self._failsafe_locked(),
                failsafe_reported=reported,
                can_arm=self._can_arm_locked(),
                stalled_s=stalled,
            )

    async def _beat(self) -> None:
        """Measure how long the whole process stands frozen (stopped, suspended: every thread, MAVSDK's too),
        so a gap longer than PX4's offboard-loss timeout means MAVSDK's set-points stopped as well. A loop
        that is only busy or starved is no such freeze: the process uses CPU meanwhile, and MAVSDK's own
        threads most likely kept sending (PX4's failsafe report would tell otherwise). Its own task, so a
        command the supervisor awaits is not taken for a stall."""
        period = self.config.supervise_period_s
        while True:
            now, cpu = self._clock(), self._cpu_clock()
            if self._last_beat_s is not None:
                gap = now - self._last_beat_s - period
                if frozen(gap, cpu - self._last_beat_cpu_s):
                    self._loop_gap_s = max(self._loop_gap_s, gap)
            self._last_beat_s, self._last_beat_cpu_s = now, cpu
            await asyncio.sleep(period)

    async def _supervise(self) -> None:
        while True:
            try:
                was = self._supervisor.engagement
                command = self._supervisor.step(self._observe())
                if self._supervisor.released and was is not Engagement.RELEASED:
                    log.warning("vehicle %d: %s", self.vehicle_id, self._supervisor.released_reason)
                if self._supervisor.failsafe_landing and was is not Engagement.LANDING:
                    stall = self._supervisor.stall_s
                    log.warning(
                        "vehicle %d: landing: %s",
                        self.vehicle_id,
                        f"the ground station stalled {stall:.1f} s, PX4 runs its offboard-loss failsafe"
                        if stall is not None
                        else "PX4 reported a failsafe it has since left",
                    )
                if command is not None:
                    self._executing = True
                    try:
                        await self._execute(command)
                    finally:
                        self._executing = False
            except asyncio.CancelledError:
                raise
            except Exception as exc:  # the supervisor must outlive any single failure
                self._fault = f"supervisor: {exc}"
                log.exception("vehicle %d: supervisor step failed", self.vehicle_id)
            await asyncio.sleep(self.config.supervise_period_s)

    async def _execute(self, command: Command) -> None:
        from mavsdk.asyncio.plugins.action import ActionError
        from mavsdk.asyncio.plugins.offboard import OffboardError

        log.info("vehicle %d: %s (%s)", self.vehicle_id, command.value, self._supervisor.engagement.value)
        try:
            await asyncio.wait_for(self._command(command), timeout=self.config.command_timeout_s)
            self._supervisor.command_done(self._clock())
        except (TimeoutError, ActionError, OffboardError) as exc:
            self._failed_commands += 1
            self._fault = f"{command.value} failed: {exc or 'timed out'}"
            log.warning("vehicle %d: %s", self.vehicle_id, self._fault)
            now = self._clock()
            if command is Command.TAKEOFF:
                self._refused_at_s = now
                self._refusal_fallback = (
                    f"PX4 refused {exc.origin.removesuffix('()')} ({exc.result.name}) and gave no reason"
                    if isinstance(exc, ActionError)
                    else f"no answer from PX4 to the take-off within {self.config.command_timeout_s:.0f} s"
                )
            self._supervisor.command_failed(command, now)

    async def _command(self, command: Command) -> None:
        from mavsdk.asyncio.plugins.offboard import OffboardError

        action, offboard = self._p.action, self._p.offboard
        if command is Command.TAKEOFF:
            # Hold first: PX4 accepts it disarmed and allows arming there, whichever mode it was left in
            # (after a disarm it returns to Offboard, where arming needs a set-point stream). Then arm and
            # take off, as before: PX4's navigator reads MIS_TAKEOFF_ALT when Takeoff mode starts, and asking
            # for Takeoff right after setting it has been seen to climb to the old 2.5 m.
            await action.set_takeoff_altitude(self._takeoff_altitude_m())
            await action.hold()
            await self._until_armable(self.config.armable_wait_s)
            await action.arm()
            await action.takeoff()
        elif command is Command.START_OFFBOARD:
            if self._latest_setpoint is not None:
                await self._forward(self._latest_setpoint)  # MAVSDK refuses to start without a set-point
            await offboard.start()
        elif command is Command.HOLD:
            try:
                await offboard.stop()  # stops MAVSDK's 20 Hz re-sending, then Hold
            except OffboardError:
                await action.hold()
        elif command is Command.LAND:
            await action.land()

    async def _until_armable(self, timeout_s: float) -> bool:
        """Wait up to timeout_s for PX4 to report that its arming checks pass (SYS_STATUS's pre-arm bit,
        through MAVSDK's health); whether they do. Seen on PX4 v1.16: a second ground station's first arming
        request, sent as PX4 noticed that station's heartbeat, was refused for "No connection to the ground
        control station" (NAV_DLL_ACT makes that a check)."""
        deadline = self._clock() + timeout_s
        while True:
            with self._cache.lock:
                if self._can_arm_locked():
                    return True
            if self._clock() >= deadline:
                return False
            await asyncio.sleep(0.1)

    def _takeoff_altitude_m(self) -> float:
        """MIS_TAKEOFF_ALT (above home) that brings the vehicle to the requested team-frame height. Home
        resets where it arms, so the ground it stands on now is the base (its last home before that)."""
        height = self._supervisor.takeoff_height_m or 2.5
        ground_z = 0.0
        with self._cache.lock:
            local, in_air = self._cache.local_ned_m, self._cache.in_air
        if local is not None and not in_air and self._frame is not None:
            ground_z = float(self._frame.to_enu(local)[2])
        elif self.home is not None and self._reference is not None:
            ground_z = float(geodetic_to_enu(self.home, reference=self._reference)[2])
        return max(self.config.min_takeoff_altitude_m, height - ground_z)

    # ---- internals: set-point streaming -------------------------------------------------------------------
    async def _stream(self) -> None:
        """Forward the agent's latest set-point while engaged, at most max_setpoint_rate_hz."""
        interval = 1.0 / self.config.max_setpoint_rate_hz
        event = self._setpoint_event
        while True:
            await event.wait()
            event.clear()
            if not self._supervisor.forwarding or self._latest_setpoint is None:
                continue
            try:
                await self._forward(self._latest_setpoint)
            except asyncio.CancelledError:
                raise
            except Exception as exc:
                self._fault = f"set-point not sent: {exc}"
            await asyncio.sleep(interval)

    async def _forward(self, setpoint: Setpoint) -> None:
        from mavsdk.asyncio.plugins.offboard import AccelerationNed, PositionNedYaw, VelocityNedYaw

        frame = self._frame
        if frame is None:
            raise Px4Error(f"vehicle {self.vehicle_id}: not placed in the team frame yet")
        ned = ned_setpoint(setpoint, frame)
        n, e, d = (float(x) for x in ned.position_ned_m)
        vn, ve, vd = (float(x) for x in ned.velocity_ned_mps)
        an, ae, ad = (float(x) for x in ned.acceleration_ned_mps2)
        await self._p.offboard.set_position_velocity_acceleration_ned(
            PositionNedYaw(n, e, d, ned.yaw_ned_deg),
            VelocityNedYaw(vn, ve, vd, ned.yaw_ned_deg),
            AccelerationNed(an, ae, ad),
        )


@dataclass
class Px4Fleet:
    """Connected PX4 vehicles sharing one team frame about `reference` (ids 1..K in URL order)."""

    autopilots: list[Px4Autopilot]
    reference: GeodeticPoint

    @classmethod
    async def open(
        cls,
        urls: Sequence[str],
        *,
        origin: GeodeticPoint | None = None,
        config: Px4Config = Px4Config(),
        clock: Callable[[], float] = time.monotonic,
    ) -> Px4Fleet:
        """Connect to every URL at once; the team frame's origin is `origin` or else vehicle 1's home."""
        if not urls:
            raise ValueError("need at least one vehicle URL")
        if len(set(urls)) != len(urls):
            raise ValueError(f"vehicle URLs must be distinct, got {list(urls)}")
        autopilots = [
            Px4Autopilot(vehicle_id=i + 1, url=url, config=config, clock=clock) for i, url in enumerate(urls)
        ]
        results = await asyncio.gather(*(a.connect() for a in autopilots), return_exceptions=True)
        failures = [r for r in results if isinstance(r, BaseException)]
        if failures:
            await asyncio.gather(*(a.close() for a in autopilots), return_exceptions=True)
            raise failures[0]
        reference = origin if origin is not None else autopilots[0].home
        if reference is None:
            raise Px4Error(
                "vehicle 1 has no home position to serve as the team origin; pass --origin lat,lon,alt"
            )
        for a in autopilots:
            a.set_reference(reference)
            a.start()
        return cls(autopilots=autopilots, reference=reference)

    async def settle(self, timeout_s: float = 5.0) -> list[bool]:
        """`Px4Autopilot.settle` on every vehicle at once; one flag per vehicle, in the fleet's order."""
        return list(await asyncio.gather(*(a.settle(timeout_s=timeout_s) for a in self.autopilots)))

    async def close(self) -> None:
        await asyncio.gather(*(a.close() for a in self.autopilots), return_exceptions=True)

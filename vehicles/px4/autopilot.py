"""PX4 autopilots through MAVSDK 4: the `Autopilot` back-end for PX4 SITL and real vehicles.

One `Px4Autopilot` per vehicle, each with its own `Mavsdk` instance and connection URL. `connect()` waits for
the autopilot and its health, sets the failsafe parameters skyring relies on (`Px4Config.failsafe_params`),
and reads the estimator origin; `start()` then runs, on the event loop it was connected on, one reader task
per telemetry stream into a state cache, a supervisor task (vehicles/px4/supervisor.py: engagement, the
set-point watchdog, respect for a pilot) and a set-point streaming task. The `Autopilot` methods are
non-blocking requests, safe to call from any thread.

Frames: the team's ENU frame is converted to the vehicle's local NED frame here and nowhere else
(vehicles/px4/geodesy.py). Telemetry goes the other way. Link loss (no telemetry for `link_lost_after_s`) is
reported in `AutopilotState.link_lost`.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, TypeVar

import numpy as np

from controller.messages import frozen_array
from vehicles.autopilot import AutopilotState, FlightMode, Setpoint
from vehicles.px4.geodesy import GeodeticPoint, LocalFrame, geodetic_to_enu
from vehicles.px4.supervisor import Command, Observation, OffboardSupervisor, SupervisorParams

if TYPE_CHECKING:
    from mavsdk.asyncio import Mavsdk
    from mavsdk.asyncio.plugins.action import ActionAsync
    from mavsdk.asyncio.plugins.offboard import OffboardAsync
    from mavsdk.asyncio.plugins.param import ParamAsync
    from mavsdk.asyncio.plugins.telemetry import TelemetryAsync

_T = TypeVar("_T")

log = logging.getLogger(__name__)

# COM_OBL_RC_ACT values skyring accepts for the offboard-loss failsafe, and NAV_DLL_ACT values for GCS loss.
OFFBOARD_LOSS_ACTIONS = {3: "Return", 4: "Land", 5: "Hold"}
DATALINK_LOSS_ACTIONS = {0: "Disabled", 1: "Hold", 2: "Return", 3: "Land"}

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
    station heartbeat, which covers a vehicle left hovering in Hold; supervise_period_s: supervisor tick;
    max_setpoint_rate_hz: set-points forwarded to MAVSDK at most this often (it re-sends the latest at 20 Hz);
    max_setpoint_range_m: set-points farther than this from the team origin are rejected and counted;
    min_takeoff_altitude_m: the lowest takeoff altitude above home skyring asks for.
    """

    connect_timeout_s: float = 30.0
    health_timeout_s: float = 60.0
    link_lost_after_s: float = 1.0
    offboard_loss_timeout_s: float = 1.0
    offboard_loss_action: int = 4
    datalink_loss_action: int = 3
    require_armable: bool = True
    supervise_period_s: float = 0.05
    max_setpoint_rate_hz: float = 20.0
    max_setpoint_range_m: float = 2000.0
    min_takeoff_altitude_m: float = 1.0
    command_timeout_s: float = 10.0
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

    def failsafe_params(self) -> dict[str, float | int]:
        """The PX4 parameters skyring sets on every vehicle it connects to (floats stay floats)."""
        return {
            "COM_OF_LOSS_T": float(self.offboard_loss_timeout_s),
            "COM_OBL_RC_ACT": int(self.offboard_loss_action),
            "NAV_DLL_ACT": int(self.datalink_loss_action),
        }


@dataclass(frozen=True, eq=False)
class NedSetpoint:
    """A set-point in one vehicle's local NED frame, as MAVSDK's offboard plugin takes it.

    position_ned_m (3,), velocity_ned_mps (3,) feed-forward, yaw_ned_deg (0 = north, clockwise; degrees is
    what MAVSDK's PositionNedYaw wants).
    """

    position_ned_m: np.ndarray
    velocity_ned_mps: np.ndarray
    yaw_ned_deg: float

    def __post_init__(self) -> None:
        object.__setattr__(self, "position_ned_m", frozen_array(self.position_ned_m, (3,), "position_ned_m"))
        object.__setattr__(
            self, "velocity_ned_mps", frozen_array(self.velocity_ned_mps, (3,), "velocity_ned_mps")
        )


def ned_setpoint(setpoint: Setpoint, frame: LocalFrame) -> NedSetpoint:
    """The team-ENU set-point expressed in the vehicle's local NED frame (position, velocity and yaw)."""
    return NedSetpoint(
        position_ned_m=frame.to_ned(setpoint.position_m),
        velocity_ned_mps=frame.vector_to_ned(setpoint.velocity_mps),
        yaw_ned_deg=math.degrees(frame.yaw_to_ned(setpoint.yaw_rad)),
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


def sitl_urls(count: int, *, first_port: int = 14540, host: str = "0.0.0.0") -> list[str]:
    """URLs for `count` local PX4 SITL instances: instance i sends to UDP 14540 + i (from i = 9 on: 14549)."""
    if count < 1:
        raise ValueError(f"need at least one SITL instance, got {count}")
    return [f"udpin://{host}:{first_port + min(i, 9)}" for i in range(count)]


class TelemetryCache:
    """The latest value of every telemetry stream, written by the reader tasks, read by `state()` from any
    thread (guarded by a lock). Local NED position/velocity, attitude (NED yaw), geodetic position and home,
    flags, battery, health, GPS accuracy; `received_s` holds when each stream last delivered."""

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
    pilot flies the vehicle, watchdog holds/landings, commands PX4 refused or that timed out, telemetry
    readings dropped as malformed; frame_source: "origin" (the estimator
    origin) or "fix" (inferred from one position reading); fault: the last problem, in words.
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
    failed_commands: int
    malformed_telemetry: int
    frame_source: str | None
    fault: str | None


class Px4Autopilot:
    """One PX4 vehicle behind the `Autopilot` protocol. `await connect()`, `set_reference(...)`, `start()`.

    clock: the wall clock the watchdog and link-loss detection run on (seconds, monotonic). AutopilotState
    stamps are on the same clock unless `use_stamp_clock` gives the caller's (e.g. a ground station's mission
    time): a reading's age is then carried over to that clock.
    """

    def __init__(
        self,
        *,
        vehicle_id: int,
        url: str,
        config: Px4Config = Px4Config(),
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.vehicle_id = int(vehicle_id)
        self.url = url
        self.config = config
        self._clock = clock
        self._cache = TelemetryCache()
        self._supervisor = OffboardSupervisor(config.supervisor)
        self._loop: asyncio.AbstractEventLoop | None = None
        self._mavsdk: Mavsdk | None = None
        self._system = None
        self._telemetry: TelemetryAsync | None = None
        self._action: ActionAsync | None = None
        self._offboard: OffboardAsync | None = None
        self._param: ParamAsync | None = None
        self._tasks: list[asyncio.Task] = []
        self._frame: LocalFrame | None = None
        self._frame_source: str | None = None
        self._origin: GeodeticPoint | None = None
        self._reference: GeodeticPoint | None = None
        self._latest_setpoint: Setpoint | None = None
        self._setpoint_event: asyncio.Event | None = None
        self._rejected_setpoints = 0
        self._failed_commands = 0
        self._fault: str | None = None
        self._executing = False
        self._stamp_clock: Callable[[], float] | None = None

    # ---- connection ---------------------------------------------------------------------------------------
    async def connect(self) -> None:
        """Connect, wait for health, set the failsafe parameters and read the estimator origin."""
        from mavsdk import ComponentType, Configuration
        from mavsdk.asyncio import Mavsdk, MavsdkConnectionError
        from mavsdk.asyncio.plugins.action import ActionAsync
        from mavsdk.asyncio.plugins.offboard import OffboardAsync
        from mavsdk.asyncio.plugins.param import ParamAsync
        from mavsdk.asyncio.plugins.telemetry import TelemetryAsync

        self._loop = asyncio.get_running_loop()
        self._setpoint_event = asyncio.Event()
        self._mavsdk = Mavsdk(Configuration.create_with_component_type(ComponentType.GROUND_STATION))
        try:
            await self._mavsdk.add_any_connection(self.url)
        except MavsdkConnectionError as exc:
            raise Px4Error(f"vehicle {self.vehicle_id}: cannot open {self.url}: {exc}") from exc
        self._system = await self._mavsdk.first_autopilot(timeout_s=self.config.connect_timeout_s)
        if self._system is None:
            raise Px4Error(
                f"vehicle {self.vehicle_id}: no autopilot heard on {self.url} within "
                f"{self.config.connect_timeout_s:.0f} s; is PX4 running and sending to that port?"
            )
        self._telemetry = TelemetryAsync(self._system)
        self._action = ActionAsync(self._system)
        self._offboard = OffboardAsync(self._system)
        self._param = ParamAsync(self._system)
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

    def _connected(self, handle: _T | None) -> _T:
        """A MAVSDK handle that connect() made; Px4Error (a clear refusal) before connect()."""
        if handle is None:
            raise Px4Error(f"vehicle {self.vehicle_id}: not connected")
        return handle

    async def _set_failsafe_params(self) -> None:
        from mavsdk.asyncio.plugins.param import ParamError

        param = self._connected(self._param)
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
            telemetry = self._connected(self._telemetry)
            origin = await asyncio.wait_for(telemetry.get_gps_global_origin(), timeout=5.0)
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
        for plugin in (self._telemetry, self._action, self._offboard, self._param):
            if plugin is not None:
                plugin.destroy()
        if self._mavsdk is not None:
            self._mavsdk.destroy()
            self._mavsdk = None

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
        )

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
            failed_commands=self._failed_commands,
            malformed_telemetry=malformed,
            frame_source=self._frame_source,
            fault=self._fault,
        )

    # ---- internals: threading -----------------------------------------------------------------------------
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
            if self._setpoint_event is not None:  # none before connect(): nothing streams yet
                self._setpoint_event.set()

    # ---- internals: telemetry readers ---------------------------------------------------------------------
    def _start_readers(self) -> None:
        t, loop = self._connected(self._telemetry), self._connected(self._loop)
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
        }
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
            return Observation(
                now_s=now,
                mode=skyring_mode(c.px4_mode, armed=c.armed, in_air=c.in_air),
                armed=c.armed,
                in_air=c.in_air,
                link_lost=now - c.last_received_s() > self.config.link_lost_after_s,
            )

    async def _supervise(self) -> None:
        while True:
            try:
                command = self._supervisor.step(self._observe())
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
        except (TimeoutError, ActionError, OffboardError) as exc:
            self._failed_commands += 1
            self._fault = f"{command.value} failed: {exc or 'timed out'}"
            log.warning("vehicle %d: %s", self.vehicle_id, self._fault)
            self._supervisor.command_failed(command)

    async def _command(self, command: Command) -> None:
        from mavsdk.asyncio.plugins.offboard import OffboardError

        action, offboard = self._connected(self._action), self._connected(self._offboard)
        if command is Command.TAKEOFF:
            await action.set_takeoff_altitude(self._takeoff_altitude_m())
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

    def _takeoff_altitude_m(self) -> float:
        """MIS_TAKEOFF_ALT (above home) that brings the vehicle to the requested team-frame height."""
        height = self._supervisor.takeoff_height_m or 2.5
        home_z = 0.0
        if self.home is not None and self._reference is not None:
            home_z = float(geodetic_to_enu(self.home, reference=self._reference)[2])
        return max(self.config.min_takeoff_altitude_m, height - home_z)

    # ---- internals: set-point streaming -------------------------------------------------------------------
    async def _stream(self) -> None:
        """Forward the agent's latest set-point while engaged, at most max_setpoint_rate_hz."""
        interval = 1.0 / self.config.max_setpoint_rate_hz
        event = self._connected(self._setpoint_event)
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
        from mavsdk.asyncio.plugins.offboard import PositionNedYaw, VelocityNedYaw

        ned = ned_setpoint(setpoint, self._connected(self._frame))
        n, e, d = (float(x) for x in ned.position_ned_m)
        vn, ve, vd = (float(x) for x in ned.velocity_ned_mps)
        await self._connected(self._offboard).set_position_velocity_ned(
            PositionNedYaw(n, e, d, ned.yaw_ned_deg), VelocityNedYaw(vn, ve, vd, ned.yaw_ned_deg)
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

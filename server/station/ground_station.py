"""The ground station's core: owns a live `Mission`, runs its control ticks, validates every operator command
before anything changes, and turns mission snapshots into the operator's view.

The REST API, the WebSocket and the viser GUI call the same methods here (it satisfies
`webui.view.OperatorActions`), so there is one path for every command: each runs on behalf of the
`webui.access.current_principal()` its surface set, is refused unless that principal is an operator, and is
audited (accepted or refused, with who, from where and its command id) in the flight log. Ticks and
commands are serialised by one lock: viser calls back from
its own threads, the API and the live runner from the asyncio loop. With a flight log attached
(`attach_log`), every command's audit record and a state sample every few ticks are recorded from here. The
mission may fly any list of autopilots (the embedded simulation or PX4 vehicles): nothing here knows which.

Every `alert_period_s` of mission time the station reads the alert conditions off the operator's view
(`server.station.alert_rules`) into its alert list (`server.station.alerts.AlertBook`); the view, the API and
the WebSocket carry that list, and acknowledging an alert is an operator command like the others.
"""

from __future__ import annotations

import functools
import inspect
import logging
import math
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import replace
from typing import TYPE_CHECKING, Any

import numpy as np

from controller.messages import Obstacle
from server.flightlog.log import FlightLog, utc_now_iso
from server.flightlog.records import AuditRecord, scalar
from server.separation import Separation, separations
from server.station.alert_rules import AlertParams, conditions
from server.station.alerts import AlertBook, UnknownAlertError
from server.station.commands import (
    CommandError,
    CommandLimits,
    UnknownTargetError,
    check_clearance,
    check_formation,
    check_obstacle,
    clearance_problems,
    limits_from_params,
)
from vehicles.camera import CameraParams
from vehicles.mission import Mission, MissionError, MissionSnapshot, Phase, VehicleSnapshot
from vehicles.pilot import AIRBORNE_PHASES, FLYING_PHASES
from webui.access import Principal, current_principal
from webui.view import (
    AgentView,
    Alert,
    CameraView,
    CommandOutcome,
    Counters,
    GeodeticOrigin,
    ObstacleView,
    PaceView,
    PersonEstimateView,
    Range,
    SceneView,
    VehicleView,
)

if TYPE_CHECKING:
    from server.station.fleet import AgentFleet


log = logging.getLogger(__name__)
AUDIT_MEMORY = 1000  # audit records kept in memory (the flight log keeps them all)
# a real-time station whose control loop has not ticked for this long stalled (the process was stopped or
# starved); a reader then waits up to STALL_WAIT_S for the next tick, not to show the team before the stall
STALL_AFTER_S = 0.5
STALL_WAIT_S = 1.0


class NotAuthorisedError(CommandError):
    """The sender may not command: not signed in (`signed_in` False), or signed in as an observer."""

    def __init__(self, message: str, *, signed_in: bool) -> None:
        super().__init__(message)
        self.signed_in = signed_in


def _recorded(method):
    """An operator command: refused unless the current principal is an operator, and audited with its outcome
    (accepted, or refused with the message the operator saw). Every surface calls these methods, so this is
    the one place every command passes through; it holds the station lock so the log orders commands and
    ticks as they ran."""
    signature = inspect.signature(method)

    @functools.wraps(method)
    def command(self: GroundStation, *args, **kwargs):
        principal = current_principal()
        with self._lock:
            try:
                self._authorise(principal)
                result = method(self, *args, **kwargs)
            except Exception as exc:
                self._view = None  # the refused-commands counter moved
                message = str(exc) if isinstance(exc, CommandError) else f"{type(exc).__name__}: {exc}"
                self.audit(
                    principal,
                    method.__name__,
                    _arguments(signature, self, args, kwargs),
                    accepted=False,
                    message=message,
                )
                raise
            self.audit(
                principal,
                method.__name__,
                _arguments(signature, self, args, kwargs),
                accepted=True,
                result=result,
            )
            return result

    return command


def _arguments(signature: inspect.Signature, station, args, kwargs) -> dict[str, Any]:
    try:
        bound = signature.bind(station, *args, **kwargs)
    except TypeError:
        return {"arguments": repr((args, kwargs))}
    bound.apply_defaults()  # an override left at False is audited as such
    return {k: scalar(v) for k, v in bound.arguments.items() if k != "self"}


class GroundStation:
    """One live mission under operator control.

    control_period_s: seconds per tick. clock: None for a simulation (mission time starts at start_s and
    advances by exactly one control period per tick, whatever the wall clock does); real vehicles pass the
    monotonic clock their telemetry is stamped with, and each tick then runs at clock() (never going back).
    link_stale_s: telemetry older than this is flagged stale (0.5 s: a few missed telemetry messages at
    PX4's rates, soon enough for the alert to reach the operator within a second). virtual_obstacle_height_m:
    height of the cylinders the operator places (above the arena). on_shutdown: called after the landing
    commands when the ground station stops (a back-end that must flush them or close links hooks in here).
    alert_params: the alert rules' thresholds (d_min from `limits` unless given); alert_period_s: mission
    seconds between two readings of the alert conditions; wall_clock: UTC seconds since the epoch for the
    operator's header and the alerts' time stamps (None: no wall time shown); origin: the team frame's
    geodetic origin, when known.
    """

    def __init__(
        self,
        *,
        mission: Mission | AgentFleet,
        control_period_s: float,
        limits: CommandLimits | None = None,
        start_s: float = 0.0,
        clock: Callable[[], float] | None = None,
        link_stale_s: float = 0.5,
        virtual_obstacle_height_m: float = 12.0,
        camera: CameraView | None = None,
        on_shutdown: Callable[[], None] | None = None,
        alert_params: AlertParams | None = None,
        alert_period_s: float = 0.1,
        wall_clock: Callable[[], float] | None = time.time,
        origin: GeodeticOrigin | None = None,
    ) -> None:
        if not (math.isfinite(control_period_s) and control_period_s > 0):
            raise ValueError(f"control_period_s must be a positive number of seconds, got {control_period_s}")
        self._mission = mission
        self._period = float(control_period_s)
        self._limits = limits or limits_from_params(mission.controller_params)
        self._clock = clock
        self._time = float(clock() if clock is not None else start_s)
        self._on_shutdown = on_shutdown
        self._stale_s = link_stale_s
        self._obstacle_height_m = virtual_obstacle_height_m
        self._camera = camera or camera_view(CameraParams())
        self._lock = threading.RLock()
        self._next_obstacle = 1
        self._refused = 0
        self._snapshot: MissionSnapshot | None = None
        self._view: SceneView | None = None
        self._log: FlightLog | None = None
        self.recent_audit: deque[AuditRecord] = deque(maxlen=AUDIT_MEMORY)
        self._alert_params = alert_params or AlertParams(safety_distance_m=self._limits.safety_distance_m)
        self._alert_period_s = float(alert_period_s)
        self._alerts = AlertBook()
        self._alerts_read_s = -math.inf
        self._wall_clock = wall_clock
        self._origin = origin
        self._pace: PaceView | None = None
        self._ticker: int | None = None  # the thread that ticks (it never waits for its own tick)
        self._tick_done = threading.Condition(threading.Lock())

    # ---- time ---------------------------------------------------------------------------------------------
    @property
    def control_period_s(self) -> float:
        return self._period

    @property
    def time_s(self) -> float:
        return self._time

    @property
    def limits(self) -> CommandLimits:
        return self._limits

    @property
    def mission(self) -> Mission | AgentFleet:
        """The in-process mission, or the fleet of onboard agents the station supervises."""
        return self._mission

    @property
    def lock(self) -> threading.RLock:
        """Held by every tick and command; hold it to read several things from one instant."""
        return self._lock

    def tick(self) -> None:
        """Run one control tick of the whole team, one control period after the previous one."""
        try:
            with self._lock:
                self._ticker = threading.get_ident()
                now = self._time + self._period if self._clock is None else max(self._clock(), self._time)
                self._time = now
                self._changed()
                self._mission.step(now)
                if now - self._alerts_read_s >= self._alert_period_s - 1e-9:
                    self._read_alerts(now)
                if self._log is not None and self._log.sample_due(now):
                    self._log.record_sample(self._cached_view)
        finally:
            with self._tick_done:  # a failed tick ends a stall too: its time is the view's
                self._tick_done.notify_all()

    # ---- flight log ---------------------------------------------------------------------------------------
    def attach_log(self, flight_log: FlightLog) -> None:
        """Record every operator command's audit record and a state sample every `flight_log.sample_period_s`
        of mission time (the first one now) to `flight_log`. Its owner closes it; a failing log never stops a
        tick."""
        with self._lock:
            self._log = flight_log
            flight_log.record_sample(self.scene_view)

    @property
    def recording_path(self) -> str | None:
        """Where the flight log is written (None: not recording)."""
        return self._log.name if self._log is not None and self._log.recording else None

    # ---- alerts and pace ----------------------------------------------------------------------------------
    def _read_alerts(self, now: float) -> None:
        view = self._cached_view()  # the tick's own reading: no stall to wait out
        utc = self._wall_clock() if self._wall_clock is not None else None
        self._alerts.update(now, conditions(view, self._alert_params), utc_s=utc)
        self._alerts_read_s = now
        self._view = None

    @property
    def alerts(self) -> tuple[Alert, ...]:
        """Every alert raised so far, most urgent first."""
        with self._lock:
            return self._alerts.alerts

    def set_pace(self, pace: PaceView | None) -> None:
        """How the live loop keeps up with the wall clock (the live runner reports it; shown and alerted)."""
        with self._lock:
            self._pace = pace
            self._view = None

    def _authorise(self, principal: Principal) -> None:
        if principal.may_command:
            return
        self._refused += 1
        if principal.role is None:
            raise NotAuthorisedError("sign in as an operator to command the MAVs", signed_in=False)
        raise NotAuthorisedError(
            f"{principal.name!r} is signed in as {principal.role.value}: only an operator may command",
            signed_in=True,
        )

    def audit(
        self,
        principal: Principal,
        command: str,
        arguments: dict[str, Any],
        *,
        accepted: bool,
        message: str = "",
        result: object = None,
    ) -> AuditRecord | None:
        """Record one command's audit record (the surfaces call this for commands they refuse before they
        reach the station: not signed in, a foreign origin, a malformed request). Never raises."""
        try:
            text = (
                None
                if result is None
                else ",".join(map(str, result))
                if isinstance(result, list)
                else str(result)
            )
            record = AuditRecord(
                time_s=self._time,
                utc=utc_now_iso(),
                command=command,
                arguments={k: scalar(v) for k, v in arguments.items()},
                operator=principal.name,
                role=principal.role.value if principal.role is not None else "",
                surface=principal.surface.value,
                remote=principal.remote,
                command_id=principal.command_id,
                accepted=accepted,
                message=message,
                result=text,
            )
        except Exception:  # noqa: BLE001 - the audit must never change a command's outcome
            log.exception("auditing the %s command failed", command)
            return None
        with self._lock:
            self.recent_audit.append(record)
            if self._log is not None:
                self._log.record_audit(record)
        return record

    # ---- reading ------------------------------------------------------------------------------------------
    def snapshot(self) -> MissionSnapshot:
        """The mission now (cached until the next tick or command)."""
        with self._lock:
            if self._snapshot is None:
                self._snapshot = self._mission.snapshot()
            return self._snapshot

    def scene_view(self) -> SceneView:
        """What the operator sees now (cached until the next tick or command). After a stall of the control
        loop it is the first tick's after the stall; a loop still stalled after STALL_WAIT_S shows no vehicle
        in formation, each with the stall as its fault (the station commands nothing while it stands)."""
        if self._stalled_s() is not None:
            with self._tick_done:  # without the station's lock, which the tick needs
                if self._stalled_s() is not None:
                    self._tick_done.wait(timeout=STALL_WAIT_S)
        with self._lock:
            stalled_s = self._stalled_s()
            view = self._cached_view()
            return view if stalled_s is None else _stalled_view(view, stalled_s)

    def _stalled_s(self) -> float | None:
        """How long a real-time station's control loop has not ticked, when past STALL_AFTER_S and asked from
        another thread than the one that ticks; None otherwise."""
        if self._clock is None or self._ticker in (None, threading.get_ident()):
            return None
        stalled_s = self._clock() - self._time
        return stalled_s if stalled_s > STALL_AFTER_S else None

    def _cached_view(self) -> SceneView:
        """The view as of the last tick or command, built at its first reading."""
        with self._lock:
            if self._view is None:
                self._view = scene_view(
                    self.snapshot(),
                    limits=self._limits,
                    link_stale_s=self._stale_s,
                    camera=self._camera,
                    counters=Counters(**self.counters()),
                    alerts=self._alerts.alerts,
                    pace=self._pace,
                    utc_s=self._wall_clock() if self._wall_clock is not None else None,
                    recording_path=self.recording_path,
                    origin=self._origin,
                )
            return self._view

    def counters(self) -> dict[str, int]:
        """Bad inputs refused and counted so far: operator commands (here and in the mission), detections the
        trackers rejected, malformed messages, controller exceptions, braking ticks."""
        c = self.snapshot().counters
        return {
            "refused_commands": self._refused + c.rejected_actions,
            "rejected_detections": c.rejected_detections,
            "rejected_messages": c.rejected_messages,
            "controller_errors": c.controller_errors,
            "braking_ticks": c.braking_ticks,
        }

    # ---- operator commands (webui.view.OperatorActions) ---------------------------------------------------
    @_recorded
    def set_formation(self, *, d_des_m: float, h_des_m: float) -> None:
        """Set d_des and h_des for every MAV (CommandError with the allowed range if outside it)."""
        with self._lock:
            formation = self._checked(
                lambda: check_formation(
                    d_des_m=d_des_m, h_des_m=h_des_m, limits=self._limits, team_size=self._team_size()
                )
            )
            self._apply(lambda: self._mission.set_formation(formation))

    @_recorded
    def add_obstacle(self, *, x_m: float, y_m: float, radius_m: float) -> str:
        """Add a virtual obstacle at ENU (x_m, y_m); returns its id ("v1", "v2", ...)."""
        with self._lock:
            snap = self.snapshot()
            vehicles = _positions(snap)
            persons = _persons(snap)
            x, y, r = self._checked(
                lambda: check_obstacle(
                    x_m=x_m,
                    y_m=y_m,
                    radius_m=radius_m,
                    limits=self._limits,
                    vehicles_m=vehicles,
                    persons_m=persons,
                    virtual_count=len(snap.virtual_obstacle_ids),
                )
            )
            taken = {o.obstacle_id for o in snap.obstacles}
            while f"v{self._next_obstacle}" in taken:
                self._next_obstacle += 1
            obstacle = Obstacle(
                obstacle_id=f"v{self._next_obstacle}",
                center_m=np.array([x, y]),
                radius_m=r,
                height_m=self._obstacle_height_m,
                kind="virtual",
            )
            self._apply(lambda: self._mission.add_obstacle(obstacle))
            self._next_obstacle += 1
            return obstacle.obstacle_id

    @_recorded
    def remove_obstacle(self, obstacle_id: str) -> None:
        """Remove a virtual obstacle (UnknownTargetError if there is none by that id; trees stay)."""
        with self._lock:
            known = {o.obstacle_id: o for o in self.snapshot().obstacles}
            if obstacle_id not in known:
                self._refuse(
                    UnknownTargetError(
                        f"no obstacle with id {obstacle_id!r}; virtual obstacles are "
                        f"{list(self.snapshot().virtual_obstacle_ids)}"
                    )
                )
            if known[obstacle_id].kind != "virtual":
                self._refuse(
                    CommandError(
                        f"obstacle {obstacle_id!r} is a {known[obstacle_id].kind}, part of "
                        "the map: only virtual obstacles can be removed"
                    )
                )
            self._apply(lambda: self._mission.remove_obstacle(obstacle_id))

    @_recorded
    def land(self, vehicle_id: int) -> None:
        """Land one MAV where it is; it leaves formation control until released."""
        with self._lock:
            self._vehicle(vehicle_id)
            self._apply(lambda: self._mission.land(vehicle_id))

    @_recorded
    def hold(self, vehicle_id: int) -> None:
        """Stop one flying MAV where it is: it hovers out of formation control until released or landed."""
        with self._lock:
            self._vehicle(vehicle_id)
            self._apply(lambda: self._mission.hold(vehicle_id))

    @_recorded
    def acknowledge_alert(self, alert_id: str) -> None:
        """Mark one alert as seen (it stays in the list); UnknownTargetError for an unknown id."""
        with self._lock:
            if not isinstance(alert_id, str):
                self._refuse(CommandError(f"an alert id is text such as 'a3', got {alert_id!r}"))
            try:
                self._alerts.acknowledge(alert_id)
            except UnknownAlertError as exc:
                self._refuse(UnknownTargetError(str(exc)))
            self._view = None

    @_recorded
    def acknowledge_all_alerts(self) -> int:
        """Mark every alert as seen; returns how many were not acknowledged before."""
        with self._lock:
            count = self._alerts.acknowledge_all()
            self._view = None
            return count

    @_recorded
    def land_all(self) -> list[int]:
        """Land every MAV that is taking off, flying, holding or found flying; returns their ids."""
        with self._lock:
            flying = [v.vehicle_id for v in self.snapshot().vehicles if _airborne(v)]
            self._apply(self._mission.land_all)
            return flying

    @_recorded
    def release(self, vehicle_id: int, *, override: bool = False) -> list[str]:
        """Give a landed MAV back to the formation (it takes off again while formation is enabled), or an
        airborne one skyring does not fly (found flying, or a pilot gave it back).

        Refused if the current d_des would space the enlarged team closer than the formation spacing allows,
        or if the MAV stands inside the person's keep-out or within d_min of a teammate (`override` lets it go
        anyway: the problems are returned and logged). A holding MAV rejoins the formation from where it
        hovers.
        """
        with self._lock:
            vehicle = self._vehicle(vehicle_id)
            if vehicle.phase in (Phase.LANDED, Phase.HOLDING):
                team = self._team_size() + 1
                low, high = self._limits.d_des_range_m(team)
                d_des = self.snapshot().formation.d_des_m
                if not low <= d_des <= high:
                    self._refuse(
                        CommandError(
                            f"with MAV {vehicle_id} back there would be {team} MAVs in formation, which "
                            f"needs d_des between {low:g} and {high:g} m (now {d_des:g} m): change d_des "
                            "first"
                        )
                    )
            released = vehicle.autopilot is not None and vehicle.autopilot.released
            overridden = []
            if vehicle.phase in (Phase.LANDED, Phase.IDLE) or released:
                overridden = self._check_clearance(
                    [vehicle.vehicle_id], action=f"release of MAV {vehicle_id}", override=override
                )
            self._apply(lambda: self._mission.release(vehicle_id))
            return overridden

    @_recorded
    def set_formation_enabled(self, enabled: bool, *, override: bool = False) -> list[str]:
        """Start (True) or stop (False: every MAV holds position) formation control.

        Starting takes off the MAVs waiting on the ground and brings in those found flying; it is refused
        while one of them stands inside the person's keep-out or within d_min of a teammate, unless
        `override` (the problems are then returned and logged).
        """
        with self._lock:
            if not isinstance(enabled, bool) or not isinstance(override, bool):
                self._refuse(CommandError(f"enabled and override must be true or false, got {enabled!r}"))
            overridden: list[str] = []
            if enabled:
                joining = [v.vehicle_id for v in self.snapshot().vehicles if v.phase == Phase.IDLE]
                overridden = self._check_clearance(
                    joining, action="start of the formation", override=override
                )
            self._apply(lambda: self._mission.set_formation_enabled(enabled))
            return overridden

    def takeoff_checks(self) -> dict[int, str]:
        """Why each MAV waiting to take off or join (idle or landed) may not, where it stands now."""
        with self._lock:
            return takeoff_checks(self.snapshot(), limits=self._limits)

    @_recorded
    def shutdown(self) -> None:
        """Land every flying MAV, then run on_shutdown (called when the ground station stops)."""
        with self._lock:
            try:
                self._mission.land_all()
            finally:
                self._changed()
                if self._on_shutdown is not None:
                    self._on_shutdown()

    # ---- internals ----------------------------------------------------------------------------------------
    def _check_clearance(self, vehicle_ids: list[int], *, action: str, override: bool) -> list[str]:
        """Refuse (CommandError, counted) a take-off or join of `vehicle_ids` that the clearance checks
        forbid, unless override: then log and return the problems overridden."""
        snap = self.snapshot()
        problems = clearance_problems(
            vehicle_ids=vehicle_ids,
            vehicles_m=_positions(snap),
            persons_m=_persons(snap),
            limits=self._limits,
            d_des_m=snap.formation.d_des_m,
        )
        lines = self._checked(lambda: check_clearance(problems, action=action, override=override))
        if lines:
            log.warning(
                "operator override of the pre-take-off checks for the %s: %s", action, "; ".join(lines)
            )
        return lines

    def _team_size(self) -> int:
        return sum(v.phase in FLYING_PHASES for v in self.snapshot().vehicles)

    def _vehicle(self, vehicle_id: int) -> VehicleSnapshot:
        for v in self.snapshot().vehicles:
            if isinstance(vehicle_id, int) and v.vehicle_id == vehicle_id:
                return v
        ids = [v.vehicle_id for v in self.snapshot().vehicles]
        self._refuse(UnknownTargetError(f"no vehicle with id {vehicle_id!r}; vehicles are {ids}"))
        raise AssertionError("unreachable")

    def _checked(self, check):
        try:
            return check()
        except CommandError:
            self._refused += 1
            raise

    def _refuse(self, error: CommandError) -> None:
        self._refused += 1
        raise error

    def _apply(self, action) -> None:
        """Run a mission action; the mission refuses with MissionError before changing anything."""
        try:
            action()
        except MissionError as exc:
            raise CommandError(str(exc)) from None
        finally:
            self._changed()

    def _changed(self) -> None:
        self._snapshot = None
        self._view = None


def _stalled_view(view: SceneView, stalled_s: float) -> SceneView:
    """The view of a station whose control loop stands: no vehicle flies in formation, and each says why."""
    fault = f"the ground station's control loop has not run for {stalled_s:.1f} s"
    vehicles = tuple(replace(v, in_formation=False, fault=fault) for v in view.vehicles)
    return replace(view, vehicles=vehicles)


def camera_view(params: CameraParams) -> CameraView:
    """The frustum drawn for a camera: vertical field of view 2 atan(height / (2 fy)), aspect width/height."""
    return CameraView(
        vertical_fov_rad=2.0 * math.atan(params.height_px / (2.0 * params.fy_px)),
        aspect=params.width_px / params.height_px,
        pitch_down_rad=params.pitch_down_rad,
        forward_offset_m=params.offset_forward_m,
    )


def _airborne(v: VehicleSnapshot) -> bool:
    """What LAND ALL lands: taking off, flying formation, holding, or found flying (idle in the air)."""
    found_flying = v.phase == Phase.IDLE and v.autopilot is not None and v.autopilot.in_air
    return v.phase in AIRBORNE_PHASES or found_flying


def _positions(snap: MissionSnapshot) -> dict[int, np.ndarray]:
    """Vehicle id -> (3,) ENU position of every MAV with telemetry."""
    return {v.vehicle_id: v.autopilot.position_m for v in snap.vehicles if v.autopilot is not None}


def _persons(snap: MissionSnapshot) -> list[np.ndarray]:
    """(3,) positions of the person the take-off checks protect: the truth when the person is simulated (the
    one whose safety counts); otherwise every finite fused estimate. Estimates are not mixed with the truth: a
    landed MAV's tracker sees nobody and its estimate drifts, which could refuse the release of a MAV that
    landed at formation distance."""
    if snap.person_truth is not None:
        return [snap.person_truth.position_m]
    return [
        v.person.position_m
        for v in snap.vehicles
        if v.person is not None and np.all(np.isfinite(v.person.position_m))
    ]


def takeoff_checks(snap: MissionSnapshot, *, limits: CommandLimits) -> dict[int, str]:
    """Why each MAV waiting to take off or join (idle, or landed awaiting release) may not where it stands
    (server/station/commands.py, clearance_problems); MAVs with no problem are left out."""
    waiting = [v.vehicle_id for v in snap.vehicles if v.phase in (Phase.IDLE, Phase.LANDED)]
    return clearance_problems(
        vehicle_ids=waiting,
        vehicles_m=_positions(snap),
        persons_m=_persons(snap),
        limits=limits,
        d_des_m=snap.formation.d_des_m,
    )


def vehicle_view(
    v: VehicleSnapshot,
    *,
    link_stale_s: float,
    now_s: float | None = None,
    person_m: np.ndarray | None = None,
    takeoff_check: str | None = None,
    separation: Separation | None = None,
) -> VehicleView:
    """One vehicle as the operator sees it (the autopilot's reported pose; stale when telemetry is old), with
    what its autopilot says of itself and why it may not take off where it stands (`takeoff_check`).
    now_s: mission time of the view, for the plan's age (None: not known); person_m (3,): where the person is
    believed to be, for the distance to the person; separation: its distances to the nearest teammate and
    obstacle (`team_separations`; None: not known)."""
    separation = separation or Separation()
    s = v.autopilot
    age = v.link_age_s if v.link_age_s is not None else math.inf
    plan = v.plan.positions_m if v.plan is not None else np.zeros((0, 3))
    distance = None
    if s is not None and person_m is not None and np.all(np.isfinite(person_m)):
        distance = float(np.hypot(*(s.position_m[:2] - person_m[:2])))
    return VehicleView(
        vehicle_id=v.vehicle_id,
        phase=v.phase.value,
        mode=s.mode.value if s is not None else "unknown",
        armed=bool(s.armed) if s is not None else False,
        in_air=bool(s.in_air) if s is not None else False,
        in_formation=v.in_formation,
        position_m=s.position_m if s is not None else np.zeros(3),
        velocity_mps=s.velocity_mps if s is not None else np.zeros(3),
        yaw_rad=s.yaw_rad if s is not None else 0.0,
        link_age_s=age,
        link_stale=age > link_stale_s
        or (s is not None and s.link_lost)
        or (v.agent is not None and v.agent.lost),
        solve_status=v.status.value if v.status is not None else "",
        solver_time_s=v.solver_time_s if v.status is not None else None,
        battery_fraction=s.battery_fraction if s is not None else None,
        plan_positions_m=plan,
        plan_age_s=max(0.0, now_s - v.plan.stamp_s) if v.plan is not None and now_s is not None else None,
        distance_to_person_m=distance,
        released=bool(s.released) if s is not None else False,
        fault=v.fault or "",
        autopilot_mode=(s.autopilot_mode or s.mode.name) if s is not None else "",
        failsafe=bool(s.failsafe) if s is not None else False,
        failsafe_reason=s.failsafe_reason if s is not None else None,
        can_arm=s.can_arm if s is not None else None,
        arming_refusal=s.arming_refusal if s is not None else None,
        takeoff_check=takeoff_check,
        agent=agent_view(v.agent) if v.agent is not None else None,
        nearest_teammate_m=separation.nearest_teammate_m,
        nearest_teammate_id=separation.nearest_teammate_id,
        nearest_obstacle_m=separation.nearest_obstacle_m,
    )


def team_separations(snap: MissionSnapshot) -> dict[int, Separation]:
    """Every vehicle's separation to its nearest airborne teammate and nearest trunk or virtual obstacle, by
    the positions the station knows (its autopilot's telemetry); in the air means the autopilot says so."""
    airborne = [v.vehicle_id for v in snap.vehicles if v.autopilot is not None and v.autopilot.in_air]
    return separations(
        positions_m=_positions(snap),
        airborne_ids=airborne,
        obstacles=[o for o in snap.obstacles if o.kind != "vehicle"],
    )


def agent_view(link, *, skew_limit_s: float = 0.05) -> AgentView:
    """A networked agent's link (vehicles.pilot.AgentLink) as the operator sees it; skew flagged beyond
    skew_limit_s."""
    offset = link.clock_offset_s
    return AgentView(
        lost=link.lost,
        age_s=link.age_s if math.isfinite(link.age_s) else 1e9,
        clock_offset_s=offset,
        clock_skew=offset is not None and abs(offset) > skew_limit_s,
        tick_period_p99_error_s=link.tick_period_p99_error_s,
        station_lost=link.station_lost,
        scheduler=link.scheduler,
        rejected_messages=link.rejected_messages,
        commands=tuple(CommandOutcome(*command) for command in link.commands),
    )


def scene_view(
    snap: MissionSnapshot,
    *,
    limits: CommandLimits,
    link_stale_s: float = 1.0,
    camera: CameraView | None = None,
    counters: Counters | None = None,
    alerts: tuple[Alert, ...] = (),
    pace: PaceView | None = None,
    utc_s: float | None = None,
    recording_path: str | None = None,
    origin: GeodeticOrigin | None = None,
) -> SceneView:
    """Adapt a mission snapshot to the operator's view.

    The drawn estimate is the tracker replica with the smallest position-covariance trace (the best-informed
    MAV); the tracking error is the mean over MAVs with an estimate of |estimate - truth| (simulation only);
    each MAV's distance to the person is measured to the drawn estimate (to the truth before there is one);
    its separation to teammates and obstacles by `team_separations`. The rest is passed through (see
    `SceneView`).
    """
    estimates = [
        (v.person.position_cov_trace_m2, v.vehicle_id, v.person)
        for v in snap.vehicles
        if v.person is not None and np.all(np.isfinite(v.person.cov))
    ]
    best = min(estimates, key=lambda e: (e[0], e[1])) if estimates else None
    truth = snap.person_truth.position_m if snap.person_truth is not None else None
    error = None
    if truth is not None and estimates:
        error = float(np.mean([np.linalg.norm(e[2].position_m - truth) for e in estimates]))
    team = sum(v.phase in FLYING_PHASES for v in snap.vehicles)
    d_range, h_range = limits.d_des_range_m(max(team, 1)), limits.h_des_range_m()
    person = best[2].position_m if best else truth
    checks = takeoff_checks(snap, limits=limits)
    separation = team_separations(snap)
    vehicles = tuple(
        vehicle_view(
            v,
            link_stale_s=link_stale_s,
            now_s=snap.stamp_s,
            person_m=person,
            takeoff_check=checks.get(v.vehicle_id),
            separation=separation.get(v.vehicle_id),
        )
        for v in snap.vehicles
    )
    return SceneView(
        time_s=snap.stamp_s,
        vehicles=vehicles,
        obstacles=tuple(ObstacleView.of(o) for o in snap.obstacles),
        formation=snap.formation,
        formation_enabled=snap.formation_enabled,
        arena_min_m=np.array(limits.arena_min_m),
        arena_max_m=np.array(limits.arena_max_m),
        d_des_range_m=Range(*d_range),
        h_des_range_m=Range(*h_range),
        obstacle_radius_range_m=Range(0.1, limits.max_obstacle_radius_m),
        person_truth_m=truth,
        person_estimate=PersonEstimateView.of(best[2]) if best else None,
        estimate_source_id=best[1] if best else None,
        tracking_error_m=error,
        camera=camera or CameraView(),
        counters=counters or Counters(),
        alerts=alerts,
        pace=pace,
        utc_s=utc_s,
        recording_path=recording_path,
        origin=origin,
    )

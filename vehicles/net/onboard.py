"""One MAV's onboard agent: the control loop of `skyring agent`, on its own thread and its own clock.

Every control period it runs the same `VehiclePilot` (phase machine) and `Agent.tick` as the in-process
mission, with what it hears over Zenoh instead of what a mission hands it:

- settings (d_des/h_des, formation on/off, obstacles) come from the station's commands and are kept when the
  station is gone; they are checked again here (defence in depth) and a refused one is acknowledged as such;
- the roster is this MAV (taking off or in formation) and every teammate whose plan says the same and was
  heard within `silent_after_s`; a teammate silent for longer leaves the roster and is avoided as a growing
  cylinder about its last plan (`vehicles.link_loss`), as the in-process mission does with a silent vehicle;
  one that went silent after it began landing is taken as landed and forgotten;
- the station's heartbeat (2 Hz) is watched: with none for `station_timeout_s` the MAV lands (it needs nothing
  from the station to fly the formation until then), like PX4's own data-link-loss failsafe;
- every command is acknowledged (`AckBody`) once applied; a re-sent one is acknowledged again, never applied
  twice;
- a state message (`StateBody`) goes to the station 10 times a second: telemetry, phase, plan, estimate,
  solver, counters, refused messages, settings, the tick period's 99th-percentile error, and the echo of the
  last heartbeat for the station's clock-offset measurement.

Time: `now` is UTC seconds (`clock`, time.time by default), the stamp every teammate compares plans and
detections on; the loop is paced on the monotonic clock so a wall-clock step never bunches ticks.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections import OrderedDict, deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from controller.messages import Obstacle
from controller.params import ControllerParams, FormationParams
from vehicles.agent import Agent, AgentInputs, AgentParams
from vehicles.autopilot import Autopilot
from vehicles.detect.calibration import Calibration
from vehicles.detect.converter import ConverterStats, DetectionConverter
from vehicles.link_loss import silent_teammate_obstacle
from vehicles.net import realtime, wire
from vehicles.net.guard import Received
from vehicles.net.keys import agent_key, station_key
from vehicles.net.session import Bus
from vehicles.net.zenoh_links import ZenohLinks
from vehicles.pilot import AIRBORNE_PHASES, MissionError, MissionParams, Phase, VehiclePilot, roster_slots
from vehicles.pilot import takeoff_height_m as takeoff_height

log = logging.getLogger(__name__)

ROSTER_PHASES = (Phase.TAKEOFF.value, Phase.FORMATION.value)
_ACK_MEMORY = 256


@dataclass(frozen=True)
class OnboardParams:
    """rate_hz: control ticks per second; state_rate_hz: state messages to the station per second;
    station_timeout_s: no station heartbeat for this long -> land (PX4's data-link loss default is 10 s);
    silent_after_s: a teammate unheard for this long leaves the roster and is avoided as silent;
    silent_keep_s: and is forgotten after this long (its failsafe has landed it by then);
    realtime_priority: the control thread's SCHED_FIFO priority 1..99, 0 for the normal scheduler
        (vehicles/net/realtime.py; refused without CAP_SYS_NICE, then the loop runs normally and says so);
    max_d_des_m / min_d_des_m, h_des bounds come from the controller's arena (see `check_settings`)."""

    rate_hz: float = 20.0
    state_rate_hz: float = 10.0
    station_timeout_s: float = 10.0
    silent_after_s: float = 1.5
    silent_keep_s: float = 60.0
    realtime_priority: int = 0

    def __post_init__(self) -> None:
        for name in ("rate_hz", "state_rate_hz", "station_timeout_s", "silent_after_s", "silent_keep_s"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be a positive number, got {value}")
        realtime.check_priority(self.realtime_priority)


def check_settings(settings: wire.SettingsBody, params: ControllerParams) -> str | None:
    """Why an agent refuses these settings (values it cannot fly safely), or None. The station checks the
    operator's input more closely (team size, obstacles over MAVs); this is the agent's own floor."""
    lo, hi = params.mpc.position_min_m, params.mpc.position_max_m
    half = 0.5 * min(hi[0] - lo[0], hi[1] - lo[1])
    d, h = settings.d_des_m, settings.h_des_m
    if not (math.isfinite(d) and 0.0 < d < half):
        return f"d_des_m = {d} m is outside (0, {half:g}) m, the arena's half width"
    if not (math.isfinite(h) and lo[2] <= h + 0.9 <= hi[2]):
        return f"h_des_m = {h} m puts the MAVs outside the arena's height band {lo[2]:g}..{hi[2]:g} m"
    ids = [o.obstacle_id for o in settings.obstacles]
    if len(set(ids)) != len(ids):
        return "obstacle ids must be unique"
    for o in settings.obstacles:
        values = (*o.center_m, o.radius_m, o.height_m)
        if not all(math.isfinite(v) for v in values) or not (0.0 < o.radius_m <= 20.0) or o.height_m <= 0:
            return (
                f"obstacle {o.obstacle_id!r} needs finite values, a radius in (0, 20] m and a positive height"
            )
    return None


class TickStats:
    """The control loop's timing: |period - nominal| of the last `window` ticks, and overruns."""

    def __init__(self, *, nominal_s: float, window: int) -> None:
        self.nominal_s = nominal_s
        self._errors: deque[float] = deque(maxlen=window)
        self._last: float | None = None
        self.ticks = 0
        self.overruns = 0

    def started(self, t_s: float) -> None:
        if self._last is not None:
            self._errors.append(abs((t_s - self._last) - self.nominal_s))
        self._last = t_s
        self.ticks += 1

    def p99_error_s(self) -> float | None:
        if len(self._errors) < 10:
            return None
        return float(np.percentile(np.fromiter(self._errors, float), 99))


class OnboardAgent:
    """The agent of MAV `vehicle_id` on `bus`, flying `autopilot`. `start()` runs it on its own thread;
    `step(now_s)` runs one tick (tests drive it directly)."""

    def __init__(
        self,
        *,
        vehicle_id: int,
        autopilot: Autopilot,
        bus: Bus,
        controller_params: ControllerParams | None = None,
        agent_params: AgentParams | None = None,
        mission_params: MissionParams | None = None,
        params: OnboardParams | None = None,
        calibration: Calibration | None = None,
        clock: Callable[[], float] = time.time,
    ) -> None:
        """calibration: the MAV's camera, for the pixel detections of `skyring detect` on its camera key
        (default: the simulated camera's)."""
        self.vehicle_id = int(vehicle_id)
        self.params = params or OnboardParams()
        self._cparams = controller_params or ControllerParams()
        self._mparams = mission_params or MissionParams()
        self._bus = bus
        self._clock = clock
        self.links = ZenohLinks(bus, vehicle_id=self.vehicle_id)
        self.converter = DetectionConverter(
            vehicle_id=self.vehicle_id, calibration=calibration or Calibration.from_camera_params()
        )
        self.pilot = VehiclePilot(
            autopilot=autopilot,
            agent=Agent(
                vehicle_id=self.vehicle_id,
                params=self._cparams,
                agent_params=agent_params,
                converter=self.converter,
            ),
            params=self._mparams,
            clock=time.perf_counter,
        )
        self._lock = threading.Lock()
        self._commands: deque[Received] = deque(maxlen=256)
        self._acks: OrderedDict[tuple[int, int], wire.AckBody] = OrderedDict()
        self._settings = wire.SettingsBody()
        self._formation = FormationParams()
        self._obstacles: tuple[Obstacle, ...] = ()
        self._heartbeat: tuple[float, float] | None = None  # (station stamp, our receive time), UTC
        self.station_lost = False
        self._next_state_s = -math.inf
        self.tick_stats = TickStats(nominal_s=1.0 / self.params.rate_hz, window=int(10 * self.params.rate_hz))
        self.refused_commands = 0
        self.loop_errors = 0
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        # What the control loop runs under, a refusal included once run() has asked; cut to fit the wire.
        self.scheduler = self._scheduler_text(None)
        team = bus.team
        self._state_key = agent_key(team, self.vehicle_id, "state")
        self._ack_key = agent_key(team, self.vehicle_id, "ack")
        bus.subscribe(station_key(team, "heartbeat"), self._on_heartbeat)
        bus.subscribe(station_key(team, "command"), self._on_command)

    # ---- reading ------------------------------------------------------------------------------------------
    @property
    def settings(self) -> wire.SettingsBody:
        return self._settings

    @property
    def phase(self) -> Phase:
        return self.pilot.phase

    # ---- the loop -----------------------------------------------------------------------------------------
    def start(self) -> None:
        """Run the control loop on its own thread until `stop()`."""
        self._thread = threading.Thread(target=self.run, name=f"agent-{self.vehicle_id}", daemon=True)
        self._thread.start()

    def stop(self, timeout_s: float = 5.0) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout_s)

    def _scheduler_text(self, refused: str | None) -> str:
        """realtime.describe of this agent's priority, cut to the wire's text limit (sent at every state)."""
        return realtime.describe(self.params.realtime_priority, refused)[: wire.MAX_TEXT]

    def run(self) -> None:
        """Tick at rate_hz on the monotonic clock until stopped; a late tick re-anchors (counted), never
        bunches; an exception in a tick is counted and logged, the loop goes on."""
        realtime.name_calling_thread(realtime.control_thread_name(self.vehicle_id))
        refused = realtime.raise_calling_thread(self.params.realtime_priority)
        self.scheduler = self._scheduler_text(refused)
        if refused is not None:
            log.warning(
                "agent %d: %s: the control loop runs under the normal scheduler", self.vehicle_id, refused
            )
        period = 1.0 / self.params.rate_hz
        next_tick = time.monotonic()
        while not self._stop.is_set():
            self.tick_stats.started(time.monotonic())
            try:
                self.step(self._clock())
            except Exception:  # noqa: BLE001 - the control loop must outlive any single failure
                self.loop_errors += 1
                if self.loop_errors <= 10 or self.loop_errors % 1000 == 0:
                    log.exception(
                        "agent %d: control tick failed (%d so far)", self.vehicle_id, self.loop_errors
                    )
            next_tick += period
            delay = next_tick - time.monotonic()
            if delay < -period:
                self.tick_stats.overruns += 1
                next_tick = time.monotonic()
                delay = 0.0
            if delay > 0:
                self._stop.wait(delay)

    def step(self, now_s: float) -> None:
        """One control tick at now_s (UTC seconds)."""
        self._apply_commands(now_s)
        self._watch_station(now_s)
        enabled = self._settings.enabled and not self.station_lost
        height = takeoff_height(
            params=self._mparams, controller_params=self._cparams, formation=self._formation
        )
        pilot = self.pilot
        pilot.observe(now_s, enabled=enabled, takeoff_height_m=height)
        self.links.phase = pilot.phase.value
        members, silent = self._teammates(now_s)
        own = [self.vehicle_id] if pilot.in_roster else []
        slots = roster_slots(sorted(members + own), offset_rad=self._mparams.slot_offset_rad)
        detections = self.links.own_detections()
        received = self.links.receive(now_s, self.vehicle_id)
        if not pilot.silent:
            out = pilot.tick(
                now_s,
                AgentInputs(
                    own=pilot.state,
                    detections=detections,
                    camera=self.links.own_camera(),
                    received=received,
                    obstacles=self._obstacles + silent,
                    formation=self._formation,
                    role=pilot.role(enabled=enabled),
                    roster=slots,
                ),
            )
            for msg in out.outbox:
                self.links.send(now_s, self.vehicle_id, msg)
        if now_s >= self._next_state_s:
            self._next_state_s = now_s + 1.0 / self.params.state_rate_hz
            self._publish_state()

    # ---- teammates ----------------------------------------------------------------------------------------
    def _teammates(self, now_s: float) -> tuple[list[int], tuple[Obstacle, ...]]:
        """Roster members heard recently, and the cylinders about teammates gone silent in the air."""
        members, silent = [], []
        for vid, heard in sorted(self.links.heard().items()):
            age = now_s - heard.received_s
            if age <= self.params.silent_after_s:
                if heard.phase in ROSTER_PHASES:
                    members.append(vid)
            elif age <= self.params.silent_keep_s and heard.phase in ROSTER_PHASES:
                silent.append(silent_teammate_obstacle(plan=heard.plan, now_s=now_s))
        return members, tuple(silent)

    # ---- the station --------------------------------------------------------------------------------------
    def _on_heartbeat(self, msg: Received) -> None:
        with self._lock:
            self._heartbeat = (msg.header.stamp, msg.received_s)

    def _on_command(self, msg: Received) -> None:
        assert isinstance(msg.body, wire.CommandBody)
        if self.vehicle_id in msg.body.targets:
            with self._lock:
                self._commands.append(msg)

    def _watch_station(self, now_s: float) -> None:
        with self._lock:
            heartbeat = self._heartbeat
        if heartbeat is None:
            return
        lost = now_s - heartbeat[1] > self.params.station_timeout_s
        if lost and not self.station_lost:
            log.warning(
                "agent %d: no station heartbeat for %.0f s: landing",
                self.vehicle_id,
                self.params.station_timeout_s,
            )
            if self.pilot.phase in AIRBORNE_PHASES:  # a holding one too: nobody could release it
                self.pilot.start_landing(now_s)
        self.station_lost = lost

    def _apply_commands(self, now_s: float) -> None:
        with self._lock:
            commands = list(self._commands)
            self._commands.clear()
        for msg in commands:
            body = msg.body
            assert isinstance(body, wire.CommandBody)
            key = (msg.header.boot, body.command_id)
            ack = self._acks.get(key)
            if ack is None:
                accepted, message = self._apply(body, now_s)
                if not accepted:
                    self.refused_commands += 1
                ack = wire.AckBody(
                    command_boot=msg.header.boot,
                    command_id=body.command_id,
                    accepted=accepted,
                    message=message,
                )
                self._acks[key] = ack
                while len(self._acks) > _ACK_MEMORY:
                    self._acks.popitem(last=False)
            self._bus.publish(self._ack_key, ack)

    def _apply(self, body: wire.CommandBody, now_s: float) -> tuple[bool, str]:
        """Apply one command: (accepted, message)."""
        if body.action == "configure":
            settings = body.settings
            if settings is None:
                return False, "a configure command needs settings"
            if settings.rev < self._settings.rev:
                return True, "superseded by newer settings"
            reason = check_settings(settings, self._cparams)
            if reason is not None:
                return False, reason
            try:
                obstacles = tuple(wire.obstacle_from_wire(o) for o in settings.obstacles)
            except ValueError as exc:
                return False, f"obstacle refused: {exc}"
            self._settings = settings
            self._formation = wire.formation_of(settings)
            self._obstacles = obstacles
            return True, ""
        if body.action == "land":
            if not self.pilot.airborne and self.pilot.phase != Phase.LANDING:
                return True, f"on the ground already ({self.pilot.phase.value})"
            self.pilot.start_landing(now_s)
            return True, ""
        if body.action == "hold":
            try:
                self.pilot.hold(now_s)
            except MissionError as exc:
                return False, str(exc)
            return True, ""
        if body.action == "release":
            try:
                self.pilot.release()
            except MissionError as exc:
                return False, str(exc)
            return True, ""
        return False, f"unknown action {body.action!r}"

    def _publish_state(self) -> None:
        self._bus.publish(self._state_key, self.state_body())

    def state_body(self) -> wire.StateBody:
        """This agent now, as the station sees it."""
        pilot = self.pilot
        snap = pilot.snapshot()
        with self._lock:
            heartbeat = self._heartbeat
        rejected = {k: v for k, v in self._bus.guard.counts().items() if v}
        return wire.StateBody(
            phase=pilot.phase.value,
            settings=self._settings,
            autopilot=wire.telemetry_to_wire(snap.autopilot) if snap.autopilot is not None else None,
            plan=wire.plan_to_wire(snap.plan, phase=pilot.phase.value) if snap.plan is not None else None,
            person=wire.person_to_wire(snap.person) if snap.person is not None else None,
            setpoint=wire._vec(snap.setpoint.position_m) if snap.setpoint is not None else None,
            setpoint_yaw_rad=float(snap.setpoint.yaw_rad) if snap.setpoint is not None else None,
            status=snap.status.value if snap.status is not None else None,
            solver_time_s=float(snap.solver_time_s),
            tick_s=snap.tick_s,
            tick_period_p99_error_s=self.tick_stats.p99_error_s(),
            control_rate_hz=self.params.rate_hz,
            teammates_known=snap.teammates_known,
            used_slot=snap.used_slot,
            fault=(snap.fault or "")[: wire.MAX_TEXT] or None,
            tracker=_fields(snap.tracker),
            counters=_fields(snap.counters),
            rejected=rejected,
            hb_stamp=heartbeat[0] if heartbeat is not None else None,
            hb_received=heartbeat[1] if heartbeat is not None else None,
            station_lost=self.station_lost,
            scheduler=self.scheduler,
            camera=_camera_counts(self.converter.stats()),
            gps_offset_m=wire._vec(snap.gps_offset_m),
        )


def _camera_counts(stats: ConverterStats) -> dict[str, int]:
    """The camera converter's counts for the state message; latencies in whole milliseconds (-1: none)."""
    out = {"received": stats.received, "converted": stats.converted, "pending": stats.pending}
    out.update({f"rejected_{k}": v for k, v in stats.rejected})
    for name, value in (("latency_p50_ms", stats.latency_p50_s), ("latency_max_ms", stats.latency_max_s)):
        out[name] = int(round(value * 1e3)) if math.isfinite(value) else -1
    return out


def _fields(value: object) -> dict[str, int]:
    return {k: int(v) for k, v in vars(value).items()}


def full_mesh_endpoints(ports: Sequence[int], *, host: str = "127.0.0.1") -> list[str]:
    """tcp/host:port for each port (helper for rehearsals and tests)."""
    return [f"tcp/{host}:{p}" for p in ports]

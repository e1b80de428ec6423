"""The ground station as supervisor of onboard agents over Zenoh (`skyring serve --agents zenoh|spawn`).

`AgentFleet` gives the `GroundStation` what it needs from a mission (snapshots and operator actions) without
computing any control: the agents fly themselves. It

- hears every agent's state (10 Hz) and shows an agent as lost when nothing came for `lost_after_s`;
- turns each operator action into a command with an id: "configure" (the whole settings value: d_des, h_des,
  formation on/off, obstacles, stamped with a revision), "land", "hold" or "release"; re-sends it every
  `resend_s` to the agents that have not acknowledged it, and marks it failed for an agent that did not within
  `command_timeout_s`; the outcome per vehicle (pending, acked, refused, failed) is in each vehicle's
  `AgentLink` and so in the page and the API;
- keeps the agents' settings in step: a station that starts (or restarts) adopts the newest settings an agent
  reports, and configures any agent that reports older ones;
- publishes its heartbeat (2 Hz) and measures each agent's clock offset from the heartbeat's round trip;
- lands through PX4 directly as well (`override`: the station's own MAVLink link to a vehicle), so a dead or
  stuck agent's vehicle can still be landed.

Its service loop (heartbeat, re-sends, time-outs) runs on its own thread, so web load cannot delay it.
"""

from __future__ import annotations

import logging
import math
import numbers
import threading
import time
from collections import OrderedDict, deque
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from controller.messages import Obstacle, SolveStatus
from controller.params import ControllerParams, FormationParams
from controller.tracker import TrackerStats
from vehicles.agent import AgentCounters
from vehicles.autopilot import Autopilot, Setpoint
from vehicles.mission import MissionCounters, MissionSnapshot, team_counters
from vehicles.net import wire
from vehicles.net.guard import Received
from vehicles.net.keys import all_agents_key, station_key
from vehicles.net.session import Bus
from vehicles.pilot import FLYING_PHASES, AgentLink, MissionError, Phase, VehicleSnapshot
from vehicles.world import PersonTruth

log = logging.getLogger(__name__)

PENDING, ACKED, REFUSED, FAILED = "pending", "acked", "refused", "failed"


@dataclass(frozen=True)
class FleetParams:
    """lost_after_s: no state for this long shows an agent lost; heartbeat_hz: station heartbeats per
    second; resend_s / command_timeout_s: command re-sending and giving up; service_hz: the service loop's
    rate; commands_shown: recent commands shown per vehicle."""

    lost_after_s: float = 0.5
    heartbeat_hz: float = 2.0
    resend_s: float = 0.25
    command_timeout_s: float = 3.0
    service_hz: float = 20.0
    commands_shown: int = 6


@dataclass
class _Command:
    command_id: int
    action: str
    targets: tuple[int, ...]
    settings: wire.SettingsBody | None
    sent_s: float
    last_sent_s: float
    outcome: dict[int, tuple[str, str]] = field(default_factory=dict)  # vid -> (status, message)


@dataclass
class _Agent:
    state: wire.StateBody | None = None
    received_s: float = -math.inf  # station monotonic clock
    offsets: deque = field(default_factory=lambda: deque(maxlen=20))  # (rtt, offset) samples


class AgentFleet:
    """Supervises the agents `vehicle_ids` of the team on `bus` (see the module docstring).

    static_obstacles: the map (trees) the station hands every agent; person_truth: the simulated person's
    truth when the station runs the rehearsal world (None in the field); override: the station's own
    autopilot link per vehicle id (PX4 through MAVSDK), used to land directly; clock: monotonic seconds.
    """

    def __init__(
        self,
        *,
        bus: Bus,
        vehicle_ids: Sequence[int],
        controller_params: ControllerParams | None = None,
        static_obstacles: Sequence[Obstacle] = (),
        formation: FormationParams | None = None,
        formation_enabled: bool = True,
        person_truth: Callable[[], PersonTruth | None] | None = None,
        override: Mapping[int, Autopilot] | None = None,
        params: FleetParams | None = None,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        ids = sorted(int(v) for v in vehicle_ids)
        if not ids or len(set(ids)) != len(ids):
            raise ValueError("a fleet needs at least one vehicle, with unique ids")
        self._bus = bus
        self._ids = tuple(ids)
        self._cparams = controller_params or ControllerParams()
        self._params = params or FleetParams()
        self._clock = clock
        self._truth = person_truth
        self._override = dict(override or {})
        formation = formation or FormationParams()
        self._settings = wire.SettingsBody(
            rev=1,  # the station's defaults: older than any operator action (revisions are UTC ns)
            d_des_m=formation.d_des_m,
            h_des_m=formation.h_des_m,
            enabled=bool(formation_enabled),
            obstacles=[wire.obstacle_to_wire(o) for o in static_obstacles],
        )
        self._lock = threading.RLock()
        self._agents = {vid: _Agent() for vid in self._ids}
        self._commands: OrderedDict[int, _Command] = OrderedDict()
        self._next_command = 1
        self._rejected_actions = 0
        self.override_landings = 0
        self.bad_reports = 0
        self._now = clock()
        self._next_heartbeat = -math.inf
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        team = bus.team
        self._command_key = station_key(team, "command")
        self._heartbeat_key = station_key(team, "heartbeat")
        bus.subscribe(all_agents_key(team, "state"), self._on_state)
        bus.subscribe(all_agents_key(team, "ack"), self._on_ack)

    # ---- lifecycle ----------------------------------------------------------------------------------------
    def start(self) -> None:
        """Run the service loop (heartbeat, re-sends, time-outs) on its own thread."""
        self._thread = threading.Thread(target=self._run, name="agent-fleet", daemon=True)
        self._thread.start()

    def close(self, *, settle_s: float = 1.5) -> None:
        """Wait up to settle_s for pending commands (e.g. the landing asked at shutdown), then stop."""
        deadline = time.monotonic() + settle_s
        while time.monotonic() < deadline and self.pending():
            time.sleep(0.05)
        self._stop.set()
        if self._thread is not None:
            self._thread.join(2.0)

    def _run(self) -> None:
        period = 1.0 / self._params.service_hz
        while not self._stop.wait(period):
            try:
                self.service()
            except Exception:  # noqa: BLE001 - supervision must go on
                log.exception("fleet service failed")

    def service(self) -> None:
        """Heartbeat when due, reconcile settings, re-send unacknowledged commands, time out old ones."""
        now = self._clock()
        if now >= self._next_heartbeat:
            self._next_heartbeat = now + 1.0 / self._params.heartbeat_hz
            self._bus.publish(self._heartbeat_key, wire.HeartbeatBody(rate_hz=self._params.heartbeat_hz))
        with self._lock:
            self._reconcile(now)
            for cmd in self._commands.values():
                waiting = [vid for vid, (status, _) in cmd.outcome.items() if status == PENDING]
                if not waiting:
                    continue
                if now - cmd.sent_s > self._params.command_timeout_s:
                    for vid in waiting:
                        cmd.outcome[vid] = (
                            FAILED,
                            f"no acknowledgement within {self._params.command_timeout_s:g} s",
                        )
                elif now - cmd.last_sent_s >= self._params.resend_s:
                    cmd.last_sent_s = now
                    self._publish(cmd, tuple(waiting))

    def pending(self) -> int:
        """Commands still waiting for an acknowledgement from a vehicle that is heard."""
        with self._lock:
            return sum(
                1
                for cmd in self._commands.values()
                for vid, (status, _) in cmd.outcome.items()
                if status == PENDING and not self._lost(vid, self._clock())
            )

    # ---- the mission interface the GroundStation drives ---------------------------------------------------
    @property
    def vehicle_ids(self) -> tuple[int, ...]:
        return self._ids

    @property
    def controller_params(self) -> ControllerParams:
        return self._cparams

    @property
    def formation(self) -> FormationParams:
        return wire.formation_of(self._settings)

    @property
    def formation_enabled(self) -> bool:
        return self._settings.enabled

    def obstacles(self) -> tuple[Obstacle, ...]:
        return tuple(wire.obstacle_from_wire(o) for o in self._settings.obstacles)

    def phase(self, vehicle_id: int) -> Phase:
        return self._vehicle(vehicle_id)[0]

    def step(self, now_s: float) -> None:
        """The station's tick: nothing to compute (the agents fly themselves); just note the time."""
        self._now = now_s

    def set_formation(self, formation: FormationParams) -> None:
        if not all(math.isfinite(v) and v > 0 for v in (formation.d_des_m, formation.h_des_m)):
            self._refuse("d_des_m and h_des_m must be positive finite numbers of metres")
        self._configure(d_des_m=float(formation.d_des_m), h_des_m=float(formation.h_des_m))

    def set_formation_enabled(self, enabled: bool) -> None:
        self._configure(enabled=bool(enabled))

    def add_obstacle(self, obstacle: Obstacle) -> None:
        if any(o.obstacle_id == obstacle.obstacle_id for o in self._settings.obstacles):
            self._refuse(f"an obstacle with id {obstacle.obstacle_id!r} exists already; choose another id")
        if len(self._settings.obstacles) >= wire.MAX_OBSTACLES:
            self._refuse(f"at most {wire.MAX_OBSTACLES} obstacles travel to the agents")
        self._configure(obstacles=[*self._settings.obstacles, wire.obstacle_to_wire(obstacle)])

    def remove_obstacle(self, obstacle_id: str) -> None:
        known = {o.obstacle_id: o for o in self._settings.obstacles}
        if obstacle_id not in known or known[obstacle_id].kind != "virtual":
            self._refuse(
                f"obstacle {obstacle_id!r} is a static obstacle and cannot be removed"
                if obstacle_id in known
                else f"no virtual obstacle with id {obstacle_id!r}"
            )
        self._configure(obstacles=[o for o in self._settings.obstacles if o.obstacle_id != obstacle_id])

    def land(self, vehicle_id: int) -> None:
        """Land one vehicle: a command to its agent, and straight to PX4 when the station has a link."""
        phase, lost = self._vehicle(vehicle_id)
        if phase in (Phase.IDLE, Phase.LANDED) and not lost:
            self._refuse(f"vehicle {vehicle_id} is on the ground already ({phase.value})")
        self._send("land", (int(vehicle_id),))
        self._land_direct(int(vehicle_id))

    def land_all(self) -> None:
        """Land every vehicle: one command to every agent, and straight to every PX4 the station reaches."""
        self._send("land", self._ids)
        for vid in self._ids:
            self._land_direct(vid)

    def hold(self, vehicle_id: int) -> None:
        """Stop one flying vehicle where it is: a command to its agent (which refuses it on the ground)."""
        phase, lost = self._vehicle(vehicle_id)
        if phase not in FLYING_PHASES or lost:
            state = "lost" if lost else phase.value
            self._refuse(
                f"vehicle {vehicle_id} is {state}; only a vehicle taking off or flying formation can be held"
            )
        self._send("hold", (int(vehicle_id),))

    def release(self, vehicle_id: int) -> None:
        phase, _ = self._vehicle(vehicle_id)
        if phase not in (Phase.LANDED, Phase.HOLDING):
            self._refuse(
                f"vehicle {vehicle_id} is {phase.value}; only a landed or holding vehicle can be released"
            )
        self._send("release", (int(vehicle_id),))

    def snapshot(self) -> MissionSnapshot:
        now, utc = self._clock(), time.time()
        with self._lock:
            vehicles = tuple(self._vehicle_snapshot(vid, now, utc) for vid in self._ids)
            settings = self._settings
        obstacles = tuple(wire.obstacle_from_wire(o) for o in settings.obstacles)
        return MissionSnapshot(
            stamp_s=self._now,
            vehicles=vehicles,
            person_truth=self._truth() if self._truth is not None else None,
            obstacles=obstacles,
            virtual_obstacle_ids=tuple(o.obstacle_id for o in obstacles if o.kind == "virtual"),
            formation=wire.formation_of(settings),
            formation_enabled=settings.enabled,
            slot_count=sum(v.phase in FLYING_PHASES for v in vehicles),
            counters=self._counters(vehicles),
        )

    # ---- receiving ----------------------------------------------------------------------------------------
    def _on_state(self, msg: Received) -> None:
        body = msg.body
        assert isinstance(body, wire.StateBody)
        vid = msg.header.sender
        with self._lock:
            agent = self._agents.get(vid)
            if agent is None:
                return
            agent.state = body
            agent.received_s = self._clock()
            if body.hb_stamp is not None and body.hb_received is not None:
                t1, t2, t3, t4 = body.hb_stamp, body.hb_received, msg.header.stamp, msg.received_s
                rtt = (t4 - t1) - (t3 - t2)
                if math.isfinite(rtt) and rtt >= 0:
                    agent.offsets.append((rtt, ((t2 - t1) + (t3 - t4)) / 2.0))

    def _on_ack(self, msg: Received) -> None:
        body = msg.body
        assert isinstance(body, wire.AckBody)
        if body.command_boot != self._bus.boot:
            return  # an answer to an earlier station run
        with self._lock:
            cmd = self._commands.get(body.command_id)
            vid = msg.header.sender
            if cmd is not None and vid in cmd.outcome and cmd.outcome[vid][0] in (PENDING, FAILED):
                cmd.outcome[vid] = (ACKED if body.accepted else REFUSED, body.message)

    # ---- internals ----------------------------------------------------------------------------------------
    def _vehicle(self, vehicle_id: int) -> tuple[Phase, bool]:
        if not isinstance(vehicle_id, numbers.Integral) or int(vehicle_id) not in self._agents:
            self._refuse(f"no vehicle with id {vehicle_id!r}; vehicles are {list(self._ids)}")
        with self._lock:
            agent = self._agents[int(vehicle_id)]
            phase = _phase(agent.state)
            return phase, self._lost(int(vehicle_id), self._clock())

    def _lost(self, vid: int, now: float) -> bool:
        return now - self._agents[vid].received_s > self._params.lost_after_s

    def _refuse(self, message: str) -> None:
        self._rejected_actions += 1
        raise MissionError(message)

    def _configure(self, **changes) -> None:
        with self._lock:
            values = {f: getattr(self._settings, f) for f in self._settings.__struct_fields__}
            values.update(changes, rev=max(time.time_ns(), self._settings.rev + 1))
            self._settings = wire.SettingsBody(**values)
            self._send("configure", self._ids, settings=self._settings)

    def _reconcile(self, now: float) -> None:
        """Adopt newer settings an agent reports; configure agents that report older ones."""
        heard = {
            vid: a.state
            for vid, a in self._agents.items()
            if a.state is not None and not self._lost(vid, now)
        }
        newest = max((s.settings for s in heard.values()), key=lambda s: s.rev, default=None)
        if newest is not None and newest.rev > self._settings.rev:
            log.info("adopting the agents' settings (revision %d)", newest.rev)
            self._settings = newest
        behind = [vid for vid, s in heard.items() if s.settings.rev < self._settings.rev]
        configuring = {
            vid
            for cmd in self._commands.values()
            if cmd.action == "configure"
            and cmd.settings is not None
            and cmd.settings.rev == self._settings.rev
            for vid, (status, _) in cmd.outcome.items()
            if status in (PENDING, ACKED, REFUSED)  # a refusal is shown, not re-sent; a failure is retried
        }
        missing = tuple(vid for vid in behind if vid not in configuring)
        if missing:
            self._send("configure", missing, settings=self._settings)

    def _send(
        self, action: str, targets: tuple[int, ...], *, settings: wire.SettingsBody | None = None
    ) -> int:
        with self._lock:
            now = self._clock()
            cmd = _Command(
                command_id=self._next_command,
                action=action,
                targets=targets,
                settings=settings,
                sent_s=now,
                last_sent_s=now,
                outcome={vid: (PENDING, "") for vid in targets},
            )
            self._next_command += 1
            self._commands[cmd.command_id] = cmd
            while len(self._commands) > 64 * len(self._ids):
                self._commands.popitem(last=False)
        self._publish(cmd, targets)
        return cmd.command_id

    def _publish(self, cmd: _Command, targets: tuple[int, ...]) -> None:
        self._bus.publish(
            self._command_key,
            wire.CommandBody(
                command_id=cmd.command_id, action=cmd.action, targets=list(targets), settings=cmd.settings
            ),
        )

    def _land_direct(self, vid: int) -> None:
        autopilot = self._override.get(vid)
        if autopilot is None:
            return
        try:
            autopilot.land()
            self.override_landings += 1
        except Exception:  # noqa: BLE001 - the command to the agent went out anyway
            log.exception("landing vehicle %d through its MAVLink link failed", vid)

    def _vehicle_snapshot(self, vid: int, now: float, utc: float) -> VehicleSnapshot:
        agent = self._agents[vid]
        s = agent.state
        lost = self._lost(vid, now)
        offset = min(agent.offsets)[1] if agent.offsets else None
        commands = tuple(
            (cmd.command_id, cmd.action, *cmd.outcome[vid])
            for cmd in list(self._commands.values())
            if vid in cmd.outcome
        )[-self._params.commands_shown :]
        link = AgentLink(
            lost=lost,
            age_s=now - agent.received_s,
            clock_offset_s=offset,
            tick_period_p99_error_s=s.tick_period_p99_error_s if s is not None else None,
            commands=commands,
            rejected_messages=sum(s.rejected.values()) if s is not None else 0,
            station_lost=s.station_lost if s is not None else False,
            scheduler=s.scheduler if s is not None else "",
        )
        if s is None:
            return VehicleSnapshot(
                vehicle_id=vid,
                phase=Phase.IDLE,
                autopilot=None,
                plan=None,
                person=None,
                setpoint=None,
                status=None,
                solver_time_s=0.0,
                tick_s=None,
                link_age_s=None,
                teammates_known=0,
                used_slot=False,
                fault="agent not heard yet",
                tracker=TrackerStats(),
                counters=AgentCounters(),
                agent=link,
            )
        autopilot = plan = person = setpoint = None
        gps_offset = np.zeros(3)
        try:
            if s.autopilot is not None:
                autopilot = wire.telemetry_from_wire(s.autopilot, vehicle_id=vid)
                if lost:
                    autopilot = replace(autopilot, link_lost=True)
            if s.plan is not None:
                plan = wire.plan_from_wire(s.plan, vehicle_id=vid)
            if s.person is not None:
                person = wire.person_from_wire(s.person)
            if s.setpoint is not None and s.setpoint_yaw_rad is not None:
                setpoint = Setpoint(
                    stamp_s=utc,
                    position_m=np.array(s.setpoint, dtype=float),
                    velocity_mps=np.zeros(3),
                    yaw_rad=s.setpoint_yaw_rad,
                )
            if s.gps_offset_m is not None:
                reported = np.array(s.gps_offset_m, dtype=float)
                if not np.all(np.isfinite(reported)):
                    raise ValueError("the GPS offset is not finite")
                gps_offset = reported
        except (ValueError, TypeError):
            self.bad_reports += 1  # an agent reported values its own types refuse: shown as unknown
        agent_now = utc + (offset or 0.0)
        return VehicleSnapshot(
            vehicle_id=vid,
            phase=_phase(s),
            autopilot=autopilot,
            plan=plan,
            person=person,
            setpoint=setpoint,
            status=_status(s.status),
            solver_time_s=s.solver_time_s,
            tick_s=s.tick_s,
            link_age_s=(agent_now - autopilot.stamp_s) if autopilot is not None else None,
            teammates_known=s.teammates_known,
            used_slot=s.used_slot,
            fault="agent lost" if lost else s.fault,
            tracker=TrackerStats(**_known(s.tracker, TrackerStats)),
            counters=AgentCounters(**_known(s.counters, AgentCounters)),
            agent=link,
            # flies the formation: its phase, and the plan it shares says so (a released or grounded agent's
            # plan does not), and it is heard
            in_formation=_phase(s) == Phase.FORMATION and plan is not None and plan.in_formation and not lost,
            gps_offset_m=gps_offset,
        )

    def _counters(self, vehicles: Sequence[VehicleSnapshot]) -> MissionCounters:
        return team_counters(vehicles, rejected_actions=self._rejected_actions)


def _phase(state: wire.StateBody | None) -> Phase:
    if state is None:
        return Phase.IDLE
    try:
        return Phase(state.phase)
    except ValueError:
        return Phase.IDLE


def _status(value: str | None) -> SolveStatus | None:
    try:
        return SolveStatus(value) if value is not None else None
    except ValueError:
        return None


def _known(counts: dict[str, int], kind: type) -> dict[str, int]:
    names = kind.__dataclass_fields__
    return {k: int(v) for k, v in counts.items() if k in names}

"""The mission: the one piece of glue that every runner drives (deterministic simulation, live ground station,
PX4 vehicles). Backend-agnostic: it talks to vehicles only through the `Autopilot` protocol, to the world
through `World` and to the radio through `Links`.

It holds one agent per vehicle, the operator's formation parameters, static and virtual obstacles, and a phase
machine per vehicle:

    IDLE --(enabled)--> TAKEOFF --(at height)--> FORMATION --land()--> LANDING --(on ground)--> LANDED
    LANDED --release()--> IDLE
    TAKEOFF, FORMATION --hold()--> HOLDING --release()--> FORMATION;  HOLDING --land()--> LANDING
    TAKEOFF, FORMATION, HOLDING --(the autopilot lands by itself: a failsafe or a pilot)--> LANDING

A MAV that is holding, landing or landed has left formation control: it publishes plans marked
not-in-formation (then none once on the ground), so its teammates avoid it but re-space to 2 pi / (K - 1) by
themselves. Operator
actions are methods that take effect at the next `step` (within one control period); a refused action raises
`MissionError` with a message a person can act on and changes nothing.
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from enum import StrEnum

from controller.messages import HorizonPlan, Obstacle, PersonEstimate, SolveStatus
from controller.params import ControllerParams, FormationParams
from controller.tracker import TrackerStats
from vehicles.agent import Agent, AgentCounters, AgentInputs, AgentOutputs, AgentParams, AgentRole
from vehicles.autopilot import Autopilot, AutopilotState, FlightMode, Setpoint
from vehicles.link_loss import silent_vehicle_obstacle
from vehicles.links import Links
from vehicles.world import PERSON_CENTRE_HEIGHT_M, PersonTruth, World


class Phase(StrEnum):
    """Where a vehicle is in the mission."""

    IDLE = "idle"
    TAKEOFF = "takeoff"
    FORMATION = "formation"
    HOLDING = "holding"  # hovering where the operator stopped it, out of formation control
    LANDING = "landing"
    LANDED = "landed"


class MissionError(ValueError):
    """An operator action the mission refused; the message says why and what to do."""


@dataclass(frozen=True)
class MissionParams:
    """takeoff_height_m: None = the formation height (h_des above a person standing on the ground) clamped
    0.5 m inside the MPC's height bounds; at_height_tolerance_m: takeoff is done within this of the target;
    retry_s: a takeoff or land command that shows no effect is re-sent after this long (lost commands over a
    real link); slot_offset_rad: bearing of roster slot 0 about the person (slot k at offset + 2 pi k / K)."""

    takeoff_height_m: float | None = None
    at_height_tolerance_m: float = 0.5
    retry_s: float = 1.0
    slot_offset_rad: float = 0.0


@dataclass(frozen=True, eq=False)
class VehicleSnapshot:
    """Everything a display needs about one vehicle.

    autopilot: latest telemetry; plan: the latest horizon plan; person: this MAV's fused estimate (its
    position_cov_m2 is the ellipsoid); setpoint: last set-point sent; status/solver_time_s: the controller's
    last result; tick_s: wall time of the last agent tick (None without a clock); link_age_s: age of the
    telemetry; teammates_known: teammates whose plans are fresh; used_slot: steering to the roster slot
    because teammates are unheard; fault: last fault line.
    """

    vehicle_id: int
    phase: Phase
    autopilot: AutopilotState | None
    plan: HorizonPlan | None
    person: PersonEstimate | None
    setpoint: Setpoint | None
    status: SolveStatus | None
    solver_time_s: float
    tick_s: float | None
    link_age_s: float | None
    teammates_known: int
    used_slot: bool
    fault: str | None
    tracker: TrackerStats
    counters: AgentCounters


@dataclass(frozen=True)
class MissionCounters:
    """Rejected inputs, summed over the team: operator actions refused; detections the trackers ignored
    (gated, stale, invalid); malformed or misaddressed messages; controller exceptions; braking ticks."""

    rejected_actions: int = 0
    rejected_detections: int = 0
    rejected_messages: int = 0
    controller_errors: int = 0
    braking_ticks: int = 0


@dataclass(frozen=True, eq=False)
class MissionSnapshot:
    """The whole mission at stamp_s: vehicles by id, the person's truth (simulation only), every obstacle
    (static and virtual), the operator's parameters, and the counters of rejected inputs."""

    stamp_s: float
    vehicles: tuple[VehicleSnapshot, ...]
    person_truth: PersonTruth | None
    obstacles: tuple[Obstacle, ...]
    virtual_obstacle_ids: tuple[str, ...]
    formation: FormationParams
    formation_enabled: bool
    slot_count: int
    counters: MissionCounters


@dataclass
class _Vehicle:
    autopilot: Autopilot
    agent: Agent
    phase: Phase = Phase.IDLE
    command_s: float = -math.inf
    last: AgentOutputs | None = None
    last_setpoint: Setpoint | None = None
    tick_s: float | None = None
    paused: bool = False
    state: AutopilotState | None = None


class Mission:
    """A team of vehicles following the person. Drive it with `step(now_s)` at the control rate."""

    def __init__(
        self,
        *,
        autopilots: Sequence[Autopilot],
        world: World,
        links: Links,
        controller_params: ControllerParams | None = None,
        formation: FormationParams | None = None,
        virtual_obstacles: Sequence[Obstacle] = (),
        formation_enabled: bool = True,
        params: MissionParams | None = None,
        agent_params: AgentParams | None = None,
        clock: Callable[[], float] | None = None,
    ) -> None:
        controller_params = controller_params or ControllerParams()
        formation = formation or FormationParams()
        ids = [a.vehicle_id for a in autopilots]
        if not ids or len(set(ids)) != len(ids):
            raise ValueError("a mission needs at least one autopilot, with unique vehicle ids")
        self._vehicles = {
            a.vehicle_id: _Vehicle(
                autopilot=a,
                agent=Agent(vehicle_id=a.vehicle_id, params=controller_params, agent_params=agent_params),
            )
            for a in sorted(autopilots, key=lambda a: a.vehicle_id)
        }
        self._world = world
        self._links = links
        self._cparams = controller_params
        self._params = params or MissionParams()
        self._check_formation(formation)
        self._formation = formation
        self._virtual: dict[str, Obstacle] = {}
        self._enabled = bool(formation_enabled)
        self._clock = clock
        self._now = 0.0
        self._rejected_actions = 0
        for o in virtual_obstacles:
            self.add_obstacle(o)

    # ---- reading ------------------------------------------------------------------------------------------
    @property
    def vehicle_ids(self) -> tuple[int, ...]:
        return tuple(self._vehicles)

    @property
    def formation(self) -> FormationParams:
        return self._formation

    @property
    def formation_enabled(self) -> bool:
        return self._enabled

    @property
    def controller_params(self) -> ControllerParams:
        return self._cparams

    def obstacles(self) -> tuple[Obstacle, ...]:
        """Static obstacles, then virtual ones in the order added."""
        return self._world.obstacles + tuple(self._virtual.values())

    def phase(self, vehicle_id: int) -> Phase:
        return self._vehicle(vehicle_id).phase

    def takeoff_height_m(self) -> float:
        if self._params.takeoff_height_m is not None:
            return self._params.takeoff_height_m
        lo, hi = self._cparams.mpc.position_min_m[2] + 0.5, self._cparams.mpc.position_max_m[2] - 0.5
        return min(max(self._formation.h_des_m + PERSON_CENTRE_HEIGHT_M, lo), hi)

    # ---- operator actions ---------------------------------------------------------------------------------
    def set_formation(self, formation: FormationParams) -> None:
        """Change d_des / h_des for every MAV from the next tick."""
        try:
            self._check_formation(formation)
        except MissionError:
            self._rejected_actions += 1
            raise
        self._formation = formation

    def add_obstacle(self, obstacle: Obstacle) -> None:
        """Add a virtual obstacle (its id must be new)."""
        if not isinstance(obstacle, Obstacle):
            self._refuse(f"expected an Obstacle, got {type(obstacle).__name__}")
        if any(o.obstacle_id == obstacle.obstacle_id for o in self.obstacles()):
            self._refuse(f"an obstacle with id {obstacle.obstacle_id!r} exists already; choose another id")
        self._virtual[obstacle.obstacle_id] = obstacle

    def remove_obstacle(self, obstacle_id: str) -> None:
        """Remove a virtual obstacle; trees cannot be removed."""
        if obstacle_id not in self._virtual:
            static = any(o.obstacle_id == obstacle_id for o in self._world.obstacles)
            self._refuse(
                f"obstacle {obstacle_id!r} is a static obstacle and cannot be removed"
                if static
                else f"no virtual obstacle with id {obstacle_id!r}"
            )
        del self._virtual[obstacle_id]

    def land(self, vehicle_id: int) -> None:
        """Land one vehicle now; it leaves formation control until released."""
        v = self._vehicle(vehicle_id)
        if v.phase in (Phase.IDLE, Phase.LANDED):
            self._refuse(f"vehicle {vehicle_id} is on the ground already ({v.phase.value})")
        self._start_landing(v)

    def land_all(self) -> None:
        """Land every vehicle that is taking off, flying or holding."""
        for v in self._vehicles.values():
            if v.phase in (Phase.TAKEOFF, Phase.FORMATION, Phase.HOLDING):
                self._start_landing(v)

    def hold(self, vehicle_id: int) -> None:
        """Stop one flying vehicle where it is: it hovers out of formation control (its teammates avoid it
        and re-space without it) until released or landed."""
        v = self._vehicle(vehicle_id)
        if v.phase not in (Phase.TAKEOFF, Phase.FORMATION):
            self._refuse(
                f"vehicle {vehicle_id} is {v.phase.value}; only a vehicle taking off or flying formation "
                "can be held"
            )
        if v.state is None or not v.state.in_air:
            self._refuse(f"vehicle {vehicle_id} is not in the air yet; land it instead to stop its takeoff")
        v.phase = Phase.HOLDING
        v.command_s = self._now
        v.autopilot.hold()

    def release(self, vehicle_id: int) -> None:
        """Give a vehicle back to the formation: a landed one takes off again (when formation is enabled), a
        holding one rejoins from where it hovers."""
        v = self._vehicle(vehicle_id)
        if v.phase == Phase.HOLDING:
            v.phase = Phase.FORMATION
            return
        if v.phase != Phase.LANDED:
            self._refuse(
                f"vehicle {vehicle_id} is {v.phase.value}; only a landed or holding vehicle can be released"
            )
        v.phase = Phase.IDLE

    def set_formation_enabled(self, enabled: bool) -> None:
        """Start (True) or stop (False) formation control; stopped MAVs hold position, idle ones stay down."""
        self._enabled = bool(enabled)

    # ---- the control tick ---------------------------------------------------------------------------------
    def step(self, now_s: float) -> None:
        """Advance the world to now_s and run one control tick of every vehicle."""
        if not math.isfinite(now_s) or now_s < self._now:
            raise ValueError(f"mission time must be finite and non-decreasing, got {now_s} after {self._now}")
        self._now = now_s
        self._world.advance(now_s)
        obstacles = self.obstacles()
        for v in self._vehicles.values():
            v.state = v.autopilot.state()
            self._advance_phase(v, now_s)
        # A vehicle whose link is lost gets no agent tick (nothing would reach it) and leaves the roster; its
        # teammates avoid it around its last plan, the wider the longer it is silent (vehicles/link_loss.py).
        silent = {vid for vid, v in self._vehicles.items() if v.state is not None and v.state.link_lost}
        obstacles += tuple(
            silent_vehicle_obstacle(
                state=self._vehicles[vid].state,
                now_s=now_s,
                plan=self._vehicles[vid].last.plan if self._vehicles[vid].last is not None else None,
            )
            for vid in sorted(silent)
        )
        roster = [
            vid
            for vid, v in self._vehicles.items()
            if v.phase in (Phase.TAKEOFF, Phase.FORMATION)
            and vid not in silent
            and not (v.state is not None and v.state.released)
        ]
        k = len(roster)
        offset = self._params.slot_offset_rad
        slots = tuple((vid, offset + 2.0 * math.pi * i / k) for i, vid in enumerate(roster))
        for vid, v in self._vehicles.items():
            if vid in silent:
                self._world.detections(vid)  # stale frames and messages are dropped, not queued up
                self._links.receive(now_s, vid)
                continue
            role = self._role(v)
            inputs = AgentInputs(
                own=v.state,
                detections=self._world.detections(vid),
                received=self._links.receive(now_s, vid),
                obstacles=obstacles,
                formation=self._formation,
                role=role,
                roster=slots,
            )
            t0 = self._clock() if self._clock is not None else None
            out = v.agent.tick(now_s, inputs)
            if t0 is not None:
                v.tick_s = self._clock() - t0
            v.last = out
            if out.setpoint is not None and role == AgentRole.FORMATION:
                v.autopilot.send_setpoint(out.setpoint)
                v.last_setpoint = out.setpoint
            for msg in out.outbox:
                self._links.send(now_s, vid, msg)

    def snapshot(self) -> MissionSnapshot:
        """The mission now, for displays, logs and metrics."""
        vehicles = []
        totals = dict.fromkeys(
            ("rejected_detections", "rejected_messages", "controller_errors", "braking_ticks"), 0
        )
        k = 0
        for vid, v in self._vehicles.items():
            out = v.last
            state = v.state
            tracker = out.tracker if out is not None else TrackerStats()
            counters = out.counters if out is not None else AgentCounters()
            control = out.control if out is not None else None
            k += v.phase in (Phase.TAKEOFF, Phase.FORMATION)
            totals["rejected_detections"] += tracker.gated + tracker.stale + tracker.invalid
            totals["rejected_messages"] += counters.rejected_messages
            totals["controller_errors"] += counters.controller_errors
            totals["braking_ticks"] += counters.braking_ticks
            vehicles.append(
                VehicleSnapshot(
                    vehicle_id=vid,
                    phase=v.phase,
                    autopilot=state,
                    plan=out.plan if out is not None else None,
                    person=out.person if out is not None else None,
                    setpoint=v.last_setpoint,
                    status=control.status if control is not None else None,
                    solver_time_s=control.solver_time_s if control is not None else 0.0,
                    tick_s=v.tick_s,
                    link_age_s=(self._now - state.stamp_s) if state is not None else None,
                    teammates_known=out.teammates_known if out is not None else 0,
                    used_slot=out.used_slot if out is not None else False,
                    fault=out.fault if out is not None else None,
                    tracker=tracker,
                    counters=counters,
                )
            )
        return MissionSnapshot(
            stamp_s=self._now,
            vehicles=tuple(vehicles),
            person_truth=self._world.person_truth(),
            obstacles=self.obstacles(),
            virtual_obstacle_ids=tuple(self._virtual),
            formation=self._formation,
            formation_enabled=self._enabled,
            slot_count=k,
            counters=MissionCounters(rejected_actions=self._rejected_actions, **totals),
        )

    # ---- internals ----------------------------------------------------------------------------------------
    def _vehicle(self, vehicle_id: int) -> _Vehicle:
        v = self._vehicles.get(int(vehicle_id)) if isinstance(vehicle_id, numbers.Integral) else None
        if v is None:
            self._refuse(f"no vehicle with id {vehicle_id!r}; vehicles are {list(self._vehicles)}")
        return v

    def _refuse(self, message: str) -> None:
        self._rejected_actions += 1
        raise MissionError(message)

    def _check_formation(self, formation: FormationParams) -> None:
        if not isinstance(formation, FormationParams):
            raise MissionError(f"expected FormationParams, got {type(formation).__name__}")
        for name in ("d_des_m", "h_des_m"):
            value = getattr(formation, name)
            if not (isinstance(value, int | float) and math.isfinite(value) and value > 0):
                raise MissionError(f"{name} must be a positive finite number of metres, got {value!r}")

    def _start_landing(self, v: _Vehicle) -> None:
        v.phase = Phase.LANDING
        v.command_s = self._now
        v.autopilot.land()

    def _advance_phase(self, v: _Vehicle, now_s: float) -> None:
        s = v.state
        if s is None:
            return
        retry = now_s - v.command_s >= self._params.retry_s
        flying = v.phase in (Phase.TAKEOFF, Phase.FORMATION, Phase.HOLDING)
        if flying and s.in_air and s.released and s.mode == FlightMode.LAND:
            v.phase = Phase.LANDING  # the autopilot's failsafe (or a pilot) is landing it
            v.command_s = now_s
        elif v.phase == Phase.IDLE and self._enabled and not s.in_air:
            v.phase = Phase.TAKEOFF
            v.command_s = now_s
            v.autopilot.takeoff(self.takeoff_height_m())
        elif v.phase == Phase.TAKEOFF:
            if (
                s.in_air
                and s.mode in (FlightMode.HOLD, FlightMode.OFFBOARD)
                and (abs(s.position_m[2] - self.takeoff_height_m()) <= self._params.at_height_tolerance_m)
            ):
                v.phase = Phase.FORMATION
                v.paused = False
            elif retry and s.mode != FlightMode.TAKEOFF and not s.in_air:
                v.command_s = now_s
                v.autopilot.takeoff(self.takeoff_height_m())
        elif v.phase == Phase.FORMATION:
            if not s.in_air and not s.armed:
                v.phase = Phase.LANDED
            elif not self._enabled and not v.paused:
                v.paused = True
                v.autopilot.hold()
            elif self._enabled:
                v.paused = False
        elif v.phase == Phase.HOLDING:
            if not s.in_air and not s.armed:
                v.phase = Phase.LANDED
            elif retry and s.mode not in (FlightMode.HOLD, FlightMode.MANUAL) and not s.released:
                v.command_s = now_s
                v.autopilot.hold()
        elif v.phase == Phase.LANDING:
            if not s.in_air:
                v.phase = Phase.LANDED
            elif retry and s.mode != FlightMode.LAND:
                v.command_s = now_s
                v.autopilot.land()

    def _role(self, v: _Vehicle) -> AgentRole:
        released = v.state is not None and v.state.released  # a pilot has it: avoid it, do not steer it
        if v.phase == Phase.FORMATION and self._enabled and not released:
            return AgentRole.FORMATION
        airborne = v.state is not None and v.state.in_air
        if airborne and v.phase in (Phase.TAKEOFF, Phase.FORMATION, Phase.HOLDING, Phase.LANDING):
            return AgentRole.AIRBORNE
        return AgentRole.GROUND

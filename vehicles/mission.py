"""The mission: the one piece of glue that every runner drives (deterministic simulation, live ground station,
PX4 vehicles). Backend-agnostic: it talks to vehicles only through the `Autopilot` protocol, to the world
through `World` and to the radio through `Links`.

It holds the operator's formation parameters, static and virtual obstacles, and one `VehiclePilot` per vehicle
(`vehicles/pilot.py`: its agent and its phase machine, the same one an onboard agent process runs alone):

    IDLE --(enabled)--> TAKEOFF --(at height)--> FORMATION --land()--> LANDING --(on ground)--> LANDED
    LANDED --release()--> IDLE
    TAKEOFF, FORMATION --hold()--> HOLDING --release()--> FORMATION
    IDLE, airborne --(the operator starts the formation or releases it)--> FORMATION
    TAKEOFF / FORMATION / HOLDING --(the autopilot lands or returns it by itself)--> LANDING

(`vehicles.pilot` has the whole machine.) The roster holds only the vehicles airborne, heard and flown by
skyring. A MAV that is holding, landing or landed has left formation control: it publishes plans marked
not-in-formation (then none once on the ground), so its teammates avoid it but re-space to 2 pi / (K - 1) by
themselves. Operator actions are methods that take effect at the next `step` (within one control period); a
refused action raises `MissionError` with a message a person can act on and changes nothing.
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import NoReturn

from controller.messages import Obstacle
from controller.params import ControllerParams, FormationParams
from vehicles.agent import Agent, AgentInputs, AgentParams
from vehicles.autopilot import Autopilot
from vehicles.link_loss import silent_vehicle_obstacle
from vehicles.links import Links
from vehicles.pilot import (
    AgentLink,
    MissionError,
    MissionParams,
    Phase,
    VehiclePilot,
    VehicleSnapshot,
    roster_slots,
    takeoff_height_m,
)
from vehicles.world import PersonTruth, World

__all__ = [
    "AgentLink",
    "Mission",
    "MissionCounters",
    "MissionError",
    "MissionParams",
    "MissionSnapshot",
    "Phase",
    "VehicleSnapshot",
]


@dataclass(frozen=True)
class MissionCounters:
    """Rejected inputs, summed over the team: operator actions refused; detections the trackers ignored
    (gated, stale, invalid); malformed or misaddressed messages; controller exceptions; braking ticks; escape
    ticks (separation rows that could not all hold); hold ticks (a roster teammate unheard too long)."""

    rejected_actions: int = 0
    rejected_detections: int = 0
    rejected_messages: int = 0
    controller_errors: int = 0
    braking_ticks: int = 0
    escape_ticks: int = 0
    hold_ticks: int = 0


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


def team_counters(vehicles: Sequence[VehicleSnapshot], *, rejected_actions: int) -> MissionCounters:
    """The team's rejected-input counters summed over its vehicles' snapshots."""
    totals = dict.fromkeys(
        (
            "rejected_detections",
            "rejected_messages",
            "controller_errors",
            "braking_ticks",
            "escape_ticks",
            "hold_ticks",
        ),
        0,
    )
    for v in vehicles:
        tracker, counters = v.tracker, v.counters
        totals["rejected_detections"] += tracker.gated + tracker.stale + tracker.invalid
        totals["rejected_messages"] += counters.rejected_messages + (
            v.agent.rejected_messages if v.agent is not None else 0
        )
        totals["controller_errors"] += counters.controller_errors
        totals["braking_ticks"] += counters.braking_ticks
        totals["escape_ticks"] += counters.escape_ticks
        totals["hold_ticks"] += counters.hold_ticks
    return MissionCounters(rejected_actions=rejected_actions, **totals)


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
        self._params = params or MissionParams()
        self._vehicles = {
            a.vehicle_id: VehiclePilot(
                autopilot=a,
                agent=Agent(vehicle_id=a.vehicle_id, params=controller_params, agent_params=agent_params),
                params=self._params,
                clock=clock,
            )
            for a in sorted(autopilots, key=lambda a: a.vehicle_id)
        }
        self._world = world
        self._links = links
        self._cparams = controller_params
        self._check_formation(formation)
        self._formation = formation
        self._virtual: dict[str, Obstacle] = {}
        self._enabled = bool(formation_enabled)
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
        return takeoff_height_m(
            params=self._params, controller_params=self._cparams, formation=self._formation
        )

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
        try:
            v.land(self._now)
        except MissionError:
            self._rejected_actions += 1
            raise

    def land_all(self) -> None:
        """Land every vehicle that is taking off, flying, holding, or found flying (adopted)."""
        for v in self._vehicles.values():
            if v.airborne:
                v.start_landing(self._now)

    def hold(self, vehicle_id: int) -> None:
        """Stop one flying vehicle where it is: it hovers out of formation control (its teammates avoid it
        and re-space without it) until released or landed."""
        v = self._vehicle(vehicle_id)
        try:
            v.hold(self._now)
        except MissionError:
            self._rejected_actions += 1
            raise

    def release(self, vehicle_id: int) -> None:
        """Give a vehicle back to the formation: a landed one takes off again (when formation is enabled), a
        holding one rejoins from where it hovers, and an airborne one skyring does not fly joins
        (`VehiclePilot.release`)."""
        v = self._vehicle(vehicle_id)
        try:
            v.release()
        except MissionError:
            self._rejected_actions += 1
            raise

    def set_formation_enabled(self, enabled: bool) -> None:
        """Start (True) or stop (False) formation control; stopped MAVs hold position, idle ones stay down.
        Starting it also brings in the airborne vehicles found flying (adopted) once their autopilot lets
        them."""
        self._enabled = bool(enabled)
        if self._enabled:
            for v in self._vehicles.values():
                v.formation_started()

    # ---- the control tick ---------------------------------------------------------------------------------
    def step(self, now_s: float) -> None:
        """Advance the world to now_s and run one control tick of every vehicle."""
        if not math.isfinite(now_s) or now_s < self._now:
            raise ValueError(f"mission time must be finite and non-decreasing, got {now_s} after {self._now}")
        self._now = now_s
        self._world.advance(now_s)
        obstacles = self.obstacles()
        height = self.takeoff_height_m()
        for v in self._vehicles.values():
            v.observe(now_s, enabled=self._enabled, takeoff_height_m=height)
        # A vehicle whose link is lost gets no agent tick (nothing would reach it) and leaves the roster; its
        # teammates avoid it around its last plan, the wider the longer it is silent (vehicles/link_loss.py).
        silent = [v for v in self._vehicles.values() if v.silent and v.state is not None]
        obstacles += tuple(
            silent_vehicle_obstacle(
                state=v.state, now_s=now_s, plan=v.last.plan if v.last is not None else None
            )
            for v in silent
            if v.state is not None
        )
        slots = roster_slots(
            [vid for vid, v in self._vehicles.items() if v.in_roster], offset_rad=self._params.slot_offset_rad
        )
        # The whole team takes in its messages (fusing the detections) before any of it plans: each part of
        # the tick then runs over the team back to back with its code and data warm (docs/fast-core.md), and
        # no agent hears a message sent in this tick, whatever its place in the vehicle order.
        ready = []
        for vid, v in self._vehicles.items():
            if v.silent:
                self._world.detections(vid)  # stale frames and messages are dropped, not queued up
                self._links.receive(now_s, vid)
                continue
            inputs = AgentInputs(
                own=v.state,
                detections=self._world.detections(vid),
                received=self._links.receive(now_s, vid),
                obstacles=obstacles,
                formation=self._formation,
                role=v.role(enabled=self._enabled),
                roster=slots,
            )
            ready.append((vid, v, inputs, v.take_in(now_s, inputs)))
        for vid, v, inputs, own_detections in ready:
            out = v.tick(now_s, inputs, own_detections=own_detections)
            for msg in out.outbox:
                self._links.send(now_s, vid, msg)

    def snapshot(self) -> MissionSnapshot:
        """The mission now, for displays, logs and metrics."""
        vehicles = tuple(v.snapshot(self._now) for v in self._vehicles.values())
        return MissionSnapshot(
            stamp_s=self._now,
            vehicles=vehicles,
            person_truth=self._world.person_truth(),
            obstacles=self.obstacles(),
            virtual_obstacle_ids=tuple(self._virtual),
            formation=self._formation,
            formation_enabled=self._enabled,
            slot_count=sum(v.in_roster for v in self._vehicles.values()),
            counters=team_counters(vehicles, rejected_actions=self._rejected_actions),
        )

    # ---- internals ----------------------------------------------------------------------------------------
    def _vehicle(self, vehicle_id: int) -> VehiclePilot:
        v = self._vehicles.get(int(vehicle_id)) if isinstance(vehicle_id, numbers.Integral) else None
        if v is None:
            self._refuse(f"no vehicle with id {vehicle_id!r}; vehicles are {list(self._vehicles)}")
            raise AssertionError("unreachable")
        return v

    def _refuse(self, message: str) -> NoReturn:
        self._rejected_actions += 1
        raise MissionError(message)

    def _check_formation(self, formation: FormationParams) -> None:
        if not isinstance(formation, FormationParams):
            raise MissionError(f"expected FormationParams, got {type(formation).__name__}")
        for name in ("d_des_m", "h_des_m"):
            value = getattr(formation, name)
            if not (isinstance(value, int | float) and math.isfinite(value) and value > 0):
                raise MissionError(f"{name} must be a positive finite number of metres, got {value!r}")

"""One vehicle's part of the mission: its autopilot, its agent and its phase machine.

    IDLE --(enabled)--> TAKEOFF --(at height)--> FORMATION --land()--> LANDING --(on ground)--> LANDED
    LANDED --release()--> IDLE
    TAKEOFF, FORMATION (in the air) --hold()--> HOLDING --release()--> FORMATION
    IDLE, airborne --(the operator starts the formation or releases it)--> FORMATION
    IDLE airborne, TAKEOFF, FORMATION, HOLDING --land(), land_all--> LANDING
    TAKEOFF / FORMATION / HOLDING --(the autopilot lands or returns it by itself)--> LANDING

A holding MAV hovers where the operator stopped it, out of formation control: its teammates avoid it and
re-space without it; released, it rejoins from where it hovers. While the autopilot runs one of its own
failsafes, release is refused in every phase: the autopilot's decision stands until it ends or the vehicle is
down.

The formation roster (the slots teammates space for) holds only vehicles that are airborne, heard, and flown
by skyring: one on the ground (e.g. its autopilot refused to arm), one a pilot took, or one the autopilot
flies in its own failsafe (Land, Hold, Return) is left out, and one the autopilot lands by itself is landing
(its failsafe's landing stands: once down it waits for release). A vehicle found airborne when the mission
starts (an earlier ground station flew it) is adopted as it is: avoided, not steered, until the operator
starts the formation or releases it.

The in-process `Mission` holds one `VehiclePilot` per vehicle and feeds them the team's roster; the onboard
agent process (`vehicles.net.onboard`) holds exactly one and builds the roster from what it hears over the
network. Both therefore fly the same phase machine, role logic and take-off/landing retries.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from enum import StrEnum

import numpy as np

from controller.messages import Detection, HorizonPlan, PersonEstimate, SolveStatus
from controller.params import ControllerParams, FormationParams
from controller.tracker import TrackerStats
from vehicles.agent import Agent, AgentCounters, AgentInputs, AgentOutputs, AgentRole
from vehicles.autopilot import Autopilot, AutopilotState, FlightMode, Setpoint
from vehicles.world import PERSON_CENTRE_HEIGHT_M


class Phase(StrEnum):
    """Where a vehicle is in the mission."""

    IDLE = "idle"
    TAKEOFF = "takeoff"
    FORMATION = "formation"
    HOLDING = "holding"  # hovering where the operator stopped it, out of formation control
    LANDING = "landing"
    LANDED = "landed"


FLYING_PHASES = (Phase.TAKEOFF, Phase.FORMATION)  # in the formation's roster
AIRBORNE_PHASES = (Phase.TAKEOFF, Phase.FORMATION, Phase.HOLDING)  # what LAND ALL lands


class MissionError(ValueError):
    """An operator action the mission refused; the message says why and what to do."""


@dataclass(frozen=True)
class MissionParams:
    """takeoff_height_m: None = the formation height (h_des above a person standing on the ground) clamped
    0.5 m inside the MPC's height bounds; at_height_tolerance_m: takeoff is done within this of the target;
    retry_s: a takeoff or land command that shows no effect is re-sent after this long (lost commands over a
    real link); slot_offset_rad: bearing of roster slot 0 about the person (slot k at offset + 2 pi k / K);
    mode_grace_s: how long an autopilot's mode reading may lag a command (PX4 reports its mode once a second):
    a Land read sooner after a take-off command is the old mode, not the autopilot landing the vehicle."""

    takeoff_height_m: float | None = None
    at_height_tolerance_m: float = 0.5
    retry_s: float = 1.0
    slot_offset_rad: float = 0.0
    mode_grace_s: float = 2.0


@dataclass(frozen=True, eq=False)
class VehicleSnapshot:
    """Everything a display needs about one vehicle.

    autopilot: latest telemetry; plan: the latest horizon plan; person: this MAV's fused estimate (its
    position_cov_m2 is the ellipsoid); setpoint: last set-point sent; status/solver_time_s: the controller's
    last result; tick_s: wall time of the last agent tick (None without a clock); link_age_s: age of the
    telemetry; teammates_known: teammates whose plans are fresh; used_slot: steering to the roster slot
    because teammates are unheard; fault: last fault line; agent: how the ground station hears this
    vehicle's agent over the network (None when the agent runs in the station's own process); in_formation: in
    the formation roster and flown by formation control now (False while its autopilot runs a failsafe, a
    pilot has it, its link is lost, or it is not airborne); gps_offset_m (3,): the agent's estimate of its
    GPS offset (AgentOutputs.gps_offset_m; zeros when unknown).
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
    agent: AgentLink | None = None
    in_formation: bool = False
    gps_offset_m: np.ndarray = field(default_factory=lambda: np.zeros(3))

    @property
    def believed_position_m(self) -> np.ndarray | None:
        """(3,) where this MAV's controller believes it is, in the team's frame: the reported position less
        the estimated GPS offset (None before the first telemetry)."""
        if self.autopilot is None:
            return None
        return self.autopilot.position_m - self.gps_offset_m


@dataclass(frozen=True)
class AgentLink:
    """The station's view of one networked agent.

    lost: no state heard for longer than the station's limit; age_s: since its last state message;
    clock_offset_s: agent clock minus station clock, measured from heartbeat round trips (None before one);
    tick_period_p99_error_s: the agent's reported 99th percentile of |tick period - nominal|;
    commands: per-vehicle command outcomes ("pending", "acked", "refused", "failed") of the latest
    commands, newest last, each as (command id, kind, outcome, message); rejected_messages: network messages
    this agent rejected (malformed, oversized, foreign team, unknown sender, other version, replayed);
    station_lost: the agent reports it no longer hears the station; scheduler: what its control loop runs
    under, as it reports it ("" before it has).
    """

    lost: bool
    age_s: float
    clock_offset_s: float | None
    tick_period_p99_error_s: float | None
    commands: tuple[tuple[int, str, str, str], ...] = ()
    rejected_messages: int = 0
    station_lost: bool = False
    scheduler: str = ""


class VehiclePilot:
    """The phase machine of one vehicle and the agent that flies it. `observe` then `tick` (or `take_in` then
    `tick`), every control period; operator actions (`land`, `hold`, `release`) take effect at once and show
    in the next readings.

    clock: only used to time agent ticks (e.g. time.perf_counter); None leaves tick_s unset.
    """

    def __init__(
        self,
        *,
        autopilot: Autopilot,
        agent: Agent,
        params: MissionParams | None = None,
        clock: Callable[[], float] | None = None,
    ) -> None:
        self.autopilot = autopilot
        self.agent = agent
        self.params = params or MissionParams()
        self.phase = Phase.IDLE
        self.command_s = -math.inf
        self.last: AgentOutputs | None = None
        self.last_setpoint: Setpoint | None = None
        self.tick_s: float | None = None
        self._take_in_s = 0.0  # the last `take_in`'s time (s), added to the tick's
        self.paused = False
        self.state: AutopilotState | None = None
        self.resume = False  # airborne and not flown by skyring: the operator asked for it to join
        self.rejoin = False  # a pilot gave it back in the air: re-engage it at the next observation
        self.held_since_s: float | None = None  # taking off: when the autopilot was first seen holding
        self._enabled = False
        self._clock = clock
        self._now = 0.0

    @property
    def vehicle_id(self) -> int:
        return self.autopilot.vehicle_id

    @property
    def silent(self) -> bool:
        """The autopilot's link is lost: nothing computed here would reach it."""
        return self.state is not None and self.state.link_lost

    @property
    def released(self) -> bool:
        """A pilot or the autopilot's failsafe has it: teammates avoid it, nobody steers it."""
        s = self.state
        return s is not None and (s.released or s.failsafe)

    @property
    def leaving(self) -> bool:
        """The autopilot is taking the vehicle down or home (Land, Return), whoever asked."""
        s = self.state
        return s is not None and s.in_air and s.mode in (FlightMode.LAND, FlightMode.RETURN)

    @property
    def _ours(self) -> bool:
        """skyring may command it: no pilot or autopilot failsafe has it, and the autopilot is not taking it
        down or home."""
        return not (self.released or self.leaving)

    @property
    def adopted(self) -> bool:
        """Found flying and not (yet) flown by skyring: idle in the air."""
        return self.phase == Phase.IDLE and self.state is not None and self.state.in_air

    @property
    def airborne(self) -> bool:
        """What LAND ALL lands: taking off, flying formation, holding, or found flying."""
        return self.phase in AIRBORNE_PHASES or self.adopted

    @property
    def in_roster(self) -> bool:
        """Counts in the formation: taking off or flying it, airborne, heard, and flown by skyring (not
        taken by a pilot or the autopilot's failsafe, not landing)."""
        airborne = self.state is not None and self.state.in_air
        return (
            self.phase in FLYING_PHASES
            and airborne
            and not self.silent
            and not self.released
            and not self.leaving
        )

    # ---- operator actions ---------------------------------------------------------------------------------
    def land(self, now_s: float) -> None:
        """Land now (also a vehicle found flying); MissionError when already on the ground."""
        if self.phase == Phase.LANDED or (self.phase == Phase.IDLE and not self.adopted):
            raise MissionError(f"vehicle {self.vehicle_id} is on the ground already ({self.phase.value})")
        self.start_landing(now_s)

    def start_landing(self, now_s: float) -> None:
        self.phase = Phase.LANDING
        self.command_s = now_s
        self.autopilot.land()

    def hold(self, now_s: float) -> None:
        """Stop where it is, out of formation control; MissionError unless taking off or flying formation
        in the air."""
        if self.phase not in FLYING_PHASES:
            raise MissionError(
                f"vehicle {self.vehicle_id} is {self.phase.value}; only a vehicle taking off or flying "
                "formation can be held"
            )
        if self.state is None or not self.state.in_air:
            raise MissionError(
                f"vehicle {self.vehicle_id} is not in the air yet; land it instead to stop its takeoff"
            )
        self.phase = Phase.HOLDING
        self.command_s = now_s
        self.autopilot.hold()

    def release(self) -> None:
        """Give the vehicle back to the formation: a landed one takes off again (when formation is enabled);
        a holding one rejoins from where it hovers; an airborne one skyring does not fly (found flying, or a
        pilot gave it back) joins it. MissionError otherwise, and while the autopilot runs a failsafe (in any
        phase): its decision stands until it ends or it is down.
        """
        s = self.state
        if s is not None and s.failsafe:
            why = f": {s.failsafe_reason}" if s.failsafe_reason else ""
            raise MissionError(
                f"vehicle {self.vehicle_id} is in its autopilot's failsafe "
                f"({s.autopilot_mode or s.mode.value}{why}); it can rejoin once the failsafe ends or it has "
                "landed"
            )
        if self.phase == Phase.LANDED:
            self.phase = Phase.IDLE
            return
        if self.phase == Phase.HOLDING:
            self.phase = Phase.FORMATION  # its set-points end the hold
            # A pilot took it while it held: re-engage it, as a vehicle a pilot gave back in formation.
            self.rejoin = s is not None and s.in_air and s.released
            return
        airborne_idle = self.phase == Phase.IDLE and s is not None and s.in_air
        taken = self.phase in FLYING_PHASES and s is not None and s.in_air and s.released
        if not (airborne_idle or taken):
            raise MissionError(
                f"vehicle {self.vehicle_id} is {self.phase.value}; only a landed or holding vehicle, or an "
                "airborne one skyring does not fly, can be released"
            )
        self.resume = True
        self.rejoin = taken

    def formation_started(self) -> None:
        """The operator started the formation: a vehicle found flying may join it (once its autopilot lets
        it)."""
        if self.phase == Phase.IDLE and self.state is not None and self.state.in_air:
            self.resume = True

    # ---- the control tick ---------------------------------------------------------------------------------
    def observe(self, now_s: float, *, enabled: bool, takeoff_height_m: float) -> AutopilotState | None:
        """Read the autopilot and advance the phase machine (take-off, landing and their retries)."""
        self._now = now_s
        self._enabled = enabled
        self.state = s = self.autopilot.state()
        if s is None:
            return None
        retry = now_s - self.command_s >= self.params.retry_s
        settled = now_s - self.command_s >= self.params.mode_grace_s
        if self.phase in AIRBORNE_PHASES and self.leaving and settled:
            self.phase = Phase.LANDING  # its autopilot lands (or returns) it: that landing stands
            self.command_s = now_s
        elif self.rejoin and self.phase in FLYING_PHASES and s.in_air and not s.failsafe:
            self.rejoin = False
            self.command_s = now_s
            self.autopilot.takeoff(takeoff_height_m)  # re-engages an airborne vehicle
        elif self.phase == Phase.IDLE and s.in_air:
            # Found flying (adopted): avoided, not steered, until the operator asks for it and PX4 lets go.
            if self.resume and enabled and not s.link_lost and not s.failsafe and not self.leaving:
                self.phase = Phase.FORMATION
                self.paused = False
                self.command_s = now_s
                self.autopilot.takeoff(takeoff_height_m)  # re-engages an airborne vehicle
        elif self.phase == Phase.IDLE and enabled:
            self.resume = False
            self.phase = Phase.TAKEOFF
            self.command_s = now_s
            self.autopilot.takeoff(takeoff_height_m)
        elif self.phase == Phase.TAKEOFF:
            held = s.in_air and s.mode in (FlightMode.HOLD, FlightMode.OFFBOARD)
            held_since = (self.held_since_s if self.held_since_s is not None else now_s) if held else None
            self.held_since_s = held_since
            at_height = abs(s.position_m[2] - takeoff_height_m) <= self.params.at_height_tolerance_m
            # A take-off that ends away from the formation height (the autopilot climbed to another one) joins
            # all the same once the autopilot has held for mode_grace_s: the controller brings it to height.
            if held_since is not None and (at_height or now_s - held_since >= self.params.mode_grace_s):
                self.phase = Phase.FORMATION
                self.paused = False
                self.held_since_s = None
            elif retry and s.mode != FlightMode.TAKEOFF and not s.in_air:
                self.command_s = now_s
                self.autopilot.takeoff(takeoff_height_m)
        elif self.phase == Phase.FORMATION:
            if not s.in_air and not s.armed:
                self.phase = Phase.LANDED
            elif not enabled and not self.paused:
                self.paused = True
                self.autopilot.hold()
            elif enabled:
                self.paused = False
        elif self.phase == Phase.HOLDING:
            if not s.in_air and not s.armed:
                self.phase = Phase.LANDED
            elif retry and s.mode not in (FlightMode.HOLD, FlightMode.MANUAL) and self._ours:
                self.command_s = now_s
                self.autopilot.hold()  # a lost hold command (not one a pilot or the autopilot overrode)
        elif self.phase == Phase.LANDING:
            if not s.in_air:
                self.phase = Phase.LANDED
            elif retry and s.mode not in (FlightMode.LAND, FlightMode.RETURN, FlightMode.MANUAL):
                self.command_s = now_s
                self.autopilot.land()  # e.g. PX4 ended its failsafe landing by itself: it still lands
        return s

    def role(self, *, enabled: bool) -> AgentRole:
        """What the agent should do this tick, from the phase and the formation switch. A vehicle a pilot or
        the autopilot's failsafe has, or that is being landed, is avoided but not steered; so is one found
        flying (airborne, idle)."""
        if self.phase == Phase.FORMATION and enabled and not self.released and not self.leaving:
            return AgentRole.FORMATION
        if self.state is not None and self.state.in_air and self.phase != Phase.LANDED:
            return AgentRole.AIRBORNE
        return AgentRole.GROUND

    def take_in(self, now_s: float, inputs: AgentInputs) -> tuple[Detection, ...]:
        """The agent's take-in ahead of `tick` (`Agent.take_in`), which then gets its answer; its time counts
        in that tick's tick_s."""
        t0 = self._clock() if self._clock is not None else None
        own = self.agent.take_in(now_s, inputs)
        if t0 is not None and self._clock is not None:
            self._take_in_s = self._clock() - t0
        return own

    def tick(
        self, now_s: float, inputs: AgentInputs, *, own_detections: tuple[Detection, ...] | None = None
    ) -> AgentOutputs:
        """Run the agent and send its set-point to the autopilot when it flies the formation.
        own_detections: `take_in`'s answer when it ran for this tick (None: the agent takes in here)."""
        t0 = self._clock() if self._clock is not None else None
        out = self.agent.tick(now_s, inputs, own_detections=own_detections)
        if t0 is not None and self._clock is not None:
            self.tick_s = self._clock() - t0 + (self._take_in_s if own_detections is not None else 0.0)
        self.last = out
        if out.setpoint is not None and inputs.role == AgentRole.FORMATION:
            self.autopilot.send_setpoint(out.setpoint)
            self.last_setpoint = out.setpoint
        return out

    def snapshot(self, now_s: float | None = None) -> VehicleSnapshot:
        """This vehicle now, for displays, logs and metrics (link age against now_s, default: last tick)."""
        now = self._now if now_s is None else now_s
        out, state = self.last, self.state
        control = out.control if out is not None else None
        return VehicleSnapshot(
            vehicle_id=self.vehicle_id,
            phase=self.phase,
            autopilot=state,
            plan=out.plan if out is not None else None,
            person=out.person if out is not None else None,
            setpoint=self.last_setpoint,
            status=control.status if control is not None else None,
            solver_time_s=control.solver_time_s if control is not None else 0.0,
            tick_s=self.tick_s,
            link_age_s=(now - state.stamp_s) if state is not None else None,
            teammates_known=out.teammates_known if out is not None else 0,
            used_slot=out.used_slot if out is not None else False,
            fault=out.fault if out is not None else None,
            tracker=out.tracker if out is not None else TrackerStats(),
            counters=out.counters if out is not None else AgentCounters(),
            in_formation=self.in_roster and self.role(enabled=self._enabled) == AgentRole.FORMATION,
            gps_offset_m=out.gps_offset_m if out is not None else np.zeros(3),
        )


def takeoff_height_m(
    *, params: MissionParams, controller_params: ControllerParams, formation: FormationParams
) -> float:
    """The take-off height: MissionParams.takeoff_height_m, else h_des above a standing person's body centre,
    kept 0.5 m inside the MPC's height bounds."""
    if params.takeoff_height_m is not None:
        return params.takeoff_height_m
    lo, hi = controller_params.mpc.position_min_m[2] + 0.5, controller_params.mpc.position_max_m[2] - 0.5
    return min(max(formation.h_des_m + PERSON_CENTRE_HEIGHT_M, lo), hi)


def roster_slots(members: list[int], *, offset_rad: float) -> tuple[tuple[int, float], ...]:
    """(vehicle id, slot bearing) of every MAV in formation, in the order given: offset + 2 pi k / K."""
    k = len(members)
    return tuple((vid, offset_rad + 2.0 * math.pi * i / k) for i, vid in enumerate(members))

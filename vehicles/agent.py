"""One MAV's onboard loop (docs/architecture.md#one-control-tick), as a plain object driven by any runner.

Per tick: fuse the MAV's own new detections and the teammates' received ones in its person-tracker replica,
keep the teammates' latest horizon plans, run the formation controller on the MAV's own reported state, and
return the set-point (position, velocity, yaw) plus the messages to broadcast (its plan at `plan_period_s`,
its detections at once). No clocks, no I/O: the deterministic simulation and the live ground station drive the
same `tick(now_s, inputs) -> outputs`.

Communication loss: a MAV that has not heard a teammate of the roster for `blind_after_s` *holds*: it rests
where it is (right after take-off, at the formation height), facing the person, until it has heard every one
within `resume_within_s` (docs/safety.md#link-loss-the-hold). MAVs that cannot hear each other are kept
apart by not moving: moving ones are not predictable. While a roster teammate is not in formation (taking
off, or holding), or unheard with holds off (`blind_after_s` = 0, the paper's MAVs flying on blind), it is
stood in for by a *phantom* plan at its roster slot (2 pi k / K about this MAV's person estimate, moving
with the person), and this MAV aims at its own slot
(docs/method.md#beyond-the-paper-the-team-without-its-links). A teammate's plan is forgotten after
`teammate_timeout_s`.

Re-planning rate: by default the MPC is solved every control tick, as in the paper. With `replan_period_s`
> 0 it is solved at most that often; in between, the set-point follows the latest plan (its state
`waypoint_step` steps ahead of now, interpolated) with the yaw turned to the current person estimate, and the
tracker still runs every tick. This is only for simulating large teams faster than real time.

Lost person: with no estimate at all (the track expired, e.g. behind a trunk with no teammate to fill in),
the controller holds the MAV where it is; the agent then turns it slowly on the spot (`search_yaw_rate_radps`)
so that its camera sweeps the surroundings and finds the person again, instead of staring at the trunk.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from enum import StrEnum

import numpy as np

from controller.angles import wrap_angle
from controller.formation import FormationController
from controller.gps_offset import GpsOffsetEstimator, GpsOffsetParams
from controller.messages import (
    ControlOutput,
    Detection,
    HorizonPlan,
    Obstacle,
    PersonEstimate,
    SolveStatus,
    VehicleState,
    read_only,
)
from controller.params import ControllerParams, FormationParams
from controller.reference import plan_acceleration_at, plan_state_at
from controller.teammates import TeammateTable
from controller.tracker import PersonTracker, TrackerStats, Verdict
from vehicles.autopilot import AutopilotState, Setpoint
from vehicles.detect.converter import ConverterStats, DetectionConverter
from vehicles.detect.pixels import CameraDetection

Message = Detection | HorizonPlan

_NO_OFFSET = read_only(np.zeros(3))  # the GPS offset of a MAV that does not estimate it (shared: read-only)


class AgentRole(StrEnum):
    """What the mission wants from the agent this tick."""

    FORMATION = "formation"  # fly: run the controller, send set-points, publish an in-formation plan
    AIRBORNE = "airborne"  # in the air, not in formation (taking off, landing, paused): publish a hold plan
    GROUND = "ground"  # on the ground: track only, publish no plan


@dataclass(frozen=True)
class AgentParams:
    """plan_period_s: how often the plan is broadcast (10 Hz); teammate_timeout_s: a teammate's plan older
    than this is forgotten (it is then neither avoided nor spaced around); search_yaw_rate_radps: how fast a
    MAV that lost the person turns on the spot to look for it (0.5 rad/s: a full turn in 12.6 s, slow enough
    for the 4 Hz detector to see the person in several frames of each turn); replan_period_s: 0 solves the MPC
    every tick (the paper), > 0 at most this often (see the module docstring); blind_after_s: a roster
    teammate unheard for longer makes this MAV hold (0: never hold). 1.5 s is 15 lost plans in a row: at any
    moment, with 25 % link loss a chance of 1e-9 per teammate, with 90 % loss 0.21 (docs/safety.md);
    resume_within_s: the hold ends (and formation flight first begins) once every roster teammate has been
    heard within this long: the age up to which the separation rows trust a teammate to hold its own
    (SeparationParams.cooperative_age_s); gps_offset: estimate this MAV's GPS offset relative to the team
    from its detections, publish it with the plans, and place the teammates by it in the separation rows
    (controller/gps_offset.py; None: take the teammates' plans as their GPS puts them);
    phantom_clearance_m: a roster slot closer than this to the MAV gets no phantom. The MAV is then inside
    the gap the phantom's separation rows keep (1.6 m and more), so the rows cannot hold and would send it on
    an escape at full authority away from a place where no vehicle is, into whoever is on the other side
    (sweep run 434, docs/safety.md); it leaves the slot by steering to its own, among real teammates' rows."""

    plan_period_s: float = 0.1
    teammate_timeout_s: float = 3.0
    search_yaw_rate_radps: float = 0.5
    replan_period_s: float = 0.0
    blind_after_s: float = 1.5
    resume_within_s: float = 0.5
    gps_offset: GpsOffsetParams | None = field(default_factory=GpsOffsetParams)
    phantom_clearance_m: float = 2.0


@dataclass(frozen=True, eq=False)
class AgentInputs:
    """One tick's inputs.

    own: the autopilot's latest state (None before the first telemetry); detections: the MAV's own camera
    detections since the last tick, already in the world frame (the simulated camera); camera: the MAV's own
    camera's pixel detections since the last tick (a real camera through `skyring detect`), converted here
    with the pose at their capture time (needs the agent's `converter`); received: teammates' messages
    delivered since the last tick; obstacles:
    static and virtual; formation: the operator's d_des/h_des; role: see AgentRole; roster: (vehicle id, slot
    bearing) of every MAV in formation, this one included, the bearing (ENU, about the person) being
    offset + 2 pi k / K; used for teammates that are unheard.
    """

    own: AutopilotState | None
    detections: tuple[Detection, ...] = ()
    camera: tuple[CameraDetection, ...] = ()
    received: tuple[Message, ...] = ()
    obstacles: tuple[Obstacle, ...] = ()
    formation: FormationParams = field(default_factory=FormationParams)
    role: AgentRole = AgentRole.FORMATION
    roster: tuple[tuple[int, float], ...] = ()


@dataclass(frozen=True)
class AgentCounters:
    """Cumulative counts: detections fused from the own camera and from teammates, plans received,
    messages rejected (malformed, own echoes, camera detections without a converter), controller exceptions
    caught, braking ticks, escape ticks (separation rows that could not all hold: controller/separation.py),
    ticks that used the roster slot, ticks held because a roster teammate was unheard (hold_ticks). The
    camera converter keeps its own counts (`AgentOutputs.camera`)."""

    own_detections_fused: int = 0
    teammate_detections_fused: int = 0
    plans_received: int = 0
    rejected_messages: int = 0
    controller_errors: int = 0
    braking_ticks: int = 0
    escape_ticks: int = 0
    slot_ticks: int = 0
    hold_ticks: int = 0


@dataclass(frozen=True, eq=False)
class AgentOutputs:
    """One tick's results: setpoint for the autopilot (None unless role is FORMATION); control: the
    controller's output; plan: the plan this MAV currently stands by (published or not); person: the fused
    estimate now; outbox: messages to broadcast; fault: one line when something went wrong this tick;
    gps_offset_m (3,): the estimate of this MAV's GPS offset relative to its team (zeros when not
    estimated): its reported position less this is where it is among its teammates."""

    stamp_s: float
    setpoint: Setpoint | None
    control: ControlOutput | None
    plan: HorizonPlan | None
    person: PersonEstimate | None
    outbox: tuple[Message, ...]
    tracker: TrackerStats
    counters: AgentCounters
    teammates_known: int = 0
    used_slot: bool = False
    fault: str | None = None
    camera: ConverterStats | None = None
    gps_offset_m: np.ndarray = field(default_factory=lambda: np.zeros(3))


@dataclass(frozen=True, eq=False)
class _Step:
    """What one tick decided: the controller's output, the plan stood by, the set-point, a fault."""

    control: ControlOutput | None = None
    plan: HorizonPlan | None = None
    setpoint: Setpoint | None = None
    fault: str | None = None
    used_slot: bool = False


_NOTHING = _Step()  # a tick that neither flies nor publishes a plan


def hold_plan(
    *,
    state: AutopilotState,
    params: ControllerParams,
    in_formation: bool = False,
    gps_offset_m: np.ndarray | None = None,
) -> HorizonPlan:
    """A plan that stays at the MAV's reported position (N+2 copies), for MAVs not under formation control;
    gps_offset_m (3,): the MAV's GPS offset estimate it carries (zeros: none)."""
    n = params.mpc.horizon_steps + 2
    return HorizonPlan(
        vehicle_id=state.vehicle_id,
        stamp_s=state.stamp_s,
        dt_s=params.mpc.dt_s,
        positions_m=read_only(np.repeat(state.position_m[None, :], n, axis=0)),
        velocities_mps=read_only(np.zeros((n, 3))),
        in_formation=in_formation,
        position_cov_m2=state.position_cov_m2,
        gps_offset_m=_NO_OFFSET if gps_offset_m is None else gps_offset_m,
    )


def _capture_order(detection: Detection) -> tuple[float, int]:
    """Sort key of detections by capture time, then source (a total order: the same every run)."""
    stamp = float(detection.stamp_s)
    return (stamp if math.isfinite(stamp) else math.inf, int(detection.source_id))


class Agent:
    """The loop of MAV `vehicle_id`: a person-tracker replica, a formation controller, teammates' plans."""

    def __init__(
        self,
        *,
        vehicle_id: int,
        params: ControllerParams | None = None,
        agent_params: AgentParams | None = None,
        converter: DetectionConverter | None = None,
    ) -> None:
        """converter: turns the own camera's pixel detections into Detections (None: the agent takes only
        world-frame detections, as from the simulated camera)."""
        self.vehicle_id = int(vehicle_id)
        self._converter = converter
        self._params = params = params or ControllerParams()
        self._ap = agent_params or AgentParams()
        self._tracker = PersonTracker(params.tracker)
        self._controller = FormationController(vehicle_id=self.vehicle_id, params=params)
        # The teammates' latest plans, checked on arrival and kept in arrays (controller/teammates.py).
        self._teammates = TeammateTable(own_id=self.vehicle_id, plan_length=params.mpc.horizon_steps + 2)
        self._last_publish_s = -math.inf
        self._search: tuple[float, float] | None = None  # (time, yaw command) while searching
        self._last_control: ControlOutput | None = None
        self._last_person: PersonEstimate | None = None
        self._holding = True  # a MAV starts formation flight only once it has heard every teammate afresh
        self._counts = dict.fromkeys(AgentCounters.__dataclass_fields__, 0)
        self._counted = tuple(self._counts.values())  # the counts as last reported (`_counters_now`)
        self._counters = AgentCounters(**self._counts)
        self._offset = GpsOffsetEstimator(self._ap.gps_offset) if self._ap.gps_offset is not None else None
        self._offset_now = _NO_OFFSET  # the estimator's offset (read-only) as of its `used` count below
        self._offset_used = -1
        self._teammate_detection_s = -math.inf  # capture time of the latest teammate detection fused

    @property
    def params(self) -> ControllerParams:
        return self._params

    def teammate_plans(self, now_s: float) -> tuple[HorizonPlan, ...]:
        """The teammates' latest plans not older than teammate_timeout_s, by vehicle id."""
        limit = now_s - self._ap.teammate_timeout_s
        return tuple(p for p in self._teammates.plans() if p.stamp_s >= limit)

    def tick(
        self, now_s: float, inputs: AgentInputs, *, own_detections: tuple[Detection, ...] | None = None
    ) -> AgentOutputs:
        """Run one control tick at now_s: take in messages (`take_in`), then follow the latest plan, re-plan,
        or hold. own_detections: what `take_in(now_s, inputs)` returned when the caller ran it already (the
        simulator lets the whole team take in before any of it plans); None takes in here."""
        detections = self.take_in(now_s, inputs) if own_detections is None else own_detections
        own = inputs.own
        flying = inputs.role == AgentRole.FORMATION and own is not None
        last = self._followable(now_s) if flying else None
        # Between re-plans the estimate of the last re-plan serves (0.1 s old at 10 Hz: a 7 cm walk).
        person = self._last_person if last is not None else self._tracker.estimate(now_s)
        self._last_person = person
        since = now_s - self._ap.teammate_timeout_s  # plans stamped before are forgotten
        known = self._teammates.fresh_count(since)
        step = _NOTHING
        if last is not None and person is not None:
            step = _Step(control=last, plan=last.plan, setpoint=self._follow(now_s, last.plan, person))
        elif own is not None and inputs.role == AgentRole.FORMATION:
            step = self._replan(now_s, own, person, since, known, inputs)
        elif own is not None and inputs.role == AgentRole.AIRBORNE:
            step = _Step(plan=hold_plan(state=own, params=self._params, gps_offset_m=self._offset_m()))
        return AgentOutputs(
            stamp_s=now_s,
            setpoint=step.setpoint,
            control=step.control,
            plan=step.plan,
            person=person,
            outbox=self._outbox(now_s, detections, step.plan),
            tracker=self._tracker.stats(),
            counters=self._counters_now(),
            teammates_known=known,
            used_slot=step.used_slot,
            fault=step.fault,
            camera=self._converter.stats() if self._converter is not None else None,
            gps_offset_m=self._offset_m(),
        )

    def _offset_m(self) -> np.ndarray:
        """(3,) this MAV's GPS offset estimate relative to its team (zeros without the estimate), read-only.
        Copied from the estimator only when it took a residual since the last copy (its `used` count moved):
        a few times a second, while every tick's messages carry it."""
        est = self._offset
        if est is not None and est.used != self._offset_used:
            self._offset_used = est.used
            self._offset_now = read_only(est.offset_m)
        return self._offset_now

    def _counters_now(self) -> AgentCounters:
        """The counts as an `AgentCounters`, built anew only when one changed (most ticks change none)."""
        values = tuple(self._counts.values())
        if values != self._counted:
            self._counted, self._counters = values, AgentCounters(**self._counts)
        return self._counters

    def take_in(self, now_s: float, inputs: AgentInputs) -> tuple[Detection, ...]:
        """The first part of a tick: keep teammates' plans, fuse their detections and this MAV's own (the
        camera's pixel detections converted with the pose at their capture time); count what is rejected.
        Returns the own world-frame detections of this tick, which `tick` publishes.

        The tick's detections, teammates' and own, are fused in capture-time order: the tracker is exact for
        any order, but each one older than the last fused re-filters from its place on (16 MAVs: 15 000
        such re-filterings in 30 s in arrival order, 4 000 sorted within the tick)."""
        counts = self._counts
        fuse: list[tuple[Detection, bool]] = []  # (detection, ours) of this tick, fused below in time order
        for msg in inputs.received:
            if isinstance(msg, Detection):
                fuse.append((msg, False))
            else:
                self._receive(msg)
        detections = inputs.detections
        if self._converter is not None:
            if inputs.own is not None:
                self._converter.record_pose(inputs.own)
            detections = detections + self._converter.convert(now_s, inputs.camera)
        else:
            counts["rejected_messages"] += len(inputs.camera)
        for det in detections:
            if isinstance(det, Detection) and det.source_id == self.vehicle_id:
                fuse.append((det, True))
            else:
                counts["rejected_messages"] += 1
        for det, ours in sorted(fuse, key=lambda item: _capture_order(item[0])):
            if not ours:
                self._receive(det)  # a teammate's (or refused: one claiming our id)
                continue
            self._learn_offset(det)
            if self._tracker.update(det) in (Verdict.ACCEPTED, Verdict.RESET):
                counts["own_detections_fused"] += 1
        return detections

    def _learn_offset(self, det: Detection) -> None:
        """Compare an own detection with the fused estimate at its stamp, before it is fused: the residual
        measures this MAV's GPS offset relative to the team, while that estimate holds a teammate's
        detection."""
        est = self._offset
        if est is None or not det.stamp_s - self._teammate_detection_s <= est.params.teammate_within_s:
            return
        person = self._tracker.estimate(det.stamp_s)
        if person is None or abs(person.stamp_s - det.stamp_s) > est.params.max_age_s:
            return
        est.update(
            det.position_m - person.position_m, det.cov_m2 + person.position_cov_m2, float(det.stamp_s)
        )

    def _replan(
        self,
        now_s: float,
        own: AutopilotState,
        person: PersonEstimate | None,
        since_s: float,
        known: int,
        inputs: AgentInputs,
    ) -> _Step:
        """Solve the formation controller on the teammates' plans stamped at or after since_s; hold when a
        roster teammate is unheard for blind_after_s; else steer to the roster slot while some are not in
        formation."""
        counts = self._counts
        hold_reason = self._hold_reason(now_s, inputs.roster)
        self._holding = hold = hold_reason is not None
        slot = dict(inputs.roster).get(self.vehicle_id)
        used_slot = slot is not None and known < len(inputs.roster) - 1 and not hold
        phantoms: tuple[HorizonPlan, ...] = ()
        if used_slot and person is not None:
            heard = self._teammates.fresh_ids(since_s)
            phantoms = self._phantoms(now_s, person, inputs, heard, np.asarray(own.position_m, dtype=float))
        if used_slot:
            counts["slot_ticks"] += 1
        try:
            control = self._controller.step(
                now_s=now_s,
                own=VehicleState(
                    vehicle_id=self.vehicle_id,
                    stamp_s=now_s,
                    position_m=own.position_m,
                    velocity_mps=own.velocity_mps,
                    yaw_rad=own.yaw_rad,
                    position_cov_m2=own.position_cov_m2,
                    gps_offset_m=self._offset_m(),
                ),
                person=person,
                teammates=self._teammates.view(since_s, phantoms),
                obstacles=inputs.obstacles,
                formation=inputs.formation,
                in_formation=not hold,
                preferred_bearing_rad=slot if used_slot else None,
                hold=hold,
            )
        except Exception as exc:  # the loop must survive a controller bug: hold and report it
            counts["controller_errors"] += 1
            self._last_control = None
            return _Step(
                plan=hold_plan(
                    state=own, params=self._params, in_formation=True, gps_offset_m=self._offset_m()
                ),
                setpoint=Setpoint(
                    stamp_s=now_s, position_m=own.position_m, velocity_mps=np.zeros(3), yaw_rad=own.yaw_rad
                ),
                fault=f"controller error: {type(exc).__name__}: {exc}",
                used_slot=used_slot,
            )
        self._last_control = control
        if control.status == SolveStatus.NO_PERSON:
            yaw = self._search_yaw(now_s, own.yaw_rad)
        else:
            self._search = None
            yaw = control.yaw_rad
        fault = None
        if control.status == SolveStatus.BRAKING:
            counts["braking_ticks"] += 1
            fault = control.fault
        elif control.status == SolveStatus.ESCAPE:
            counts["escape_ticks"] += 1
            fault = control.fault
        elif control.status == SolveStatus.HOLD:
            counts["hold_ticks"] += 1
            fault = hold_reason
        setpoint = Setpoint(
            stamp_s=now_s,
            position_m=control.waypoint_position_m,
            velocity_mps=control.waypoint_velocity_mps,
            yaw_rad=yaw,
            acceleration_mps2=control.waypoint_acceleration_mps2,
        )
        return _Step(control=control, plan=control.plan, setpoint=setpoint, fault=fault, used_slot=used_slot)

    def _outbox(
        self, now_s: float, detections: tuple[Detection, ...], plan: HorizonPlan | None
    ) -> tuple[Message, ...]:
        """Own detections at once; the plan at most every plan_period_s."""
        outbox: list[Message] = [
            d for d in detections if isinstance(d, Detection) and d.source_id == self.vehicle_id
        ]
        if plan is not None and now_s - self._last_publish_s >= self._ap.plan_period_s - 1e-9:
            outbox.append(plan)
            self._last_publish_s = now_s
        return tuple(outbox)

    def _followable(self, now_s: float) -> ControlOutput | None:
        """The latest solved output when this tick may follow its plan instead of solving the MPC again."""
        last = self._last_control
        if (
            self._ap.replan_period_s > 0.0
            and last is not None
            and self._last_person is not None
            and last.status == SolveStatus.SOLVED
            and 0.0 <= now_s - last.plan.stamp_s < self._ap.replan_period_s - 1e-9
        ):
            return last
        return None

    def _follow(self, now_s: float, plan: HorizonPlan, person: PersonEstimate) -> Setpoint:
        """The set-point of a tick between re-plans: the plan's state waypoint_step steps ahead of now."""
        ahead_s = now_s - plan.stamp_s + self._params.reference.waypoint_step * plan.dt_s
        position, velocity = plan_state_at(
            plan.positions_m, plan.velocities_mps, elapsed_s=ahead_s, dt_s=plan.dt_s
        )
        to_person = person.position_m - position
        return Setpoint(
            stamp_s=now_s,
            position_m=position,
            velocity_mps=velocity,
            yaw_rad=math.atan2(to_person[1], to_person[0]),
            acceleration_mps2=plan_acceleration_at(plan.velocities_mps, elapsed_s=ahead_s, dt_s=plan.dt_s),
        )

    def _phantoms(
        self,
        now_s: float,
        person: PersonEstimate,
        inputs: AgentInputs,
        heard_ids: set[int],
        own_position_m: np.ndarray,
    ) -> tuple[HorizonPlan, ...]:
        """Plans at the roster slots of the in-formation teammates not heard from (heard_ids: the fresh
        in-formation plans' vehicle ids), moving with the person; none at a slot within phantom_clearance_m
        of own_position_m (3,)."""
        n = self._params.mpc.horizon_steps + 2
        dt = self._params.mpc.dt_s
        velocity = np.array([person.velocity_mps[0], person.velocity_mps[1], 0.0])
        drift = np.arange(n)[:, None] * dt * velocity[None, :]
        velocities = read_only(np.repeat(velocity[None, :], n, axis=0))  # the same for every phantom
        d, h = inputs.formation.d_des_m, inputs.formation.h_des_m
        own_offset = self._offset_m()
        out = []
        for vid, bearing in inputs.roster:
            if vid == self.vehicle_id or vid in heard_ids:
                continue
            slot = person.position_m + np.array([d * math.cos(bearing), d * math.sin(bearing), h])
            if np.linalg.norm(slot - own_position_m) < self._ap.phantom_clearance_m:
                continue
            out.append(
                HorizonPlan(
                    vehicle_id=vid,
                    stamp_s=now_s,
                    dt_s=dt,
                    positions_m=read_only(slot[None, :] + drift),
                    velocities_mps=velocities,
                    in_formation=True,
                    gps_offset_m=own_offset,  # placed in our own frame
                )
            )
        return tuple(out)

    def _hold_reason(self, now_s: float, roster: tuple[tuple[int, float], ...]) -> str | None:
        """Why this tick holds (a roster teammate unheard for blind_after_s; or, holding already, one not
        heard within resume_within_s), or None."""
        ap = self._ap
        unheard = self._unheard(now_s, roster, ap.blind_after_s)
        if unheard:
            return (
                f"hold: teammate {', '.join(map(str, unheard))} unheard for more than {ap.blind_after_s:g} s"
            )
        waiting = self._unheard(now_s, roster, ap.resume_within_s) if self._holding else []
        if waiting:
            ids = ", ".join(map(str, waiting))
            return f"hold: waiting to hear teammate {ids} within {ap.resume_within_s:g} s"
        return None

    def _unheard(self, now_s: float, roster: tuple[tuple[int, float], ...], within_s: float) -> list[int]:
        """The roster teammates (ids) with no plan stamped within within_s ([] when holds are off)."""
        if self._ap.blind_after_s <= 0.0:
            return []
        heard = self._teammates.fresh_ids(now_s - within_s, in_formation=False)
        return [vid for vid, _ in roster if vid != self.vehicle_id and vid not in heard]

    def _search_yaw(self, now_s: float, yaw_rad: float) -> float:
        """The yaw command of the search turn: advancing at search_yaw_rate_radps from where it began."""
        if self._search is None:
            self._search = (now_s, yaw_rad)
        t0, yaw0 = self._search
        self._search = (now_s, yaw0 + self._ap.search_yaw_rate_radps * (now_s - t0))
        return wrap_angle(self._search[1])

    def _receive(self, msg: object) -> None:
        counts = self._counts
        if isinstance(msg, Detection) and msg.source_id != self.vehicle_id:
            if self._tracker.update(msg) in (Verdict.ACCEPTED, Verdict.RESET):
                counts["teammate_detections_fused"] += 1
                self._teammate_detection_s = max(self._teammate_detection_s, float(msg.stamp_s))
        elif isinstance(msg, HorizonPlan) and msg.vehicle_id != self.vehicle_id:
            limit = self._offset.params.max_offset_m if self._offset is not None else math.inf
            x, y, z = msg.gps_offset_m.tolist()  # (3,): HorizonPlan checks it
            if not (abs(x) <= limit and abs(y) <= limit and abs(z) <= limit):  # NaN included
                counts["rejected_messages"] += 1
                return
            if self._teammates.update(msg) == "refused":  # non-finite numbers, a bad step, a wild covariance
                counts["rejected_messages"] += 1
                return
            counts["plans_received"] += 1
        else:
            counts["rejected_messages"] += 1

"""What the operator's view reads and what it may ask for.

webui never imports server/: the ground station adapts its mission snapshot to these frozen view types and
hands the UI an object satisfying `OperatorActions`. Units are SI, the frame is the team's local ENU world
frame (x east, y north, z up, metres).

These frozen dataclasses are the one definition of what the operator sees: the 3-D page draws them, and
`webui.schema` turns them into the JSON of the REST API (and its OpenAPI document), of the WebSocket stream
and of the flight log's state channel. A field added here appears on all of them; give it a default so older
flight logs stay readable. numpy fields carry their shape in their type (`webui.arrays`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import StrEnum
from typing import Protocol

import numpy as np

from controller.messages import Obstacle, PersonEstimate, frozen_array
from controller.params import FormationParams
from webui.arrays import Age, Cov6, Points3, Real, Vec2, Vec3


@dataclass(frozen=True)
class CommandOutcome:
    """One operator command as one vehicle's agent answered it: action "configure", "land" or "release";
    outcome "pending", "acked", "refused" (message says why) or "failed" (timed out)."""

    command_id: int
    action: str
    outcome: str
    message: str = ""


@dataclass(frozen=True)
class AgentView:
    """How the station hears a vehicle's onboard agent over the network (None for in-process agents).

    lost: nothing heard for longer than the station's limit; age_s: since its last state; clock_offset_s:
    agent clock minus station clock (None before a measurement); clock_skew: beyond the station's limit
    (50 ms); tick_period_p99_error_s: the agent's control-tick jitter; station_lost: the agent no longer hears
    the station; scheduler: what its control loop runs under, as it reports it ("" before it has);
    rejected_messages: network messages it refused; commands: recent operator commands and how the agent
    answered them, newest last.
    """

    lost: bool
    age_s: float
    clock_offset_s: float | None = None
    clock_skew: bool = False
    tick_period_p99_error_s: float | None = None
    station_lost: bool = False
    scheduler: str = ""
    rejected_messages: int = 0
    commands: tuple[CommandOutcome, ...] = ()


@dataclass(frozen=True, eq=False)
class VehicleView:
    """One MAV as the operator sees it.

    position_m (3,), velocity_mps (3,) and yaw_rad (ENU) as reported by its autopilot; plan_positions_m
    (M, 3) its latest horizon plan (M = 0 when none) and plan_age_s how old that plan is (None: no plan yet);
    phase: the mission's phase name (e.g. "formation", "holding", "landing", "landed"); mode: the autopilot
    flight mode name; link_age_s: seconds since its last telemetry (stale when `link_stale`); solver_time_s:
    the MPC solver's own time of the last solve (0 when the closed form solved it; None before the first);
    battery_fraction in [0, 1] or None when unknown; in_formation: flown by formation control in the roster
    now; distance_to_person_m: horizontal distance to the fused person estimate (None without one); released:
    the autopilot or a pilot took it out of skyring's control; fault: the controller's last fault line (""
    when none); agent: its onboard agent's link (None when the agent runs in the station).

    What the autopilot itself says (the truth when it differs from skyring's reading): autopilot_mode: its own
    mode name (PX4: "OFFBOARD", "LAND", "HOLD", "RETURN_TO_LAUNCH", ...; "" when the back-end has none);
    failsafe: it runs one of its own failsafes now, failsafe_reason its words for it (e.g. "battery 14 % at
    or below 15 %: landing"); can_arm: its pre-arm checks pass (None: unknown or armed); arming_refusal: its
    words for the last arming or take-off it refused; takeoff_check: why the ground station would not let
    this vehicle take off or join the formation where it stands now (inside the person's keep-out, or within
    d_min of a teammate), None when it may.

    Separation, from the positions the station knows (the autopilots' own, GPS drift included), for the
    operator's alerts: nearest_teammate_m the 3-D distance to the closest other airborne MAV and
    nearest_teammate_id its id; nearest_obstacle_m the horizontal distance to the nearest trunk or virtual
    obstacle surface it is below the top of (negative inside). None when not applicable: on the ground, alone
    in the air, no obstacle beside it.
    """

    vehicle_id: int
    phase: str
    mode: str
    armed: bool
    in_air: bool
    in_formation: bool
    position_m: Vec3
    yaw_rad: Real
    link_age_s: Age
    link_stale: bool
    velocity_mps: Vec3 = field(default_factory=lambda: np.zeros(3))
    solve_status: str = ""
    solver_time_s: float | None = None
    battery_fraction: float | None = None
    plan_positions_m: Points3 = field(default_factory=lambda: np.zeros((0, 3)))
    autopilot_mode: str = ""
    failsafe: bool = False
    failsafe_reason: str | None = None
    can_arm: bool | None = None
    arming_refusal: str | None = None
    takeoff_check: str | None = None
    agent: AgentView | None = None
    plan_age_s: float | None = None
    distance_to_person_m: float | None = None
    released: bool = False
    fault: str = ""
    nearest_teammate_m: float | None = None
    nearest_teammate_id: int | None = None
    nearest_obstacle_m: float | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "position_m", frozen_array(self.position_m, (3,), "position_m"))
        object.__setattr__(self, "velocity_mps", frozen_array(self.velocity_mps, (3,), "velocity_mps"))
        object.__setattr__(
            self, "plan_positions_m", frozen_array(self.plan_positions_m, (-1, 3), "plan_positions_m")
        )

    @property
    def altitude_m(self) -> float:
        """Height above the team origin's ground plane (the ENU z)."""
        return float(self.position_m[2])

    @property
    def speed_mps(self) -> float:
        """Norm of the reported velocity."""
        return float(np.linalg.norm(self.velocity_mps))


@dataclass(frozen=True)
class CameraView:
    """The on-board camera drawn as a frustum: vertical field of view, image aspect (width / height), downward
    pitch and forward offset from the body centre (the paper's camera: 40.5 deg vertical, 2040 / 1086 px,
    45 deg down, 0.18 m ahead)."""

    vertical_fov_rad: float = float(2.0 * np.arctan(543.0 / 1470.33))
    aspect: float = 2040.0 / 1086.0
    pitch_down_rad: float = float(np.deg2rad(45.0))
    forward_offset_m: float = 0.18


@dataclass(frozen=True)
class Range:
    """A closed interval [low, high] an operator value must lie in (units of the value it bounds)."""

    low: float
    high: float


class Severity(StrEnum):
    """How urgently an alert needs the operator: info (for the record), warning (look soon), critical (act
    now). Ordered: `SEVERITY_RANK` gives the order."""

    INFO = "info"
    WARNING = "warning"
    CRITICAL = "critical"


SEVERITY_RANK = {Severity.INFO: 0, Severity.WARNING: 1, Severity.CRITICAL: 2}


@dataclass(frozen=True)
class Alert:
    """One condition the operator is told about, kept in the list until the station stops.

    alert_id: unique ("a1", "a2", ...); kind: what it is about (battery, separation, ...); vehicle_id: the MAV
    it concerns (None: the whole team, e.g. the control loop); subject: what else it involves (the other MAV,
    the trunk), "" when nothing; severity: the worst seen since it was last raised; message: the condition
    as it stands now (or stood when it cleared); first_s / last_s: mission time it was first raised and last
    seen holding; first_utc_s: wall time (UTC, seconds since the epoch) it was first raised, None when the
    station has no wall clock; active: the condition still holds; acknowledged: an operator has seen it
    (cleared when it comes back or gets worse); count: times it was raised.
    """

    alert_id: str
    kind: str
    vehicle_id: int | None
    subject: str
    severity: Severity
    message: str
    first_s: float
    last_s: float
    active: bool
    acknowledged: bool
    count: int = 1
    first_utc_s: float | None = None


@dataclass(frozen=True)
class PaceView:
    """How the control loop keeps up with the wall clock: requested_speed (simulated seconds per wall second
    asked for; 1 for real vehicles), realtime_factor (achieved over the last second of wall time, None until
    measured), capacity (the speed the last few ticks' computing time allows: a loop whose ticks take longer
    than their period falls behind, which this shows before the achieved factor does; None until measured)
    and fell_behind (times the loop gave up catching up since the start)."""

    requested_speed: float
    realtime_factor: float | None = None
    fell_behind: int = 0
    capacity: float | None = None


@dataclass(frozen=True)
class GeodeticOrigin:
    """The team frame's origin: latitude and longitude (degrees, WGS-84) and altitude (m, AMSL)."""

    lat_deg: float
    lon_deg: float
    alt_m: float


@dataclass(frozen=True, eq=False)
class ObstacleView:
    """A vertical cylinder standing on the ground: axis at ENU center_m (2,), radius_m, height_m; kind "tree"
    (part of the map) or "virtual" (placed by the operator)."""

    obstacle_id: str
    center_m: Vec2
    radius_m: float
    height_m: float
    kind: str

    def __post_init__(self) -> None:
        object.__setattr__(self, "center_m", frozen_array(self.center_m, (2,), "center_m"))

    @classmethod
    def of(cls, obstacle: Obstacle | ObstacleView) -> ObstacleView:
        if isinstance(obstacle, ObstacleView):
            return obstacle
        return cls(
            obstacle_id=obstacle.obstacle_id,
            center_m=obstacle.center_m,
            radius_m=float(obstacle.radius_m),
            height_m=float(obstacle.height_m),
            kind=obstacle.kind,
        )


@dataclass(frozen=True, eq=False)
class PersonEstimateView:
    """The fused person estimate drawn: valid at stamp_s, position_m (3,), velocity_mps (3,), cov (6, 6) the
    covariance of [position, velocity] (m^2, m^2/s^2)."""

    stamp_s: float
    position_m: Vec3
    velocity_mps: Vec3
    cov: Cov6

    def __post_init__(self) -> None:
        object.__setattr__(self, "position_m", frozen_array(self.position_m, (3,), "position_m"))
        object.__setattr__(self, "velocity_mps", frozen_array(self.velocity_mps, (3,), "velocity_mps"))
        object.__setattr__(self, "cov", frozen_array(self.cov, (6, 6), "cov"))

    @property
    def position_cov_m2(self) -> np.ndarray:
        """(3, 3) covariance of the position: drawn as the ellipsoid."""
        return self.cov[:3, :3]

    @property
    def position_cov_trace_m2(self) -> float:
        return float(np.trace(self.cov[:3, :3]))

    @classmethod
    def of(cls, estimate: PersonEstimate | PersonEstimateView) -> PersonEstimateView:
        if isinstance(estimate, PersonEstimateView):
            return estimate
        return cls(
            stamp_s=float(estimate.stamp_s),
            position_m=estimate.position_m,
            velocity_mps=estimate.velocity_mps,
            cov=estimate.cov,
        )


@dataclass(frozen=True)
class Counters:
    """Bad inputs refused and counted since the start: operator commands refused, detections the trackers
    gated out (stale or invalid), malformed or misaddressed messages between MAVs, controller exceptions
    caught (the MAV braked), ticks a MAV braked instead of applying an unsolved plan."""

    refused_commands: int = 0
    rejected_detections: int = 0
    rejected_messages: int = 0
    controller_errors: int = 0
    braking_ticks: int = 0


@dataclass(frozen=True, eq=False)
class SceneView:
    """Everything drawn at one instant.

    person_truth_m (3,): the simulated person's true body centre (None outside simulation); person_estimate:
    the fused estimate drawn with its covariance ellipsoid (None before the first detection);
    estimate_source_id: the MAV whose tracker replica it comes from; tracking_error_m: mean over MAVs of
    |estimate - truth| (simulation only, else None); arena_min_m / arena_max_m (3,): the box the MAVs fly
    in; d_des_range_m / h_des_range_m / obstacle_radius_range_m: what the operator may set (the same limits
    the ground station enforces); counters: bad inputs refused so far; alerts: every alert raised so far
    (`Alert`), most urgent first; pace: how the control loop keeps up (None when not measured); utc_s: wall
    time of this view (UTC seconds since the epoch; None in a replay without one); recording_path: the flight
    log being written (None: not recording); origin: the team frame's geodetic origin (None when unknown, as
    in simulation). Obstacles and the estimate may be given as the controller's `Obstacle` /
    `PersonEstimate`: they are kept as their view types.
    """

    time_s: float
    vehicles: tuple[VehicleView, ...]
    obstacles: tuple[ObstacleView, ...]
    formation: FormationParams
    formation_enabled: bool
    arena_min_m: Vec3
    arena_max_m: Vec3
    d_des_range_m: Range
    h_des_range_m: Range
    obstacle_radius_range_m: Range = Range(0.1, 5.0)
    person_truth_m: Vec3 | None = None
    person_estimate: PersonEstimateView | None = None
    estimate_source_id: int | None = None
    tracking_error_m: float | None = None
    camera: CameraView = field(default_factory=CameraView)
    counters: Counters = field(default_factory=Counters)
    alerts: tuple[Alert, ...] = ()
    pace: PaceView | None = None
    utc_s: float | None = None
    recording_path: str | None = None
    origin: GeodeticOrigin | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "vehicles", tuple(self.vehicles))
        object.__setattr__(self, "alerts", tuple(self.alerts))
        object.__setattr__(self, "obstacles", tuple(ObstacleView.of(o) for o in self.obstacles))
        if self.person_estimate is not None:
            object.__setattr__(self, "person_estimate", PersonEstimateView.of(self.person_estimate))
        object.__setattr__(self, "arena_min_m", frozen_array(self.arena_min_m, (3,), "arena_min_m"))
        object.__setattr__(self, "arena_max_m", frozen_array(self.arena_max_m, (3,), "arena_max_m"))
        if self.person_truth_m is not None:
            truth = frozen_array(self.person_truth_m, (3,), "person_truth_m")
            object.__setattr__(self, "person_truth_m", truth)


@dataclass(frozen=True)
class FormationState:
    """The formation as the operator sets it: d_des_m / h_des_m (m), whether formation control runs
    (False: every MAV holds position), and the ranges d_des_m / h_des_m may be set to now (a projection of
    `SceneView`)."""

    d_des_m: float
    h_des_m: float
    enabled: bool
    d_des_range_m: Range
    h_des_range_m: Range

    @classmethod
    def of(cls, view: SceneView) -> FormationState:
        return cls(
            d_des_m=view.formation.d_des_m,
            h_des_m=view.formation.h_des_m,
            enabled=view.formation_enabled,
            d_des_range_m=view.d_des_range_m,
            h_des_range_m=view.h_des_range_m,
        )


class OperatorActions(Protocol):
    """The operator commands the UI may call. Each is validated before anything changes; a refusal raises
    ValueError (or a subclass) whose message says what to do instead, and the UI shows it as a notification.
    """

    def set_formation(self, *, d_des_m: float, h_des_m: float) -> None:
        """Set the desired horizontal distance and height above the person (m)."""

    def add_obstacle(self, *, x_m: float, y_m: float, radius_m: float) -> str:
        """Add a virtual obstacle (vertical cylinder) at ENU (x_m, y_m); returns its id."""
        ...

    def remove_obstacle(self, obstacle_id: str) -> None:
        """Remove a virtual obstacle by id."""

    def land(self, vehicle_id: int) -> None:
        """Land one MAV; it leaves formation control until released."""

    def hold(self, vehicle_id: int) -> None:
        """Stop one flying MAV where it is (it hovers out of formation control until released or landed)."""

    def land_all(self) -> None:
        """Land every MAV."""

    def release(self, vehicle_id: int, *, override: bool = False) -> None:
        """Return a landed MAV to formation control (it takes off again), a holding one (it rejoins from where
        it hovers), or an airborne one skyring does not fly; override: let it take off or join although the
        pre-take-off checks refuse it (logged)."""

    def acknowledge_alert(self, alert_id: str) -> None:
        """Mark one alert as seen; it stays in the list (KeyError-like refusal for an unknown id)."""

    def acknowledge_all_alerts(self) -> int:
        """Mark every alert as seen; returns how many were newly acknowledged."""
        ...

    def set_formation_enabled(self, enabled: bool, *, override: bool = False) -> object:
        """Start (True) or stop (False, hold position) formation control for the whole team; override: start
        although the pre-take-off checks refuse a vehicle (logged)."""

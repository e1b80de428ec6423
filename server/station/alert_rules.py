"""What is wrong right now, read off the operator's view: the conditions the alert list is raised from.

`conditions(view, params)` is pure: it looks only at the `webui.view.SceneView` the operator sees (the
vehicles' reported positions, battery, link, plans and autopilot flags, the obstacles, the arena, the control
loop's pace), so a replayed view gives the same conditions as the live one did. One rule per kind:

- battery: below `battery_low_fraction` (warning) or `battery_critical_fraction` (critical);
- separation: two airborne MAVs closer than d_min + margin (warning) or d_min (critical);
- trunk_clearance: an airborne MAV's horizontal clearance to an obstacle's surface, below the obstacle's
  top, under `obstacle_warn_m` (warning) or `obstacle_critical_m` (critical);
- arena: an airborne MAV outside the arena's footprint or above its ceiling (warning; critical beyond
  `arena_critical_m`);
- link: no telemetry for longer than the station's stale limit (critical in the air, warning on the ground);
- agent: a networked onboard agent not heard for longer than the station's limit, or an airborne MAV with a
  live link whose controller published no plan for `agent_lost_s` (critical);
- realtime: the control loop achieved less than `realtime_fraction` of the speed asked for over the last
  second, or its last ticks took so long that it cannot reach that fraction (warning);
- failsafe: the autopilot runs its own failsafe (battery, offboard loss, ...) (critical);
- arming: the autopilot refused to arm (warning);
- solver: the MPC failed and the MAV brakes instead (warning);
- hold: the MAV holds because it has not heard a teammate (docs/safety.md#link-loss-the-hold) (warning).
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np

from server.station.alerts import Condition
from webui.view import SceneView, Severity, VehicleView

FLYING = ("takeoff", "formation", "holding")


@dataclass(frozen=True)
class AlertParams:
    """Thresholds of the alert rules.

    battery_low_fraction / battery_critical_fraction: state of charge in [0, 1] (the simulated autopilot's
    own failsafe lands at 0.15: `vehicles.sim.autopilot.AirframeParams.battery_land_fraction`);
    safety_distance_m: d_min between MAVs (the controller's guarantee, eq. 15); separation_margin_m: the
    warning band above it; obstacle_warn_m / obstacle_critical_m: horizontal clearance to an obstacle's
    surface; arena_critical_m: how far outside the arena a warning becomes critical; agent_lost_s: age of
    the newest plan after which an airborne MAV's controller counts as lost; realtime_fraction: achieved /
    requested speed below which the loop is behind.
    """

    battery_low_fraction: float = 0.25
    battery_critical_fraction: float = 0.15
    safety_distance_m: float = 1.5
    separation_margin_m: float = 0.5
    obstacle_warn_m: float = 1.0
    obstacle_critical_m: float = 0.5
    arena_critical_m: float = 2.0
    agent_lost_s: float = 1.0
    realtime_fraction: float = 0.8

    def __post_init__(self) -> None:
        if not 0.0 <= self.battery_critical_fraction <= self.battery_low_fraction <= 1.0:
            raise ValueError("battery thresholds must satisfy 0 <= critical <= low <= 1")
        if not 0.0 <= self.obstacle_critical_m <= self.obstacle_warn_m:
            raise ValueError("obstacle thresholds must satisfy 0 <= critical <= warn")
        for name in ("safety_distance_m", "separation_margin_m", "arena_critical_m", "agent_lost_s"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0.0):
                raise ValueError(f"{name} must be a finite number >= 0, got {value}")
        if not 0.0 < self.realtime_fraction <= 1.0:
            raise ValueError(f"realtime_fraction must be in (0, 1], got {self.realtime_fraction}")


def conditions(view: SceneView, params: AlertParams) -> list[Condition]:
    """Every condition that holds in `view`, one rule after the other (see the module docstring)."""
    out: list[Condition] = []
    for v in view.vehicles:
        out += _battery(v, params)
        out += _arena(v, view, params)
        out += _link(v)
        out += _agent(v, params)
        out += _autopilot(v)
        out += _solver(v)
        out += _hold(v)
        out += _obstacles(v, view, params)
    out += _separation(view, params)
    out += _realtime(view, params)
    return out


def airborne(v: VehicleView) -> bool:
    """A MAV the rules about flying apply to: in the air, or in a flying phase."""
    return v.in_air or v.phase in FLYING


def _battery(v: VehicleView, p: AlertParams) -> list[Condition]:
    b = v.battery_fraction
    if b is None or not math.isfinite(b) or b >= p.battery_low_fraction:
        return []
    critical = b < p.battery_critical_fraction
    limit = p.battery_critical_fraction if critical else p.battery_low_fraction
    word = "critical" if critical else "low"
    return [
        Condition(
            kind="battery",
            vehicle_id=v.vehicle_id,
            severity=Severity.CRITICAL if critical else Severity.WARNING,
            message=f"MAV {v.vehicle_id} battery {word}: {b * 100:.0f} % (below {limit * 100:.0f} %)",
        )
    ]


def _arena(v: VehicleView, view: SceneView, p: AlertParams) -> list[Condition]:
    if not v.in_air or not np.all(np.isfinite(v.position_m)):
        return []
    low, high = view.arena_min_m, view.arena_max_m
    below = low[:2] - v.position_m[:2]
    above = v.position_m - high
    outside = float(max(np.max(below), np.max(above)))
    if outside <= 0.0:
        return []
    where = "above the arena's ceiling" if above[2] == outside else "outside the arena"
    return [
        Condition(
            kind="arena",
            vehicle_id=v.vehicle_id,
            severity=Severity.CRITICAL if outside > p.arena_critical_m else Severity.WARNING,
            message=f"MAV {v.vehicle_id} is {outside:.1f} m {where} at "
            f"({v.position_m[0]:.1f}, {v.position_m[1]:.1f}, {v.position_m[2]:.1f}) m",
        )
    ]


def _link(v: VehicleView) -> list[Condition]:
    if not v.link_stale:
        return []
    age = "never heard from" if not math.isfinite(v.link_age_s) else f"no telemetry for {v.link_age_s:.1f} s"
    return [
        Condition(
            kind="link",
            vehicle_id=v.vehicle_id,
            severity=Severity.CRITICAL if airborne(v) else Severity.WARNING,
            message=f"MAV {v.vehicle_id} link stale: {age}",
        )
    ]


def _agent(v: VehicleView, p: AlertParams) -> list[Condition]:
    if v.agent is not None and v.agent.lost:
        return [
            Condition(
                kind="agent",
                vehicle_id=v.vehicle_id,
                severity=Severity.CRITICAL,
                message=f"MAV {v.vehicle_id} agent lost: nothing heard from its onboard agent for "
                f"{v.agent.age_s:.1f} s",
            )
        ]
    if v.link_stale or not v.in_air or v.phase not in FLYING:
        return []
    age = v.plan_age_s
    if age is not None and age <= p.agent_lost_s:
        return []
    since = "has published no plan" if age is None else f"published no plan for {age:.1f} s"
    return [
        Condition(
            kind="agent",
            vehicle_id=v.vehicle_id,
            severity=Severity.CRITICAL,
            message=f"MAV {v.vehicle_id} agent lost: its controller {since}",
        )
    ]


def _autopilot(v: VehicleView) -> list[Condition]:
    out = []
    if v.failsafe:
        out.append(
            Condition(
                kind="failsafe",
                vehicle_id=v.vehicle_id,
                severity=Severity.CRITICAL,
                message=f"MAV {v.vehicle_id} autopilot failsafe ({v.autopilot_mode or v.mode}): "
                f"{v.failsafe_reason or 'the autopilot runs its own failsafe'}",
            )
        )
    if v.arming_refusal:
        out.append(
            Condition(
                kind="arming",
                vehicle_id=v.vehicle_id,
                severity=Severity.WARNING,
                message=f"MAV {v.vehicle_id} refused to arm: {v.arming_refusal}",
            )
        )
    return out


def _solver(v: VehicleView) -> list[Condition]:
    return _status_warning(v, "braking", "solver", "solver failed, braking")


def _hold(v: VehicleView) -> list[Condition]:
    return _status_warning(v, "hold", "hold", "holds, not hearing its team")


def _status_warning(v: VehicleView, status: str, kind: str, what: str) -> list[Condition]:
    """A warning while the MAV's controller reports `status`, with its fault (less the status prefix)."""
    if v.solve_status != status:
        return []
    why = f": {v.fault.removeprefix(status + ': ')}" if v.fault else ""
    return [
        Condition(
            kind=kind,
            vehicle_id=v.vehicle_id,
            severity=Severity.WARNING,
            message=f"MAV {v.vehicle_id} {what}{why}",
        )
    ]


def _obstacles(v: VehicleView, view: SceneView, p: AlertParams) -> list[Condition]:
    if not v.in_air or not np.all(np.isfinite(v.position_m)):
        return []
    out = []
    for o in view.obstacles:
        if v.position_m[2] > o.height_m:
            continue
        clearance = float(np.hypot(*(v.position_m[:2] - o.center_m))) - o.radius_m
        if clearance >= p.obstacle_warn_m:
            continue
        name = "trunk" if o.kind == "tree" else f"{o.kind} obstacle"
        out.append(
            Condition(
                kind="trunk_clearance",
                vehicle_id=v.vehicle_id,
                subject=f"{name} {o.obstacle_id}",
                severity=Severity.CRITICAL if clearance < p.obstacle_critical_m else Severity.WARNING,
                message=f"MAV {v.vehicle_id} {clearance:.2f} m from {name} {o.obstacle_id} "
                f"(warning below {p.obstacle_warn_m:g} m)",
            )
        )
    return out


def _separation(view: SceneView, p: AlertParams) -> list[Condition]:
    flying = [v for v in view.vehicles if v.in_air and np.all(np.isfinite(v.position_m))]
    warn = p.safety_distance_m + p.separation_margin_m
    out = []
    for a, b in itertools.combinations(sorted(flying, key=lambda v: v.vehicle_id), 2):
        d = float(np.linalg.norm(a.position_m - b.position_m))
        if d >= warn:
            continue
        out.append(
            Condition(
                kind="separation",
                vehicle_id=a.vehicle_id,
                subject=f"MAV {b.vehicle_id}",
                severity=Severity.CRITICAL if d < p.safety_distance_m else Severity.WARNING,
                message=f"MAVs {a.vehicle_id} and {b.vehicle_id} {d:.2f} m apart "
                f"(d_min {p.safety_distance_m:g} m + margin {p.separation_margin_m:g} m)",
            )
        )
    return out


def _realtime(view: SceneView, p: AlertParams) -> list[Condition]:
    pace = view.pace
    if pace is None:
        return []
    floor = p.realtime_fraction * pace.requested_speed
    achieved, capacity = pace.realtime_factor, pace.capacity
    if achieved is not None and achieved < floor:
        why = f"{achieved:.2f}x achieved"
    elif capacity is not None and capacity < floor:
        why = f"its ticks allow {capacity:.2f}x at most"
    else:
        return []
    return [
        Condition(
            kind="realtime",
            vehicle_id=None,
            severity=Severity.WARNING,
            message=f"control loop behind real time: {why}, {pace.requested_speed:g}x asked",
        )
    ]

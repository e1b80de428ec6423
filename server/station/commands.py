"""Validation of operator commands: every command is checked here before anything changes.

A refused command raises `CommandError` (HTTP 422) or `UnknownTargetError` (HTTP 404) with a message that says
what to do instead; the REST API and the viser GUI both call the ground station, which calls these checks, so
there is one path and one wording for every refusal.

The limits come from the controller's own parameters (`limits_from_params`):
- the arena is the MPC's position box (MpcParams.position_min_m / position_max_m: x, y in [-20, 20] m and z
  in [3, 10] m by default);
- h_des: a MAV flies at the person's body centre (`person_center_height_m`, 0.9 m) plus h_des, which must
  stay inside the arena's height band: h_des in [z_min - 0.9, z_max - 0.9] = [2.1, 9.1] m by default;
- d_des, from below: K MAVs evenly spaced on the circle are 2 d_des sin(pi / K) apart, which must be at
  least the fresh teammate-repulsion d_max (FieldParams.teammate_d_max_base_m plus both MAVs' default
  covariance radii, 3.0 m) so that the finished formation is outside each other's repulsion; and the
  person-repulsion threshold (FieldParams.person_d_min_fraction * d_des) must be at least the safety
  distance d_min (FieldParams.teammate_d_min_m = e_max + v_max dt, paper eq. 15);
- d_des, from above: the circle about a person in the arena's centre must stay d_min
  (FieldParams.obstacle_d_min_m) inside the arena: d_des <= min half-width - d_min (18.5 m by default);
- a virtual obstacle's centre must lie inside the arena; its radius must be positive and at most
  `max_obstacle_radius_m`; its surface must stay at least FieldParams.obstacle_d_min_m (the distance at
  which the obstacle's repulsion saturates) from the person and from every MAV, so it never covers either;
- before a MAV takes off (start of the formation, release) or joins the formation from the air, it must stand
  outside the person's keep-out (the person-repulsion threshold, person_clearance_fraction * d_des: 7 m at
  the default d_des of 8 m) and at least d_min (safety_distance_m) from every teammate, horizontally: a
  take-off climbs straight up, into the person's space or a teammate's. An explicit operator override lets
  it go anyway, and the override is logged.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from controller.params import ControllerParams, FormationParams
from vehicles.world import PERSON_CENTRE_HEIGHT_M

PERSON_CENTER_HEIGHT_M = PERSON_CENTRE_HEIGHT_M  # the person's position message: body centre above the ground


class CommandError(ValueError):
    """An operator command was refused before anything changed; the message says what to do instead."""


class UnknownTargetError(CommandError):
    """The command names a vehicle or obstacle that does not exist."""


@dataclass(frozen=True)
class CommandLimits:
    """What an operator may set, in metres (see the module docstring for where each number comes from).

    arena_min_m / arena_max_m: (x, y, z) corners of the flight box; safety_distance_m: d_min around MAVs, the
    person and obstacle surfaces; formation_spacing_m: the least distance between neighbours on the circle;
    person_clearance_fraction: the person-repulsion threshold as a fraction of d_des.
    """

    arena_min_m: tuple[float, float, float] = (-20.0, -20.0, 3.0)
    arena_max_m: tuple[float, float, float] = (20.0, 20.0, 10.0)
    safety_distance_m: float = 1.5
    obstacle_clearance_m: float = 1.5
    formation_spacing_m: float = 3.0
    person_clearance_fraction: float = 7.0 / 8.0
    person_center_height_m: float = PERSON_CENTER_HEIGHT_M
    max_obstacle_radius_m: float = 5.0
    max_virtual_obstacles: int = 32

    def d_des_range_m(self, team_size: int) -> tuple[float, float]:
        """[low, high] for d_des with `team_size` MAVs in formation (the spacing rule needs K >= 2)."""
        low = self.safety_distance_m / self.person_clearance_fraction
        if team_size >= 2:
            low = max(low, self.formation_spacing_m / (2.0 * math.sin(math.pi / team_size)))
        width_x = self.arena_max_m[0] - self.arena_min_m[0]
        width_y = self.arena_max_m[1] - self.arena_min_m[1]
        half_width = 0.5 * min(width_x, width_y)
        return _round_up(low), _round_down(half_width - self.obstacle_clearance_m)

    def h_des_range_m(self) -> tuple[float, float]:
        """[low, high] for h_des: the MAVs' height person_center + h_des stays inside the arena's z band."""
        return (
            _round_up(self.arena_min_m[2] - self.person_center_height_m),
            _round_down(self.arena_max_m[2] - self.person_center_height_m),
        )


def _vec3(values: Sequence[float]) -> tuple[float, float, float]:
    x, y, z = (float(v) for v in values)
    return x, y, z


def limits_from_params(
    params: ControllerParams,
    *,
    person_center_height_m: float = PERSON_CENTER_HEIGHT_M,
    default_cov_radius_m: float = 0.5,
) -> CommandLimits:
    """The command limits implied by the controller's parameters (module docstring). default_cov_radius_m: a
    MAV's self-localisation covariance radius (sqrt of 0.25 m^2, the default VehicleState covariance)."""
    f = params.fields
    return CommandLimits(
        arena_min_m=_vec3(params.mpc.position_min_m),
        arena_max_m=_vec3(params.mpc.position_max_m),
        safety_distance_m=f.teammate_d_min_m,
        obstacle_clearance_m=f.obstacle_d_min_m,
        formation_spacing_m=f.teammate_d_max_base_m + 2.0 * default_cov_radius_m,
        person_clearance_fraction=f.person_d_min_fraction,
        person_center_height_m=person_center_height_m,
    )


def finite(name: str, value: object) -> float:
    """`value` as a float, or CommandError if it is not a finite number."""
    try:
        number = float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        raise CommandError(f"{name} must be a number, got {value!r}") from None
    if not math.isfinite(number):
        raise CommandError(f"{name} must be a finite number, got {value!r}")
    return number


def check_formation(
    *, d_des_m: object, h_des_m: object, limits: CommandLimits, team_size: int
) -> FormationParams:
    """The FormationParams to apply, or CommandError naming the allowed range."""
    d_des, h_des = finite("d_des_m", d_des_m), finite("h_des_m", h_des_m)
    d_low, d_high = limits.d_des_range_m(team_size)
    if not d_low <= d_des <= d_high:
        raise CommandError(
            f"d_des_m = {d_des:g} m is outside what the arena and safety distances allow with {team_size} "
            f"MAVs in formation: choose a value between {d_low:g} and {d_high:g} m"
        )
    h_low, h_high = limits.h_des_range_m()
    if not h_low <= h_des <= h_high:
        raise CommandError(
            f"h_des_m = {h_des:g} m would fly the MAVs outside the arena's height band "
            f"({limits.arena_min_m[2]:g} to {limits.arena_max_m[2]:g} m): choose a value between {h_low:g} "
            f"and {h_high:g} m"
        )
    return FormationParams(d_des_m=d_des, h_des_m=h_des)


def check_obstacle(
    *,
    x_m: object,
    y_m: object,
    radius_m: object,
    limits: CommandLimits,
    vehicles_m: Mapping[int, np.ndarray],
    persons_m: Sequence[np.ndarray],
    virtual_count: int,
) -> tuple[float, float, float]:
    """(x, y, radius) of a new virtual obstacle, or CommandError.

    vehicles_m: vehicle id -> (3,) position of every MAV (landed ones too: they may be released);
    persons_m: (3,) positions of the person (truth in simulation and/or estimates); virtual_count: how many
    virtual obstacles exist already.
    """
    x, y, r = finite("x_m", x_m), finite("y_m", y_m), finite("radius_m", radius_m)
    if r <= 0.0:
        raise CommandError(f"radius_m must be positive, got {r:g} m")
    if r > limits.max_obstacle_radius_m:
        raise CommandError(
            f"radius_m = {r:g} m is larger than {limits.max_obstacle_radius_m:g} m: cover a "
            "large area with several obstacles"
        )
    (x0, y0, _), (x1, y1, _) = limits.arena_min_m, limits.arena_max_m
    if not (x0 <= x <= x1 and y0 <= y <= y1):
        raise CommandError(
            f"the obstacle's centre ({x:.1f}, {y:.1f}) m is outside the arena "
            f"x in [{x0:g}, {x1:g}] m, y in [{y0:g}, {y1:g}] m: place it inside"
        )
    if virtual_count >= limits.max_virtual_obstacles:
        raise CommandError(
            f"there are already {virtual_count} virtual obstacles (the most allowed): remove one first"
        )
    keep = r + limits.obstacle_clearance_m
    for person in persons_m:
        gap = math.hypot(x - float(person[0]), y - float(person[1]))
        if gap < keep:
            raise CommandError(
                f"an obstacle of radius {r:g} m at ({x:.1f}, {y:.1f}) m would cover the person at "
                f"({person[0]:.1f}, {person[1]:.1f}) m: place it at least {keep:.1f} m from the person "
                f"(now {gap:.1f} m) or make it smaller"
            )
    for vehicle_id, position in sorted(vehicles_m.items()):
        gap = math.hypot(x - float(position[0]), y - float(position[1]))
        if gap < keep:
            raise CommandError(
                f"an obstacle of radius {r:g} m at ({x:.1f}, {y:.1f}) m would cover MAV {vehicle_id} at "
                f"({position[0]:.1f}, {position[1]:.1f}) m: place it at least {keep:.1f} m from the MAV "
                f"(now {gap:.1f} m) or make it smaller"
            )
    return x, y, r


def clearance_problems(
    *,
    vehicle_ids: Sequence[int],
    vehicles_m: Mapping[int, np.ndarray],
    persons_m: Sequence[np.ndarray],
    limits: CommandLimits,
    d_des_m: float,
) -> dict[int, str]:
    """Why each of `vehicle_ids` may not take off or join the formation where it stands (module docstring):
    inside the person's keep-out, or within d_min of a teammate; the vehicles with no problem are left out.

    vehicles_m: vehicle id -> (3,) ENU position of every MAV (all of them count as teammates); persons_m: (3,)
    positions of the person (truth and/or estimates; none: the keep-out cannot be checked).
    """
    keep_out = limits.person_clearance_fraction * d_des_m
    problems: dict[int, str] = {}
    for vid in vehicle_ids:
        here = vehicles_m.get(vid)
        if here is None:
            continue
        reasons = []
        for person in persons_m:
            gap = math.hypot(float(here[0]) - float(person[0]), float(here[1]) - float(person[1]))
            if gap < keep_out:
                reasons.append(
                    f"stands {gap:.1f} m from the person, inside the {keep_out:.1f} m keep-out "
                    f"({limits.person_clearance_fraction:g} d_des)"
                )
                break
        for other, there in sorted(vehicles_m.items()):
            if other == vid:
                continue
            gap = math.hypot(float(here[0]) - float(there[0]), float(here[1]) - float(there[1]))
            if gap < limits.safety_distance_m:
                reasons.append(
                    f"stands {gap:.1f} m from MAV {other}, closer than d_min = {limits.safety_distance_m:g} m"
                )
        if reasons:
            problems[vid] = "; ".join(reasons)
    return problems


def check_clearance(problems: Mapping[int, str], *, action: str, override: bool) -> list[str]:
    """CommandError naming every vehicle in `problems` (what `action` would do to it and how to proceed),
    unless `override`: then the problems are returned for the log."""
    lines = [f"MAV {vid} {why}" for vid, why in sorted(problems.items())]
    if lines and not override:
        raise CommandError(
            f"{action} refused: " + "; ".join(lines) + ". Move it (or the person), or repeat with the "
            "override to take off anyway (the override is logged)"
        )
    return lines


def _round_up(value: float) -> float:
    return math.ceil(value * 10.0 - 1e-9) / 10.0


def _round_down(value: float) -> float:
    return math.floor(value * 10.0 + 1e-9) / 10.0

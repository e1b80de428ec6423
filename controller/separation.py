"""Separation constraints: the half-planes that keep one MAV's plan apart from its teammates' plans and
outside the trunks, added to its MPC as linear rows (docs/safety.md).

The paper's repulsive fields (eqs. 13, 15) shape the plan but promise nothing. These rows are the guarantee:

- **Teammates, buffered Voronoi cells on the shared plans.** At every plan step n our previous plan's
  position q(n) and teammate j's planned position m_j(n) define the plane through their midpoint with unit
  normal a = (q - m) / |q - m|; our new plan must keep p(n) on our side, `separation_m / 2` plus our share
  of what we cannot know beyond it: a . p(n) >= a . (q + m) / 2 + (separation_m + inflation_j) / 2 +
  brake_n. inflation_j is both self-localisation covariance radii (eq. 15's r_sigma) and the plan's age
  times the speed bound. The teammate builds the mirror row from the same two plans, so two cooperating
  MAVs that both hold their rows stay `separation_m + inflation` apart.
- **Braking room.** The horizon (1.5 s) is shorter than a stop from 5 m/s, so a plan may meet its rows and
  still close in too fast to stop later. Each cooperative row carries the braking distance of our half of
  the pair's closing speed along a: v^2 / (2 b), b = step_brake_mps2 before the last step and brake_mps2 at
  it, capped at brake_margin_max_m.
- **Teammates that do not cooperate** (out of formation: taking off, holding, landing; or silent longer than
  `cooperative_age_s`): we keep the whole distance from their (aligned, possibly extrapolated) plan,
  separation_m + inflation_j from m_j(n), and the braking room of the whole closing speed at the last step.
- **Trunks.** A vertical plane tangent to the trunk's cylinder grown by `obstacle_clearance_m` (and
  `obstacle_sigmas` times our covariance radius), facing our planned position, at every step where that
  position is below the trunk's top; the disc lies wholly behind the plane, so keeping to the plane keeps
  clear of the disc. Like a cooperative teammate row, it also keeps the braking room of our planned
  closing speed on the trunk, v^2 / (2 b) (step_brake_mps2, brake_mps2 at the last step, capped at
  brake_margin_max_m): without it a plan could meet every trunk row and still graze the grown disc at
  the horizon's end at speed, and the vehicle, lagging its plan as it brakes, cut into it (run 912 of
  the safety sweep: docs/safety.md). The plane is moved out by how far the vehicle lags its plan
  towards the trunk (`lag_m`): the row is for the vehicle.
- **The arena's floor.** At every step our previous plan is within reach of the floor (MpcParams'
  position_min_m's z), a row keeps the plan at or above the floor, or above the previous plan where that
  is lower, weighted 20 times a teammate row. Without it, rows that cannot all hold (a silent teammate
  above, whose gap grows with its age) drove an escaping plan down through the soft state bounds, whose
  penalty is ten times smaller than the rows', to below the ground (`floor_rows`). It never pushes a plan
  up.

All rows are soft with one exact penalty (controller/mpc.py `HalfPlanes`): the QP is never infeasible, and
whenever the rows can all hold the plan holds them exactly. When they cannot (squeezed between trunks, a
teammate inside our cell), the controller escapes (formation.py): it brakes towards its current position
and separates vertically from the closest teammate, and counts it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from controller.fields import FieldParams, ObstacleSet, TeammatePaths
from controller.kernel_args import kernel_array
from controller.mpc import HalfPlanes
from controller.separation_kernel import (
    closest_teammate,
    empty_rows,
    floor_rows_kernel,
    obstacle_rows_kernel,
    teammate_rows_kernel,
    tick_rows,
)


@dataclass(frozen=True)
class SeparationParams:
    """The separation constraints' distances (m), decelerations (m/s^2) and ages (s).

    enabled: add the rows at all (False: the paper's fields alone, for comparison).
    separation_m: the distance two cooperating plans keep apart at every step before inflation (both
        covariance radii, the plans' age): above the 1.5 m the safety sweep checks by about what following a
        plan costs, and small enough that 16 MAVs on the d_des = 8 m circle (3.12 m apart) hold their rows.
    obstacle_clearance_m: the distance every planned position keeps from a trunk's surface.
    obstacle_sigmas: how many of our self-localisation std (the covariance radius, eq. 15's r_sigma) the trunk
        rows keep beyond obstacle_clearance_m: trunks are mapped in the true world and our GPS error along a
        row's normal is unknown, so a row 1 sigma out is crossed by 16 % of the GPS errors, 1.5 sigma by 7 %
        (with 2, 3 of the 12 paper flights left their formation bounds: docs/safety.md).
    hold_obstacle_sigmas: the same for a hold's trunk rows (`held_rows`). In formation flight the paper's
        trunk field keeps a MAV about 1.5 m off the bark, 3 sigma, and the rows are the line behind it; a
        hold flies without the fields, so its rows keep the field's 3 sigma themselves, as far as braking
        on the spot allows.
    step_brake_mps2, brake_mps2: the decelerations whose braking distance each cooperative row keeps (before
        the last step, and at it); brake_margin_max_m caps that room.
    cooperative_age_s: a teammate whose plan is older than this is not trusted to hold its own row.
    row_reach_m: a row that our previous plan meets with more than this to spare is left out: the new plan
        starts where the previous one is and would have to move that much further, in 0.1 s of re-planning,
        to meet it (it costs, as rows do, and cannot bind).
    escape_violation_m, escape_steps: a plan that misses a row of its first escape_steps steps by more than
        escape_violation_m is replaced by an escape (`imminent_miss_m`); later misses are left to the next
        ticks, which see them sooner (a stale teammate's wide row may never hold, and must not stop the team).
    escape_climb_m: the height difference an escape aims for from a teammate closer than separation_m.
    plan_deviation_mps2: how fast a teammate's newest plan can part from the last one we heard (two
        vehicles' 4 m/s^2): a plan t old is off by at most plan_deviation_mps2 t^2 / 2, or the speed bound
        times its age, whichever is less (`age_margin_m`).
    obstacle_row_weight: a trunk row is this many times a teammate row (its normal and offset scaled): the
        rows of a plan step share the QP's slack for that step, their largest weighted violation, so when
        rows cannot all hold the plan gives way to a teammate (who also moves away) before a trunk (which
        does not).
    floor_row_weight: the same for the arena floor's rows (`floor_rows`): a plan sinks below the floor by
        a twentieth of what it gives way to its teammates' rows.
    """

    enabled: bool = True
    separation_m: float = 1.6
    obstacle_clearance_m: float = 0.2
    obstacle_sigmas: float = 1.5
    hold_obstacle_sigmas: float = 3.0
    step_brake_mps2: float = 3.0
    brake_mps2: float = 2.0
    brake_margin_max_m: float = 4.0
    cooperative_age_s: float = 0.5
    row_reach_m: float = 4.0
    escape_violation_m: float = 0.05
    escape_steps: int = 5
    escape_climb_m: float = 2.0
    obstacle_row_weight: float = 5.0
    floor_row_weight: float = 20.0
    plan_deviation_mps2: float = 8.0

    def __post_init__(self) -> None:
        for name, value in vars(self).items():
            if name == "enabled":
                continue
            if not (math.isfinite(value) and value >= 0.0):
                raise ValueError(f"SeparationParams.{name} must be a finite number >= 0, got {value}")
        if self.obstacle_row_weight <= 0.0 or self.floor_row_weight <= 0.0:
            raise ValueError("SeparationParams: the row weights must be > 0")
        if self.step_brake_mps2 <= 0.0 or self.brake_mps2 <= 0.0:
            raise ValueError("SeparationParams: the braking decelerations must be > 0")


def row_margins(planes: HalfPlanes, positions_m: np.ndarray) -> np.ndarray:
    """(R,) a . p(step) - b of every row for plan positions (N+2, 3): >= 0 where the row holds."""
    p = positions_m[planes.steps]
    return np.einsum("ri,ri->r", planes.normals_xy, p[:, :2]) + planes.z_normals * p[:, 2] - planes.offsets


def imminent_miss_m(planes: HalfPlanes, positions_m: np.ndarray, *, steps: int) -> float:
    """The largest shortfall (m, >= 0) of plan positions (N+2, 3) from the rows of steps 1..steps."""
    near = planes.steps <= steps
    if not near.any():
        return 0.0
    return max(0.0, -float(row_margins(planes, positions_m)[near].min()))


@dataclass(frozen=True, eq=False)
class SeparationRows:
    """The rows of one tick and where they came from.

    planes: the MPC's half-planes (R rows: the teammate rows, then the trunk rows, then the floor rows);
    teammate_rows, obstacle_rows, floor_rows: how many of each; closest_teammate_m: the smallest distance
    between our previous plan and a teammate's plan over the horizon (inf when none);
    closest_teammate_index: that teammate's index in the TeammatePaths (-1: none).
    """

    planes: HalfPlanes
    teammate_rows: int
    obstacle_rows: int
    closest_teammate_m: float
    closest_teammate_index: int
    floor_rows: int = 0

    @property
    def count(self) -> int:
        return self.teammate_rows + self.obstacle_rows + self.floor_rows


def held_rows(
    rows: SeparationRows,
    *,
    start_m: np.ndarray,
    velocity_mps: np.ndarray,
    decel_mps2: float,
    trunk_widening_m: float = 0.0,
) -> SeparationRows:
    """A hold's rows (formation.py): each teammate row eased to what braking on the spot can keep, each
    trunk row widened by trunk_widening_m as far as that braking allows.

    Braking at decel_mps2 against the start velocity (3,) m/s runs straight from start_m (3,) to the stop
    point, so the path's least reach along a row's normal is at one of the two. A teammate row that this path
    would break is moved back to that reach: a holding MAV closes on a teammate no further than braking
    must, and a neighbour's gap never pushes a resting MAV about. A trunk row is moved out by
    trunk_widening_m (m), but never past that reach, so the wider margin never pushes a hold away from a
    trunk it already stands closer to; it only stops it sooner. Floor rows stay as they are."""
    t, o = rows.teammate_rows, rows.obstacle_rows
    if t == 0 and (o == 0 or trunk_widening_m <= 0.0):
        return rows
    start = np.asarray(start_m, dtype=float)
    v = np.asarray(velocity_mps, dtype=float)
    stop = start + v * (np.linalg.norm(v) / (2.0 * decel_mps2))
    planes = rows.planes
    normals = np.column_stack([planes.normals_xy, planes.z_normals])
    reach = np.minimum(normals @ start, normals @ stop)  # (R,) the braking path's least reach
    offsets = planes.offsets.copy()
    offsets[:t] = np.minimum(offsets[:t], reach[:t])
    trunk = slice(t, t + o)
    scale = np.linalg.norm(normals[trunk], axis=1)  # the rows' weight: normals and offsets are scaled
    widened = np.minimum(offsets[trunk] + scale * trunk_widening_m, reach[trunk])
    offsets[trunk] = np.maximum(offsets[trunk], widened)
    return replace(rows, planes=replace(planes, offsets=offsets))


def age_margin_m(ages_s: np.ndarray, *, speed_term_m: np.ndarray, params: SeparationParams) -> np.ndarray:
    """(J,) how far each teammate may be from the plan we heard, ages_s (J,) s old: the lesser of the speed
    bound's term (speed_term_m (J,), eq. 15's r_comm) and the deviation a re-plan can build up."""
    ages = np.maximum(np.asarray(ages_s, dtype=float), 0.0)
    return np.minimum(speed_term_m, 0.5 * params.plan_deviation_mps2 * ages * ages)


def braking_room_m(closing_mps: np.ndarray, *, decel_mps2: float, cap_m: float) -> np.ndarray:
    """Distance to stop a closing speed (m/s, >= 0 counts; negative: moving apart) at decel_mps2, capped."""
    v = np.maximum(closing_mps, 0.0)
    return np.minimum(v * v / (2.0 * decel_mps2), cap_m)


def teammate_rows(
    *,
    own_path_m: np.ndarray,
    own_velocities_mps: np.ndarray,
    mates: TeammatePaths,
    cooperative: np.ndarray,
    inflation_m: np.ndarray,
    dt_s: float,
    own_id: int,
    params: SeparationParams,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Buffered Voronoi rows against every teammate at plan steps 1..S-1.

    own_path_m, own_velocities_mps: (S, 3) our previous plan on this tick's horizon (S = N+1 steps, step 0
    at the start state); mates.positions_m (J, S, 3); cooperative (J,) bool; inflation_m (J,) m.
    Returns steps (R,), normals (R, 3), offsets (R,) and the pair distances (J, S).
    """
    diff_all = own_path_m[None, :, :] - mates.positions_m  # (J, S, 3)
    dist_all = np.sqrt(np.einsum("jsi,jsi->js", diff_all, diff_all))  # (J, S)
    gap_all = params.separation_m + inflation_m  # (J,) what each pair must keep
    # teammates whose rows are all out of reach (module docstring) are left before the real work
    near = dist_all.min(axis=1) < gap_all + params.brake_margin_max_m + params.row_reach_m
    diff, dist, gap, coop = diff_all[near], dist_all[near], gap_all[near], cooperative[near]
    tie = np.where(mates.vehicle_ids[near] < own_id, 1.0, -1.0)  # coincident plans: split along x by id
    fallback = np.zeros_like(diff)
    fallback[..., 0] = tie[:, None]
    normals = np.where(dist[..., None] > 1e-6, diff / np.maximum(dist, 1e-12)[..., None], fallback)
    positions = mates.positions_m[near]
    mate_v = np.gradient(positions, dt_s, axis=1) if diff.shape[1] > 1 else np.zeros_like(diff)
    closing = -np.einsum("jsi,jsi->js", normals, own_velocities_mps[None] - mate_v)  # (J', S) m/s
    last = diff.shape[1] - 1
    share = np.where(coop, 0.5, 1.0)[:, None]  # our part of the closing speed
    room = braking_room_m(share * closing, decel_mps2=params.step_brake_mps2, cap_m=params.brake_margin_max_m)
    room[:, last] = braking_room_m(
        share[:, 0] * closing[:, last], decel_mps2=params.brake_mps2, cap_m=params.brake_margin_max_m
    )
    room[~coop, :last] = 0.0
    # a . m + |q - m| = a . q: a cooperative row keeps p on our side of the midpoint plus half the gap, any
    # other row keeps the whole gap from the teammate's plan. `keep` is each row's distance to go, measured
    # along a from our previous plan: rows farther than row_reach_m from binding are left out.
    keep = np.where(coop[:, None], 0.5 * (dist + gap[:, None]), gap[:, None]) + room
    a_dot_m = np.einsum("jsi,jsi->js", normals, positions)
    use = keep - dist > -params.row_reach_m
    use[:, 0] = False
    j, s = np.nonzero(use)
    return s, normals[j, s], a_dot_m[j, s] + keep[j, s], dist_all


def trunk_margin_m(params: SeparationParams, own_cov_radius_m: float) -> float:
    """How far (m) every trunk row stands off the bark: the clearance and obstacle_sigmas covariance radii."""
    return params.obstacle_clearance_m + params.obstacle_sigmas * own_cov_radius_m


def obstacle_rows(
    *,
    own_path_m: np.ndarray,
    own_velocities_mps: np.ndarray,
    obstacles: ObstacleSet,
    own_cov_radius_m: float,
    params: SeparationParams,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Tangent planes to every trunk near our previous plan (within row_reach_m of binding), at steps
    1..S-1 below its top, moved out by the braking room of our planned closing speed on the trunk.

    own_path_m, own_velocities_mps: (S, 3) our previous plan on the horizon.
    Returns steps (R,), normals (R, 3) with zero z, offsets (R,), both scaled by obstacle_row_weight."""
    if obstacles.count == 0:
        return np.zeros(0, dtype=np.int64), np.zeros((0, 3)), np.zeros(0)
    rel = own_path_m[None, :, :2] - obstacles.centers_m[:, None, :]  # (M, S, 2)
    dist = np.sqrt(np.einsum("msi,msi->ms", rel, rel))
    normals_xy = np.where(
        dist[..., None] > 1e-6, rel / np.maximum(dist, 1e-12)[..., None], np.array([1.0, 0.0])
    )
    closing = -np.einsum("msi,si->ms", normals_xy, np.asarray(own_velocities_mps, dtype=float)[:, :2])
    room = braking_room_m(closing, decel_mps2=params.step_brake_mps2, cap_m=params.brake_margin_max_m)
    room[:, -1] = braking_room_m(
        closing[:, -1], decel_mps2=params.brake_mps2, cap_m=params.brake_margin_max_m
    )
    grown = obstacles.radii_m[:, None] + trunk_margin_m(params, own_cov_radius_m) + room  # (M, S)
    offsets = np.einsum("msi,mi->ms", normals_xy, obstacles.centers_m) + grown
    below = own_path_m[None, :, 2] < obstacles.heights_m[:, None] + params.obstacle_clearance_m
    near = dist - grown < params.row_reach_m
    use = below & near
    use[:, 0] = False
    m, s = np.nonzero(use)
    normals = np.zeros((m.shape[0], 3))
    normals[:, :2] = normals_xy[m, s]
    w = params.obstacle_row_weight
    return s, w * normals, w * offsets[m, s]


def floor_rows(
    *, own_path_m: np.ndarray, floor_m: float, params: SeparationParams
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rows z(n) >= min(floor_m, q_z(n)) at the steps 1..S-1 where our previous plan q (S, 3) is within
    row_reach_m of the floor, scaled by floor_row_weight: when rows cannot all hold, the plan gives way to a
    teammate long before it sinks below the floor, and the row never asks a plan below the floor (the climb
    after take-off) to rise. Returns steps (R,), normals (R, 3), offsets (R,)."""
    heights = np.asarray(own_path_m, dtype=float)[:, 2]
    near = heights - floor_m < params.row_reach_m
    near[0] = False
    steps = np.flatnonzero(near)
    w = params.floor_row_weight
    normals = np.zeros((steps.shape[0], 3))
    normals[:, 2] = w
    return steps, normals, w * np.minimum(floor_m, heights[steps])


def separation_rows(
    *,
    own_path_m: np.ndarray,
    own_velocities_mps: np.ndarray,
    mates: TeammatePaths,
    mate_ages_s: np.ndarray,
    inflation_m: np.ndarray,
    obstacles: ObstacleSet,
    own_cov_radius_m: float,
    dt_s: float,
    own_id: int,
    params: SeparationParams,
    lag_m: np.ndarray | None = None,
    floor_m: float | None = None,
    compiled: bool = True,
) -> SeparationRows:
    """Every separation row of one tick (see the module docstring), as the MPC's soft `HalfPlanes`.

    own_path_m, own_velocities_mps: (S, 3) our previous plan on the horizon, starting at the start state;
    mate_ages_s (J,): each teammate plan's age; inflation_m (J,): what each row grows by (m).
    The rows constrain plan step n = 1..S-1 (the MPC's x(n); x(0) is the start state). lag_m (3,): where
    the vehicle is less where its plan starts (the follower lags the plan, up to the leash); every trunk row
    is tightened by the lag's part towards its plane, so it holds for the vehicle rather than for the plan.
    floor_m: the arena's floor (m), kept by `floor_rows`; None: no floor rows.
    compiled: build them with separation_kernel.py's kernels (the default) or with the numpy reference here.
    """
    cooperative = mates.in_formation & (mate_ages_s <= params.cooperative_age_s)
    build = _compiled_rows if compiled else _reference_rows
    steps, normals, offsets, (t, o, f), closest_index, closest = build(
        own_path_m,
        own_velocities_mps,
        mates,
        cooperative,
        inflation_m,
        obstacles,
        own_cov_radius_m,
        dt_s,
        own_id,
        params,
        floor_m,
    )
    if lag_m is not None and o:
        trunk = slice(t, t + o)
        offsets[trunk] = offsets[trunk] + np.maximum(-(normals[trunk] @ np.asarray(lag_m, dtype=float)), 0.0)
    return rows_of(steps, normals, offsets, (t, o, f), closest_index, closest)


def rows_of(
    steps: np.ndarray,
    normals: np.ndarray,
    offsets: np.ndarray,
    counts: tuple[int, int, int],
    closest_index: int,
    closest: float,
) -> SeparationRows:
    """The tick's `SeparationRows` from its rows, steps (R,), normals (R, 3) and offsets (R,), and their
    (teammate, trunk, floor) counts."""
    planes = HalfPlanes(steps=steps, normals_xy=normals[:, :2], normals_z=normals[:, 2], offsets=offsets)
    t, o, f = counts
    return SeparationRows(planes, t, o, closest, closest_index, floor_rows=f)


def tick_separation_rows(
    *,
    own_path_m: np.ndarray,
    own_velocities_mps: np.ndarray,
    mates: TeammatePaths,
    own_gps_offset_m: np.ndarray,
    obstacles: ObstacleSet,
    own_cov_radius_m: float,
    dt_s: float,
    own_id: int,
    params: SeparationParams,
    fields: FieldParams,
    lag_m: np.ndarray,
    floor_m: float,
) -> SeparationRows:
    """A controller tick's rows in one compiled call (separation_kernel.tick_rows): `separation_rows` of the
    teammates placed by the GPS offsets (`TeammatePaths.placed_by`), each teammate's rows grown by
    `row_inflation` (both covariance radii, eq. 15's age term and `age_margin_m`), with the lag and the floor.
    The same bits as that composition (tests/controller/test_separation_kernel.py)."""
    own_path = kernel_array(own_path_m, float)
    own_vel = kernel_array(own_velocities_mps, float)
    count, steps = mates.count, own_path.shape[0]
    out_steps, out_normals, out_offsets = empty_rows((count + obstacles.count + 1) * steps)
    offsets = np.zeros((count, 3)) if mates.gps_offsets_m is None else mates.gps_offsets_m
    centers, radii, heights = obstacles.kernel_arrays()
    t, o, f, closest_index, closest = tick_rows(
        own_path,
        own_vel,
        kernel_array(mates.positions_m, float),
        kernel_array(mates.vehicle_ids, np.int64),
        kernel_array(mates.in_formation, np.bool_),
        kernel_array(mates.d_max_m, float),
        kernel_array(mates.ages, float),
        kernel_array(offsets, float),
        kernel_array(own_gps_offset_m, float),
        fields.teammate_d_max_base_m,
        fields.teammate_speed_mps,
        fields.teammate_age_grace_s,
        0.5 * params.plan_deviation_mps2,
        params.cooperative_age_s,
        params.separation_m,
        centers,
        radii,
        heights,
        trunk_margin_m(params, float(own_cov_radius_m)),
        params.obstacle_clearance_m,
        params.obstacle_row_weight,
        float(dt_s),
        int(own_id),
        params.step_brake_mps2,
        params.brake_mps2,
        params.brake_margin_max_m,
        params.row_reach_m,
        float(floor_m),
        params.floor_row_weight,
        kernel_array(lag_m, float),
        out_steps,
        out_normals,
        out_offsets,
    )
    r = t + o + f
    return rows_of(out_steps[:r], out_normals[:r], out_offsets[:r], (t, o, f), closest_index, closest)


def _reference_rows(
    own_path, own_vel, mates, cooperative, inflation, obstacles, own_cov_radius, dt, own_id, params, floor
):
    """The rows by the numpy functions above: (steps (R,), normals (R, 3), offsets (R,), (teammate, trunk,
    floor) row counts, closest teammate's index, its distance)."""
    if mates.count:
        t_steps, t_normals, t_offsets, dist = teammate_rows(
            own_path_m=own_path,
            own_velocities_mps=own_vel,
            mates=mates,
            cooperative=cooperative,
            inflation_m=inflation,
            dt_s=dt,
            own_id=own_id,
            params=params,
        )
        per_mate = dist.min(axis=1)
        closest_index = int(np.argmin(per_mate))
        closest = float(per_mate[closest_index])
    else:
        t_steps, t_normals, t_offsets = np.zeros(0, dtype=np.int64), np.zeros((0, 3)), np.zeros(0)
        closest_index, closest = -1, math.inf
    o_steps, o_normals, o_offsets = obstacle_rows(
        own_path_m=own_path,
        own_velocities_mps=own_vel,
        obstacles=obstacles,
        own_cov_radius_m=own_cov_radius,
        params=params,
    )
    f_steps, f_normals, f_offsets = np.zeros(0, dtype=np.int64), np.zeros((0, 3)), np.zeros(0)
    if floor is not None:
        f_steps, f_normals, f_offsets = floor_rows(own_path_m=own_path, floor_m=floor, params=params)
    counts = (len(t_steps), len(o_steps), len(f_steps))
    return (
        np.concatenate([t_steps, o_steps, f_steps]).astype(np.int64),
        np.concatenate([t_normals, o_normals, f_normals]),
        np.concatenate([t_offsets, o_offsets, f_offsets]),
        counts,
        closest_index,
        closest,
    )


def _compiled_rows(
    own_path, own_vel, mates, cooperative, inflation, obstacles, own_cov_radius, dt, own_id, params, floor
):
    """The same as `_reference_rows`, by separation_kernel.py's kernels, each writing its rows after the
    previous one's into one set of arrays (no concatenation)."""
    own_path = kernel_array(own_path, float)
    own_vel = kernel_array(own_vel, float)
    steps = own_path.shape[0]
    count = mates.count
    out_steps, out_normals, out_offsets = empty_rows((count + obstacles.count + 1) * steps)
    dist = np.empty((count, steps))
    centers, radii, heights = obstacles.kernel_arrays()
    t = teammate_rows_kernel(
        own_path,
        own_vel,
        kernel_array(mates.positions_m, float),
        kernel_array(mates.vehicle_ids, np.int64),
        kernel_array(cooperative, np.bool_),
        params.separation_m + np.asarray(inflation, dtype=float),
        float(dt),
        int(own_id),
        params.step_brake_mps2,
        params.brake_mps2,
        params.brake_margin_max_m,
        params.row_reach_m,
        out_steps,
        out_normals,
        out_offsets,
        dist,
    )
    o = obstacle_rows_kernel(
        own_path,
        own_vel,
        centers,
        radii,
        heights,
        trunk_margin_m(params, float(own_cov_radius)),
        params.obstacle_clearance_m,
        params.step_brake_mps2,
        params.brake_mps2,
        params.brake_margin_max_m,
        params.row_reach_m,
        params.obstacle_row_weight,
        out_steps[t:],
        out_normals[t:],
        out_offsets[t:],
    )
    f = 0
    if floor is not None:
        n = t + o
        f = floor_rows_kernel(
            own_path,
            float(floor),
            params.row_reach_m,
            params.floor_row_weight,
            out_steps[n:],
            out_normals[n:],
            out_offsets[n:],
        )
    closest_index, closest = closest_teammate(dist)
    rows = t + o + f
    return out_steps[:rows], out_normals[:rows], out_offsets[:rows], (t, o, f), closest_index, closest

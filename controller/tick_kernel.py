"""What a formation-flight tick computes between its start state and its MPC solve, in one compiled call.

formation.py's tick aligns the teammates' plans to our horizon (`teammates.fresh_paths`), computes the
external inputs on our previous plan (`fields_kernel._kernel`), aims at the terminal reference
(`reference_kernel.aim`) and builds the separation rows (`separation_kernel.tick_rows`): four kernels, each
behind its own Python wrapper. `inputs_and_rows` calls the same four kernels in the same order with the same
arguments, so it gives the same bits (tests/controller/test_tick_kernel.py), without the Python between them
(docs/fast-core.md, "One call from the start state to the solve"). The wrappers stay: the general path (a
hold, the price baseline, phantom teammates, the separation rows switched off) and the reference.
"""

from __future__ import annotations

import numba
import numpy as np

from controller.fields_kernel import _kernel as input_terms_kernel
from controller.mpc import MpcParams
from controller.params import ControllerParams
from controller.reference_kernel import aim
from controller.separation_kernel import tick_rows
from controller.teammates import fresh_paths

# Indices of the per-controller constants (`tick_constants`), all float
(
    K_DT,  # s: the MPC's step
    K_HORIZON_S,  # s: (N+1) dt, the reference's horizon
    K_RADIUS_CAP,  # m: FieldParams.covariance_radius_cap_m
    K_MATE_SPEED,  # m/s: FieldParams.teammate_speed_mps
    K_MATE_GRACE,  # s: FieldParams.teammate_age_grace_s
    K_D_MAX_BASE,  # m: FieldParams.teammate_d_max_base_m
    K_HALF_DEVIATION,  # m/s^2: half SeparationParams.plan_deviation_mps2
    K_COOPERATIVE_AGE,  # s
    K_SEPARATION,  # m
    K_CLEARANCE,  # m: obstacle_clearance_m
    K_OBSTACLE_WEIGHT,
    K_STEP_BRAKE,  # m/s^2
    K_BRAKE,  # m/s^2
    K_BRAKE_CAP,  # m: brake_margin_max_m
    K_REACH,  # m: row_reach_m
    K_FLOOR,  # m: the arena's floor
    K_FLOOR_WEIGHT,
) = range(17)


def tick_constants(params: ControllerParams, mpc: MpcParams) -> np.ndarray:
    """(17,) the K_* constants of a controller with these parameters (mpc: its MPC's, which the price
    baseline changes)."""
    f, sep = params.fields, params.separation
    constants = np.empty(17)
    constants[K_DT] = mpc.dt_s
    constants[K_HORIZON_S] = (mpc.horizon_steps + 1) * mpc.dt_s
    constants[K_RADIUS_CAP] = f.covariance_radius_cap_m
    constants[K_MATE_SPEED] = f.teammate_speed_mps
    constants[K_MATE_GRACE] = f.teammate_age_grace_s
    constants[K_D_MAX_BASE] = f.teammate_d_max_base_m
    constants[K_HALF_DEVIATION] = 0.5 * sep.plan_deviation_mps2
    constants[K_COOPERATIVE_AGE] = sep.cooperative_age_s
    constants[K_SEPARATION] = sep.separation_m
    constants[K_CLEARANCE] = sep.obstacle_clearance_m
    constants[K_OBSTACLE_WEIGHT] = sep.obstacle_row_weight
    constants[K_STEP_BRAKE] = sep.step_brake_mps2
    constants[K_BRAKE] = sep.brake_mps2
    constants[K_BRAKE_CAP] = sep.brake_margin_max_m
    constants[K_REACH] = sep.row_reach_m
    constants[K_FLOOR] = mpc.position_min_m[2]
    constants[K_FLOOR_WEIGHT] = sep.floor_row_weight
    return constants


@numba.njit(cache=True)
def inputs_and_rows(
    table,  # (positions (C, L, 3), lengths (C,), stamps (C,), steps (C,), radii (C,), ids (C,), in formation
    # (C,), GPS offsets (C, 3)): a TeammateTable's columns (`TeammateTable.kernel_columns`)
    rows,  # (J,) int64: the table's rows fresh for this tick
    now_s,
    constants,  # (17,) float: K_* above
    d_max_head,  # m: eq. 15's base plus our own capped covariance radius
    trunk_margin,  # m: separation.trunk_margin_m of our capped covariance radius
    start_p,  # (3,) m: the start position
    horizon,  # (2, S, 3): our previous plan's positions and velocities on the horizon
    measured_p,  # (3,) m: the measured position (the rows' lag is measured less start)
    own_offset,  # (3,) m: our GPS offset
    person_p,  # (3,) m
    person_v,  # (3,) m/s
    step_times,  # (S,) s: n dt
    predict,  # ReferenceParams.predict_person
    passing,  # ReferenceParams.pass_through
    bearing,  # rad: where the terminal reference lies about the person
    d_des,  # m
    h_des,  # m
    field_params,  # (23,) fields_kernel's parameter vector
    terms,  # (6,) bool: FieldTerms' tracking, teammates, obstacles, person, approach, dqmpc_thresholds
    own_id,
    in_formation,
    centers,  # (M, 2) m
    radii,  # (M,) m
    heights,  # (M,) m
    weights,  # (S,) s^2: input_displacement's weights
    arena_lo,  # (3,) m
    arena_hi,  # (3,) m
):  # pragma: no cover - compiled; tested against formation.py's wrappers
    """The tick's teammates (their aligned plans (J, S, 3), ids, in-formation flags, GPS offsets, eq. 15
    d_max and ages), its external inputs (6, S, 3) in TERMS order and their fault flag, its terminal
    reference target (2, 3), and its separation rows (steps, normals (R, 3), offsets) with their (teammate,
    trunk, floor) counts, the closest teammate's index and distance."""
    c = constants
    positions, lengths, stamps, plan_dts, mate_radii, row_ids, mate_flying, offsets = table
    count = rows.shape[0]
    steps = horizon.shape[1]
    dt = c[K_DT]
    mates = np.empty((count, steps, 3))
    ids = np.empty(count, np.int64)
    flying = np.empty(count, np.bool_)
    mate_offsets = np.empty((count, 3))
    d_max = np.empty(count)
    ages = np.empty(count)
    fresh_paths(
        positions, lengths, stamps, plan_dts, mate_radii, row_ids, mate_flying, offsets, rows, now_s, dt,
        False, c[K_RADIUS_CAP], d_max_head, c[K_MATE_SPEED], c[K_MATE_GRACE],
        mates, ids, flying, mate_offsets, d_max, ages,
    )  # fmt: skip
    # the person's horizontal position at each step: formation `_inputs`, numpy's p + v t in numpy's order
    person_xy = np.empty((steps, 2))
    for n in range(steps):
        for a in range(2):
            person_xy[n, a] = person_p[a] + person_v[a] * step_times[n] if predict else person_p[a]
    team_size = 1
    for j in range(count):
        team_size += 1 if flying[j] else 0
    inputs = np.zeros((6, steps, 3))
    own_path, own_vel = horizon[0], horizon[1]
    fault = input_terms_kernel(
        own_path, own_vel, True, person_xy, mates, ids, flying, d_max, centers, radii, heights, team_size,
        d_des, field_params, terms[0], terms[1], terms[2], terms[3], terms[4], terms[5], own_id, in_formation,
        inputs,
    )  # fmt: skip
    target = np.empty((2, 3))
    aim(
        start_p, person_p, person_v, bearing, d_des, h_des, c[K_HORIZON_S], predict, passing, weights,
        inputs[0], dt, arena_lo, arena_hi, target,
    )  # fmt: skip
    lag = np.empty(3)
    for i in range(3):
        lag[i] = measured_p[i] - start_p[i]
    capacity = (count + centers.shape[0] + 1) * steps
    out_steps = np.zeros(capacity, np.int64)
    out_normals = np.zeros((capacity, 3))
    out_offsets = np.zeros(capacity)
    t, o, f, closest_index, closest = tick_rows(
        own_path, own_vel, mates, ids, flying, d_max, ages, mate_offsets, own_offset, c[K_D_MAX_BASE],
        c[K_MATE_SPEED], c[K_MATE_GRACE], c[K_HALF_DEVIATION], c[K_COOPERATIVE_AGE], c[K_SEPARATION],
        centers, radii, heights, trunk_margin, c[K_CLEARANCE], c[K_OBSTACLE_WEIGHT], dt, own_id,
        c[K_STEP_BRAKE], c[K_BRAKE], c[K_BRAKE_CAP], c[K_REACH], c[K_FLOOR], c[K_FLOOR_WEIGHT], lag,
        out_steps, out_normals, out_offsets,
    )  # fmt: skip
    counted = t + o + f
    return (
        (mates, ids, flying, mate_offsets, d_max, ages),
        inputs,
        fault,
        target,
        (out_steps[:counted], out_normals[:counted], out_offsets[:counted]),
        (t, o, f, closest_index, closest),
    )

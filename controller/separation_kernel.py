"""The separation rows of separation.py as compiled kernels (numba).

`separation.teammate_rows` and `separation.obstacle_rows` are the readable numpy forms and the reference;
the kernels here build the same rows in one pass without numpy's per-call overhead (about 25 small array
operations per tick there, a quarter of a millisecond at 8 MAVs). They keep the reference's order of
operations, so the two agree to round-off (tests/controller/test_separation_kernel.py). Compiled code is
cached on disk (`cache=True`): only the first start compiles.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from controller.scalar_kernels import age_term_m, maximum, minimum


@numba.njit(cache=True)
def _room(closing: float, decel: float, cap: float) -> float:
    v = max(closing, 0.0)
    return min(v * v / (2.0 * decel), cap)


@numba.njit(cache=True)
def row_inflation(
    d_max, ages, d_max_base, speed, grace, half_deviation, out
):  # pragma: no cover - compiled; tested against the numpy form in tests/controller/test_separation_kernel.py
    """out (J,) = what each teammate's rows grow by: both covariance radii, d_max - d_max_base - r_comm
    (eq. 15, fields.teammate_age_term_m's r_comm = speed * max(age - grace, 0)), plus the age margin
    min(r_comm, half_deviation * age^2) (separation.age_margin_m); d_max, ages (J,). numpy's operations in
    numpy's order, its minimum and maximum included (`scalar_kernels`): the same bits as formation.py
    computed them with numpy."""
    for j in range(d_max.shape[0]):
        r_comm = age_term_m(ages[j], speed, grace)
        held = maximum(ages[j], 0.0)
        out[j] = ((d_max[j] - d_max_base) - r_comm) + minimum(r_comm, (half_deviation * held) * held)


@numba.njit(cache=True)
def teammate_rows_kernel(
    own_path,  # (S, 3)
    own_vel,  # (S, 3)
    mate_pos,  # (J, S, 3)
    mate_ids,  # (J,) int64
    coop,  # (J,) bool
    gap,  # (J,) m: separation_m + inflation
    dt,
    own_id,
    step_brake,
    brake,
    cap,
    reach,
    out_steps,  # (J * S,) int64
    out_normals,  # (J * S, 3)
    out_offsets,  # (J * S,)
    dist_out,  # (J, S)
):
    """Fill the rows of `separation.teammate_rows` into the out arrays; return how many."""
    n_mates, n_steps = mate_pos.shape[0], mate_pos.shape[1]
    last = n_steps - 1
    count = 0
    for j in range(n_mates):
        closest = math.inf
        for s in range(n_steps):
            dx = own_path[s, 0] - mate_pos[j, s, 0]
            dy = own_path[s, 1] - mate_pos[j, s, 1]
            dz = own_path[s, 2] - mate_pos[j, s, 2]
            d = math.sqrt(dx * dx + dy * dy + dz * dz)
            dist_out[j, s] = d
            closest = min(closest, d)
        if not closest < gap[j] + cap + reach:
            continue
        share = 0.5 if coop[j] else 1.0
        for s in range(1, n_steps):
            d = dist_out[j, s]
            if d > 1e-6:
                ax = (own_path[s, 0] - mate_pos[j, s, 0]) / max(d, 1e-12)
                ay = (own_path[s, 1] - mate_pos[j, s, 1]) / max(d, 1e-12)
                az = (own_path[s, 2] - mate_pos[j, s, 2]) / max(d, 1e-12)
            else:
                ax, ay, az = (1.0 if mate_ids[j] < own_id else -1.0), 0.0, 0.0
            if n_steps == 1:
                vx = vy = vz = 0.0
            elif s == last:
                vx = (mate_pos[j, s, 0] - mate_pos[j, s - 1, 0]) / dt
                vy = (mate_pos[j, s, 1] - mate_pos[j, s - 1, 1]) / dt
                vz = (mate_pos[j, s, 2] - mate_pos[j, s - 1, 2]) / dt
            else:
                vx = (mate_pos[j, s + 1, 0] - mate_pos[j, s - 1, 0]) / (2.0 * dt)
                vy = (mate_pos[j, s + 1, 1] - mate_pos[j, s - 1, 1]) / (2.0 * dt)
                vz = (mate_pos[j, s + 1, 2] - mate_pos[j, s - 1, 2]) / (2.0 * dt)
            closing = -(ax * (own_vel[s, 0] - vx) + ay * (own_vel[s, 1] - vy) + az * (own_vel[s, 2] - vz))
            if s == last:
                room = _room(share * closing, brake, cap)
            elif coop[j]:
                room = _room(share * closing, step_brake, cap)
            else:
                room = 0.0
            keep = (0.5 * (d + gap[j]) if coop[j] else gap[j]) + room
            if not keep - d > -reach:
                continue
            a_dot_m = ax * mate_pos[j, s, 0] + ay * mate_pos[j, s, 1] + az * mate_pos[j, s, 2]
            out_steps[count] = s
            out_normals[count, 0], out_normals[count, 1], out_normals[count, 2] = ax, ay, az
            out_offsets[count] = a_dot_m + keep
            count += 1
    return count


@numba.njit(cache=True)
def obstacle_rows_kernel(
    own_path,  # (S, 3)
    own_vel,  # (S, 3)
    centers,  # (M, 2)
    radii,  # (M,)
    heights,  # (M,)
    extra,  # m: obstacle_clearance_m + own covariance radius
    clearance,  # m: obstacle_clearance_m (the height band above a top)
    step_brake,
    brake,
    cap,
    reach,
    weight,
    out_steps,  # (M * S,) int64
    out_normals,  # (M * S, 3)
    out_offsets,  # (M * S,)
):
    """Fill the rows of `separation.obstacle_rows` into the out arrays, ordered as there; return how many."""
    last = own_path.shape[0] - 1
    count = 0
    for m in range(centers.shape[0]):
        base = radii[m] + extra
        for s in range(1, own_path.shape[0]):
            if not own_path[s, 2] < heights[m] + clearance:
                continue
            rx = own_path[s, 0] - centers[m, 0]
            ry = own_path[s, 1] - centers[m, 1]
            d = math.sqrt(rx * rx + ry * ry)
            if not d - base < reach + cap:  # out of reach whatever the braking room (at most cap)
                continue
            if d > 1e-6:
                nx, ny = rx / max(d, 1e-12), ry / max(d, 1e-12)
            else:
                nx, ny = 1.0, 0.0
            closing = -(nx * own_vel[s, 0] + ny * own_vel[s, 1])
            grown = base + _room(closing, brake if s == last else step_brake, cap)
            if not d - grown < reach:
                continue
            out_steps[count] = s
            out_normals[count, 0], out_normals[count, 1], out_normals[count, 2] = (
                weight * nx,
                weight * ny,
                0.0,
            )
            out_offsets[count] = weight * (nx * centers[m, 0] + ny * centers[m, 1] + grown)
            count += 1
    return count


@numba.njit(cache=True)
def floor_rows_kernel(own_path, floor, reach, weight, out_steps, out_normals, out_offsets):
    """Fill the rows of `separation.floor_rows` into the out arrays, ordered as there; return how many."""
    count = 0
    for s in range(1, own_path.shape[0]):
        height = own_path[s, 2]
        if height - floor < reach:
            out_steps[count] = s
            out_normals[count, 0], out_normals[count, 1], out_normals[count, 2] = 0.0, 0.0, weight
            out_offsets[count] = weight * min(floor, height)
            count += 1
    return count


@numba.njit(cache=True)
def closest_teammate(dist):
    """(index, distance) of the teammate whose plan comes closest over the horizon, dist (J, S); (-1, inf)
    for none. The first of equals, as numpy's argmin of the row minima."""
    best, index = math.inf, -1
    for j in range(dist.shape[0]):
        low = dist[j, 0]
        for s in range(1, dist.shape[1]):
            low = min(low, dist[j, s])
        if index < 0 or low < best:
            best, index = low, j
    return index, best


def empty_rows(capacity: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Out arrays for a kernel: steps (capacity,) int64, normals (capacity, 3), offsets (capacity,)."""
    return np.zeros(capacity, dtype=np.int64), np.zeros((capacity, 3)), np.zeros(capacity)


@numba.njit(cache=True)
def tick_rows(
    own_path,  # (S, 3)
    own_vel,  # (S, 3)
    mate_pos,  # (J, S, 3) as the teammates' table gives them (not yet placed by the GPS offsets)
    mate_ids,  # (J,) int64
    mate_in_formation,  # (J,) bool
    mate_d_max,  # (J,) m, eq. 15
    mate_ages,  # (J,) s
    mate_offsets,  # (J, 3) m, each sender's GPS offset
    own_offset,  # (3,) m, ours
    d_max_base,
    speed,
    grace,
    half_deviation,
    cooperative_age,
    separation,
    centers,  # (M, 2)
    radii,  # (M,)
    heights,  # (M,)
    trunk_margin,
    clearance,
    obstacle_weight,
    dt,
    own_id,
    step_brake,
    brake,
    cap,
    reach,
    floor,  # m: the arena's floor
    floor_weight,
    lag,  # (3,) m
    out_steps,  # ((J + M + 1) S,) int64
    out_normals,  # ((J + M + 1) S, 3)
    out_offsets,  # ((J + M + 1) S,)
):  # pragma: no cover - compiled; tested against what it replaces
    """One tick's separation rows in one call: what formation.py composed from `row_inflation`,
    `TeammatePaths.placed_by`, `teammate_rows_kernel`, `obstacle_rows_kernel`, `floor_rows_kernel`,
    `closest_teammate` and the trunk rows' lag, in their order and with their operations (the lag by np.dot,
    the BLAS product numpy's @ made): the same bits. Returns (teammate rows, trunk rows, floor rows, closest
    teammate's index, its distance (m))."""
    count = mate_pos.shape[0]
    steps = own_path.shape[0]
    inflation = np.empty(count)
    row_inflation(mate_d_max, mate_ages, d_max_base, speed, grace, half_deviation, inflation)
    gap = np.empty(count)
    coop = np.empty(count, dtype=np.bool_)
    for j in range(count):
        gap[j] = separation + inflation[j]
        coop[j] = mate_in_formation[j] and mate_ages[j] <= cooperative_age
    # placed_by: both GPS offsets taken out, only when one of them is not zero (x + 0.0 turns -0.0 into 0.0)
    shift = np.empty((count, 3))
    moved = False
    for j in range(count):
        for i in range(3):
            shift[j, i] = own_offset[i] - mate_offsets[j, i]
            moved = moved or shift[j, i] != 0.0
    placed = mate_pos
    if moved:
        placed = np.empty_like(mate_pos)
        for j in range(count):
            for s in range(mate_pos.shape[1]):
                for i in range(3):
                    placed[j, s, i] = mate_pos[j, s, i] + shift[j, i]
    dist = np.empty((count, steps))
    t = teammate_rows_kernel(
        own_path, own_vel, placed, mate_ids, coop, gap, dt, own_id, step_brake, brake, cap, reach,
        out_steps, out_normals, out_offsets, dist,
    )  # fmt: skip
    o = obstacle_rows_kernel(
        own_path, own_vel, centers, radii, heights, trunk_margin, clearance, step_brake, brake, cap, reach,
        obstacle_weight, out_steps[t:], out_normals[t:], out_offsets[t:],
    )  # fmt: skip
    n = t + o
    f = floor_rows_kernel(
        own_path, floor, reach, floor_weight, out_steps[n:], out_normals[n:], out_offsets[n:]
    )
    if o:
        towards = np.dot(out_normals[t : t + o], lag)
        for r in range(o):
            out_offsets[t + r] = out_offsets[t + r] + maximum(-towards[r], 0.0)
    index, closest = closest_teammate(dist)
    return t, o, f, index, closest

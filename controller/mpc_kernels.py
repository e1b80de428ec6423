"""The MPC's per-solve arithmetic as compiled kernels (numba): the condensed QP's vectors, the rollout, and
the half-planes' rows.

`mpc.py` keeps the readable numpy form of each (`ModelPredictiveController._solve_vectors`, `predict`,
`_half_plane_rows`); these compute the same numbers in one pass each without numpy's per-call overhead, and
tests/controller/test_mpc.py checks them against it. Compiled code is cached on disk (`cache=True`): only the
first start compiles.
"""

from __future__ import annotations

import numba
import numpy as np

from controller.dual_active_set import OPTIMAL
from controller.qp import closed_form_kernel, compiled_step_3

# solve_fast's verdicts
CLOSED_FORM = 0  # the closed form is the optimum; the plan is written
NEEDS_SOLVER = 1  # a row or a resting gradient fails: q, lo, hi, z, rows, gradient are written for ExactQp
INVALID = 2  # an argument is not finite or beyond `plausible`: nothing is written

# solve_with_planes' paths
PLANES_CLOSED_FORM = 0  # the closed form meets every half-plane row after all (to the rows' tolerance)
PLANES_ACTIVE_SET = 1  # the compiled active set solved the QP with the half-plane rows
PLANES_UNSOLVED = 2  # it did not end optimal: the caller hands the rows to ExactQp.finish (DAQP decides)


@numba.njit(cache=True)
def input_box(
    f: np.ndarray,
    input_min: np.ndarray,
    input_max: np.ndarray,
    plan_min: np.ndarray,
    plan_max: np.ndarray,
    bound_plan: bool,
    box_lo: np.ndarray,
    box_hi: np.ndarray,
) -> None:  # pragma: no cover - compiled; tested through ModelPredictiveController
    """Write each step's input box (M, 3) into box_lo, box_hi: mpc.input_box's numbers (see there)."""
    for n in range(f.shape[0]):
        for a in range(3):
            lo, hi = input_min[a], input_max[a]
            if bound_plan:
                low, high = plan_min[a] - f[n, a], plan_max[a] - f[n, a]
                lo, hi = min(max(lo, low), high), min(max(hi, low), high)
            box_lo[n, a], box_hi[n, a] = lo, hi


@numba.njit(cache=True)
def _six_rows_times(matrix, r, vector, count, s0, s1, s2, s3, s4, s5):  # pragma: no cover - compiled
    """The sums s0..s5 of rows r..r+5 of matrix, each continued over its first `count` entries times vector,
    in order; the six sums side by side so that their additions overlap."""
    for j in range(count):
        x = vector[j]
        s0 += matrix[r, j] * x
        s1 += matrix[r + 1, j] * x
        s2 += matrix[r + 2, j] * x
        s3 += matrix[r + 3, j] * x
        s4 += matrix[r + 4, j] * x
        s5 += matrix[r + 5, j] * x
    return s0, s1, s2, s3, s4, s5


@numba.njit(cache=True)
def condensed_vectors(
    free_x0: np.ndarray,
    input_to_state: np.ndarray,
    q_terminal: np.ndarray,
    l_template: np.ndarray,
    u_template: np.ndarray,
    x0: np.ndarray,
    reference: np.ndarray,
    f: np.ndarray,
    gravity: np.ndarray,
    effort: int,
    input_weight: float,
    slack_weight: float,
    box_lo: np.ndarray,
    box_hi: np.ndarray,
    q: np.ndarray,
    lo: np.ndarray,
    hi: np.ndarray,
) -> None:  # pragma: no cover - compiled; tested through ModelPredictiveController
    """Write q (n,), lo, hi (rows,) of the condensed QP (see mpc.py's module docstring).

    free_x0 (6M, 6), input_to_state (6M, 3M), q_terminal (3M, 6) = 2 G_N^T W; templates (rows,) hold the
    input rows (3M, overwritten by each step's box box_lo, box_hi (M, 3)), then the state upper rows (6M),
    the state lower rows (6M) and the slack rows; x0, reference (6,), f (M, 3), gravity (3,); effort 0 =
    hover (u + g), 1 = planned (u + f + g), 2 = raw (u).
    """
    m = f.shape[0]
    nu = 3 * m
    ns = 6 * m
    acc = np.empty(nu)
    for n in range(m):
        for a in range(3):
            acc[3 * n + a] = f[n, a] + gravity[a]
    lo[:] = l_template
    hi[:] = u_template
    for n in range(m):
        for a in range(3):
            lo[3 * n + a], hi[3 * n + a] = box_lo[n, a], box_hi[n, a]
    terminal = np.empty(6)
    free = np.empty(6)
    for step in range(m):
        # The six state rows of a step are summed side by side, each in its own order (free_x0 x0, then
        # input_to_state acc), so that their additions overlap: the same bits as one row after the other.
        # input_to_state is block lower triangular in steps: the rows of step k only see inputs of steps < k+1
        r = 6 * step
        last = 3 * (step + 1)
        sums = _six_rows_times(free_x0, r, x0, 6, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
        free[0], free[1], free[2], free[3], free[4], free[5] = _six_rows_times(
            input_to_state, r, acc, last, *sums
        )
        for i in range(6):
            hi[nu + r + i] -= free[i]
            lo[nu + ns + r + i] -= free[i]
            if step == m - 1:
                terminal[i] = free[i] - reference[i]
    for i in range(nu):
        if effort == 0:
            offset = gravity[i % 3]
        elif effort == 1:
            offset = acc[i]
        else:
            offset = 0.0
        s = 2.0 * input_weight * offset
        for j in range(6):
            s += q_terminal[i, j] * terminal[j]
        q[i] = s
    for i in range(nu, q.shape[0]):
        q[i] = slack_weight


@numba.njit(cache=True)
def rollout(
    position: np.ndarray,
    velocity: np.ndarray,
    inputs: np.ndarray,
    f: np.ndarray,
    gravity: np.ndarray,
    dt: float,
    box_lo: np.ndarray,
    box_hi: np.ndarray,
    state_min: np.ndarray,
    state_max: np.ndarray,
    clipped: np.ndarray,
    positions: np.ndarray,
    velocities: np.ndarray,
) -> float:  # pragma: no cover - compiled; tested through ModelPredictiveController
    """Clip inputs (M, 3) into each step's box box_lo, box_hi (M, 3) (into `clipped`), roll the double
    integrator (eq. 6) forward from position, velocity (3,) into positions, velocities (M+1, 3), and return
    the largest state-bound excursion (m or m/s; NaN when something is not finite). Same arithmetic order as
    mpc.predict."""
    m = inputs.shape[0]
    half = 0.5 * dt * dt
    worst = -np.inf
    for a in range(3):
        p0 = position[a]
        v0 = velocity[a]
        positions[0, a] = p0
        velocities[0, a] = v0
        v = v0
        acc_sum = 0.0
        step_sum = 0.0
        for n in range(m):
            u = min(max(inputs[n, a], box_lo[n, a]), box_hi[n, a])
            clipped[n, a] = u
            acc = (u + f[n, a]) + gravity[a]
            step_sum += dt * v + half * acc
            acc_sum += acc
            p = p0 + step_sum
            v = v0 + dt * acc_sum
            positions[n + 1, a] = p
            velocities[n + 1, a] = v
            excess = max(p - state_max[a], state_min[a] - p, v - state_max[3 + a], state_min[3 + a] - v)
            if not (excess == excess):
                return np.nan
            worst = max(worst, excess)
    return worst


@numba.njit(cache=True)
def roll_out_variables(
    z, position, velocity, f, gravity, dt, box_lo, box_hi, state_min, state_max, inputs, positions, velocities
):  # pragma: no cover - compiled; tested through ModelPredictiveController
    """`rollout` of the inputs among the QP's variables z (the first 3(N+1), step by step): the plan of a
    solution, whichever step found it."""
    m = f.shape[0]
    return rollout(
        position,
        velocity,
        z[: 3 * m].reshape((m, 3)),
        f,
        gravity,
        dt,
        box_lo,
        box_hi,
        state_min,
        state_max,
        inputs,
        positions,
        velocities,
    )


@numba.njit(cache=True)
def solve_fast(
    free_x0,
    input_to_state,
    q_terminal,
    l_template,
    u_template,
    position,
    velocity,
    target_position,
    target_velocity,
    f,
    gravity,
    effort,
    input_weight,
    slack_weight,
    plausible,
    qp_data,
    dt,
    input_min,
    input_max,
    plan_min,
    plan_max,
    bound_plan,
    state_min,
    state_max,
    box_lo,
    box_hi,
    q,
    lo,
    hi,
    z,
    rows,
    gradient,
    inputs,
    positions,
    velocities,
):  # pragma: no cover - compiled; tested through ModelPredictiveController
    """One MPC solve's arithmetic in one call: check the arguments, write each step's input box into box_lo,
    box_hi (`input_box`), build q, lo, hi (`condensed_vectors`),
    run ExactQp's step 1 (`closed_form_kernel`, qp_data = ExactQp.kernel_data) and, when it is the optimum,
    roll the plan out (`rollout`). Returns (verdict, largest state-bound excursion)."""
    for arr in (position, velocity, target_position, target_velocity):
        for i in range(3):
            if not abs(arr[i]) <= plausible:
                return INVALID, 0.0
    for n in range(f.shape[0]):
        for i in range(3):
            if not abs(f[n, i]) <= plausible:
                return INVALID, 0.0
    x0 = np.empty(6)
    reference = np.empty(6)
    for i in range(3):
        x0[i], x0[3 + i] = position[i], velocity[i]
        reference[i], reference[3 + i] = target_position[i], target_velocity[i]
    input_box(f, input_min, input_max, plan_min, plan_max, bound_plan, box_lo, box_hi)
    condensed_vectors(
        free_x0,
        input_to_state,
        q_terminal,
        l_template,
        u_template,
        x0,
        reference,
        f,
        gravity,
        effort,
        input_weight,
        slack_weight,
        box_lo,
        box_hi,
        q,
        lo,
        hi,
    )
    gain, a, rest_idx, p_rest, tol, opt_tol = qp_data
    if not closed_form_kernel(gain, a, rest_idx, p_rest, tol, opt_tol, q, lo, hi, z, rows, gradient):
        return NEEDS_SOLVER, 0.0
    violation = roll_out_variables(
        z,
        position,
        velocity,
        f,
        gravity,
        dt,
        box_lo,
        box_hi,
        state_min,
        state_max,
        inputs,
        positions,
        velocities,
    )
    return CLOSED_FORM, violation


@numba.njit(cache=True)
def half_plane_rows(
    input_to_state: np.ndarray,
    free: np.ndarray,
    steps: np.ndarray,
    normals: np.ndarray,
    offsets: np.ndarray,
    soft: np.ndarray,
    rows: np.ndarray,
    lower: np.ndarray,
) -> None:  # pragma: no cover - compiled; tested against ModelPredictiveController._half_plane_rows
    """Write the half-planes' rows (R, n) and lower bounds (R,) of the exact QP, as `_half_plane_rows`: row r
    is a^T G_p(n) on the inputs and soft_r on step n's slack (one of the last N+1 columns), its bound
    b - a^T h_p(n); input_to_state (6(N+1), 3(N+1)), free (6(N+1),) the free response, steps (R,) in 1..N+1,
    normals (R, 3). rows must be zero beyond the inputs and the slacks' columns. Same order of operations as
    the numpy form: same bits."""
    nu = input_to_state.shape[1]
    slack0 = rows.shape[1] - nu // 3 - 1  # the column of the slack of step n is slack0 + n
    for r in range(steps.shape[0]):
        first = 6 * (steps[r] - 1)
        ax, ay, az = normals[r, 0], normals[r, 1], normals[r, 2]
        for j in range(nu):
            rows[r, j] = (
                ax * input_to_state[first, j] + ay * input_to_state[first + 1, j]
            ) + az * input_to_state[first + 2, j]
        rows[r, slack0 + steps[r]] = soft[r]
        lower[r] = offsets[r] - ((ax * free[first] + ay * free[first + 1]) + az * free[first + 2])


@numba.njit(cache=True)
def checked_planes(
    steps: np.ndarray,
    normals_xy: np.ndarray,
    normals_z: np.ndarray | None,
    soft: np.ndarray | None,
    last_step: int,
    normals: np.ndarray,
    weights: np.ndarray,
) -> bool:  # pragma: no cover - compiled; tested through ModelPredictiveController.solve
    """Whether every step (R,) lies in 1..last_step; and write normals (R, 3) from normals_xy (R, 2) and
    normals_z (R,) (None: 0) and weights (R,) 1.0 / 0.0 from soft (R,) bool (None: all 1.0), in one pass over
    the rows instead of half a dozen numpy calls (mpc.py `_checked_half_planes` checks the shapes)."""
    for r in range(steps.shape[0]):
        if not 1 <= steps[r] <= last_step:
            return False
        normals[r, 0] = normals_xy[r, 0]
        normals[r, 1] = normals_xy[r, 1]
        normals[r, 2] = 0.0 if normals_z is None else normals_z[r]
        weights[r] = 1.0 if soft is None or soft[r] else 0.0
    return True


@numba.njit(cache=True)
def plane_shortfall(
    steps: np.ndarray, normals: np.ndarray, offsets: np.ndarray, positions: np.ndarray
) -> float:  # pragma: no cover - compiled; tested against the numpy form in tests/controller/test_mpc.py
    """Largest shortfall b - a^T p(n) (m; <= 0 when every half-plane holds) of a plan's positions (N+2, 3)
    from half-planes with steps (R,) in 1..N+1, normals (R, 3) and offsets (R,); NaN when a normal or an
    offset is not finite, -inf for no rows. The closed form's check of the half-planes: when its plan meets
    them, no row of them need be built (docs/fast-core.md#extra-constraints-half-planes)."""
    worst = -np.inf
    for r in range(steps.shape[0]):
        p = positions[steps[r]]
        ax, ay, az, b = normals[r, 0], normals[r, 1], normals[r, 2], offsets[r]
        if not (abs(ax) < np.inf and abs(ay) < np.inf and abs(az) < np.inf and abs(b) < np.inf):
            return np.nan
        worst = max(worst, b - ((ax * p[0] + ay * p[1]) + az * p[2]))
    return worst


@numba.njit(cache=True)
def solve_with_planes(
    input_to_state,
    free_x0,
    steps,
    normals,
    offsets,
    soft,
    active_set,
    q,
    lo,
    hi,
    z,
    position,
    velocity,
    f,
    gravity,
    dt,
    box_lo,
    box_hi,
    state_min,
    state_max,
    extra,
    lower,
    inputs,
    positions,
    velocities,
):  # pragma: no cover - compiled; tested against ExactQp.finish's path through ModelPredictiveController
    """ExactQp.finish for the solve where only half-plane rows failed the closed form z (n,) (its fixed rows
    all held, so step 2 has nothing to re-solve): write the rows into extra (R, n), zero beyond the inputs
    and slacks, and their bounds into lower (R,) (`half_plane_rows` on the free response from x(0) =
    (position, velocity) by free_x0 (6(N+1), 6) and input_to_state); keep z when no row misses by more than
    the rows' tolerance, else solve the whole problem by the compiled active set (active_set =
    ExactQp.compiled_active_set); roll the plan out (`rollout`). Returns (path, iterations, largest
    state-bound excursion, largest half-plane shortfall); PLANES_UNSOLVED writes no plan.

    The same decisions and the same bits as mpc.py's path through ExactQp.finish: every product that numpy
    hands to BLAS there (the free response, the rows' values at z) is numba's np.dot here, which calls BLAS
    too (docs/fast-core.md, "Bits in compiled code")."""
    x0 = np.empty(6)
    x0[:3], x0[3:] = position, velocity
    free = np.dot(free_x0, x0) + np.dot(input_to_state, (f + gravity).ravel())
    half_plane_rows(input_to_state, free, steps, normals, offsets, soft, extra, lower)
    tol = active_set[6]
    count = steps.shape[0]
    values = np.dot(extra, z)
    missed = False
    for r in range(count):
        if values[r] < lower[r] - tol:
            missed = True
            break
    path, iterations = PLANES_CLOSED_FORM, 0
    x = z
    if missed:
        m0 = lo.shape[0]
        lo_all = np.empty(m0 + count)
        hi_all = np.empty(m0 + count)
        lo_all[:m0], hi_all[:m0] = lo, hi
        lo_all[m0:], hi_all[m0:] = lower, np.inf
        flag, iterations, x = compiled_step_3(active_set, q, extra, lo_all, hi_all)
        if flag != OPTIMAL:
            return PLANES_UNSOLVED, iterations, 0.0, 0.0
        path = PLANES_ACTIVE_SET
    violation = roll_out_variables(
        x,
        position,
        velocity,
        f,
        gravity,
        dt,
        box_lo,
        box_hi,
        state_min,
        state_max,
        inputs,
        positions,
        velocities,
    )
    return path, iterations, violation, plane_shortfall(steps, normals, offsets, positions)

"""The convex MPC of one MAV (paper Sec. III-D: cost `J_ACT` eq. (4), problem eq. (5), dynamics eq. (6), state
and input bounds eqs. (7)-(8), A and B eq. (9); numbered in the order of the RA-L text), solved with OSQP.

The QP, with x(n) = [position, velocity] (6,) in ENU and W_E = input_weight * I3:

    minimise   sum_{n=0..N} (u(n) + c(n))^T W_E (u(n) + c(n))                   (effort, eq. 4)
             + (p(N+1) - p_ref)^T W_p (p(N+1) - p_ref)
             + (v(N+1) - v_ref)^T W_v (v(N+1) - v_ref)                            (terminal, eq. 4)
             + slack_weight * sum(s) + slack_quadratic_weight * s^T s              (soft state bounds)
    s.t.       x(n+1) = A x(n) + B (u(n) + f(n) + g),  n = 0..N                  (eq. 6)
               x_min - s <= x(n) <= x_max + s,  n = 1..N+1,  s >= 0                 (eq. 7, softened)
               u_min <= u(n) <= u_max                                            (eq. 8, hard)
               a_min <= u(n) + f(n) <= a_max          (the plan's acceleration; `input_box`, hard)

with c(n) = g ("hover"), f(n) + g ("planned") or 0 ("raw"). The second box is skyring's: the paper bounds u
alone, so a strong field made plans brake or swerve faster than any vehicle can (docs/safety.md, "Plans the
vehicle can fly"); MpcParams.plan_acceleration_*_mps2 = None restores the paper's bound.

Condensed form: the variables are z = [u(0..N) (N+1, 3) | s (6,)] and the states are affine in them,
x(1..N+1) = h + G u, with h the free response to x(0) and f + g (`predict` with u = 0) and G the
(6(N+1), 3(N+1)) input-to-state matrix; chosen over the sparse form because ADMM converged faster and more
reliably on it (docs/method.md#condensed-form). State bounds are soft, with one slack per state component
shared over the horizon and an exact penalty, because a strong external input can make them infeasible
(docs/method.md#soft-state-bounds, docs/method.md#infeasible-qps).

Solvers (MpcParams.solver): "exact" (the default) is controller/qp.py: the unconstrained optimum in closed
form whenever it provably solves the QP (almost every tick of a formation flight), otherwise the exact answer
of a dense dual active-set solver (compiled, controller/dual_active_set.py, or DAQP: `MpcParams.active_set`).
"osqp" is the OSQP set-up, kept as the reference the exact path is tested against (docs/fast-core.md has the
measurements).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import osqp
import scipy.sparse as sp

from controller.kernel_args import kernel_array
from controller.mpc_kernels import (
    CLOSED_FORM,
    INVALID,
    NEEDS_SOLVER,
    PLANES_ACTIVE_SET,
    PLANES_UNSOLVED,
    checked_planes,
    half_plane_rows,
    plane_shortfall,
    roll_out_variables,
    solve_fast,
    solve_with_planes,
)
from controller.qp import ACTIVE_SET_SOLVERS, ExactQp

EFFORT_MODES = ("hover", "planned", "raw")
SOLVERS = ("exact", "osqp")
ACCEPTED_STATUSES = ("solved", "solved inaccurate")
# Any argument beyond this (m, m/s, m/s^2, or weight) is rejected: it is far outside any flight, and the
# solver's data would leave OSQP's range (it takes 1e30 as infinity and silently ignores invalid updates).
PLAUSIBLE_MAGNITUDE = 1.0e6


@dataclass(frozen=True)
class MpcParams:
    """MPC horizon, bounds and weights (docs/method.md#the-mpc). ENU, z up.

    horizon_steps: N (inputs u(0..N), states x(1..N+1)); dt_s: step length.
    Bounds are per axis (x, y, z). input_*_mps2 bound the commanded acceleration u *before* gravity is added
    (hover is u_z = gravity_mps2). Position and velocity bounds are soft (slack with an exact penalty).
    effort: what the input-effort term penalises: "hover" = u + g (skyring's default, hover costs nothing),
    "planned" = u + f + g (the authors' code), "raw" = u (the paper as written).
    slack_weight: linear penalty per m (or m/s) of the largest violation of each state component's bounds;
    slack_quadratic_weight: its quadratic companion (per m^2), there for the solver's convergence.

    solver: "exact" (closed form when provably optimal, else an active-set solver; controller/qp.py) or "osqp"
    (the reference). eps_abs / eps_rel are OSQP's termination tolerances, max_iterations its (and the active
    set's) iteration cap, polishing its active-set refinement. accept_inaccurate: count OSQP's "solved
    inaccurate" (the iteration cap was hit with the residuals within OSQP's loosened tolerances) as ok: the
    plan is re-rolled through the exact dynamics with inputs clipped into their box, so it is consistent
    and admissible, only less optimal, which beats braking. Every other status (infeasible, cap hit far from a
    solution, non-convex) is a failure.
    active_set: the exact solver's active-set step, "compiled" (the default: one compiled dual active-set
    solve) or "daqp" (DAQP on a working set of rows); controller/qp.py, docs/fast-core.md says how they
    compare.
    violation_tolerance: bound excursions up to this (m or m/s) are solver round-off and reported as 0.
    plan_acceleration_min_mps2, plan_acceleration_max_mps2: bounds per axis on u(n) + f(n) (before gravity,
    like the input box), the acceleration the plan asks of the vehicle with the fields included
    (`input_box`); None for both is the paper as written (u alone is bounded).
    half_plane_weight, half_plane_quadratic_weight: the exact penalty per m of each plan step's largest
    violation of the soft half-planes a solve may be given (`HalfPlanes`), and its quadratic companion; far
    above slack_weight, so a half-plane gives way only when it cannot hold.
    """

    horizon_steps: int = 15
    dt_s: float = 0.1
    position_min_m: tuple[float, float, float] = (-20.0, -20.0, 3.0)
    position_max_m: tuple[float, float, float] = (20.0, 20.0, 10.0)
    velocity_min_mps: tuple[float, float, float] = (-5.0, -5.0, -0.5)
    velocity_max_mps: tuple[float, float, float] = (5.0, 5.0, 0.5)
    input_min_mps2: tuple[float, float, float] = (-3.0, -3.0, 3.0)
    input_max_mps2: tuple[float, float, float] = (3.0, 3.0, 11.0)
    gravity_mps2: float = 9.81
    input_weight: float = 10.0
    terminal_position_weight: float = 100.0
    terminal_velocity_weight: float = 100.0
    effort: str = "hover"
    solver: str = "exact"
    active_set: str = "compiled"
    slack_weight: float = 1.0e4
    slack_quadratic_weight: float = 5.0e3
    eps_abs: float = 1.0e-5
    eps_rel: float = 1.0e-5
    max_iterations: int = 4000
    polishing: bool = True
    accept_inaccurate: bool = True
    violation_tolerance: float = 1.0e-4
    half_plane_weight: float = 1.0e5
    half_plane_quadratic_weight: float = 1.0e3
    plan_acceleration_min_mps2: tuple[float, float, float] | None = (-3.0, -3.0, 3.0)
    plan_acceleration_max_mps2: tuple[float, float, float] | None = (3.0, 3.0, 11.0)

    def __post_init__(self) -> None:
        if self.horizon_steps < 1:
            raise ValueError(f"horizon_steps must be >= 1, got {self.horizon_steps}")
        if not (np.isfinite(self.dt_s) and self.dt_s > 0):
            raise ValueError(f"dt_s must be a positive number of seconds, got {self.dt_s}")
        if self.effort not in EFFORT_MODES:
            raise ValueError(f"effort must be one of {EFFORT_MODES}, got {self.effort!r}")
        if self.solver not in SOLVERS:
            raise ValueError(f"solver must be one of {SOLVERS}, got {self.solver!r}")
        if self.active_set not in ACTIVE_SET_SOLVERS:
            raise ValueError(f"active_set must be one of {ACTIVE_SET_SOLVERS}, got {self.active_set!r}")
        bounds = [
            ("position", self.position_min_m, self.position_max_m),
            ("velocity", self.velocity_min_mps, self.velocity_max_mps),
            ("input", self.input_min_mps2, self.input_max_mps2),
        ]
        if (self.plan_acceleration_min_mps2 is None) != (self.plan_acceleration_max_mps2 is None):
            raise ValueError("plan_acceleration_min_mps2 and plan_acceleration_max_mps2: both or neither")
        plan_min, plan_max = self.plan_acceleration_min_mps2, self.plan_acceleration_max_mps2
        if plan_min is not None and plan_max is not None:
            bounds.append(("plan acceleration", plan_min, plan_max))
        for name, lo, hi in bounds:
            lo_a, hi_a = np.asarray(lo, dtype=float), np.asarray(hi, dtype=float)
            if lo_a.shape != (3,) or hi_a.shape != (3,) or not np.all(np.isfinite(lo_a) & np.isfinite(hi_a)):
                raise ValueError(f"{name} bounds must be 3 finite numbers each")
            if np.any(lo_a > hi_a):
                raise ValueError(f"{name} bounds: min {tuple(lo)} exceeds max {tuple(hi)}")
        if not (np.isfinite(self.input_weight) and self.input_weight > 0):
            raise ValueError(f"input_weight must be positive, got {self.input_weight}")
        for name in ("terminal_position_weight", "terminal_velocity_weight", "slack_quadratic_weight"):
            if not (np.isfinite(getattr(self, name)) and getattr(self, name) >= 0):
                raise ValueError(f"{name} must be a finite number >= 0, got {getattr(self, name)}")
        if not (np.isfinite(self.slack_weight) and self.slack_weight > 0):
            raise ValueError(f"slack_weight must be positive, got {self.slack_weight}")
        if not (np.isfinite(self.half_plane_weight) and self.half_plane_weight > 0):
            raise ValueError(f"half_plane_weight must be positive, got {self.half_plane_weight}")
        if not (np.isfinite(self.half_plane_quadratic_weight) and self.half_plane_quadratic_weight > 0):
            raise ValueError(
                f"half_plane_quadratic_weight must be > 0, got {self.half_plane_quadratic_weight}"
            )

    @property
    def gravity_vector_mps2(self) -> np.ndarray:
        """(3,) g = (0, 0, -gravity) in ENU."""
        return np.array([0.0, 0.0, -self.gravity_mps2])


@dataclass(frozen=True, eq=False)
class HalfPlanes:
    """Linear constraints on the plan's positions, one per row r:
    normals_xy[r] . p(steps[r])[:2] + normals_z[r] * p(steps[r])[2] >= offsets[r], with steps (R,) int in
    1..N+1, normals_xy (R, 2), normals_z (R,) or None (= 0: a vertical plane, the usual case), offsets (R,) m.
    A generic hook for constraints built outside the MPC (e.g. separation half-planes); they enter the QP as
    extra rows on the condensed inputs (docs/fast-core.md#extra-constraints-half-planes).

    soft: (R,) bool, None = every row soft. The soft rows of plan step n share one slack w(n) >= 0 with an
    exact penalty (MpcParams.half_plane_weight): a^T x(n) + w(n) >= b, so they never make the QP infeasible
    and hold exactly whenever they all can. Shared within a step, the rows of that step give way evenly (no
    teammate's is traded for another's); one per step, a step whose rows cannot hold lets no other step's give
    way (docs/safety.md, "One slack per plan step"). Hard rows have no slack: if they cannot hold the solve
    fails (ok=False, status "infeasible") and the caller brakes or escapes."""

    steps: np.ndarray
    normals_xy: np.ndarray
    offsets: np.ndarray
    soft: np.ndarray | None = None
    normals_z: np.ndarray | None = None

    @property
    def z_normals(self) -> np.ndarray:
        """(R,) normals_z, zeros where it is None (vertical planes)."""
        return np.zeros(len(self.steps)) if self.normals_z is None else np.asarray(self.normals_z, float)


# The checked half-planes: steps (R,) int64, normals (R, 3), offsets (R,) m, soft (R,) 1.0 / 0.0.
Planes = tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]


def _plane_violation(planes: Planes, positions: np.ndarray) -> float:
    """Largest shortfall (m, >= 0) of the plan's positions (N+2, 3) from the half-planes."""
    steps, normals, offsets, _ = planes
    return max(0.0, float((offsets - np.einsum("ri,ri->r", normals, positions[steps])).max()))


def _shortfall(planes: Planes, positions: np.ndarray) -> float:
    """`_plane_violation` by the compiled kernel, unclipped: <= 0 when every half-plane holds, NaN when one
    is not finite (mpc_kernels.plane_shortfall)."""
    steps, normals, offsets, _ = planes
    return plane_shortfall(steps, normals, offsets, positions)


@dataclass(frozen=True, eq=False)
class MpcSolution:
    """One MPC solve (N = horizon_steps). When not ok, the arrays are NaN: apply `braking_plan` instead."""

    ok: bool  # True only if the solver solved and every number is finite
    status: str  # the solver's status string ("solved" ...), or "invalid_input"
    message: str | None  # one line when not ok
    inputs_mps2: np.ndarray  # (N+1, 3) u(0..N), ENU, before gravity is added (hover: u_z = g)
    positions_m: np.ndarray  # (N+2, 3) x(0..N+1); x(0) = the given position
    velocities_mps: np.ndarray  # (N+2, 3)
    max_state_violation: float  # largest slack (m or m/s); 0 when no soft bound is active
    iterations: int  # solver iterations (0: the exact solver's closed form)
    solve_time_s: float  # the solver's own reported run time (OSQP: update, iterations, polish; exact: DAQP's
    # time, 0 for the closed form, which takes microseconds and is not timed: the controller reads no clock)
    half_plane_violation_m: float = 0.0  # largest violation of the given half-planes by the plan (m)
    path: str = "osqp"  # which solver produced it: "osqp", or the exact solver's "closed_form", "blocks",
    # "active_set" (controller/qp.py)


def predict(
    *,
    position_m: np.ndarray,
    velocity_mps: np.ndarray,
    inputs_mps2: np.ndarray,
    external_inputs_mps2: np.ndarray,
    params: MpcParams,
) -> tuple[np.ndarray, np.ndarray]:
    """Roll the double integrator forward (eq. 6): x(n+1) = A x(n) + B (u(n) + f(n) + g).

    position_m, velocity_mps: (3,) x(0); inputs_mps2, external_inputs_mps2: (M, 3) u(0..M-1), f(0..M-1).
    Returns (M+1, 3) positions and (M+1, 3) velocities, row 0 being x(0).
    """
    u = np.asarray(inputs_mps2, dtype=float)
    f = np.asarray(external_inputs_mps2, dtype=float)
    if u.ndim != 2 or u.shape[1] != 3 or f.shape != u.shape:
        raise ValueError(f"inputs and external inputs must both be (M, 3), got {u.shape} and {f.shape}")
    dt = params.dt_s
    acc = u + f + params.gravity_vector_mps2
    p0 = np.asarray(position_m, dtype=float).reshape(3)
    v0 = np.asarray(velocity_mps, dtype=float).reshape(3)
    velocities = np.vstack([v0, v0 + dt * np.cumsum(acc, axis=0)])
    steps = dt * velocities[:-1] + (0.5 * dt * dt) * acc
    positions = np.vstack([p0, p0 + np.cumsum(steps, axis=0)])
    return positions, velocities


def input_box(external_inputs_mps2: np.ndarray, params: MpcParams) -> tuple[np.ndarray, np.ndarray]:
    """(M, 3) lower and upper bounds of u(0..M-1) under the external inputs f (M, 3) (m/s^2, before gravity).

    With the plan's acceleration bounded (params.plan_acceleration_*_mps2 = a_min, a_max), the input box
    [u_min, u_max] intersected with [a_min - f(n), a_max - f(n)], so that u(n) + f(n) stays in [a_min, a_max];
    where the two are disjoint (a field stronger than the boxes allow for), the single u of the second
    nearest to the first: the plan then moves with the field at a_min or a_max, as far as a vehicle can.
    Without it, the input box.
    """
    f = np.asarray(external_inputs_mps2, dtype=float)
    lo = np.broadcast_to(np.asarray(params.input_min_mps2, dtype=float), f.shape)
    hi = np.broadcast_to(np.asarray(params.input_max_mps2, dtype=float), f.shape)
    if params.plan_acceleration_min_mps2 is None or params.plan_acceleration_max_mps2 is None:
        return lo.copy(), hi.copy()
    low = np.asarray(params.plan_acceleration_min_mps2, dtype=float) - f
    high = np.asarray(params.plan_acceleration_max_mps2, dtype=float) - f
    return np.clip(lo, low, high), np.clip(hi, low, high)


def braking_plan(
    *, position_m: np.ndarray, velocity_mps: np.ndarray, params: MpcParams
) -> tuple[np.ndarray, np.ndarray]:
    """(N+2,3) positions and velocities of a plan that decelerates at the input bound to rest and holds (the
    fallback when the solver fails); finite for finite input; position clipped into the position bounds.

    Each axis takes the net acceleration -v/dt (rest within one step) clipped to what the input box allows
    once gravity is added, so it brakes at the bound until the last step, then holds. External inputs are
    ignored; nothing raises (non-finite input gives non-finite output).
    """
    g = params.gravity_vector_mps2
    acc_lo = np.asarray(params.input_min_mps2, dtype=float) + g
    acc_hi = np.asarray(params.input_max_mps2, dtype=float) + g
    dt = params.dt_s
    n_rows = params.horizon_steps + 2
    positions = np.empty((n_rows, 3))
    velocities = np.empty((n_rows, 3))
    positions[0] = np.asarray(position_m, dtype=float).reshape(3)
    velocities[0] = np.asarray(velocity_mps, dtype=float).reshape(3)
    with np.errstate(invalid="ignore"):
        for k in range(n_rows - 1):
            a = np.clip(-velocities[k] / dt, acc_lo, acc_hi)
            positions[k + 1] = positions[k] + dt * velocities[k] + (0.5 * dt * dt) * a
            velocities[k + 1] = velocities[k] + dt * a
    return np.clip(positions, params.position_min_m, params.position_max_m), velocities


def _magnitude_problem(value: np.ndarray, name: str) -> str | None:
    """Why `value` cannot enter the QP (not finite, or beyond PLAUSIBLE_MAGNITUDE), or None."""
    if not np.all(np.isfinite(value)):
        return f"{name} is not finite"
    if np.any(np.abs(value) > PLAUSIBLE_MAGNITUDE):
        return f"{name} is implausibly large (beyond {PLAUSIBLE_MAGNITUDE:g})"
    return None


def _checked_weight(
    value: np.ndarray | None, default: float, name: str
) -> tuple[np.ndarray | None, str | None]:
    """((3, 3) symmetric PSD weight, None), or (None, reason) for a non-finite, asymmetric or indefinite one.

    A wrong shape is a programming error and raises ValueError.
    """
    if value is None:
        return default * np.eye(3), None
    w = np.asarray(value, dtype=float)
    if w.shape != (3, 3):
        raise ValueError(f"{name} must be a (3, 3) matrix, got shape {w.shape}")
    why = _magnitude_problem(w, name)
    if why:
        return None, why
    scale = max(1.0, float(np.max(np.abs(w))))
    if np.max(np.abs(w - w.T)) > 1e-9 * scale:
        return None, f"{name} is not symmetric"
    w = 0.5 * (w + w.T)
    if np.linalg.eigvalsh(w)[0] < -1e-9 * scale:
        return None, f"{name} is not positive semidefinite"
    return w, None


class ModelPredictiveController:
    """The MPC of eqs. (4)-(8), built once as a condensed OSQP problem and updated every solve.

    Each solve updates q, l, u (and P's values, whose dense pattern is fixed, only when a terminal weight
    changed) and warm-starts OSQP from the previous primal-dual solution, shifted by as many steps as the
    vehicle has moved along the previous plan: k = the plan step whose state is nearest the new x(0). At a
    control tick of dt_s that is one step (receding horizon); for an identical re-solve, or ticks much shorter
    than dt_s, it is zero. The MPC reads no clock, so it infers the elapsed steps from the state.

    planes_in_one_call: with the compiled active set, a solve whose closed form failed only its half-planes
    runs ExactQp.finish's steps and the rollout in one compiled call (mpc_kernels.solve_with_planes); False
    sends it through ExactQp.finish, the readable path that call is tested against (same plans, same bits).
    """

    def __init__(self, params: MpcParams, *, planes_in_one_call: bool = True) -> None:
        self._params = params
        self._planes_in_one_call = planes_in_one_call
        m = params.horizon_steps + 1
        self._n_steps = m
        self._nu = 3 * m
        self._n_var = self._nu + 6
        self._g = params.gravity_vector_mps2
        self._input_min = np.asarray(params.input_min_mps2, dtype=float)
        self._input_max = np.asarray(params.input_max_mps2, dtype=float)
        bounded = params.plan_acceleration_min_mps2 is not None
        self._plan_bounded = bounded
        self._plan_min = np.asarray(params.plan_acceleration_min_mps2 if bounded else self._input_min, float)
        self._plan_max = np.asarray(params.plan_acceleration_max_mps2 if bounded else self._input_max, float)
        self._state_min = np.concatenate([params.position_min_m, params.velocity_min_mps]).astype(float)
        self._state_max = np.concatenate([params.position_max_m, params.velocity_max_mps]).astype(float)
        self._free_x0, self._input_to_state = self._prediction_matrices()
        self._g_terminal = self._input_to_state[-6:]
        self._a_matrix = self._build_constraints()
        self._n_constraints = self._nu + 12 * m + 6  # rows of _a_matrix (see _build_constraints)
        self._upper_rows = slice(self._nu, self._nu + 6 * m)  # rows of G u - s <= x_max - h
        self._lower_rows = slice(self._nu + 6 * m, self._nu + 12 * m)  # rows of G u + s >= x_min - h
        self._l_template, self._u_template = self._constant_bounds()
        self._p_rows, self._p_cols, self._p_indptr = self._p_pattern()
        self._shifts = [self._shift_permutations(k) for k in range(m)]
        self._exact = params.solver == "exact"
        # The exact solver's QP has one more variable per plan step: the slack w(n) >= 0 shared by the
        # half-planes on step n (last, steps 1..N+1 in order).
        self._n_exact = self._n_var + m
        a_dense = self._a_matrix.toarray()
        self._a_exact = np.zeros((a_dense.shape[0] + m, self._n_exact))
        self._a_exact[:-m, :-m] = a_dense
        self._a_exact[-m:, -m:] = np.eye(m)
        self._l_exact = np.append(self._l_template, np.zeros(m))
        self._u_exact = np.append(self._u_template, np.full(m, np.inf))
        self._slack_hessian = 2.0 * params.half_plane_quadratic_weight * np.eye(m)
        self._resting = np.arange(self._n_exact) >= self._nu
        self._state_min_c = np.ascontiguousarray(self._state_min)
        self._state_max_c = np.ascontiguousarray(self._state_max)
        self._effort_code = EFFORT_MODES.index(params.effort)
        self._work: tuple | None = None  # _solve_exact's work arrays
        self._fallbacks = 0
        self._default_w_terminal = np.diag(
            [params.terminal_position_weight] * 3 + [params.terminal_velocity_weight] * 3
        )
        self._setup_solver()

    @property
    def horizon_steps(self) -> int:
        return self._params.horizon_steps

    @property
    def params(self) -> MpcParams:
        return self._params

    @property
    def active_set_fallbacks(self) -> int:
        """Solves whose compiled active-set step did not end optimal (infeasible rows, its iteration limit),
        so that DAQP's path answered them (always 0 with `MpcParams.active_set` "daqp")."""
        return self._fallbacks

    def reset(self) -> None:
        """Forget the warm start and OSQP's adapted step size: the next solve is like a fresh controller's."""
        self._setup_solver()

    # ----------------------------------------------------------------------------------------------- build
    def _prediction_matrices(self) -> tuple[np.ndarray, np.ndarray]:
        """(6M, 6) map of x(0) and (6M, 3M) map of the accelerations a(0..N) to stacked x(1..N+1), M = N+1.

        From eqs. (6) and (9) per axis: p(k) = p(0) + k dt v(0) + sum_{n<k} dt^2 (k - n - 1/2) a(n),
        v(k) = v(0) + sum_{n<k} dt a(n); a(n) = u(n) + f(n) + g enters like u(n), so one matrix serves both.
        """
        m, dt = self._n_steps, self._params.dt_s
        k = np.arange(1, m + 1)[:, None]
        n = np.arange(m)[None, :]
        to_position = np.where(n < k, dt * dt * (k - n - 0.5), 0.0)
        to_velocity = np.where(n < k, dt, 0.0)
        gain = np.zeros((m, 6, m, 3))
        free = np.zeros((m, 6, 6))
        for axis in range(3):
            gain[:, axis, :, axis] = to_position
            gain[:, 3 + axis, :, axis] = to_velocity
            free[:, axis, axis] = 1.0
            free[:, axis, 3 + axis] = dt * k[:, 0]
            free[:, 3 + axis, 3 + axis] = 1.0
        return free.reshape(6 * m, 6), gain.reshape(6 * m, 3 * m)

    def _build_constraints(self) -> sp.csc_matrix:
        """Rows: input box 3M, state upper 6M (G u - s), state lower 6M (G u + s), s >= 0 (6)."""
        m, nu = self._n_steps, self._nu
        slack_of_row = np.tile(np.eye(6), (m, 1))
        gain = self._input_to_state
        return sp.csc_matrix(
            np.block(
                [
                    [np.eye(nu), np.zeros((nu, 6))],
                    [gain, -slack_of_row],
                    [gain, slack_of_row],
                    [np.zeros((6, nu)), np.eye(6)],
                ]
            )
        )

    def _constant_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """l, u of every row, state bounds not yet shifted by the free response (`_solve_vectors` does)."""
        m = self._n_steps
        inf = np.full(6 * m, np.inf)
        lo = np.concatenate([np.tile(self._input_min, m), -inf, np.tile(self._state_min, m), np.zeros(6)])
        hi = np.concatenate(
            [np.tile(self._input_max, m), np.tile(self._state_max, m), inf, np.full(6, np.inf)]
        )
        return lo, hi

    def _p_pattern(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Fixed CSC pattern of P's upper triangle: dense on the inputs (terminal weights couple them all),
        diagonal on the slacks. Returns row and column of every stored entry, and indptr."""
        rows, cols = np.triu_indices(self._n_var)
        keep = (cols < self._nu) | (rows == cols)
        rows, cols = rows[keep], cols[keep]
        order = np.lexsort((rows, cols))
        rows, cols = rows[order], cols[order]
        indptr = np.concatenate([[0], np.cumsum(np.bincount(cols, minlength=self._n_var))])
        return rows, cols, indptr

    def _p_data(self, w_terminal: np.ndarray) -> np.ndarray:
        """P's stored values for the (6, 6) terminal weight blockdiag(W_p, W_v); OSQP minimises z'Pz/2+q'z."""
        p = np.zeros((self._n_var, self._n_var))
        gt = self._g_terminal
        p[: self._nu, : self._nu] = (
            2.0 * self._params.input_weight * np.eye(self._nu) + 2.0 * gt.T @ w_terminal @ gt
        )
        p[self._nu :, self._nu :] = 2.0 * self._params.slack_quadratic_weight * np.eye(6)
        return p[self._p_rows, self._p_cols]

    def _shift_permutations(self, k: int) -> tuple[np.ndarray, np.ndarray]:
        """Index arrays that move every per-step block of z and y k steps earlier, repeating the last step."""
        m, nu = self._n_steps, self._nu
        steps = np.minimum(np.arange(m) + k, m - 1)

        def block(start: int, width: int) -> np.ndarray:
            return (start + width * steps[:, None] + np.arange(width)).ravel()

        slacks = np.arange(6)
        z_idx = np.concatenate([block(0, 3), nu + slacks])
        y_idx = np.concatenate([block(0, 3), block(nu, 6), block(nu + 6 * m, 6), nu + 12 * m + slacks])
        return z_idx, y_idx

    def _elapsed_steps(self, plan: np.ndarray, x0: np.ndarray) -> int:
        """Index k in 0..N of the previous plan's state (rows of (M+1, 6)) nearest x0 (6,), velocities
        weighted by dt_s so both parts are metres."""
        scale = np.array([1.0, 1.0, 1.0] + [self._params.dt_s] * 3)
        return int(np.argmin(np.linalg.norm((plan[: self._n_steps] - x0) * scale, axis=1)))

    def _exact_qp(self, w_terminal: np.ndarray) -> ExactQp:
        """The exact solver for this terminal weight (P's upper triangle from `_p_data`, mirrored)."""
        p = np.zeros((self._n_exact, self._n_exact))
        p[self._p_rows, self._p_cols] = self._p_data(w_terminal)
        p = p + np.triu(p, 1).T
        p[self._n_var :, self._n_var :] = self._slack_hessian
        return ExactQp(
            p,
            self._a_exact,
            self._resting,
            iteration_limit=self._params.max_iterations,
            active_set=self._params.active_set,
        )

    def _setup_solver(self) -> None:
        prm = self._params
        self._w_terminal = self._default_w_terminal
        self._q_terminal = np.ascontiguousarray(2.0 * self._g_terminal.T @ self._w_terminal)
        self._warm: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None  # z, y, plan states (M+1, 6)
        if self._exact:
            self._qp = self._exact_qp(self._w_terminal)
            return
        p_matrix = sp.csc_matrix(
            (self._p_data(self._w_terminal), self._p_rows, self._p_indptr), shape=(self._n_var, self._n_var)
        )
        # OSQP fixes its cost scaling at setup from P and q: set up with the q of a representative (hover)
        # problem, slack weights included; with q = 0 later solves ran badly scaled (2050 vs 170 iterations).
        centre = 0.5 * (self._state_min[:3] + self._state_max[:3])
        x0 = np.concatenate([centre, np.zeros(3)])
        q, lo, hi = self._solve_vectors(x0, x0, np.zeros((self._n_steps, 3)))
        self._solver = osqp.OSQP()
        self._solver.setup(
            p_matrix,
            q,
            self._a_matrix,
            lo,
            hi,
            eps_abs=prm.eps_abs,
            eps_rel=prm.eps_rel,
            max_iter=prm.max_iterations,
            polishing=prm.polishing,
            warm_starting=True,
            adaptive_rho=True,
            adaptive_rho_interval=25,  # fixed, so solves are deterministic (the default adapts on timing)
            check_termination=5,
            verbose=False,
        )

    # ----------------------------------------------------------------------------------------------- solve
    def _solve_vectors(
        self, x0: np.ndarray, reference: np.ndarray, f: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """q, l, u from x(0) (6,), the terminal reference (6,) and f (M, 3); h (6M,) is the free response."""
        prm = self._params
        free = self._free_response(x0, f)
        if prm.effort == "hover":
            offset = np.tile(self._g, self._n_steps)
        elif prm.effort == "planned":
            offset = (f + self._g).ravel()
        else:
            offset = np.zeros(self._nu)
        q = np.empty(self._n_var)
        q[: self._nu] = (2.0 * prm.input_weight) * offset + self._q_terminal @ (free[-6:] - reference)
        q[self._nu :] = prm.slack_weight
        lo, hi = self._l_template.copy(), self._u_template.copy()
        box_lo, box_hi = input_box(f, prm)
        lo[: self._nu], hi[: self._nu] = box_lo.ravel(), box_hi.ravel()
        lo[self._lower_rows] -= free
        hi[self._upper_rows] -= free
        return q, lo, hi

    def _checked_half_planes(self, half_planes: HalfPlanes | None) -> Planes | None:
        """(steps (R,) int, normals (R, 3), offsets (R,), soft (R,) float 1/0) of the given half-planes, None
        when there are none; ValueError for wrong shapes or steps."""
        if half_planes is None or len(half_planes.steps) == 0:
            return None
        steps = np.asarray(half_planes.steps)
        count = steps.shape[0]
        normals_xy = kernel_array(half_planes.normals_xy, float)
        offsets = kernel_array(half_planes.offsets, float)
        soft = None if half_planes.soft is None else kernel_array(half_planes.soft, None)
        normals_z = None if half_planes.normals_z is None else kernel_array(half_planes.normals_z, float)
        if (
            steps.ndim != 1
            or normals_xy.shape != (count, 2)
            or offsets.shape != (count,)
            or (soft is not None and soft.shape != (count,))
            or (normals_z is not None and normals_z.shape != (count,))
        ):
            raise ValueError(
                "half-planes: steps (R,), normals_xy (R, 2), offsets (R,), soft (R,), normals_z (R,); "
                f"got {count} steps"
            )
        if soft is not None and soft.dtype != bool:
            raise ValueError(f"half-plane soft must be an array of bool, got {soft.dtype}")
        steps = kernel_array(steps, np.int64) if steps.dtype.kind in "iu" else None
        normals, weights = np.empty((count, 3)), np.empty(count)
        if steps is None or not checked_planes(
            steps, normals_xy, normals_z, soft, self._n_steps, normals, weights
        ):
            raise ValueError(f"half-plane steps must be integers in 1..{self._n_steps}")
        return steps, normals, offsets, weights

    def _half_plane_rows(
        self,
        planes: Planes,
        position: np.ndarray,
        velocity: np.ndarray,
        f: np.ndarray,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The half-planes as extra rows of the exact QP: a^T G_p(n) u + w(n) >= b - a^T h_p(n), with G_p(n)
        the position rows of the input-to-state map at step n, h the free response, w(n) step n's slack (one
        of the last N+1 variables; a hard row has 0 there). Returns (rows (R, n), lower (R,), upper (R,))."""
        steps, normals, offsets, soft = planes
        free = self._free_response(np.concatenate([position, velocity]), f)
        first = 6 * (steps - 1)  # the x row of step n in the stacked states; y, z are the next two
        rows = np.zeros((len(steps), self._n_exact))
        rows[:, : self._nu] = (
            normals[:, 0:1] * self._input_to_state[first]
            + normals[:, 1:2] * self._input_to_state[first + 1]
            + normals[:, 2:3] * self._input_to_state[first + 2]
        )
        rows[np.arange(len(steps)), self._n_var + steps - 1] = soft
        lower = offsets - (
            normals[:, 0] * free[first] + normals[:, 1] * free[first + 1] + normals[:, 2] * free[first + 2]
        )
        return rows, lower, np.full(len(steps), np.inf)

    def _free_response(self, x0: np.ndarray, f: np.ndarray) -> np.ndarray:
        """(6(N+1),) the stacked states with no input, from x(0) (6,) under f (N+1, 3) and gravity."""
        return self._free_x0 @ x0 + self._input_to_state @ (f + self._g).ravel()

    def _half_plane_rows_compiled(
        self, planes: Planes, position: np.ndarray, velocity: np.ndarray, f: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """`_half_plane_rows` by the compiled kernel (mpc_kernels.half_plane_rows): the same bits."""
        steps, normals, offsets, soft = planes
        count = len(steps)
        rows, lower = np.zeros((count, self._n_exact)), np.empty(count)
        free = self._free_response(np.concatenate([position, velocity]), f)
        half_plane_rows(self._input_to_state, free, steps, normals, offsets, soft, rows, lower)
        return rows, lower, np.full(count, np.inf)

    def _solve_exact(
        self,
        *,
        position_m: np.ndarray,
        velocity_mps: np.ndarray,
        target_position_m: np.ndarray,
        target_velocity_mps: np.ndarray,
        external_inputs_mps2: np.ndarray,
        half_planes: Planes | None = None,
    ) -> MpcSolution | None:
        """The solve with ExactQp: arithmetic in compiled kernels (mpc_kernels.py); the closed form in one
        call. None when a number is not finite or implausible (the caller says which)."""
        prm = self._params
        n = self._n_steps
        qp = self._qp
        # Work arrays, reused from solve to solve (nothing returned refers to them).
        if self._work is None or self._work[0] is not qp:
            rows_n = self._l_exact.shape[0]
            self._work = (
                qp,
                np.empty(self._n_exact),
                np.empty(rows_n),
                np.empty(rows_n),
                np.empty(self._n_exact),
                np.empty(qp.row_count),
                np.empty(qp.resting_count),
                np.empty((n, 3)),
                np.empty((n, 3)),
            )
        _, q, lo, hi, z, rows, gradient, box_lo, box_hi = self._work
        inputs = np.empty((n, 3))
        positions = np.empty((n + 1, 3))
        velocities = np.empty((n + 1, 3))
        f = external_inputs_mps2  # C-contiguous and writable (`kernel_array`, in solve)
        verdict, violation = solve_fast(
            self._free_x0,
            self._input_to_state,
            self._q_terminal,
            self._l_exact,
            self._u_exact,
            position_m,
            velocity_mps,
            target_position_m,
            target_velocity_mps,
            f,
            self._g,
            self._effort_code,
            prm.input_weight,
            prm.slack_weight,
            PLAUSIBLE_MAGNITUDE,
            qp.kernel_data,
            prm.dt_s,
            self._input_min,
            self._input_max,
            self._plan_min,
            self._plan_max,
            self._plan_bounded,
            self._state_min_c,
            self._state_max_c,
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
        )
        if verdict == INVALID:
            return None
        q[self._n_var :] = prm.half_plane_weight  # the kernel set every slack's weight to slack_weight
        extra: tuple[np.ndarray, np.ndarray, np.ndarray] | tuple[None, None, None] = (None, None, None)
        fixed_rows_ok = False  # whether the closed form satisfied every fixed row (then only extras failed)
        shortfall = -np.inf  # the plan's largest shortfall from the half-planes (m)
        if half_planes is not None:
            if verdict == CLOSED_FORM:
                # The closed form's plan is checked against the half-planes themselves: its slacks rest at 0,
                # so a^T p(n) >= b is the row a^T G z + w(n) >= b - a^T h, and no row need be built for it.
                shortfall = _shortfall(half_planes, positions)
                if not shortfall == shortfall:  # NaN: a normal or an offset is not finite
                    return None
                if shortfall > 1e-9:
                    verdict, fixed_rows_ok = NEEDS_SOLVER, True
            elif not (np.all(np.isfinite(half_planes[1])) and np.all(np.isfinite(half_planes[2]))):
                return None
        path, iterations, time_s = "closed_form", 0, 0.0
        solver = qp.compiled_active_set if self._planes_in_one_call else None
        if half_planes is not None and fixed_rows_ok and solver is not None:
            # Only the half-planes failed: ExactQp.finish's steps and the rollout in one compiled call.
            steps, normals, offsets, soft = half_planes
            count = len(steps)
            extra_rows, extra_lower = np.zeros((count, self._n_exact)), np.empty(count)
            found, iterations, violation, shortfall = solve_with_planes(
                self._input_to_state,
                self._free_x0,
                steps,
                normals,
                offsets,
                soft,
                solver,
                q,
                lo,
                hi,
                z,
                position_m,
                velocity_mps,
                f,
                self._g,
                prm.dt_s,
                box_lo,
                box_hi,
                self._state_min_c,
                self._state_max_c,
                extra_rows,
                extra_lower,
                inputs,
                positions,
                velocities,
            )
            if found == PLANES_UNSOLVED:  # ExactQp.finish runs the compiled solver again, then DAQP
                extra = (extra_rows, extra_lower, np.full(count, np.inf))
            else:
                verdict = CLOSED_FORM  # the plan is written
                path = "active_set" if found == PLANES_ACTIVE_SET else "closed_form"
        elif half_planes is not None and verdict != CLOSED_FORM:
            extra = self._half_plane_rows_compiled(half_planes, position_m, velocity_mps, f)
        if verdict != CLOSED_FORM:
            result = qp.finish(q, lo, hi, fixed_rows_ok, z, rows, gradient, *extra)
            self._fallbacks += result.fallback
            if not result.ok:
                message = f"exact QP: {result.status} ({result.message})"
                return self._failure(
                    result.status, message, result.iterations, result.solve_time_s, path=result.path
                )
            path, iterations, time_s = result.path, result.iterations, result.solve_time_s
            violation = roll_out_variables(
                result.x,
                position_m,
                velocity_mps,
                f,
                self._g,
                prm.dt_s,
                box_lo,
                box_hi,
                self._state_min_c,
                self._state_max_c,
                inputs,
                positions,
                velocities,
            )
            if half_planes is not None:
                shortfall = _shortfall(half_planes, positions)
        if not np.isfinite(violation):
            return self._failure("non_finite_plan", "the plan is not finite", iterations)
        plane_violation = max(0.0, shortfall)
        for arr in (inputs, positions, velocities):
            arr.setflags(write=False)  # handed on (e.g. into a HorizonPlan) without a copy
        return MpcSolution(
            ok=True,
            status="solved",
            message=None,
            inputs_mps2=inputs,
            positions_m=positions,
            velocities_mps=velocities,
            max_state_violation=violation if violation > prm.violation_tolerance else 0.0,
            iterations=iterations,
            solve_time_s=time_s,
            half_plane_violation_m=plane_violation if plane_violation > prm.violation_tolerance else 0.0,
            path=path,
        )

    def _solve_osqp_with_half_planes(
        self,
        q: np.ndarray,
        lo: np.ndarray,
        hi: np.ndarray,
        planes: Planes,
        arrays: dict[str, np.ndarray],
        w_terminal: np.ndarray,
    ):
        """OSQP on the QP with the half-planes' rows and their slacks w(n) (the exact solver's problem),
        set up for this solve alone (its rows change every solve); the result's x and y are cut back to
        the problem without them, so the caller treats it like the warm-started solver's result."""
        prm = self._params
        n = self._n_exact
        p = np.zeros((n, n))
        p[self._p_rows, self._p_cols] = self._p_data(w_terminal)
        p[self._n_var :, self._n_var :] = self._slack_hessian
        extra, extra_lo, extra_hi = self._half_plane_rows(
            planes, arrays["position_m"], arrays["velocity_mps"], arrays["external_inputs_mps2"]
        )
        a = sp.vstack([self._a_exact, extra], format="csc")
        solver = osqp.OSQP()
        solver.setup(
            sp.csc_matrix(np.triu(p)),
            np.append(q, np.full(self._n_steps, prm.half_plane_weight)),
            a,
            np.concatenate([lo, np.zeros(self._n_steps), extra_lo]),
            np.concatenate([hi, np.full(self._n_steps, np.inf), extra_hi]),
            eps_abs=prm.eps_abs,
            eps_rel=prm.eps_rel,
            max_iter=prm.max_iterations,
            polishing=prm.polishing,
            adaptive_rho=True,
            adaptive_rho_interval=25,
            check_termination=5,
            verbose=False,
        )
        return solver.solve(raise_error=False)

    def _failure(
        self, status: str, message: str, iterations: int = 0, time_s: float = 0.0, path: str = "osqp"
    ) -> MpcSolution:
        n = self._n_steps
        return MpcSolution(
            ok=False,
            status=status,
            message=message,
            inputs_mps2=np.full((n, 3), np.nan),
            positions_m=np.full((n + 1, 3), np.nan),
            velocities_mps=np.full((n + 1, 3), np.nan),
            max_state_violation=float("nan"),
            iterations=iterations,
            solve_time_s=time_s,
            path=path,
        )

    def solve(
        self,
        *,
        position_m: np.ndarray,
        velocity_mps: np.ndarray,
        target_position_m: np.ndarray,
        target_velocity_mps: np.ndarray,
        external_inputs_mps2: np.ndarray,
        terminal_position_weight: np.ndarray | None = None,
        terminal_velocity_weight: np.ndarray | None = None,
        half_planes: HalfPlanes | None = None,
    ) -> MpcSolution:
        """Plan u(0..N) from x(0) = (position_m, velocity_mps), (3,) each, to the terminal reference
        (target_position_m, target_velocity_mps), (3,) each, under the external inputs f(0..N), (N+1, 3).

        half_planes: linear constraints on the plan's horizontal positions (`HalfPlanes`), soft or hard; both
        solvers take them (OSQP sets up a one-off problem with the extra rows, without warm start). Steps
        outside 1..N+1 or wrong shapes raise ValueError.

        terminal_*_weight: (3, 3) symmetric PSD W_p / W_v for this solve; None = the params' scalar * I3.
        Wrong shapes raise ValueError (a programming error). Non-finite or implausibly large numbers, or an
        asymmetric / indefinite weight, give ok=False, status "invalid_input", and leave the controller as is;
        a solver failure gives ok=False with OSQP's status, and the next solve starts cold.
        """
        prm = self._params
        n = self._n_steps
        arrays = {}
        for name, value, shape in (
            ("position_m", position_m, (3,)),
            ("velocity_mps", velocity_mps, (3,)),
            ("target_position_m", target_position_m, (3,)),
            ("target_velocity_mps", target_velocity_mps, (3,)),
            ("external_inputs_mps2", external_inputs_mps2, (n, 3)),
        ):
            arr = kernel_array(value, float)
            if arr.shape != shape:
                raise ValueError(f"{name} must have shape {shape}, got {arr.shape}")
            arrays[name] = arr
        planes = self._checked_half_planes(half_planes)
        default_weights = terminal_position_weight is None and terminal_velocity_weight is None
        if self._exact and default_weights and self._w_terminal is self._default_w_terminal:
            solution = self._solve_exact(**arrays, half_planes=planes)  # checks its numbers in the kernel
            if solution is not None:
                return solution
        reasons = []
        values = np.concatenate([arr.ravel() for arr in arrays.values()])
        if not np.all(np.abs(values) <= PLAUSIBLE_MAGNITUDE):  # also False for NaN
            reasons = [why for name, arr in arrays.items() if (why := _magnitude_problem(arr, name))]
        if planes is not None:
            reasons += [
                why
                for name, arr in (("half-plane normals", planes[1]), ("half-plane offsets", planes[2]))
                if (why := _magnitude_problem(arr, name))
            ]
        wp, why_p = _checked_weight(
            terminal_position_weight, prm.terminal_position_weight, "terminal_position_weight"
        )
        wv, why_v = _checked_weight(
            terminal_velocity_weight, prm.terminal_velocity_weight, "terminal_velocity_weight"
        )
        reasons += [why for why in (why_p, why_v) if why]
        if reasons:
            return self._failure("invalid_input", "; ".join(reasons))

        if default_weights:
            w_terminal = self._default_w_terminal
        else:
            w_terminal = np.zeros((6, 6))
            w_terminal[:3, :3], w_terminal[3:, 3:] = wp, wv
        if not np.array_equal(w_terminal, self._w_terminal):
            self._w_terminal = w_terminal if default_weights else w_terminal.copy()
            self._q_terminal = np.ascontiguousarray(2.0 * self._g_terminal.T @ w_terminal)
            if self._exact:
                self._qp = self._exact_qp(w_terminal)
            else:
                self._solver.update(Px=self._p_data(w_terminal))
        elif default_weights:
            self._w_terminal = self._default_w_terminal
        if self._exact:
            solution = self._solve_exact(**arrays, half_planes=planes)
            assert solution is not None  # the numbers were checked above
            return solution
        x0 = np.concatenate([arrays["position_m"], arrays["velocity_mps"]])
        reference = np.concatenate([arrays["target_position_m"], arrays["target_velocity_mps"]])
        f = arrays["external_inputs_mps2"]
        q, lo, hi = self._solve_vectors(x0, reference, f)
        if planes is not None:
            result = self._solve_osqp_with_half_planes(q, lo, hi, planes, arrays, w_terminal)
        else:
            self._solver.update(q=q, l=lo, u=hi)
            if self._warm is not None:
                z_prev, y_prev, plan_prev = self._warm
                z_shift, y_shift = self._shifts[self._elapsed_steps(plan_prev, x0)]
                self._solver.warm_start(x=z_prev[z_shift], y=y_prev[y_shift])
            result = self._solver.solve(raise_error=False)
        info = result.info
        status, iterations, run_time = str(info.status), int(info.iter), float(info.run_time)
        accepted = ACCEPTED_STATUSES if prm.accept_inaccurate else ACCEPTED_STATUSES[:1]
        if status not in accepted or not (np.all(np.isfinite(result.x)) and np.all(np.isfinite(result.y))):
            self._warm = None
            self._solver.warm_start(x=np.zeros(self._n_var), y=np.zeros(self._n_constraints))
            message = f"OSQP: {status} after {iterations} iterations"
            return self._failure(status, message, iterations, run_time)

        # The plan returned is the exact rollout of the box-clipped inputs: it obeys the dynamics exactly.
        box = (lo[: self._nu].reshape(n, 3), hi[: self._nu].reshape(n, 3))  # input_box, as _solve_vectors set
        inputs = np.clip(result.x[: self._nu].reshape(n, 3), *box)
        positions, velocities = predict(
            position_m=arrays["position_m"],
            velocity_mps=arrays["velocity_mps"],
            inputs_mps2=inputs,
            external_inputs_mps2=f,
            params=prm,
        )
        plan = np.hstack([positions, velocities])
        violation = float(max(np.max(plan[1:] - self._state_max), np.max(self._state_min - plan[1:])))
        if not (np.all(np.isfinite(plan)) and np.isfinite(violation)):
            self._warm = None
            return self._failure("non_finite_plan", "the plan is not finite", iterations, run_time)
        plane_violation = 0.0
        if planes is None:
            self._warm = (np.array(result.x), np.array(result.y), plan)
        else:
            plane_violation = _plane_violation(planes, positions)
        violation = violation if violation > prm.violation_tolerance else 0.0
        return MpcSolution(
            ok=True,
            status=status,
            message=None,
            inputs_mps2=inputs,
            positions_m=positions,
            velocities_mps=velocities,
            max_state_violation=violation,
            iterations=iterations,
            solve_time_s=run_time,
            half_plane_violation_m=plane_violation if plane_violation > prm.violation_tolerance else 0.0,
        )

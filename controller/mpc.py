"""The convex MPC of one MAV (paper Sec. III-D: cost `J_ACT` eq. (4), problem eq. (5), dynamics eq. (6), state
and input bounds eqs. (7)-(8), A and B eq. (9); numbers as in the RA-L text's order), solved with OSQP.

Variables z = [u(0..N) (N+1, 3) | x(1..N+1) (N+1, 6) | s (6,)], x = [position, velocity] in ENU:

    minimise   sum_n (u(n) + c(n))^T W_E (u(n) + c(n))                          (effort, eq. 4)
             + (p(N+1) - p_ref)^T W_p (p(N+1) - p_ref)
             + (v(N+1) - v_ref)^T W_v (v(N+1) - v_ref)                            (terminal, eq. 4)
             + slack_weight * sum(s) + slack_quadratic_weight * s^T s              (soft state bounds)
    s.t.       x(n+1) = A x(n) + B (u(n) + f(n) + g),  n = 0..N                  (eq. 6)
               x_min - s <= x(n) <= x_max + s,  n = 1..N+1,  s >= 0                 (eq. 7, softened)
               u_min <= u(n) <= u_max                                            (eq. 8, hard)

with c(n) = g ("hover"), f(n) + g ("planned") or 0 ("raw"), W_E = input_weight * I3.

State bounds are soft because a strong external input can make them infeasible (METHOD.md, pitfall 1). Slack
layout: one slack per state component (x, y, z, vx, vy, vz) shared over the horizon, an L-infinity penalty:
6 extra variables instead of 96, and exact (the plan equals the hard-bounded one whenever that exists) as long
as slack_weight exceeds the summed multipliers of the component's bound rows. The small quadratic slack term
does not change that (its slope at s = 0 is zero) but gives OSQP curvature in s: with a purely linear penalty
it needed about 1100 iterations per cold solve, with it about 170.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import osqp
import scipy.sparse as sp

EFFORT_MODES = ("hover", "planned", "raw")
ACCEPTED_STATUSES = ("solved", "solved inaccurate")


@dataclass(frozen=True)
class MpcParams:
    """MPC horizon, bounds and weights (METHOD.md "The MPC"). ENU, z up.

    horizon_steps: N (inputs u(0..N), states x(1..N+1)); dt_s: step length.
    Bounds are per axis (x, y, z). input_*_mps2 bound the commanded acceleration u *before* gravity is added
    (hover is u_z = gravity_mps2). Position and velocity bounds are soft (slack with an exact penalty).
    effort: what the input-effort term penalises: "hover" = u + g (skyring's default, hover costs nothing),
    "planned" = u + f + g (the authors' code), "raw" = u (the paper as written).
    slack_weight: linear penalty per m (or m/s) of the largest violation of each state component's bounds;
    slack_quadratic_weight: its quadratic companion (per m^2), there for the solver's convergence.

    Solver: eps_abs / eps_rel are OSQP's termination tolerances, max_iterations its iteration cap, polishing
    its active-set refinement. accept_inaccurate: count OSQP's "solved inaccurate" (iteration cap reached with
    residuals within 10x the tolerances) as ok: the plan is re-rolled through the exact dynamics with inputs
    clipped into their box, so it is consistent and admissible, only less optimal; braking would be worse.
    warm_start_shift_steps: horizon steps the previous solution is shifted for the next warm start (1 when the
    control tick equals dt_s, 0 when ticks are much shorter than a step).
    violation_tolerance: bound excursions up to this (m or m/s) are solver round-off and reported as 0.
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
    slack_weight: float = 1.0e4
    slack_quadratic_weight: float = 5.0e3
    eps_abs: float = 1.0e-5
    eps_rel: float = 1.0e-5
    max_iterations: int = 4000
    polishing: bool = True
    accept_inaccurate: bool = True
    warm_start_shift_steps: int = 1
    violation_tolerance: float = 1.0e-4

    def __post_init__(self) -> None:
        if self.horizon_steps < 1:
            raise ValueError(f"horizon_steps must be >= 1, got {self.horizon_steps}")
        if not (np.isfinite(self.dt_s) and self.dt_s > 0):
            raise ValueError(f"dt_s must be a positive number of seconds, got {self.dt_s}")
        if self.effort not in EFFORT_MODES:
            raise ValueError(f"effort must be one of {EFFORT_MODES}, got {self.effort!r}")
        for name, lo, hi in (
            ("position", self.position_min_m, self.position_max_m),
            ("velocity", self.velocity_min_mps, self.velocity_max_mps),
            ("input", self.input_min_mps2, self.input_max_mps2),
        ):
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
        if not 0 <= self.warm_start_shift_steps <= self.horizon_steps:
            raise ValueError("warm_start_shift_steps must be in 0..horizon_steps")

    @property
    def gravity_vector_mps2(self) -> np.ndarray:
        """(3,) g = (0, 0, -gravity) in ENU."""
        return np.array([0.0, 0.0, -self.gravity_mps2])


@dataclass(frozen=True, eq=False)
class MpcSolution:
    """One MPC solve (N = horizon_steps). When not ok, the arrays are NaN: apply `braking_plan` instead."""

    ok: bool  # True only if OSQP solved and every number is finite
    status: str  # OSQP's status string, or "invalid_input"
    message: str | None  # one line when not ok
    inputs_mps2: np.ndarray  # (N+1, 3) u(0..N), ENU, before gravity is added (hover: u_z = g)
    positions_m: np.ndarray  # (N+2, 3) x(0..N+1); x(0) = the given position
    velocities_mps: np.ndarray  # (N+2, 3)
    max_state_violation: float  # largest slack (m or m/s); 0 when no soft bound is active
    iterations: int
    solve_time_s: float  # OSQP's own run time (no clocks read here)


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
    if not np.all(np.isfinite(w)):
        return None, f"{name} is not finite"
    scale = max(1.0, float(np.max(np.abs(w))))
    if np.max(np.abs(w - w.T)) > 1e-9 * scale:
        return None, f"{name} is not symmetric"
    w = 0.5 * (w + w.T)
    if np.linalg.eigvalsh(w)[0] < -1e-9 * scale:
        return None, f"{name} is not positive semidefinite"
    return w, None


class ModelPredictiveController:
    """The MPC of eqs. (4)-(8), built once as an OSQP problem and updated every solve.

    Sparse form (states kept as variables: 150 variables, 342 rows for N = 15), chosen by measurement against
    the condensed form (inputs and slacks only): per iteration they cost about the same (4.6 vs 5.0 us), but
    the condensed P is dense, because the terminal weights couple every input, so re-factorising after a
    terminal-weight change costs 87 us against 51 us, and the sparse P keeps those weights in two dense 3x3
    blocks: `update(Px=...)` without re-setup. Each solve updates q, l, u (Px only when a terminal weight
    changed) and warm-starts OSQP from the previous primal-dual solution shifted by `warm_start_shift_steps`.
    """

    def __init__(self, params: MpcParams) -> None:
        self._params = params
        n_steps = params.horizon_steps + 1
        self._n_steps = n_steps
        self._nu = 3 * n_steps
        self._nx = 6 * n_steps
        self._n_var = self._nu + self._nx + 6
        self._x_last = self._nu + self._nx - 6  # column of x(N+1)
        dt = params.dt_s
        self._a6 = np.block([[np.eye(3), dt * np.eye(3)], [np.zeros((3, 3)), np.eye(3)]])
        self._b6 = np.vstack([0.5 * dt * dt * np.eye(3), dt * np.eye(3)])
        self._g = params.gravity_vector_mps2
        self._input_min = np.asarray(params.input_min_mps2, dtype=float)
        self._input_max = np.asarray(params.input_max_mps2, dtype=float)
        self._state_min = np.concatenate([params.position_min_m, params.velocity_min_mps]).astype(float)
        self._state_max = np.concatenate([params.position_max_m, params.velocity_max_mps]).astype(float)
        self._build_p_pattern()
        self._a_matrix = self._build_constraints()
        self._l_template, self._u_template = self._constant_bounds()
        self._q_template = np.zeros(self._n_var)
        self._q_template[-6:] = params.slack_weight
        self._z_shift, self._y_shift = self._shift_permutations(params.warm_start_shift_steps)
        self._setup_solver()

    @property
    def horizon_steps(self) -> int:
        return self._params.horizon_steps

    @property
    def params(self) -> MpcParams:
        return self._params

    def reset(self) -> None:
        """Forget the warm start and OSQP's adapted step size: the next solve is like a fresh controller's."""
        self._setup_solver()

    # ----------------------------------------------------------------------------------------------- build
    def _build_p_pattern(self) -> None:
        """Upper-triangular CSC pattern of P: diagonal on u and s, two dense 3x3 blocks on x(N+1)."""
        indptr = [0]
        indices: list[int] = []
        slots: list[int] = []  # data positions of the terminal blocks
        block_rc: list[tuple[int, int, int]] = []  # (0 = position / 1 = velocity, row, col)
        for col in range(self._n_var):
            if col < self._nu or col >= self._nu + self._nx:
                indices.append(col)
            elif col >= self._x_last:
                block, c = divmod(col - self._x_last, 3)
                for r in range(c + 1):
                    slots.append(len(indices))
                    block_rc.append((block, r, c))
                    indices.append(self._x_last + 3 * block + r)
            indptr.append(len(indices))
        self._p_indptr = np.array(indptr)
        self._p_indices = np.array(indices)
        self._p_slots = np.array(slots)
        self._p_block_rc = tuple(np.array(block_rc).T)
        base = np.zeros(len(indices))
        base[: self._nu] = 2.0 * self._params.input_weight
        base[-6:] = 2.0 * self._params.slack_quadratic_weight
        self._p_base = base

    def _p_data(self, wp: np.ndarray, wv: np.ndarray) -> np.ndarray:
        """P's values for terminal weights wp, wv (3, 3): 2 W_E, 2 W_p, 2 W_v (OSQP minimises z'Pz/2+q'z)."""
        data = self._p_base.copy()
        data[self._p_slots] = 2.0 * np.stack([wp, wv])[self._p_block_rc]
        return data

    def _build_constraints(self) -> sp.csc_matrix:
        """Rows: dynamics 6(N+1), input box 3(N+1), state upper 6(N+1), state lower 6(N+1), s >= 0 (6)."""
        n_steps, nu, nx = self._n_steps, self._nu, self._nx
        # dynamics: x(n+1) - A x(n) - B u(n) = B (f(n) + g) [+ A x(0) for n = 0]
        dyn_x = sp.identity(nx) - sp.kron(sp.eye(n_steps, k=-1), self._a6)
        dynamics = sp.hstack([sp.kron(sp.identity(n_steps), -self._b6), dyn_x, sp.csc_matrix((nx, 6))])
        box = sp.hstack([sp.identity(nu), sp.csc_matrix((nu, nx + 6))])
        slack_of_row = sp.csc_matrix(np.tile(np.eye(6), (n_steps, 1)))
        upper = sp.hstack([sp.csc_matrix((nx, nu)), sp.identity(nx), -slack_of_row])
        lower = sp.hstack([sp.csc_matrix((nx, nu)), sp.identity(nx), slack_of_row])
        slack = sp.hstack([sp.csc_matrix((6, nu + nx)), sp.identity(6)])
        return sp.vstack([dynamics, box, upper, lower, slack]).tocsc()

    def _constant_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """l, u of every row; the dynamics rows (zero here) are filled in per solve."""
        n_steps, nx = self._n_steps, self._nx
        inf = np.full(nx, np.inf)
        lo = np.concatenate(
            [
                np.zeros(nx),
                np.tile(self._input_min, n_steps),
                -inf,
                np.tile(self._state_min, n_steps),
                np.zeros(6),
            ]
        )
        hi = np.concatenate(
            [
                np.zeros(nx),
                np.tile(self._input_max, n_steps),
                np.tile(self._state_max, n_steps),
                inf,
                np.full(6, np.inf),
            ]
        )
        return lo, hi

    def _shift_permutations(self, k: int) -> tuple[np.ndarray, np.ndarray]:
        """Index arrays that move every per-step block of z and y k steps earlier, repeating the last step."""
        steps = np.minimum(np.arange(self._n_steps) + k, self._n_steps - 1)

        def block(start: int, width: int) -> np.ndarray:
            return (start + width * steps[:, None] + np.arange(width)).ravel()

        nu, nx = self._nu, self._nx
        z_idx = np.concatenate([block(0, 3), block(nu, 6), np.arange(nu + nx, nu + nx + 6)])
        y_idx = np.concatenate(
            [
                block(0, 6),
                block(nx, 3),
                block(nx + nu, 6),
                block(2 * nx + nu, 6),
                np.arange(3 * nx + nu, 3 * nx + nu + 6),
            ]
        )
        return z_idx, y_idx

    def _setup_solver(self) -> None:
        prm = self._params
        self._wp = prm.terminal_position_weight * np.eye(3)
        self._wv = prm.terminal_velocity_weight * np.eye(3)
        p_matrix = sp.csc_matrix(
            (self._p_data(self._wp, self._wv), self._p_indices, self._p_indptr),
            shape=(self._n_var, self._n_var),
        )
        # OSQP fixes its cost scaling at setup from P and q: set up with the q of a representative (hover)
        # problem, slack weights included, or later updates run badly scaled (measured: 2050 vs 170
        # iterations).
        centre = 0.5 * (self._state_min[:3] + self._state_max[:3])
        q, lo, hi = self._solve_vectors(
            np.concatenate([centre, np.zeros(3)]), centre, np.zeros(3), np.zeros((self._n_steps, 3))
        )
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
            adaptive_rho_interval=25,  # a fixed interval keeps the solves deterministic (not time-based)
            check_termination=5,
            verbose=False,
        )
        self._warm: tuple[np.ndarray, np.ndarray] | None = None

    # ----------------------------------------------------------------------------------------------- solve
    def _solve_vectors(
        self, x0: np.ndarray, p_ref: np.ndarray, v_ref: np.ndarray, f: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """q, l, u from x(0) (6,), the terminal reference (3,) + (3,) and f (N+1, 3)."""
        effort = self._params.effort
        q = self._q_template.copy()
        if effort == "hover":
            q[: self._nu] = np.tile((2.0 * self._params.input_weight) * self._g, self._n_steps)
        elif effort == "planned":
            q[: self._nu] = ((2.0 * self._params.input_weight) * (f + self._g)).ravel()
        q[self._x_last : self._x_last + 3] = -2.0 * (self._wp @ p_ref)
        q[self._x_last + 3 : self._x_last + 6] = -2.0 * (self._wv @ v_ref)
        rhs = ((f + self._g) @ self._b6.T).ravel()
        rhs[:6] += self._a6 @ x0
        lo, hi = self._l_template.copy(), self._u_template.copy()
        lo[: self._nx] = rhs
        hi[: self._nx] = rhs
        return q, lo, hi

    def _failure(self, status: str, message: str, iterations: int = 0, time_s: float = 0.0) -> MpcSolution:
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
    ) -> MpcSolution:
        """Plan u(0..N) from x(0) = (position_m, velocity_mps), (3,) each, to the terminal reference
        (target_position_m, target_velocity_mps), (3,) each, under the external inputs f(0..N), (N+1, 3).

        terminal_*_weight: (3, 3) symmetric PSD W_p / W_v for this solve; None = the params' scalar * I3.
        Wrong shapes raise ValueError (a programming error). Non-finite numbers or an asymmetric / indefinite
        weight give ok=False, status "invalid_input"; a solver failure gives ok=False with OSQP's status.
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
            arr = np.asarray(value, dtype=float)
            if arr.shape != shape:
                raise ValueError(f"{name} must have shape {shape}, got {arr.shape}")
            arrays[name] = arr
        reasons = [f"{name} is not finite" for name, arr in arrays.items() if not np.all(np.isfinite(arr))]
        wp, why_p = _checked_weight(
            terminal_position_weight, prm.terminal_position_weight, "terminal_position_weight"
        )
        wv, why_v = _checked_weight(
            terminal_velocity_weight, prm.terminal_velocity_weight, "terminal_velocity_weight"
        )
        reasons += [why for why in (why_p, why_v) if why]
        if reasons:
            return self._failure("invalid_input", "; ".join(reasons))

        if not (np.array_equal(wp, self._wp) and np.array_equal(wv, self._wv)):
            self._wp, self._wv = wp, wv
            self._solver.update(Px=self._p_data(wp, wv))
        x0 = np.concatenate([arrays["position_m"], arrays["velocity_mps"]])
        f = arrays["external_inputs_mps2"]
        q, lo, hi = self._solve_vectors(x0, arrays["target_position_m"], arrays["target_velocity_mps"], f)
        self._solver.update(q=q, l=lo, u=hi)
        if self._warm is not None:
            self._solver.warm_start(x=self._warm[0][self._z_shift], y=self._warm[1][self._y_shift])
        result = self._solver.solve(raise_error=False)
        status, iterations, run_time = (
            str(result.info.status),
            int(result.info.iter),
            float(result.info.run_time),
        )
        accepted = ACCEPTED_STATUSES if prm.accept_inaccurate else ACCEPTED_STATUSES[:1]
        if status not in accepted or not (np.all(np.isfinite(result.x)) and np.all(np.isfinite(result.y))):
            self._warm = None
            self._solver.warm_start(x=np.zeros(self._n_var), y=np.zeros(len(self._l_template)))
            return self._failure(
                status, f"OSQP: {status} after {iterations} iterations", iterations, run_time
            )
        self._warm = (np.array(result.x), np.array(result.y))

        # The plan returned is the exact rollout of the box-clipped inputs: it obeys the dynamics exactly.
        inputs = np.clip(result.x[: self._nu].reshape(n, 3), self._input_min, self._input_max)
        positions, velocities = predict(
            position_m=arrays["position_m"],
            velocity_mps=arrays["velocity_mps"],
            inputs_mps2=inputs,
            external_inputs_mps2=f,
            params=prm,
        )
        states = np.hstack([positions[1:], velocities[1:]])
        violation = float(max(np.max(states - self._state_max), np.max(self._state_min - states)))
        violation = violation if violation > prm.violation_tolerance else 0.0
        if not (np.all(np.isfinite(states)) and np.isfinite(violation)):
            return self._failure("non_finite_plan", "the plan is not finite", iterations, run_time)
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
        )

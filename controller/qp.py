"""An exact solver for the small dense QPs the MPC re-solves every control tick.

    minimise   z^T P z / 2 + q^T z     subject to   l <= A z <= u   (rows: fixed ones, then per-solve extras)

P is fixed at construction (it only changes with the terminal weights, and then the solver is rebuilt);
q, l, u and the extra rows (e.g. separation half-planes whose normals move every tick) change per solve.

Why not just an iterative solver: in formation flight the optimum is often the unconstrained one, a fixed
linear map of q (almost always at K = 3; in a 16-MAV ring a teammate's separation row is active on most
ticks: docs/fast-core.md, "The QP"). This module tries that first and proves it optimal, and only otherwise
runs a real active-set solver (DAQP, dual active set, exact up to round-off) on as small a problem as is
exact:

1. Closed form. *Resting* variables (slacks of soft rows with an exact penalty) are held at 0, the others
   take the equality-constrained minimiser z_f = -P_ff^-1 q_f. It is the optimum exactly when the KKT
   conditions hold with every row inactive: every row satisfied (to `feasibility_tol`) and the cost's
   gradient on each resting variable >= 0 (its lower bound 0 is then the only active constraint, with a
   non-negative multiplier).
2. Per block. Variables split into independent blocks (connected through P or a fixed row; for the MPC: the
   three axes, each with its own slacks). A block whose closed form fails is solved alone with DAQP; the
   others keep their closed form. Extra rows that touch more than one block (coupling rows) are left out of
   this step: the result is optimal for the problem without them (a relaxation), so if it satisfies them
   too it is optimal for the whole problem.
3. Whole problem. Otherwise DAQP with a working set of rows: the resting variables' bounds and the rows the
   answer so far misses, grown until the answer meets every row (optimal then, as a relaxation's optimum
   that is feasible), each round solved cold. A round solves only the blocks its rows reach (the others
   keep their step 1-2 optimum) and leaves at 0 the resting variables no row in play reaches; it hands DAQP
   the problem in y = L^T z (P = L L^T, factored once), whose Hessian is the identity. DAQP's set-up, which
   grows with the rows and variables and must factor a general Hessian, was most of the cost here.
   With `active_set="compiled"` step 3 is instead one call of controller/dual_active_set.py on the whole
   problem (every row, every variable, the same y = L^T z); DAQP's rounds answer only what it does not
   solve to optimality.

Resting variables must each have a fixed row that bounds them below by exactly 0 and nothing else (`rest`
rows), so step 1's dual check is the whole KKT story. Shapes: n variables, m0 fixed rows, m1 extra rows.
"""

from __future__ import annotations

from dataclasses import dataclass

import daqp
import numba
import numpy as np

from controller.dual_active_set import OPTIMAL, solve_identity_qp
from controller.sparse_rows import csr_times

DAQP_INF = 1.0e30  # DAQP's own "no bound"

WORKING_SET_ROUNDS = 5
"""Step 3 adds the rows its answer misses and solves again at most this many times, then takes every row (in
the K = 16 benchmark flight it needs 1.6 set-ups on average, with 16 rows at the median)."""

W_CACHE_SIZE = 64  # sets of variables whose W step 3 keeps (see `ExactQp._w_restricted`)


def _daqp_solve(
    p: np.ndarray, q: np.ndarray, a: np.ndarray, lo: np.ndarray, hi: np.ndarray, settings: dict
) -> tuple[np.ndarray, int, int, float]:
    """(x, DAQP exit flag, iterations, DAQP's solve time) of min x^T P x / 2 + q^T x, lo <= A x <= hi,
    solved cold (DAQP's one-call interface: a third of a `daqp.Model`'s overhead)."""
    x, _, flag, info = daqp.solve(p, q, a, hi, lo, np.zeros(a.shape[0], dtype=np.intc), **settings)
    return np.asarray(x, dtype=float), int(flag), int(info["iterations"]), float(info["solve_time"])


ACTIVE_SET_SOLVERS = ("daqp", "compiled")
STATUSES = ("solved", "infeasible", "failed")
PATHS = ("closed_form", "blocks", "active_set")

Csr = tuple[np.ndarray, np.ndarray, np.ndarray]  # (indptr, indices, values) of a sparse matrix, row by row
# solve_identity_qp's problem data: W (n, n) upper triangular, the fixed rows' CSR, start rows (s,), start
# variables (s,), the feasibility tolerance, the iteration limit (ExactQp.compiled_active_set)
CompiledActiveSet = tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, float, int]


@dataclass(frozen=True, eq=False)
class QpResult:
    """One solve. x (n,) the minimiser (NaN unless status is "solved"); status: solved, infeasible (no z
    satisfies the rows) or failed (the active-set solver stopped, e.g. at its iteration limit); path: which
    step of the module docstring produced x; iterations: active-set iterations (0 for the closed form)."""

    x: np.ndarray
    status: str
    path: str
    iterations: int
    message: str | None = None
    solve_time_s: float = 0.0  # DAQP's own reported time; 0 for the closed form (no clock is read here)
    fallback: bool = False  # the compiled active set did not end optimal, and DAQP's path answered

    @property
    def ok(self) -> bool:
        return self.status == "solved"


@numba.njit(cache=True)
def compiled_step_3(active_set, q, extra_a, lo, hi):  # pragma: no cover - compiled
    """Step 3 by `solve_identity_qp` for q (n,) with the problem's data active_set
    (`ExactQp.compiled_active_set`), the extra rows extra_a (m1, n) and every row's bounds lo, hi (m0 + m1,).
    Returns (exit flag, iterations, z (n,)); z is the optimum only when the flag is OPTIMAL."""
    w_upper, a_ptr, a_idx, a_val, start_rows, start_vars, tol, limit = active_set
    n = q.shape[0]
    z = np.empty(n)
    multipliers = np.empty(n + 1)
    active = np.empty(n + 1, dtype=np.int64)
    flag, _, iterations = solve_identity_qp(
        w_upper,
        q,
        a_ptr,
        a_idx,
        a_val,
        extra_a,
        lo,
        hi,
        start_rows,
        start_vars,
        tol,
        limit,
        z,
        multipliers,
        active,
    )
    return flag, iterations, z


@numba.njit(cache=True)
def closed_form_kernel(
    gain, a, rest_idx, p_rest, tol, opt_tol, q, lo, hi, z, rows, gradient
):  # pragma: no cover
    """Step 1 in one compiled pass over sparse (CSR) gain, A and P's resting rows: z = gain @ q, rows = A z,
    gradient = (P z + q)[resting]. Writes the three outputs; returns True when every row holds within tol and
    every resting gradient is >= -opt_tol. The sparsity is the per-axis split: no product with a zero."""
    g_ptr, g_idx, g_val = gain
    csr_times(g_ptr, g_idx, g_val, q, z, 0)
    ok = True
    a_ptr, a_idx, a_val = a
    csr_times(a_ptr, a_idx, a_val, z, rows, 0)
    for r in range(rows.shape[0]):
        if not (lo[r] - tol <= rows[r] <= hi[r] + tol):
            ok = False
    p_ptr, p_idx, p_val = p_rest
    for r in range(rest_idx.shape[0]):
        s = q[rest_idx[r]]
        for k in range(p_ptr[r], p_ptr[r + 1]):
            s += p_val[k] * z[p_idx[k]]
        gradient[r] = s
        if not (s >= -opt_tol):
            ok = False
    return ok


def _csr(matrix: np.ndarray) -> Csr:
    """(indptr, indices, values) of a dense matrix's non-zeros, row by row."""
    rows, cols = np.nonzero(matrix)
    indptr = np.concatenate([[0], np.cumsum(np.bincount(rows, minlength=matrix.shape[0]))]).astype(np.int64)
    return indptr, cols.astype(np.int64), np.ascontiguousarray(matrix[rows, cols], dtype=float)


def _blocks(p: np.ndarray, a: np.ndarray) -> list[np.ndarray]:
    """Connected components (index arrays, ascending) of the variables coupled by P or by a row of A."""
    n = p.shape[0]
    parent = list(range(n))

    def find(i: int) -> int:
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    def join(i: int, j: int) -> None:
        ri, rj = find(i), find(j)
        if ri != rj:
            parent[max(ri, rj)] = min(ri, rj)

    rows, cols = np.nonzero(p)
    for i, j in zip(rows.tolist(), cols.tolist(), strict=True):
        join(i, j)
    for row in a:
        support = np.flatnonzero(row).tolist()
        for j in support[1:]:
            join(support[0], j)
    roots = np.array([find(i) for i in range(n)])
    return [np.flatnonzero(roots == r) for r in np.unique(roots)]


class _Block:
    """One independent block: its variables, fixed rows, closed-form map and its own DAQP workspace."""

    def __init__(self, variables: np.ndarray, rows: np.ndarray, p: np.ndarray, a: np.ndarray) -> None:
        self.variables = variables
        self.rows = rows
        self.p = np.ascontiguousarray(p[np.ix_(variables, variables)])
        self.a = np.ascontiguousarray(a[np.ix_(rows, variables)])
        self.model: daqp.Model | None = None

    def solve(
        self, q: np.ndarray, lo: np.ndarray, hi: np.ndarray, settings: dict
    ) -> tuple[np.ndarray, int, int, float]:
        """(x of the block, DAQP exit flag, iterations, DAQP's solve time), warm-started from this block's
        previous solve."""
        q_b = q[self.variables]
        lo_b = np.maximum(lo[self.rows], -DAQP_INF)
        hi_b = np.minimum(hi[self.rows], DAQP_INF)
        model = self.model
        if model is None:
            self.model = model = daqp.Model()
            model.settings = settings
            model.setup(self.p, q_b, self.a, hi_b, lo_b, np.zeros(len(self.rows), dtype=np.intc))
        else:
            model.update(f=q_b, bupper=hi_b, blower=lo_b)
        x, _, flag, info = model.solve()
        return np.asarray(x, dtype=float), int(flag), int(info["iterations"]), float(info["solve_time"])


class ExactQp:
    """The solver of the module docstring for one fixed P (n, n) and fixed rows A (m0, n).

    resting: (n,) bool, the variables held at 0 by the closed form (each needs a fixed row 0 <= z_i, alone).
    feasibility_tol: how far (in the rows' units) a row may be violated and still count as satisfied; also
    DAQP's primal tolerance. optimality_tol: how negative a resting variable's gradient may be.
    active_set: step 3's solver, "daqp" (the working set of rows above) or "compiled"
    (controller/dual_active_set.py: the whole problem in one compiled call, DAQP's path as its fallback
    when it does not end optimal or P is singular).
    """

    def __init__(
        self,
        p: np.ndarray,
        a: np.ndarray,
        resting: np.ndarray,
        *,
        feasibility_tol: float = 1.0e-9,
        optimality_tol: float = 1.0e-9,
        iteration_limit: int = 1000,
        active_set: str = "daqp",
    ) -> None:
        if active_set not in ACTIVE_SET_SOLVERS:
            raise ValueError(f"active_set must be one of {ACTIVE_SET_SOLVERS}, got {active_set!r}")
        p = np.array(p, dtype=float)
        a = np.array(a, dtype=float)
        resting = np.asarray(resting, dtype=bool)
        n = p.shape[0]
        if p.shape != (n, n) or a.ndim != 2 or a.shape[1] != n or resting.shape != (n,):
            raise ValueError(f"shapes: P {p.shape}, A {a.shape}, resting {resting.shape} do not agree")
        if not (np.all(np.isfinite(p)) and np.all(np.isfinite(a))):
            raise ValueError("P and A must be finite")
        if np.max(np.abs(p - p.T)) > 1e-12 * max(1.0, float(np.max(np.abs(p)))):
            raise ValueError("P must be symmetric")
        free = ~resting
        p_ff = p[np.ix_(free, free)]
        try:
            chol = np.linalg.cholesky(p_ff)
        except np.linalg.LinAlgError:
            raise ValueError("P restricted to the non-resting variables must be positive definite") from None
        for i in np.flatnonzero(resting):
            alone = (a[:, i] != 0.0) & (np.count_nonzero(a, axis=1) == 1)
            if not alone.any():
                raise ValueError(f"resting variable {i} needs a fixed row that bounds it alone")
        self.n = n
        self._p = p
        self._a = a
        self._resting = resting
        self._rest_idx = np.flatnonzero(resting)
        alone = np.count_nonzero(a, axis=1) == 1
        self._rest_rows = np.flatnonzero(alone & np.any(a[:, resting] != 0.0, axis=1))
        # z = gain @ q: -P_ff^-1 on the free variables, 0 on the resting ones.
        inv_ff = np.linalg.inv(chol).T @ np.linalg.inv(chol)
        gain = np.zeros((n, n))
        gain[np.ix_(free, free)] = -inv_ff
        self._gain = gain
        self._gain_csr = _csr(gain)
        self._a_csr = _csr(a)
        self._p_rest_csr = _csr(p[resting])
        self._a_reaches = a != 0.0  # (m0, n) which variables each fixed row reaches (step 3's working set)
        self._tol = float(feasibility_tol)
        self._opt_tol = float(optimality_tol)
        self._settings = {"primal_tol": float(feasibility_tol), "iter_limit": int(iteration_limit)}
        row_block = np.full(a.shape[0], -1)  # -1: a row on no variable
        blocks = []
        for b, variables in enumerate(_blocks(p, a)):
            in_block = np.zeros(n, dtype=bool)
            in_block[variables] = True
            rows = np.flatnonzero(np.any(a[:, in_block] != 0.0, axis=1))
            row_block[rows] = b
            blocks.append(_Block(variables, rows, p, a))
        self._blocks = blocks
        self._row_block = row_block
        self._var_block = np.empty(n, dtype=int)
        for b, block in enumerate(blocks):
            self._var_block[block.variables] = b
        self._rest_row_var = np.nonzero(a[self._rest_rows])[1]  # each rest row's one variable
        # A resting variable that P couples to nothing (its only cost is its own) can be left at 0 by step 3
        # when no row it must meet is in play (see `_working_set`).
        off_diagonal = np.count_nonzero(p, axis=1) - (np.diag(p) != 0)
        self._separable_rest = resting & (off_diagonal == 0)
        # Step 3 hands DAQP its problem in the variables y = L^T z (P = L L^T), where the cost is |y|^2 / 2:
        # DAQP's set-up then has no Hessian to factor (0.03 instead of 0.14 ms at the MPC's size). L has no
        # entry between variables that P does not connect, so W = L^-T restricted to whole blocks is the same
        # map for the blocks' own P. None when P is not positive definite (resting variables with no
        # quadratic cost): step 3 then gives DAQP P itself.
        try:
            self._w: np.ndarray | None = np.linalg.inv(np.linalg.cholesky(p)).T
        except np.linalg.LinAlgError:
            self._w = None
        self._w_sub: dict[bytes, np.ndarray] = {}  # W restricted to a round's variables, by their mask
        self._compiled = active_set == "compiled" and self._w is not None
        # the compiled solver's own W: upper triangular exactly (its loops skip the lower part), row-major
        self._w_upper = np.ascontiguousarray(np.triu(self._w)) if self._w is not None else None
        self._iteration_limit = int(iteration_limit)
        # The compiled solver starts with the separable resting variables at 0, their rows active.
        starts = self._separable_rest[self._rest_row_var]
        self._start_rows = self._rest_rows[starts].astype(np.int64)
        self._start_vars = self._rest_row_var[starts].astype(np.int64)
        self._active_set_data: CompiledActiveSet | None = None
        if self._compiled:
            assert self._w_upper is not None
            self._active_set_data = (
                self._w_upper,
                *self._a_csr,
                self._start_rows,
                self._start_vars,
                self._tol,
                self._iteration_limit,
            )

    @property
    def block_count(self) -> int:
        return len(self._blocks)

    def closed_form(self, q: np.ndarray) -> np.ndarray:
        """(n,) step 1's candidate for q (n,): -P_ff^-1 q_f on the free variables, 0 on the resting ones."""
        return self._gain @ q

    @property
    def kernel_data(self) -> tuple[Csr, Csr, np.ndarray, Csr, float, float]:
        """The leading arguments of `closed_form_kernel` for this problem (sparse gain, A, resting rows of P,
        tolerances), for callers that run step 1 inside their own compiled code and then call `finish`."""
        return (self._gain_csr, self._a_csr, self._rest_idx, self._p_rest_csr, self._tol, self._opt_tol)

    @property
    def compiled_active_set(self) -> CompiledActiveSet | None:
        """The arguments of `solve_identity_qp` that belong to this problem (W upper triangular, the fixed
        rows as CSR, the start rows and variables, the feasibility tolerance, the iteration limit), None when
        step 3 is DAQP's: for callers that run step 3 inside their own compiled code
        (mpc_kernels.solve_with_planes)."""
        return self._active_set_data

    @property
    def row_count(self) -> int:
        return self._a.shape[0]

    @property
    def resting_count(self) -> int:
        return self._rest_idx.shape[0]

    def solve(
        self,
        q: np.ndarray,
        lo: np.ndarray,
        hi: np.ndarray,
        extra_a: np.ndarray | None = None,
        extra_lo: np.ndarray | None = None,
        extra_hi: np.ndarray | None = None,
    ) -> QpResult:
        """Minimise for q (n,), fixed-row bounds lo, hi (m0,) and optional extra rows (m1, n) with bounds
        (m1,). Bounds may be +-inf. Returns the exact minimiser (to DAQP's tolerances when step 2 or 3
        ran)."""
        z = np.empty(self.n)
        rows = np.empty(self._a.shape[0])
        gradient = np.empty(self._rest_idx.shape[0])
        ok = closed_form_kernel(*self.kernel_data, q, lo, hi, z, rows, gradient)
        return self.finish(q, lo, hi, ok, z, rows, gradient, extra_a, extra_lo, extra_hi)

    def finish(
        self,
        q: np.ndarray,
        lo: np.ndarray,
        hi: np.ndarray,
        closed_form_ok: bool,
        z: np.ndarray,
        rows: np.ndarray,
        gradient: np.ndarray,
        extra_a: np.ndarray | None = None,
        extra_lo: np.ndarray | None = None,
        extra_hi: np.ndarray | None = None,
    ) -> QpResult:
        """Steps 2 and 3 after step 1 ran (`closed_form_kernel`: its verdict and its outputs z (n,), rows
        (m0,), gradient (resting,), which this may overwrite); the extra rows are checked here."""
        extra = extra_a is not None and extra_a.shape[0] > 0
        iterations, time_s = 0, 0.0
        extra_rows = np.zeros(0)  # the extra rows' values at z
        if closed_form_ok:
            # Every block's closed form is optimal for its own rows, so only extra rows can have failed.
            if not extra:
                return QpResult(x=z, status="solved", path="closed_form", iterations=0)
            assert extra_a is not None and extra_lo is not None and extra_hi is not None
            extra_rows = extra_a @ z
            if not self._missed(extra_rows, extra_lo, extra_hi).any():
                return QpResult(x=z, status="solved", path="closed_form", iterations=0)
        else:
            # Step 2: re-solve only the blocks whose own rows or resting variables fail.
            bad_rows = self._missed(rows, lo, hi)
            bad_rest = ~(gradient >= -self._opt_tol)
            failing = set(self._var_block[self._rest_idx[bad_rest]].tolist())
            failing.update(self._row_block[bad_rows & (self._row_block >= 0)].tolist())
            for b in sorted(failing):
                block = self._blocks[b]
                x_b, flag, its, t_s = block.solve(q, lo, hi, self._settings)
                iterations += its
                time_s += t_s
                if flag < 0:
                    return self._failed(flag, iterations)
                z[block.variables] = x_b
            coupling_ok = True
            if extra:
                assert extra_a is not None and extra_lo is not None and extra_hi is not None
                extra_rows = extra_a @ z
                coupling_ok = not self._missed(extra_rows, extra_lo, extra_hi).any()
            if coupling_ok and failing:
                return QpResult(
                    x=z, status="solved", path="blocks", iterations=iterations, solve_time_s=time_s
                )

        # Step 3: the whole problem, by a working set of rows. DAQP's set-up grows with its rows and variables
        # and is most of its cost here (a cold set-up with every row: 0.21 ms, its solve 0.01 ms), so each
        # round gets only what can matter (`_working_set`): the rows the answer so far misses (and the
        # resting variables' bounds) and the variables they reach. A relaxation whose optimum meets the rows
        # left out is optimal with them too; rows it misses join the next round.
        if not extra:
            extra_a, extra_lo, extra_hi = np.zeros((0, self.n)), np.zeros(0), np.zeros(0)
        assert extra_a is not None and extra_lo is not None and extra_hi is not None
        fallback = False
        if self._compiled:
            result = self._solve_compiled(q, lo, hi, extra_a, extra_lo, extra_hi, iterations)
            if result is not None:
                return result
            fallback = True
        lo_all = np.maximum(np.concatenate([lo, extra_lo]), -DAQP_INF)
        hi_all = np.minimum(np.concatenate([hi, extra_hi]), DAQP_INF)
        keep = np.zeros(lo_all.shape[0], dtype=bool)
        keep[self._rest_rows] = True
        x = z
        m0 = self._a.shape[0]
        # the closed form's row values are at hand when only extra rows failed
        values = np.concatenate([rows, extra_rows]) if closed_form_ok else None
        for round_ in range(WORKING_SET_ROUNDS + 1):
            if values is None:
                values = np.concatenate([self._a @ x, extra_a @ x])
            missed = self._missed(values, lo_all, hi_all)
            if round_ > 0 and not (missed & ~keep).any():
                break
            keep = np.ones_like(keep) if round_ == WORKING_SET_ROUNDS else keep | missed
            variables, kept, idle = self._working_set(keep[:m0], keep[m0:], extra_a, q)
            a_sub = np.vstack([self._a[kept[:m0]], extra_a[kept[m0:]]])[:, variables]
            x_sub, flag, its, t_s = self._solve_relaxation(variables, q, a_sub, lo_all[kept], hi_all[kept])
            iterations += its
            time_s += t_s
            if flag < 0:  # a relaxation without a solution: nor has the whole
                return self._failed(flag, iterations, fallback=fallback)
            x = x.copy()
            x[variables] = x_sub
            x[idle] = 0.0
            values = None
        return QpResult(
            x=x,
            status="solved",
            path="active_set",
            iterations=iterations,
            solve_time_s=time_s,
            fallback=fallback,
        )

    def _solve_compiled(
        self,
        q: np.ndarray,
        lo: np.ndarray,
        hi: np.ndarray,
        extra_a: np.ndarray,
        extra_lo: np.ndarray,
        extra_hi: np.ndarray,
        iterations: int,
    ) -> QpResult | None:
        """Step 3 by `solve_identity_qp` on every row; None (DAQP's path then runs) unless it ends
        optimal, so an infeasible verdict or the iteration limit is always confirmed by DAQP."""
        solver = self.compiled_active_set
        assert solver is not None
        flag, its, x = compiled_step_3(
            solver,
            q,
            np.ascontiguousarray(extra_a, dtype=float),
            np.concatenate([lo, extra_lo]),
            np.concatenate([hi, extra_hi]),
        )
        if flag != OPTIMAL:
            return None
        return QpResult(x=x, status="solved", path="active_set", iterations=iterations + its)

    def _missed(self, values: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
        """(m,) bool: which row values (m,) lie outside lo, hi (m,) by more than the feasibility tolerance."""
        return (values < lo - self._tol) | (values > hi + self._tol)

    def _solve_relaxation(
        self, variables: np.ndarray, q: np.ndarray, a_sub: np.ndarray, lo: np.ndarray, hi: np.ndarray
    ) -> tuple[np.ndarray, int, int, float]:
        """`_daqp_solve` of step 3's problem on the given variables (n,) bool with rows a_sub (r, k), in
        y = L^T z when P allows (then mapped back): (z of the variables, flag, iterations, time)."""
        if self._w is None:
            p_sub = np.ascontiguousarray(self._p[variables][:, variables])
            return _daqp_solve(p_sub, q[variables], a_sub, lo, hi, self._settings)
        w = self._w_restricted(variables)
        y, flag, its, t_s = _daqp_solve(
            np.eye(w.shape[0]), w.T @ q[variables], a_sub @ w, lo, hi, self._settings
        )
        return w @ y, flag, its, t_s

    def _w_restricted(self, variables: np.ndarray) -> np.ndarray:
        """W (k, k) on the variables (n,) bool. Cached: a flight's rounds solve few distinct sets of blocks
        (the cache is emptied when it holds W_CACHE_SIZE of them)."""
        assert self._w is not None
        key = variables.tobytes()
        w = self._w_sub.get(key)
        if w is None:
            if len(self._w_sub) >= W_CACHE_SIZE:
                self._w_sub.clear()
            # sliced as rows then columns, not np.ix_: the layout decides BLAS's round-off downstream
            w = self._w_sub[key] = self._w[variables][:, variables]
        return w

    def _working_set(
        self, keep_fixed: np.ndarray, keep_extra: np.ndarray, extra_a: np.ndarray, q: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """What one round of step 3 solves, given the kept fixed rows (m0,) and extra rows (m1,) (bool):
        (variables (n,) bool, rows (m0 + m1,) bool, idle (n,) bool).

        The variables are the blocks the kept rows reach (the rest keep their step 1-2 values, optimal for
        their own blocks with all their rows; no row or P entry joins them to the ones solved), less the
        idle ones: resting variables that P couples to nothing, with a cost that rises from 0 (q >= 0) and
        no kept row but their bound 0 <= z; their optimum is 0 whatever the others do. The rows are the kept
        ones that reach only the variables solved (a resting variable's bound goes with it)."""
        keep_fixed = keep_fixed.copy()
        keep_fixed[self._rest_rows] = False
        reached = self._a_reaches[keep_fixed].any(axis=0) | (extra_a[keep_extra] != 0.0).any(axis=0)
        block_reached = np.zeros(len(self._blocks), dtype=bool)
        block_reached[self._var_block[reached]] = True
        variables = block_reached[self._var_block]
        idle = variables & self._separable_rest & ~reached & (q >= 0.0)
        variables &= ~idle
        keep_fixed[self._rest_rows] = variables[self._rest_row_var]
        return variables, np.concatenate([keep_fixed, keep_extra]), idle

    def _failed(self, flag: int, iterations: int, *, fallback: bool = False) -> QpResult:
        status = "infeasible" if flag == -1 else "failed"
        return QpResult(
            x=np.full(self.n, np.nan),
            status=status,
            path="active_set",
            iterations=iterations,
            message=f"DAQP exit flag {flag}",
            fallback=fallback,
        )

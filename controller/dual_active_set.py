"""A compiled dual active-set solver (Goldfarb and Idnani, 1983) for QPs whose Hessian is the identity.

    minimise   |y|^2 / 2 + c^T y     subject to   lo <= A W y <= hi

with the rows given in the original variables z = W y (W = L^-T for P = L L^T, c = W^T q), so this is
min z^T P z / 2 + q^T z, lo <= A z <= hi. controller/qp.py hands it step 3's whole problem in one call
(`MpcParams.active_set = "compiled"`), where DAQP needs a working set of rows, a set-up per round and a dozen
numpy calls around each.

The method: start at the unconstrained optimum y = -c and repeatedly take the most violated row into the
active set, moving y and the active rows' multipliers u along the directions that keep the active rows
tight and u >= 0, and dropping an active row whose multiplier reaches 0 on the way. Every iterate is the
optimum of the problem with its active rows as equalities (dual feasible); the first that violates no row
is the optimum. The active normals N are kept as N = J[:, :k] R (J orthogonal (n, n), R upper triangular
(k, k)), updated by Givens rotations, so each iteration costs O(n^2) and no system is solved from scratch.

Rows are read in place, the fixed ones as CSR, the per-solve (extra) ones dense, turned into CSR once per
solve (their zeros skipped: a half-plane row of step n reaches only the inputs before it and one slack): a
row's value is a^T z, and its normal in y, W^T a, is computed only for a row that enters the active set. J
is kept transposed and W's transpose beside it, so that rotations and products run along memory; every sum
still adds its terms in the same order, so the answer is the same to the bit as with the plain layout. The
row values (`sparse_rows.csr_times`), J^T n and W^T q are summed four rows side by side, each sum still in
its own order, so that their additions overlap instead of waiting on one another; terms, columns and
rotations that are exactly zero or the identity are skipped, which changes no sum that starts at +0.0 (at
most the sign of a zero in J, which no sum or rotation can see). The closed form's resting variables start
in the active set at 0 (`solve_identity_qp`'s start rows), so a solve where only a few rows bind takes a
few iterations. Exit flags: 1 optimal, -1 infeasible (a violated row whose normal the active normals span,
with no active row to give way), -2 iteration limit.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from controller.sparse_rows import csr_times

OPTIMAL, INFEASIBLE, ITERATION_LIMIT = 1, -1, -2

_DEPENDENT = 1.0e-12
"""A row whose normal lies in the active normals' span to within this (relative) is linearly dependent."""


@numba.njit(cache=True)
def _sparse(dense, ptr, idx, val):  # pragma: no cover - compiled
    """The nonzeros of dense (m, n) as CSR into ptr (m + 1,), idx and val (m n,), column order kept."""
    count = 0
    for r in range(dense.shape[0]):
        ptr[r] = count
        for c in range(dense.shape[1]):
            if dense[r, c] != 0.0:
                idx[count] = c
                val[count] = dense[r, c]
                count += 1
    ptr[dense.shape[0]] = count


@numba.njit(cache=True)
def _nonzero_indices(vector, out):  # pragma: no cover - compiled
    """Write the indices of vector's nonzero entries (n,), ascending, into out (n,); return how many."""
    count = 0
    for i in range(vector.shape[0]):
        if vector[i] != 0.0:
            out[count] = i
            count += 1
    return count


@numba.njit(cache=True)
def _transpose_times(j_t, normal, nonzero, nz, d):  # pragma: no cover - compiled
    """d (n,) = J^T normal for J given as j_t = J^T (J^T n, and W^T q), over normal's nz nonzero entries
    (indices `nonzero`, ascending): each d[i] sums its terms in that order (skipping a zero term never changes
    a sum that starts at +0.0), four rows of j_t side by side so that the sums' additions overlap."""
    nf = j_t.shape[0]
    i = 0
    while i + 4 <= nf:
        r0, r1, r2, r3 = j_t[i], j_t[i + 1], j_t[i + 2], j_t[i + 3]
        s0 = s1 = s2 = s3 = 0.0
        for e in range(nz):
            t = nonzero[e]
            v = normal[t]
            s0 += r0[t] * v
            s1 += r1[t] * v
            s2 += r2[t] * v
            s3 += r3[t] * v
        d[i], d[i + 1], d[i + 2], d[i + 3] = s0, s1, s2, s3
        i += 4
    while i < nf:
        s = 0.0
        row = j_t[i]
        for e in range(nz):
            t = nonzero[e]
            s += row[t] * normal[t]
        d[i] = s
        i += 1


@numba.njit(cache=True)
def _row_values(a_ptr, a_idx, a_val, e_ptr, e_idx, e_val, z, values):  # pragma: no cover - compiled
    """values (m0 + m1,) = the fixed rows and the extra rows (both CSR) at z (n,). The extra rows' zeros
    are skipped: with z finite, a sum from +0.0 is never -0.0, so adding 0 * z[c] never changes it."""
    csr_times(a_ptr, a_idx, a_val, z, values, 0)
    csr_times(e_ptr, e_idx, e_val, z, values, a_ptr.shape[0] - 1)


@numba.njit(cache=True)
def _normal(a_ptr, a_idx, a_val, extra_a, w, row, sign, out):  # pragma: no cover - compiled
    """out (n,) = sign * W^T a for row `row` (fixed rows first, then extra rows), W upper triangular."""
    nf = w.shape[0]
    out[:] = 0.0
    m0 = a_ptr.shape[0] - 1
    if row < m0:
        for k in range(a_ptr[row], a_ptr[row + 1]):
            c, v = a_idx[k], sign * a_val[k]
            for i in range(c, nf):
                out[i] += w[c, i] * v
    else:
        r = row - m0
        for c in range(nf):
            v = sign * extra_a[r, c]
            if v != 0.0:
                for i in range(c, nf):
                    out[i] += w[c, i] * v


@numba.njit(cache=True)
def _upper_times(w_t, y, z):  # pragma: no cover - compiled
    """z (n,) = W y for W (n, n) upper triangular, given as w_t = W^T: each z[i] summed over its columns in
    order, the columns outermost so that the sums run side by side along memory."""
    z[:] = 0.0
    for col in range(w_t.shape[0]):
        w_col, y_col = w_t[col], y[col]
        if y_col == 0.0:
            continue
        for i in range(col + 1):
            z[i] += w_col[i] * y_col


@numba.njit(cache=True)
def _rotate_columns(j_t, a, b, cs, sn):  # pragma: no cover - compiled
    """Columns a, b of J become cs J_a + sn J_b and -sn J_a + cs J_b (rows a, b of j_t = J^T: contiguous)."""
    ja, jb = j_t[a], j_t[b]
    for i in range(ja.shape[0]):
        x, y = ja[i], jb[i]
        ja[i] = cs * x + sn * y
        jb[i] = -sn * x + cs * y


@numba.njit(cache=True)
def _drop(j_t, r_mat, u, active, k, l):  # pragma: no cover - compiled
    """Remove active row l of k: shift R's columns, u and active left, restore R's triangle by rotations of
    its rows (and the same rotations of J's columns, rows of j_t = J^T). Returns k - 1."""
    for c in range(l, k - 1):
        for i in range(k):
            r_mat[i, c] = r_mat[i, c + 1]
        u[c] = u[c + 1]
        active[c] = active[c + 1]
    for i in range(k):
        r_mat[i, k - 1] = 0.0
    for j in range(l, k - 1):
        x, y = r_mat[j, j], r_mat[j + 1, j]
        h = math.hypot(x, y)
        if h == 0.0:
            continue
        cs, sn = x / h, y / h
        for c in range(j, k - 1):
            p, q = r_mat[j, c], r_mat[j + 1, c]
            r_mat[j, c] = cs * p + sn * q
            r_mat[j + 1, c] = -sn * p + cs * q
        r_mat[j + 1, j] = 0.0
        _rotate_columns(j_t, j, j + 1, cs, sn)
    return k - 1


@numba.njit(cache=True)
def solve_identity_qp(
    w,
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
    iteration_limit,
    z,
    multipliers,
    active,
):  # pragma: no cover - compiled
    """Solve the module's QP for q (n,). w (n, n) is W (upper triangular); rows: fixed (CSR, m0 rows)
    then extra (m1, n) dense; lo, hi (m0 + m1,) may be +-inf; tol is the rows' feasibility tolerance.

    start_rows, start_vars (s,): fixed rows 0 <= a z_v (a > 0, nothing else in the row) of variables v that
    neither P nor W couple to any other (so the row's normal in y is a W_vv e_v), taken as active from the
    start with z_v = 0 where their multiplier c_v / (a W_vv) is >= 0: the closed form's resting variables,
    which would otherwise each cost an iteration.

    Writes z (n,) = W y (the optimum; only meaningful when the flag is OPTIMAL), and for the k active rows
    multipliers (k,) >= 0 and active (k,) = 2 row + side (side 0: the row's lower bound, 1: its upper
    one). Returns (flag, k, iterations)."""
    nf = w.shape[0]
    m = lo.shape[0]
    w_t = np.ascontiguousarray(w.T)
    normal = np.empty(nf)
    nonzero = np.empty(nf, dtype=np.int64)
    nz = _nonzero_indices(q, nonzero)
    c = np.empty(nf)  # W^T q: the zeros right of w_t's diagonal change no sum (q is finite)
    _transpose_times(w_t, q, nonzero, nz, c)
    y = -c
    j_t = np.zeros((nf, nf))  # J^T: J's columns as rows, so rotations and J d run along memory
    r_mat = np.zeros((nf, nf))
    u = np.zeros(nf + 1)
    act = np.zeros(nf + 1, dtype=np.int64)
    in_set = np.zeros(2 * m, dtype=np.bool_)
    values = np.empty(m)
    d = np.empty(nf)
    step = np.empty(nf)
    r_dir = np.empty(nf)
    taken = np.zeros(nf, dtype=np.bool_)
    m1 = extra_a.shape[0]
    e_ptr = np.empty(m1 + 1, dtype=np.int64)
    e_idx = np.empty(m1 * nf, dtype=np.int64)
    e_val = np.empty(m1 * nf)
    _sparse(extra_a, e_ptr, e_idx, e_val)
    k = 0
    for t in range(start_rows.shape[0]):
        row, v = start_rows[t], start_vars[t]
        coef = 0.0
        for e in range(a_ptr[row], a_ptr[row + 1]):
            coef += a_val[e]
        diag = coef * w[v, v]
        if lo[row] == 0.0 and diag > 0.0 and c[v] >= 0.0 and not taken[v]:
            y[v] = 0.0
            j_t[k, v] = 1.0
            r_mat[k, k] = diag
            u[k] = c[v] / diag
            act[k] = 2 * row
            in_set[2 * row] = True
            taken[v] = True
            k += 1
    col = k
    for i in range(nf):
        if not taken[i]:
            j_t[col, i] = 1.0
            col += 1
    iterations = 0
    flag = ITERATION_LIMIT
    while iterations < iteration_limit:
        _upper_times(w_t, y, z)
        _row_values(a_ptr, a_idx, a_val, e_ptr, e_idx, e_val, z, values)
        worst, row, side = tol, -1, 0
        for r in range(m):
            if values[r] < lo[r] - worst and not in_set[2 * r]:
                worst, row, side = lo[r] - values[r], r, 0
            if values[r] > hi[r] + worst and not in_set[2 * r + 1]:
                worst, row, side = values[r] - hi[r], r, 1
        if row < 0:
            flag = OPTIMAL
            break
        sign = 1.0 if side == 0 else -1.0
        bound = lo[row] if side == 0 else -hi[row]
        _normal(a_ptr, a_idx, a_val, extra_a, w, row, sign, normal)
        norm2 = 0.0
        for i in range(nf):
            norm2 += normal[i] * normal[i]
        u_new = 0.0
        added = False
        nz = _nonzero_indices(normal, nonzero)
        while iterations < iteration_limit and not added:
            iterations += 1
            _transpose_times(j_t, normal, nonzero, nz, d)  # d = J^T n
            free2 = 0.0  # |d[k:]|^2 = n^T step
            for i in range(k, nf):
                free2 += d[i] * d[i]
            # the primal step direction J[:, k:] d[k:], summed over t in the same order for every i
            step[:] = 0.0
            for t in range(k, nf):
                j_row, d_t = j_t[t], d[t]
                if d_t == 0.0:
                    continue
                for i in range(nf):
                    step[i] += j_row[i] * d_t
            for i in range(k - 1, -1, -1):  # the dual direction R^-1 d[:k]
                s = d[i]
                for t in range(i + 1, k):
                    s -= r_mat[i, t] * r_dir[t]
                r_dir[i] = s / r_mat[i, i]
            t_primal = np.inf
            if free2 > _DEPENDENT * _DEPENDENT * norm2:
                slack = bound
                for i in range(nf):
                    slack -= normal[i] * y[i]
                t_primal = max(slack, 0.0) / free2
            t_dual, drop_at = np.inf, -1
            for i in range(k):
                if r_dir[i] > 0.0 and u[i] / r_dir[i] < t_dual:
                    t_dual, drop_at = u[i] / r_dir[i], i
            t = min(t_primal, t_dual)
            if t == np.inf:
                return INFEASIBLE, k, iterations
            if t_primal < np.inf:
                for i in range(nf):
                    y[i] += t * step[i]
            for i in range(k):
                u[i] -= t * r_dir[i]
            u_new += t
            if t_primal <= t_dual:
                for jj in range(nf - 1, k, -1):  # rotate d[k+1:] into d[k]
                    x, yy = d[jj - 1], d[jj]
                    if yy == 0.0 and x >= 0.0:
                        continue
                    h = math.hypot(x, yy)
                    if h == 0.0:
                        continue
                    cs, sn = x / h, yy / h
                    d[jj - 1], d[jj] = h, 0.0
                    _rotate_columns(j_t, jj - 1, jj, cs, sn)
                for i in range(k + 1):
                    r_mat[i, k] = d[i]
                u[k] = u_new
                act[k] = 2 * row + side
                in_set[2 * row + side] = True
                k += 1
                added = True
            else:
                in_set[act[drop_at]] = False
                k = _drop(j_t, r_mat, u, act, k, drop_at)
    for i in range(k):
        multipliers[i] = u[i]
        active[i] = act[i]
    return flag, k, iterations

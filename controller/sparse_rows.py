"""Products of a matrix in compressed sparse rows (CSR: row pointers, column indices, values) with a vector,
compiled: the closed form's gain and rows (controller/qp.py) and the active set's row values
(controller/dual_active_set.py) are such products, evaluated on every solve and every iteration."""

from __future__ import annotations

import numba


@numba.njit(cache=True)
def csr_times(ptr, idx, val, x, out, first):  # pragma: no cover - compiled
    """out[first + r] = row r of the CSR matrix (ptr (m + 1,), idx, val) at x (n,), summed from +0.0 over
    the row's entries in order. Four rows are summed side by side, each sum in its own order, so that their
    additions overlap instead of waiting on one another: the same bits as one row after the other."""
    rows = ptr.shape[0] - 1
    r = 0
    while r + 4 <= rows:
        b0, b1, b2, b3 = ptr[r], ptr[r + 1], ptr[r + 2], ptr[r + 3]
        common = min(ptr[r + 1] - b0, ptr[r + 2] - b1, ptr[r + 3] - b2, ptr[r + 4] - b3)
        s0 = s1 = s2 = s3 = 0.0
        for e in range(common):
            s0 += val[b0 + e] * x[idx[b0 + e]]
            s1 += val[b1 + e] * x[idx[b1 + e]]
            s2 += val[b2 + e] * x[idx[b2 + e]]
            s3 += val[b3 + e] * x[idx[b3 + e]]
        for k in range(b0 + common, ptr[r + 1]):
            s0 += val[k] * x[idx[k]]
        for k in range(b1 + common, ptr[r + 2]):
            s1 += val[k] * x[idx[k]]
        for k in range(b2 + common, ptr[r + 3]):
            s2 += val[k] * x[idx[k]]
        for k in range(b3 + common, ptr[r + 4]):
            s3 += val[k] * x[idx[k]]
        out[first + r] = s0
        out[first + r + 1] = s1
        out[first + r + 2] = s2
        out[first + r + 3] = s3
        r += 4
    while r < rows:
        s = 0.0
        for k in range(ptr[r], ptr[r + 1]):
            s += val[k] * x[idx[k]]
        out[first + r] = s
        r += 1

"""Specification of the compiled CSR product (controller/sparse_rows.py): the same bits as summing each row
on its own, in order."""

from __future__ import annotations

import numpy as np

from controller.sparse_rows import csr_times


def sequential_sum(values, weights) -> float:
    """The plain sum from +0.0, one term after another in the given order (Python floats: IEEE doubles)."""
    s = 0.0
    for v, w in zip(values, weights, strict=True):
        s += float(v) * float(w)
    return s


def test_rows_summed_side_by_side_are_each_rows_sum_in_order_to_the_bit():
    """Rows summed four side by side give each row's plain in-order sum exactly, for rows of any length
    (0 to 30 terms, so blocks of four have unequal lengths) and any count (not a multiple of four)."""
    rng = np.random.default_rng(7)
    n, m = 40, 23
    lengths = rng.integers(0, 31, m)
    ptr = np.concatenate([[0], np.cumsum(lengths)]).astype(np.int64)
    idx = np.concatenate([np.sort(rng.choice(n, size=k, replace=False)) for k in lengths]).astype(np.int64)
    val = rng.normal(size=ptr[-1]) * 10.0 ** rng.integers(-8, 9, ptr[-1])
    z = rng.normal(size=n) * 10.0 ** rng.integers(-8, 9, n)
    values = np.full(m + 2, np.nan)
    csr_times(ptr, idx, val, z, values, 2)
    expected = [sequential_sum(val[ptr[r] : ptr[r + 1]], z[idx[ptr[r] : ptr[r + 1]]]) for r in range(m)]
    assert [float(x).hex() for x in values[2:]] == [x.hex() for x in expected]

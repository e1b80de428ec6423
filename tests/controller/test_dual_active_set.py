"""Specification of the compiled dual active-set solver (controller/dual_active_set.py) on its own: the
minimiser of small QPs against CVXPY + Clarabel, rows entering and leaving the active set, resting variables
that start at 0 and leave it when a row needs them, infeasible rows and the iteration limit. Its use as the
MPC's active-set step is specified in test_qp.py."""

from __future__ import annotations

import numpy as np
import pytest
from test_qp import cvxpy_qp_reference
from test_sparse_rows import sequential_sum

from controller.dual_active_set import (
    INFEASIBLE,
    ITERATION_LIMIT,
    OPTIMAL,
    _transpose_times,
    solve_identity_qp,
)
from controller.qp import _csr

NO_START = np.zeros(0, dtype=np.int64)


def solve(p, q, a, lo, hi, *, extra_rows=0, start_rows=NO_START, start_vars=NO_START, limit=1000):
    """(flag, x, active count, iterations) of min x^T P x / 2 + q^T x, lo <= A x <= hi; the last
    `extra_rows` rows of A are handed to the solver as its dense per-solve rows, the others as CSR."""
    n = p.shape[0]
    w = np.ascontiguousarray(np.triu(np.linalg.inv(np.linalg.cholesky(p)).T))
    fixed, extra = a[: a.shape[0] - extra_rows], np.ascontiguousarray(a[a.shape[0] - extra_rows :])
    x, multipliers, active = np.empty(n), np.empty(n + 1), np.empty(n + 1, dtype=np.int64)
    flag, k, its = solve_identity_qp(
        w, q, *_csr(fixed), extra, lo, hi, start_rows, start_vars, 1e-9, limit, x, multipliers, active
    )
    if flag == OPTIMAL:
        assert np.all(multipliers[:k] >= 0.0)
    return flag, x, k, its


def test_the_corner_of_two_rows_is_the_minimiser():
    """min |x - (10, 10)|^2 / 2 with y <= 0 and x - y <= 5: the first row taken (y <= 0, missed by 10)
    leaves (10, 0), which misses the second; with both the optimum is their corner (5, 0)."""
    flag, x, k, its = solve(
        np.eye(2),
        np.array([-10.0, -10.0]),
        np.array([[0.0, 1.0], [1.0, -1.0]]),
        np.full(2, -np.inf),
        np.array([0.0, 5.0]),
        extra_rows=1,
    )
    assert (flag, k, its) == (OPTIMAL, 2, 2)
    np.testing.assert_allclose(x, [5.0, 0.0], atol=1e-12)


def random_problem(rng: np.random.Generator):
    """A dense QP of 8 variables and 14 two-sided rows whose unconstrained minimiser misses several rows."""
    n, m = 8, 14
    root = rng.normal(size=(n, n))
    p = root @ root.T + 0.5 * np.eye(n)
    q = rng.normal(0.0, 5.0, n)
    a = rng.normal(size=(m, n)) * (rng.random((m, n)) < 0.6)
    centre = a @ rng.normal(0.0, 0.3, n)
    width = rng.uniform(0.2, 2.0, m)
    lo = np.where(rng.random(m) < 0.2, -np.inf, centre - width)
    hi = np.where(rng.random(m) < 0.2, np.inf, centre + width)
    return p, q, a, lo, hi


def test_random_dense_problems_match_cvxpy_and_rows_leave_the_active_set():
    """200 random problems: the minimiser equals CVXPY + Clarabel's to 1e-6, and on some of them a row
    taken into the active set had to leave it again (more iterations than rows active at the end)."""
    worst, dropped = 0.0, 0
    for seed in range(200):
        p, q, a, lo, hi = random_problem(np.random.default_rng(seed))
        flag, x, k, its = solve(p, q, a, lo, hi, extra_rows=7)
        assert flag == OPTIMAL
        worst = max(worst, float(np.max(np.abs(x - cvxpy_qp_reference(p, q, a, lo, hi)))))
        dropped += its > k
    assert worst < 1e-6
    assert dropped >= 10


@pytest.mark.parametrize(("slack_cost", "expected"), [(10.0, (5.0, 0.0)), (1.0, (4.5, 0.5))])
def test_a_resting_slack_leaves_zero_only_when_it_is_cheaper_than_the_row(slack_cost, expected):
    """min (x - 3)^2 / 2 + c w + w^2 / 2 with x + w >= 5 and w >= 0 (w starts at rest, its row active): at
    x = 5 the row costs 2 per m, so a slack costing c = 10 stays at 0, and one costing c = 1 gives way to
    w = 0.5, x = 4.5 (where the row's price, 2 - w, equals the slack's, 1 + w)."""
    flag, x, _, _ = solve(
        np.eye(2),
        np.array([-3.0, slack_cost]),
        np.array([[0.0, 1.0], [1.0, 1.0]]),
        np.array([0.0, 5.0]),
        np.array([np.inf, np.inf]),
        extra_rows=1,
        start_rows=np.array([0], dtype=np.int64),
        start_vars=np.array([1], dtype=np.int64),
    )
    assert flag == OPTIMAL
    np.testing.assert_allclose(x, expected, atol=1e-12)


def test_a_resting_variable_with_a_negative_cost_does_not_start_at_rest():
    """A start row is taken only where its multiplier is >= 0: with q_w = -1 the minimiser is w = 1."""
    flag, x, k, _ = solve(
        np.eye(2),
        np.array([0.0, -1.0]),
        np.array([[0.0, 1.0]]),
        np.array([0.0]),
        np.array([np.inf]),
        start_rows=np.array([0], dtype=np.int64),
        start_vars=np.array([1], dtype=np.int64),
    )
    assert (flag, k) == (OPTIMAL, 0)
    np.testing.assert_allclose(x, [0.0, 1.0], atol=1e-12)


def test_contradictory_rows_are_infeasible():
    flag, _, _, _ = solve(
        np.eye(2),
        np.zeros(2),
        np.array([[1.0, 0.0], [1.0, 0.0]]),
        np.array([1.0, -np.inf]),
        np.array([np.inf, 0.0]),
    )
    assert flag == INFEASIBLE


def test_the_iteration_limit_is_reported_not_a_partial_answer():
    p, q, a, lo, hi = random_problem(np.random.default_rng(0))
    assert solve(p, q, a, lo, hi, limit=1)[0] == ITERATION_LIMIT


def test_j_transpose_times_a_normal_skips_its_zeros_without_changing_a_bit():
    """d = J^T n over n's nonzero entries only, four rows side by side, equals the plain in-order sums over
    every entry to the bit, for a row count that is not a multiple of four and J with zeros of both signs."""
    rng = np.random.default_rng(8)
    size = 23
    j_t = rng.normal(size=(size, size)) * (rng.random((size, size)) < 0.7)
    j_t[rng.random((size, size)) < 0.1] = -0.0
    normal = rng.normal(size=size) * (rng.random(size) < 0.5)
    nonzero = np.flatnonzero(normal).astype(np.int64)
    d = np.full(size, np.nan)
    _transpose_times(j_t, normal, np.concatenate([nonzero, [0] * (size - nonzero.size)]), nonzero.size, d)
    expected = [sequential_sum(j_t[i], normal) for i in range(size)]
    assert [float(x).hex() for x in d] == [x.hex() for x in expected]

"""Specification of the exact QP layer (controller/qp.py) and of the MPC's exact solver built on it: the same
minimiser as OSQP (tight tolerances, polished) and as CVXPY (HiGHS for the MPC's QPs, Clarabel for the generic
ones), to 1e-6, on 260 instances, most of them with active constraints."""

from __future__ import annotations

import functools
from typing import NamedTuple

import cvxpy as cp
import numpy as np
import osqp
import pytest
import scipy.sparse as sp
from test_mpc import KINDS, cvxpy_mpc_problem, psd_root, random_case, solve_by_clarabel

from controller.mpc import HalfPlanes, ModelPredictiveController, MpcParams
from controller.qp import ExactQp

TOL = 1e-6


# --------------------------------------------------------------------------------------- generic problems
def osqp_reference(p, q, a, lo, hi) -> np.ndarray:
    solver = osqp.OSQP()
    solver.setup(
        sp.csc_matrix(np.triu(p)),
        q,
        sp.csc_matrix(a),
        lo,
        hi,
        eps_abs=1e-11,
        eps_rel=1e-11,
        max_iter=500_000,
        polishing=True,
        verbose=False,
    )
    result = solver.solve(raise_error=False)
    assert result.info.status == "solved"
    return np.asarray(result.x)


class QpModel(NamedTuple):
    """A CVXPY model of a generic QP (`qp_model`): the problem, its variable x and its parameters."""

    problem: cp.Problem
    x: cp.Variable
    root: cp.Parameter  # R with R^T R = P
    q: cp.Parameter
    a_hi: cp.Parameter  # A with the rows of an infinite upper bound zeroed
    hi: cp.Parameter  # the upper bounds, 1 where infinite
    a_lo: cp.Parameter
    lo: cp.Parameter  # the lower bounds, -1 where infinite


@functools.cache
def qp_model(n: int, rows: int) -> QpModel:
    """min x^T P x / 2 + q^T x with A x <= hi and A x >= lo over n variables and `rows` rows, written as
    |R x|^2 / 2 + q^T x, the side of a row whose bound is infinite as 0 <= 1 (or 0 >= -1), with P (through R),
    q, A and the bounds as CVXPY parameters: built once per shape, as CVXPY's canonicalisation is most of a
    solve's time, and each instance only sets the parameters."""
    x = cp.Variable(n)
    root, q = cp.Parameter((n, n)), cp.Parameter(n)
    a_hi, a_lo = cp.Parameter((rows, n)), cp.Parameter((rows, n))
    hi, lo = cp.Parameter(rows), cp.Parameter(rows)
    objective = cp.Minimize(0.5 * cp.sum_squares(root @ x) + q @ x)
    problem = cp.Problem(objective, [a_hi @ x <= hi, a_lo @ x >= lo])
    assert problem.is_dpp()
    return QpModel(problem, x, root, q, a_hi, hi, a_lo, lo)


def cvxpy_qp_reference(p, q, a, lo, hi) -> np.ndarray:
    """min x^T P x / 2 + q^T x, lo <= A x <= hi by CVXPY + Clarabel at 1e-11 (`qp_model`)."""
    rows, n = a.shape
    model = qp_model(n, rows)
    finite_hi, finite_lo = np.isfinite(hi), np.isfinite(lo)
    model.root.value, model.q.value = psd_root(p), q
    model.a_hi.value, model.hi.value = np.where(finite_hi[:, None], a, 0.0), np.where(finite_hi, hi, 1.0)
    model.a_lo.value, model.lo.value = np.where(finite_lo[:, None], a, 0.0), np.where(finite_lo, lo, -1.0)
    solve_by_clarabel(model.problem, 1e-11)
    return np.asarray(model.x.value)


def soft_block_problem(rng: np.random.Generator, *, coupled: bool):
    """Three independent blocks of 6 variables with 2 soft rows each (a resting slack per block, exact
    penalty), hard boxes; `coupled` adds 3 hard rows across blocks (like separation half-planes)."""
    blocks, n_u = 3, 6
    n = blocks * (n_u + 1)
    p = np.zeros((n, n))
    rows, lo, hi = [], [], []
    for b in range(blocks):
        u = slice(b * n_u, (b + 1) * n_u)
        m = rng.normal(size=(n_u, n_u))
        p[u, u] = m @ m.T + 0.5 * np.eye(n_u)
        s = blocks * n_u + b
        p[s, s] = 2.0
        for j in range(n_u):  # box
            row = np.zeros(n)
            row[b * n_u + j] = 1.0
            rows.append(row)
            lo.append(-1.0)
            hi.append(1.0)
        for _ in range(2):  # soft rows: c^T u - s <= d (and c^T u + s >= -d)
            c = rng.normal(size=n_u)
            d = rng.uniform(0.0, 1.0)
            upper = np.zeros(n)
            upper[u], upper[s] = c, -1.0
            lower = np.zeros(n)
            lower[u], lower[s] = c, 1.0
            rows += [upper, lower]
            lo += [-np.inf, -d]
            hi += [d, np.inf]
        row = np.zeros(n)
        row[s] = 1.0
        rows.append(row)
        lo.append(0.0)
        hi.append(np.inf)
    a = np.array(rows)
    resting = np.arange(n) >= blocks * n_u
    q = np.concatenate([rng.normal(0.0, rng.choice([0.1, 3.0]), blocks * n_u), np.full(blocks, 50.0)])
    extra = None
    if coupled:
        extra_a = np.zeros((3, n))
        extra_a[:, : blocks * n_u] = rng.normal(size=(3, blocks * n_u))
        extra = (extra_a, np.full(3, -np.inf), rng.uniform(-0.5, 0.5, 3))
    return p, q, a, np.array(lo), np.array(hi), resting, extra


GENERIC = [(seed, coupled) for seed in range(30) for coupled in (False, True)]


@pytest.fixture(scope="module")
def generic_results():
    """(path, exact x, OSQP x, CVXPY x, x with the compiled active-set step) for 60 generic soft-row problems,
    half with coupling rows."""
    out = []
    for seed, coupled in GENERIC:
        p, q, a, lo, hi, resting, extra = soft_block_problem(np.random.default_rng(seed), coupled=coupled)
        result = ExactQp(p, a, resting).solve(q, lo, hi, *(extra or ()))
        compiled = ExactQp(p, a, resting, active_set="compiled").solve(q, lo, hi, *(extra or ()))
        assert result.ok and compiled.ok and compiled.path == result.path
        a_all, lo_all, hi_all = a, lo, hi
        if extra is not None:
            a_all = np.vstack([a, extra[0]])
            lo_all, hi_all = np.concatenate([lo, extra[1]]), np.concatenate([hi, extra[2]])
        out.append(
            (
                result.path,
                result.x,
                osqp_reference(p, q, a_all, lo_all, hi_all),
                cvxpy_qp_reference(p, q, a_all, lo_all, hi_all),
                compiled.x,
            )
        )
    return out


def test_generic_problems_match_osqp(generic_results):
    assert max(np.max(np.abs(x - ref)) for _, x, ref, _, _ in generic_results) < TOL


def test_generic_problems_match_cvxpy(generic_results):
    assert max(np.max(np.abs(x - ref)) for _, x, _, ref, _ in generic_results) < TOL


def test_generic_problems_by_the_compiled_active_set_match_cvxpy(generic_results):
    assert max(np.max(np.abs(x - ref)) for _, _, _, ref, x in generic_results) < TOL


def test_generic_problems_take_every_path(generic_results):
    """The instances cover the closed form, the per-block solve and the whole-problem active set."""
    paths = [path for path, *_ in generic_results]
    assert {paths.count(p) >= 5 for p in ("closed_form", "blocks", "active_set")} == {True}


def _with_extra(a, lo, hi, extra):
    extra_a, extra_lo, extra_hi = extra
    return np.vstack([a, extra_a]), np.concatenate([lo, extra_lo]), np.concatenate([hi, extra_hi])


def test_rows_reaching_two_blocks_leave_the_third_at_its_own_optimum():
    """Coupling rows on half of block 1's variables and all of block 0's: the active-set rounds solve those
    two blocks whole (P couples the rest of block 1 to what the rows reach) and keep block 2's own
    solution, which is still the whole problem's minimiser."""
    worst, active = 0.0, 0
    for seed in range(30):
        p, q, a, lo, hi, resting, extra = soft_block_problem(np.random.default_rng(seed), coupled=True)
        assert extra is not None
        extra_a = extra[0].copy()
        extra_a[:, 9:18] = 0.0
        result = ExactQp(p, a, resting).solve(q, lo, hi, extra_a, extra[1], extra[2])
        reference = cvxpy_qp_reference(p, q, *_with_extra(a, lo, hi, (extra_a, extra[1], extra[2])))
        worst = max(worst, float(np.max(np.abs(result.x - reference))))
        active += result.path == "active_set"
    assert worst < TOL
    assert active >= 20


@pytest.mark.parametrize("active_set", ["daqp", "compiled"])
def test_resting_variables_without_quadratic_cost_still_solve_exactly(active_set):
    """Slacks with a linear penalty only (P singular there): the active set works on P itself instead of
    its Cholesky factor (the compiled step, which needs the factor, leaves it to DAQP), with the same
    minimiser."""
    p, q, a, lo, hi, resting, extra = soft_block_problem(np.random.default_rng(3), coupled=True)
    assert extra is not None
    p[18:, 18:] = 0.0
    result = ExactQp(p, a, resting, active_set=active_set).solve(q, lo, hi, *extra)
    assert result.ok and result.path == "active_set"
    np.testing.assert_allclose(result.x, cvxpy_qp_reference(p, q, *_with_extra(a, lo, hi, extra)), atol=TOL)


def test_closed_form_is_the_unconstrained_minimiser_when_nothing_binds():
    p, q, a, lo, hi, resting, _ = soft_block_problem(np.random.default_rng(1), coupled=False)
    q[:18] = 0.01
    result = ExactQp(p, a, resting).solve(q, lo * 100.0, np.where(np.isfinite(hi), hi * 100.0, hi))
    assert result.path == "closed_form" and result.iterations == 0
    free = ~resting
    np.testing.assert_allclose(result.x[free], np.linalg.solve(p[np.ix_(free, free)], -q[free]), atol=1e-12)
    np.testing.assert_array_equal(result.x[resting], 0.0)


def test_blocks_follow_the_coupling_of_p_and_the_rows():
    p, _, a, *_ = soft_block_problem(np.random.default_rng(2), coupled=False)
    assert ExactQp(p, a, np.arange(p.shape[0]) >= 18).block_count == 3
    a_coupled = np.vstack([a, np.r_[np.ones(18), np.zeros(3)]])
    assert ExactQp(p, a_coupled, np.arange(p.shape[0]) >= 18).block_count == 1


def test_infeasible_rows_are_reported_not_solved():
    p = np.eye(2)
    a = np.array([[1.0, 0.0], [1.0, 0.0]])
    result = ExactQp(p, a, np.zeros(2, dtype=bool)).solve(
        np.zeros(2), np.array([1.0, -np.inf]), np.array([np.inf, -1.0])
    )
    assert not result.ok and result.status == "infeasible" and np.all(np.isnan(result.x))


def test_resting_variable_without_its_own_bound_row_is_refused():
    with pytest.raises(ValueError, match="resting variable"):
        ExactQp(np.eye(2), np.array([[1.0, 1.0]]), np.array([False, True]))


def test_indefinite_hessian_is_refused():
    with pytest.raises(ValueError, match="positive definite"):
        ExactQp(np.diag([1.0, -1.0]), np.eye(2), np.zeros(2, dtype=bool))


# -------------------------------------------------------------------------------------------- the MPC
MPC_CASES = 200


def cvxpy_mpc_reference(
    params: MpcParams, case: dict, planes: HalfPlanes | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The MPC's QP from the equations (states as variables, as in test_mpc.py) through CVXPY + HiGHS, an
    active-set QP solver, exact at the vertex. (Clarabel, an interior-point method, stops 1e-5..4e-4 away from
    it on these degenerate instances, inputs at their bounds, whatever its tolerances; OSQP at 1e-11 with
    polishing ends "inaccurate" on some instances with one half-plane slack per plan step.)"""
    problem, u, p, v = cvxpy_mpc_problem(params, case, planes)
    cold = dict(canon_backend=cp.SCIPY_CANON_BACKEND, warm_start=False)  # not from the last instance's answer
    try:
        problem.solve(solver=cp.HIGHS, **cold)
    except cp.SolverError:  # HiGHS's QP solver ends in "Solve error" on a few instances (2 of the 200 here,
        # where the input box is shifted by f): then OSQP at 1e-12, polished, which solves those exactly
        problem.solve(solver=cp.OSQP, eps_abs=1e-12, eps_rel=1e-12, max_iter=400_000, polishing=True, **cold)
    assert problem.status == cp.OPTIMAL
    assert u.value is not None and p.value is not None and v.value is not None
    return u.value, p.value, v.value


def flight_case(rng: np.random.Generator) -> dict:
    """A formation-flight tick: near the terminal reference, moderate speed and external inputs."""
    position = rng.uniform([-12.0, -12.0, 6.0], [12.0, 12.0, 9.0])
    velocity = rng.normal(0.0, 1.0, 3) * np.array([1.0, 1.0, 0.1])
    external = np.zeros((16, 3))
    external[:, :2] = rng.normal(0.0, 0.5, 2) + rng.normal(0.0, 0.2, (16, 2))
    return dict(
        position_m=position,
        velocity_mps=velocity,
        target_position_m=position + rng.normal(0.0, 1.0, 3) * np.array([1.0, 1.0, 0.2]),
        target_velocity_mps=rng.normal(0.0, 0.7, 3) * np.array([1.0, 1.0, 0.0]),
        external_inputs_mps2=external,
    )


REFERENCE = MpcParams(solver="osqp", eps_abs=1e-11, eps_rel=1e-11, max_iterations=200_000)


@pytest.fixture(scope="module")
def mpc_results():
    """200 MPC instances of every kind (active state bounds, saturated inputs, huge forces, coupled terminal
    weights), solved in sequence by one exact controller, one tight OSQP controller, CVXPY + HiGHS and an
    exact controller with the compiled active-set step (which none of them may hand to DAQP)."""
    rng = np.random.default_rng(20261128)
    exact = ModelPredictiveController(MpcParams(active_set="daqp"))
    reference = ModelPredictiveController(REFERENCE)
    compiled = ModelPredictiveController(MpcParams(active_set="compiled"))
    out = []
    for i in range(MPC_CASES):
        if i % 4 == 3:
            case = flight_case(rng)
        else:
            case = random_case(rng, KINDS[i % len(KINDS)])
            if i % 2:  # half with the formation controller's fixed diagonal weights: the split into axes
                del case["terminal_position_weight"], case["terminal_velocity_weight"]
        ours, ref = exact.solve(**case), reference.solve(**case)
        weights = {
            "terminal_position_weight": case.get("terminal_position_weight", 100.0 * np.eye(3)),
            "terminal_velocity_weight": case.get("terminal_velocity_weight", 100.0 * np.eye(3)),
        }
        cvx = cvxpy_mpc_reference(MpcParams(), {**case, **weights})
        out.append((ours, ref, cvx, compiled.solve(**case)))
    assert compiled.active_set_fallbacks == 0
    return out


@pytest.mark.slow  # 200 instances through CVXPY and three controllers: about 6 s of CPU
def test_mpc_exact_inputs_match_osqp(mpc_results):
    assert all(ours.ok and ref.ok for ours, ref, _, _ in mpc_results)
    assert max(np.max(np.abs(ours.inputs_mps2 - ref.inputs_mps2)) for ours, ref, _, _ in mpc_results) < TOL


@pytest.mark.slow  # 200 instances through CVXPY and three controllers: about 6 s of CPU
def test_mpc_exact_inputs_match_cvxpy(mpc_results):
    assert max(np.max(np.abs(ours.inputs_mps2 - cvx[0])) for ours, _, cvx, _ in mpc_results) < TOL


@pytest.mark.slow  # 200 instances through CVXPY and three controllers: about 6 s of CPU
def test_mpc_exact_plan_matches_cvxpy(mpc_results):
    errors = [
        max(np.max(np.abs(ours.positions_m - cvx[1])), np.max(np.abs(ours.velocities_mps - cvx[2])))
        for ours, _, cvx, _ in mpc_results
    ]
    assert max(errors) < TOL


@pytest.mark.slow  # 200 instances through CVXPY and three controllers: about 6 s of CPU
def test_mpc_compiled_active_set_matches_cvxpy(mpc_results):
    """The compiled active-set step: the same inputs and plan as CVXPY's, by the same solver path."""
    assert all(comp.ok and comp.path == ours.path for ours, _, _, comp in mpc_results)
    assert max(np.max(np.abs(comp.inputs_mps2 - cvx[0])) for _, _, cvx, comp in mpc_results) < TOL
    assert max(np.max(np.abs(comp.positions_m - cvx[1])) for _, _, cvx, comp in mpc_results) < TOL


@pytest.mark.slow  # 200 instances through CVXPY and three controllers: about 6 s of CPU
def test_mpc_instances_are_mostly_constrained(mpc_results):
    """At least half of the 200 need the active-set solver (a bound or a saturated input is active); the
    flight-like ones mostly do not."""
    paths = [ours.path for ours, _, _, _ in mpc_results]
    assert paths.count("closed_form") >= 25
    assert len(paths) - paths.count("closed_form") >= MPC_CASES // 2


@pytest.mark.slow  # 200 instances through CVXPY and three controllers: about 6 s of CPU
def test_mpc_exact_reports_the_same_violation_as_osqp(mpc_results):
    for ours, ref, _, _ in mpc_results:
        assert ours.max_state_violation == pytest.approx(ref.max_state_violation, abs=1e-6)


# ---------------------------------------------------------------------------------- soft half-planes (hook)
def _with_weights(case: dict) -> dict:
    return {
        **case,
        "terminal_position_weight": 100.0 * np.eye(3),
        "terminal_velocity_weight": 100.0 * np.eye(3),
    }


def _cut(rng: np.random.Generator, plan_positions: np.ndarray, count: int, depth_m: float) -> HalfPlanes:
    """count half-planes that the given plan violates by depth_m at random steps from 8 on (late enough for
    the input authority to meet them) and random directions."""
    steps = rng.integers(8, len(plan_positions), count)
    angles = rng.uniform(0.0, 2.0 * np.pi, count)
    normals = np.stack([np.cos(angles), np.sin(angles)], axis=1)
    offsets = np.einsum("ri,ri->r", normals, plan_positions[steps, :2]) + depth_m
    return HalfPlanes(steps=steps, normals_xy=normals, offsets=offsets)


@pytest.fixture(scope="module")
def half_plane_results():
    """30 flight-like instances, each with 1-4 half-planes its free plan violates by 0.05-0.3 m, solved in
    sequence by one exact controller, by the MPC's own OSQP set-up at tight tolerances, and by CVXPY + OSQP
    with the same soft constraints written out independently."""
    rng = np.random.default_rng(515)
    controller = ModelPredictiveController(MpcParams(active_set="daqp"))
    reference = ModelPredictiveController(REFERENCE)
    compiled = ModelPredictiveController(MpcParams(active_set="compiled"))
    out = []
    for _ in range(30):
        case = flight_case(rng)
        free = controller.solve(**case)
        planes = _cut(rng, free.positions_m, int(rng.integers(1, 5)), float(rng.uniform(0.05, 0.3)))
        out.append(
            (
                controller.solve(**case, half_planes=planes),
                cvxpy_mpc_reference(MpcParams(), _with_weights(case), planes),
                planes,
                reference.solve(**case, half_planes=planes),
                compiled.solve(**case, half_planes=planes),
            )
        )
    assert compiled.active_set_fallbacks == 0
    return out


def test_half_planes_match_cvxpy(half_plane_results):
    assert all(ours.ok for ours, _, _, _, _ in half_plane_results)
    assert max(np.max(np.abs(ours.inputs_mps2 - cvx[0])) for ours, cvx, _, _, _ in half_plane_results) < TOL


def test_half_planes_by_the_compiled_active_set_match_cvxpy(half_plane_results):
    assert all(comp.ok for *_, comp in half_plane_results)
    assert max(np.max(np.abs(comp.inputs_mps2 - cvx[0])) for _, cvx, _, _, comp in half_plane_results) < TOL
    for ours, _, _, _, comp in half_plane_results:
        assert comp.half_plane_violation_m == pytest.approx(ours.half_plane_violation_m, abs=1e-6)


def test_half_planes_match_osqp(half_plane_results):
    assert all(ref.ok for _, _, _, ref, _ in half_plane_results)
    assert (
        max(np.max(np.abs(ours.inputs_mps2 - ref.inputs_mps2)) for ours, _, _, ref, _ in half_plane_results)
        < TOL
    )
    for ours, _, _, ref, _ in half_plane_results:
        assert ours.half_plane_violation_m == pytest.approx(ref.half_plane_violation_m, abs=1e-6)


def test_half_planes_that_can_hold_are_held(half_plane_results):
    """A single late cut of at most 0.3 m into a free plan can be met within the input box: no violation is
    left. (Several cuts in different directions at nearby steps may contradict each other; those are only
    compared with CVXPY.) Every solve needed the active-set solver: the closed form violated the cuts."""
    single = [ours for ours, _, planes, _, _ in half_plane_results if len(planes.steps) == 1]
    assert len(single) >= 5
    assert all(ours.half_plane_violation_m == 0.0 for ours in single)
    assert all(ours.path == "active_set" for ours, _, _, _, _ in half_plane_results)


def test_contradictory_half_planes_give_way_without_failing():
    case = flight_case(np.random.default_rng(3))
    controller = ModelPredictiveController(MpcParams())
    x = controller.solve(**case).positions_m[5, 0]
    planes = HalfPlanes(  # x >= x5 + 1 and x <= x5 - 1 at step 5: 2 m apart, cannot both hold
        steps=np.array([5, 5]),
        normals_xy=np.array([[1.0, 0.0], [-1.0, 0.0]]),
        offsets=np.array([x + 1.0, -x + 1.0]),
    )
    sol = controller.solve(**case, half_planes=planes)
    assert sol.ok and sol.half_plane_violation_m == pytest.approx(1.0, abs=1e-3)


def test_no_half_planes_leave_the_solution_unchanged():
    case = flight_case(np.random.default_rng(4))
    controller = ModelPredictiveController(MpcParams())
    empty = HalfPlanes(steps=np.zeros(0, dtype=int), normals_xy=np.zeros((0, 2)), offsets=np.zeros(0))
    np.testing.assert_array_equal(
        controller.solve(**case).inputs_mps2, controller.solve(**case, half_planes=empty).inputs_mps2
    )


def _separation_planes(plan_positions: np.ndarray, turn: float, soft: bool, tilt: float) -> HalfPlanes:
    """Planes shaped like separation constraints, on the free plan (N+2, 3) they are cut into: one on every
    step 1..N+1 (a teammate's buffered cell ahead of the MAV: normal against the plan's heading by step 8,
    turned by `turn` rad and tilted up by `tilt`, normalised) that the MAV stands inside of and the plan's
    step 8 crosses by 40 % of how far it moves towards it, and one on steps 10..N+1 (a trunk's tangent,
    vertical, turned 1 rad further) that the plan's last step crosses by 0.1 m; all soft or all hard."""
    steps = np.arange(1, len(plan_positions))
    late = steps[steps >= 10]
    heading = plan_positions[8, :2] - plan_positions[0, :2]
    angle = np.arctan2(heading[1], heading[0]) + np.pi + turn
    cell = np.array([np.cos(angle), np.sin(angle), tilt]) / np.hypot(1.0, tilt)
    trunk = np.array([np.cos(angle + 1.0), np.sin(angle + 1.0), 0.0])
    depth = max(0.02, 0.4 * float(cell @ (plan_positions[0] - plan_positions[8])))
    return HalfPlanes(
        steps=np.concatenate([steps, late]),
        normals_xy=np.vstack([np.tile(cell[:2], (len(steps), 1)), np.tile(trunk[:2], (len(late), 1))]),
        normals_z=np.concatenate([np.full(len(steps), cell[2]), np.zeros(len(late))]),
        offsets=np.concatenate(
            [
                np.full(len(steps), cell @ plan_positions[8] + depth),
                np.full(len(late), trunk @ plan_positions[-1] + 0.1),
            ]
        ),
        soft=np.full(len(steps) + len(late), soft),
    )


@pytest.mark.parametrize("soft", [True, False])
@pytest.mark.parametrize("tilt", [0.0, 0.5])
def test_separation_planes_on_every_step_match_osqp(soft, tilt):
    """20 flight-like instances whose free plan crosses a plane held on every step (vertical, or tilted so
    climbing helps) and a second one on the late steps (the shape of separation constraints: teammates'
    cells, trunks), hard or soft: the exact solver's inputs (either active-set step) equal tight OSQP's on
    the same problem to 1e-6,
    and so does the planes' remaining violation; hard planes either hold exactly or both solvers call the
    problem infeasible."""
    rng = np.random.default_rng(77 + soft + int(10 * tilt))
    exact = ModelPredictiveController(MpcParams(active_set="daqp"))
    reference = ModelPredictiveController(REFERENCE)
    compiled = ModelPredictiveController(MpcParams(active_set="compiled"))
    solved = 0
    for _ in range(20):
        case = flight_case(rng)
        planes = _separation_planes(exact.solve(**case).positions_m, rng.uniform(-0.6, 0.6), soft, tilt)
        ours, ref = exact.solve(**case, half_planes=planes), reference.solve(**case, half_planes=planes)
        comp = compiled.solve(**case, half_planes=planes)
        assert ours.ok == ref.ok == comp.ok
        if ours.ok:
            assert ours.path != "closed_form"
            np.testing.assert_allclose(ours.inputs_mps2, ref.inputs_mps2, rtol=0, atol=TOL)
            np.testing.assert_allclose(comp.inputs_mps2, ref.inputs_mps2, rtol=0, atol=TOL)
            assert ours.half_plane_violation_m == pytest.approx(ref.half_plane_violation_m, abs=1e-6)
            solved += 1
            if not soft:
                assert ours.half_plane_violation_m == 0.0
        else:
            assert (ours.status, ref.status, comp.status) == ("infeasible", "primal infeasible", "infeasible")
    assert compiled.active_set_fallbacks == 20 - solved  # only an infeasible problem goes to DAQP
    assert solved >= 15  # most can hold (the MAV starts inside its cell); the rest are compared as failures


def squeezed_at_step_5(soft: np.ndarray | None = None, active_set: str = "daqp"):
    """(case, controller, x, planes): a flight case, x(5) of its free plan, and two rows of step 5 with 0.2 m
    of gap around it, x(5) >= x + 0.1 and x(5) <= x - 0.1 (each alone can hold)."""
    case = flight_case(np.random.default_rng(3))
    controller = ModelPredictiveController(MpcParams(active_set=active_set))
    x = controller.solve(**case).positions_m[5, 0]
    planes = HalfPlanes(
        steps=np.array([5, 5]),
        normals_xy=np.array([[1.0, 0.0], [-1.0, 0.0]]),
        offsets=np.array([x + 0.1, -x + 0.1]),
        soft=soft,
    )
    return case, controller, x, planes


@pytest.mark.parametrize("active_set", ["daqp", "compiled"])
def test_hard_half_planes_that_cannot_hold_fail_the_solve(active_set):
    """Hard rows have no slack: contradictory ones make the QP infeasible, reported as such (the caller
    brakes or escapes); with one of them soft, that one gives way."""
    case, controller, x, planes = squeezed_at_step_5(soft=np.array([True, False]), active_set=active_set)
    mixed = controller.solve(**case, half_planes=planes)
    assert mixed.ok and mixed.half_plane_violation_m == pytest.approx(0.2, abs=1e-3)
    assert mixed.positions_m[5, 0] == pytest.approx(x - 0.1, abs=1e-6)  # the hard row holds exactly
    hard = HalfPlanes(planes.steps, planes.normals_xy, planes.offsets, soft=np.array([False, False]))
    sol = controller.solve(**case, half_planes=hard)
    assert not sol.ok and sol.status == "infeasible"
    assert controller.active_set_fallbacks == (active_set == "compiled")  # DAQP confirms the verdict
    assert controller.solve(**case).ok  # and the next solve without them is unaffected


def test_a_step_whose_rows_cannot_hold_lets_no_other_steps_rows_give_way():
    """Each plan step has its own slack: a row at step 1 beyond any input's reach gives way, and a row at step
    12 on another axis, which the free plan misses by 0.3 m, still holds exactly (with one slack shared by
    every row it gave way by its whole 0.3 m, at no extra cost)."""
    case = flight_case(np.random.default_rng(3))
    controller = ModelPredictiveController(MpcParams())
    free = controller.solve(**case).positions_m
    planes = HalfPlanes(
        steps=np.array([1, 12]),
        normals_xy=np.array([[1.0, 0.0], [0.0, 1.0]]),
        offsets=np.array([free[1, 0] + 5.0, free[12, 1] + 0.3]),
    )
    sol = controller.solve(**case, half_planes=planes)
    assert sol.ok and sol.half_plane_violation_m > 4.0  # step 1's row gives way
    assert sol.positions_m[12, 1] >= free[12, 1] + 0.3 - 1e-6  # step 12's holds


def test_the_rows_of_one_step_give_way_evenly():
    """Two contradictory rows of one step share its slack: each gives way by half the gap (the largest
    violation is what costs), not one by the whole gap."""
    case, controller, x, planes = squeezed_at_step_5()
    sol = controller.solve(**case, half_planes=planes)
    assert sol.ok and sol.half_plane_violation_m == pytest.approx(0.1, abs=1e-3)
    assert sol.positions_m[5, 0] == pytest.approx(x, abs=1e-3)


@pytest.mark.parametrize(
    "steps", [np.array([0]), np.array([17]), np.array([3, -1]), np.array([2.0]), np.array([2], np.uint8) - 3]
)
def test_half_plane_step_outside_the_horizon_raises(steps):
    """Steps must be integers in 1..N+1 (N + 1 = 16): 0, N+2, a negative one, a float and a wrapped uint8
    (255) are refused before any row is built."""
    planes = HalfPlanes(
        steps=steps, normals_xy=np.tile([1.0, 0.0], (len(steps), 1)), offsets=np.zeros(len(steps))
    )
    with pytest.raises(ValueError, match="steps"):
        ModelPredictiveController(MpcParams()).solve(
            **flight_case(np.random.default_rng(6)), half_planes=planes
        )


def test_half_planes_without_z_normals_or_soft_are_vertical_and_soft():
    """normals_z None means vertical planes (0) and soft None every row soft (weight 1): the same solve as
    with them written out."""
    rng = np.random.default_rng(61)
    case = flight_case(rng)
    controller = ModelPredictiveController(MpcParams())
    planes = _cut(rng, controller.solve(**case).positions_m, 4, 0.2)
    written = HalfPlanes(
        steps=planes.steps.astype(np.int32),
        normals_xy=planes.normals_xy,
        offsets=planes.offsets,
        soft=np.ones(4, dtype=bool),
        normals_z=np.zeros(4),
    )
    implicit, explicit = (
        controller.solve(**case, half_planes=planes),
        controller.solve(**case, half_planes=written),
    )
    assert implicit.path == explicit.path == "active_set"
    np.testing.assert_array_equal(implicit.inputs_mps2, explicit.inputs_mps2)


def test_a_row_the_first_working_set_leaves_out_joins_when_the_answer_misses_it():
    """Two coupling rows on min |x - (10, 10)|^2 / 2: the unconstrained optimum misses only y <= 0; with that
    row alone the answer (10, 0) misses x - y <= 5, which met the unconstrained optimum; with both the optimum
    is their corner (5, 0)."""
    qp = ExactQp(np.eye(2), np.array([[1.0, 0.0]]), np.zeros(2, dtype=bool))  # a fixed row x >= -100, slack
    extra_a = np.array([[0.0, 1.0], [1.0, -1.0]])
    result = qp.solve(
        np.array([-10.0, -10.0]),
        np.array([-100.0]),
        np.array([np.inf]),
        extra_a,
        np.full(2, -np.inf),
        np.array([0.0, 5.0]),
    )
    assert result.status == "solved" and result.path == "active_set"
    np.testing.assert_allclose(result.x, [5.0, 0.0], atol=1e-9)


def test_half_planes_in_one_compiled_call_are_finishs_answer_to_the_bit():
    """mpc_kernels.solve_with_planes (the default with the compiled active set) against the same solve through
    ExactQp.finish on 200 flight-like instances with separation-shaped planes (soft, random turns and tilts)
    or random cuts: the same path, iterations, plan and violations, to the bit. Both controllers solve the
    same sequence (the free plan first): step 2's DAQP blocks keep their workspaces from solve to solve."""
    rng = np.random.default_rng(2026_12_07)
    fused = ModelPredictiveController(MpcParams(active_set="compiled"))
    through_finish = ModelPredictiveController(MpcParams(active_set="compiled"), planes_in_one_call=False)
    paths = []
    for i in range(200):
        case = flight_case(rng)
        free = fused.solve(**case).positions_m
        through_finish.solve(**case)
        if i % 2:
            planes = _separation_planes(free, rng.uniform(-0.6, 0.6), True, rng.choice([0.0, 0.5]))
        else:
            planes = _cut(rng, free, int(rng.integers(1, 6)), float(rng.uniform(0.01, 0.5)))
        one, two = fused.solve(**case, half_planes=planes), through_finish.solve(**case, half_planes=planes)
        assert (one.ok, one.path, one.iterations) == (two.ok, two.path, two.iterations)
        for a, b in (
            (one.inputs_mps2, two.inputs_mps2),
            (one.positions_m, two.positions_m),
            (one.velocities_mps, two.velocities_mps),
        ):
            np.testing.assert_array_equal(a, b)
        assert (one.max_state_violation, one.half_plane_violation_m) == (
            two.max_state_violation,
            two.half_plane_violation_m,
        )
        paths.append(one.path)
    assert paths.count("active_set") >= 150

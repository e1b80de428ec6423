"""Specification of the MPC (controller/mpc.py): paper eqs. (4)-(9), docs/method.md#the-mpc and
docs/method.md#infeasible-qps."""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import replace
from typing import NamedTuple

import cvxpy as cp
import numpy as np
import pytest

from controller.mpc import (
    SOLVERS,
    HalfPlanes,
    ModelPredictiveController,
    MpcParams,
    MpcSolution,
    _plane_violation,
    braking_plan,
    input_box,
    predict,
)
from controller.mpc_kernels import plane_shortfall

PARAMS = MpcParams()
OSQP = MpcParams(solver="osqp")  # for the tests of OSQP's own behaviour (iterations, warm starts)
N = PARAMS.horizon_steps
STEPS = N + 1
G = np.array([0.0, 0.0, -PARAMS.gravity_mps2])
HOVER = np.array([0.0, 0.0, PARAMS.gravity_mps2])
PAPER_BOUND = MpcParams(plan_acceleration_min_mps2=None, plan_acceleration_max_mps2=None)  # u alone bounded


def solve(
    controller: ModelPredictiveController,
    *,
    position_m: np.ndarray | None = None,
    velocity_mps: np.ndarray | None = None,
    target_position_m: np.ndarray | None = None,
    target_velocity_mps: np.ndarray | None = None,
    external_inputs_mps2: np.ndarray | None = None,
    terminal_position_weight: np.ndarray | None = None,
    terminal_velocity_weight: np.ndarray | None = None,
) -> MpcSolution:
    """One solve of a hover problem at (0, 0, 6) m, with the given arguments replacing its parts."""
    return controller.solve(
        position_m=np.array([0.0, 0.0, 6.0]) if position_m is None else position_m,
        velocity_mps=np.zeros(3) if velocity_mps is None else velocity_mps,
        target_position_m=np.array([0.0, 0.0, 6.0]) if target_position_m is None else target_position_m,
        target_velocity_mps=np.zeros(3) if target_velocity_mps is None else target_velocity_mps,
        external_inputs_mps2=np.zeros((STEPS, 3)) if external_inputs_mps2 is None else external_inputs_mps2,
        terminal_position_weight=terminal_position_weight,
        terminal_velocity_weight=terminal_velocity_weight,
    )


def state_space_rollout(x0: np.ndarray, inputs: np.ndarray, external: np.ndarray, dt: float) -> np.ndarray:
    """(M+1, 6) states by the matrix recursion of eq. (6) with A, B of eq. (9), written out independently."""
    a = np.eye(6)
    a[:3, 3:] = dt * np.eye(3)
    b = np.vstack([0.5 * dt * dt * np.eye(3), dt * np.eye(3)])
    states = [np.asarray(x0, dtype=float)]
    for u, f in zip(inputs, external, strict=True):
        states.append(a @ states[-1] + b @ (u + f + G))
    return np.array(states)


# ------------------------------------------------------------------------------------------ CVXPY reference
def reference_input_box(params: MpcParams, f: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(M, 3) bounds of u under f (M, 3), written out per element: the input box, and with the plan's
    acceleration bounded also u + f in [a_min, a_max]; where no u meets both, the u nearest the input box
    whose u + f is in [a_min, a_max]."""
    lo, hi = np.empty(f.shape), np.empty(f.shape)
    for n, a in np.ndindex(*f.shape):
        u_min, u_max = params.input_min_mps2[a], params.input_max_mps2[a]
        if params.plan_acceleration_min_mps2 is None or params.plan_acceleration_max_mps2 is None:
            lo[n, a], hi[n, a] = u_min, u_max
            continue
        a_min, a_max = params.plan_acceleration_min_mps2[a], params.plan_acceleration_max_mps2[a]
        if a_max - f[n, a] < u_min:  # the field pushes past what u can hold back: u + f at a_max
            lo[n, a] = hi[n, a] = a_max - f[n, a]
        elif a_min - f[n, a] > u_max:
            lo[n, a] = hi[n, a] = a_min - f[n, a]
        else:
            lo[n, a], hi[n, a] = max(u_min, a_min - f[n, a]), min(u_max, a_max - f[n, a])
    return lo, hi


def psd_root(weight: np.ndarray) -> np.ndarray:
    """R with R^T R = weight (symmetric PSD), so that x^T W x = |R x|^2: by the eigen-decomposition, which a
    singular W does not stop (a Cholesky factorisation would)."""
    eig, vec = np.linalg.eigh(weight)
    return np.sqrt(np.clip(eig, 0.0, None))[:, None] * vec.T


class MpcModel(NamedTuple):
    """A CVXPY model of the MPC's QP (`mpc_model`): the problem, its variables u, positions and velocities,
    and `load`, which sets its parameters to one instance (case, half-planes)."""

    problem: cp.Problem
    u: cp.Variable
    p: cp.Variable
    v: cp.Variable
    load: Callable[[dict, HalfPlanes | None], None]


@functools.cache
def mpc_model(params: MpcParams, plane_rows: int) -> MpcModel:
    """The MPC's QP written from the equations, states as variables, with room for `plane_rows` soft
    half-plane rows a^T p(n) + w(n) >= b (the slack w(n) shared by the rows of plan step n; unused rows read
    0 >= -1). The instance's data are CVXPY parameters: built once per (params, plane_rows), as CVXPY's
    canonicalisation is most of a solve's time, and each instance only sets the parameters. A terminal weight
    W enters as w0 |R x(M) - R x_ref|^2 with R^T R = W / w0 (w0 the params' scalar weight) and R x_ref set in
    numpy (a product of two parameters is not DPP): HiGHS then ends as near the exact vertex as with
    quad_form(x(M) - x_ref, W), about 5e-8; with w0 = 1, or with x(M) - x_ref as a variable, up to 4e-7."""
    dt, m = params.dt_s, params.horizon_steps + 1
    g = params.gravity_vector_mps2
    x0, v0 = cp.Parameter(3), cp.Parameter(3)
    f, u_lo, u_hi = (cp.Parameter((m, 3)) for _ in range(3))
    wp_root, wv_root = cp.Parameter((3, 3)), cp.Parameter((3, 3))  # R of W / w0
    wp_ref, wv_ref = cp.Parameter(3), cp.Parameter(3)  # R p_ref, R v_ref
    wp0, wv0 = params.terminal_position_weight, params.terminal_velocity_weight
    u, p, v, s = cp.Variable((m, 3)), cp.Variable((m + 1, 3)), cp.Variable((m + 1, 3)), cp.Variable(6)
    acc = u + f + g
    ones = np.ones((m, 1))
    s_pos = ones @ cp.reshape(s[:3], (1, 3), order="C")
    s_vel = ones @ cp.reshape(s[3:], (1, 3), order="C")
    constraints = [
        p[0] == x0,
        v[0] == v0,
        p[1:] == p[:-1] + dt * v[:-1] + 0.5 * dt * dt * acc,
        v[1:] == v[:-1] + dt * acc,
        u >= u_lo,
        u <= u_hi,
        p[1:] <= ones @ np.atleast_2d(params.position_max_m) + s_pos,
        p[1:] >= ones @ np.atleast_2d(params.position_min_m) - s_pos,
        v[1:] <= ones @ np.atleast_2d(params.velocity_max_mps) + s_vel,
        v[1:] >= ones @ np.atleast_2d(params.velocity_min_mps) - s_vel,
        s >= 0,
    ]
    offset = {"hover": np.tile(g, (m, 1)), "planned": f + g, "raw": np.zeros((m, 3))}[params.effort]
    cost = (
        params.input_weight * cp.sum_squares(u + offset)
        + wp0 * cp.sum_squares(wp_root @ p[m] - wp_ref)
        + wv0 * cp.sum_squares(wv_root @ v[m] - wv_ref)
        + params.slack_weight * cp.sum(s)
        + params.slack_quadratic_weight * cp.sum_squares(s)
    )
    room = max(plane_rows, 1)  # the half-plane rows' parameters, in the problem if plane_rows > 0
    normals = cp.Parameter((room, 3 * (m + 1)))  # row r's normal at the columns of p(steps[r])
    slack_of_row = cp.Parameter((room, m))  # 1 at the column of w(steps[r]) (w(n) at n - 1)
    offsets = cp.Parameter(room)
    if plane_rows:
        w = cp.Variable(m)
        p_flat = cp.reshape(p, (3 * (m + 1),), order="C")  # p(n) at columns 3n..3n+2
        constraints += [normals @ p_flat + slack_of_row @ w >= offsets, w >= 0]
        cost += params.half_plane_weight * cp.sum(w) + params.half_plane_quadratic_weight * cp.sum_squares(w)
    problem = cp.Problem(cp.Minimize(cost), constraints)
    assert problem.is_dpp()

    def load(case: dict, planes: HalfPlanes | None) -> None:
        x0.value, v0.value = case["position_m"], case["velocity_mps"]
        f.value = case["external_inputs_mps2"]
        u_lo.value, u_hi.value = reference_input_box(params, case["external_inputs_mps2"])
        root_p = psd_root(case["terminal_position_weight"] / wp0)
        root_v = psd_root(case["terminal_velocity_weight"] / wv0)
        wp_root.value, wp_ref.value = root_p, root_p @ case["target_position_m"]
        wv_root.value, wv_ref.value = root_v, root_v @ case["target_velocity_mps"]
        if plane_rows:
            a, slack = np.zeros((plane_rows, 3 * (m + 1))), np.zeros((plane_rows, m))
            b = np.full(plane_rows, -1.0)
            if planes is not None:
                rows = zip(planes.steps, planes.normals_xy, planes.z_normals, planes.offsets, strict=True)
                for r, (n, a_xy, a_z, b_r) in enumerate(rows):
                    a[r, 3 * n : 3 * n + 3] = a_xy[0], a_xy[1], a_z
                    slack[r, n - 1], b[r] = 1.0, b_r
            normals.value, slack_of_row.value, offsets.value = a, slack, b

    return MpcModel(problem, u, p, v, load)


PLANE_ROWS = 16  # the models' room for half-plane rows grows in steps of 16 rows


def cvxpy_mpc_problem(
    params: MpcParams, case: dict, planes: HalfPlanes | None = None
) -> tuple[cp.Problem, cp.Variable, cp.Variable, cp.Variable]:
    """The MPC's QP written from the equations, states as variables, with the soft half-planes if given (the
    slack w(n) shared by the rows of plan step n); returns (problem, u, positions, velocities) to solve: the
    `mpc_model` with room for them (their count rounded up to PLANE_ROWS' multiple), set to this instance."""
    rows = 0 if planes is None else len(planes.steps)
    model = mpc_model(params, -(-rows // PLANE_ROWS) * PLANE_ROWS)
    model.load(case, planes)
    return model.problem, model.u, model.p, model.v


def solve_by_clarabel(problem: cp.Problem, tol: float, **options) -> None:
    """Solve a reference problem by Clarabel with every tolerance at `tol`, cold (each instance on its own,
    not from the last one's solution), and require an optimal status."""
    problem.solve(
        solver=cp.CLARABEL,
        tol_gap_abs=tol,
        tol_gap_rel=tol,
        tol_feas=tol,
        tol_ktratio=tol,
        warm_start=False,
        **options,
    )
    assert problem.status == cp.OPTIMAL


def cvxpy_reference(params: MpcParams, case: dict) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """`cvxpy_mpc_problem` solved by Clarabel at 1e-10; returns (u, positions, velocities)."""
    problem, u, p, v = cvxpy_mpc_problem(params, case)
    solve_by_clarabel(problem, 1e-10, canon_backend=cp.SCIPY_CANON_BACKEND)
    assert u.value is not None and p.value is not None and v.value is not None
    return u.value, p.value, v.value


def random_psd(rng: np.random.Generator) -> np.ndarray:
    """A full symmetric PSD (3, 3) weight: random rotation, eigenvalues in [0, 200] (one may be near 0)."""
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    eig = rng.uniform(0.0, 200.0, 3)
    eig[rng.integers(3)] *= rng.choice([1.0, 0.01])
    return q @ np.diag(eig) @ q.T


def formation_weight(rng: np.random.Generator) -> np.ndarray:
    """The formation controller's kind of W_v: 100 I with a lowered weight along a horizontal tangent."""
    angle = rng.uniform(0, 2 * np.pi)
    t = np.array([-np.sin(angle), np.cos(angle), 0.0])
    return 100.0 * np.eye(3) - rng.uniform(80.0, 100.0) * np.outer(t, t)


def random_case(rng: np.random.Generator, kind: str) -> dict:
    lo, hi = np.array(PARAMS.position_min_m), np.array(PARAMS.position_max_m)
    position = rng.uniform(lo + 1.0, hi - 1.0)
    velocity = rng.uniform(-2.0, 2.0, 3) * np.array([1.0, 1.0, 0.2])
    target = rng.uniform(lo, hi)
    external = np.tile(rng.normal(0.0, 1.0, 3) * np.array([1.0, 1.0, 0.2]), (STEPS, 1))
    external += rng.normal(0.0, 0.3, (STEPS, 3))
    wp, wv = random_psd(rng), random_psd(rng)
    if kind == "position_bound":  # start at or beyond a face, moving outwards
        axis, side = rng.integers(3), rng.choice([-1.0, 1.0])
        face = hi[axis] if side > 0 else lo[axis]
        position[axis] = face + side * rng.uniform(-1.0, 0.5)
        velocity[axis] = side * (rng.uniform(2.0, 5.0) if axis < 2 else rng.uniform(0.2, 0.5))
    elif kind == "velocity_bound":  # start faster than the velocity bounds
        velocity = rng.uniform(5.5, 8.0, 3) * rng.choice([-1.0, 1.0], 3) * np.array([1.0, 1.0, 0.2])
    elif kind == "far_target":  # saturates the inputs
        direction = rng.normal(size=3)
        target = position + rng.uniform(30.0, 60.0) * direction / np.linalg.norm(direction)
    elif kind == "large_force":  # persistent force above the input authority
        force = rng.normal(size=3) * np.array([1.0, 1.0, 0.3])
        external = np.tile(rng.uniform(5.0, 20.0) * force / np.linalg.norm(force), (STEPS, 1))
    elif kind == "formation":
        wp, wv = 100.0 * np.eye(3), formation_weight(rng)
    return dict(
        position_m=position,
        velocity_mps=velocity,
        target_position_m=target,
        target_velocity_mps=rng.normal(0.0, 1.0, 3) * np.array([1.0, 1.0, 0.0]),
        external_inputs_mps2=external,
        terminal_position_weight=wp,
        terminal_velocity_weight=wv,
    )


EFFORT_MODES = ("hover", "planned", "raw")
KINDS = ("nominal", "position_bound", "velocity_bound", "far_target", "large_force", "formation")


@pytest.fixture(scope="module")
def references() -> list[tuple[str, dict, tuple[np.ndarray, np.ndarray, np.ndarray]]]:
    """60 seeded instances, 10 per kind, effort modes in turn, each with its CVXPY reference (solved once for
    both solvers): (effort mode, solve() keywords, reference)."""
    rng = np.random.default_rng(20261123)
    out = []
    for i in range(60):
        mode = EFFORT_MODES[i % 3]
        case = random_case(rng, KINDS[i % len(KINDS)])
        out.append((mode, case, cvxpy_reference(MpcParams(effort=mode), case)))
    return out


@pytest.fixture(scope="module", params=SOLVERS)
def compared(request, references) -> list[tuple[str, MpcSolution, tuple[np.ndarray, np.ndarray, np.ndarray]]]:
    """The `references` solved by each solver; one controller per mode is reused, so the solves also exercise
    warm starts from unrelated problems and terminal-weight updates."""
    controllers = {
        mode: ModelPredictiveController(MpcParams(effort=mode, solver=request.param)) for mode in EFFORT_MODES
    }
    return [(mode, controllers[mode].solve(**case), ref) for mode, case, ref in references]


@pytest.mark.slow  # an independent CVXPY model of 30 random QPs
def test_matches_cvxpy_inputs(compared):
    errors = [np.max(np.abs(sol.inputs_mps2 - ref[0])) for _, sol, ref in compared]
    assert all(sol.ok and sol.status == "solved" for _, sol, _ in compared)
    assert max(errors) < 1e-3


@pytest.mark.slow  # an independent CVXPY model of 30 random QPs
def test_matches_cvxpy_states(compared):
    errors = [
        max(np.max(np.abs(sol.positions_m - ref[1])), np.max(np.abs(sol.velocities_mps - ref[2])))
        for _, sol, ref in compared
    ]
    assert max(errors) < 1e-3


STATE_MIN = np.concatenate([PARAMS.position_min_m, PARAMS.velocity_min_mps])
STATE_MAX = np.concatenate([PARAMS.position_max_m, PARAMS.velocity_max_mps])


def reference_violation(positions: np.ndarray, velocities: np.ndarray) -> float:
    """Largest excursion of x(1..N+1) beyond the soft bounds (m or m/s), 0 inside them."""
    states = np.hstack([positions[1:], velocities[1:]])
    return float(max(0.0, np.max(states - STATE_MAX), np.max(STATE_MIN - states)))


def test_reference_instances_include_active_state_bounds(compared):
    """The comparison covers plans that must leave the state box (the soft bounds' slack is active)."""
    active = [reference_violation(p, v) > 0.01 for _, _, (_, p, v) in compared]
    assert sum(active) >= 10


def test_reference_instances_include_saturated_inputs(compared):
    lo, hi = np.array(PARAMS.input_min_mps2), np.array(PARAMS.input_max_mps2)
    saturated = [
        np.any(np.isclose(u, lo, atol=1e-6) | np.isclose(u, hi, atol=1e-6)) for _, _, (u, _, _) in compared
    ]
    assert sum(saturated) >= 20


@pytest.mark.slow  # an independent CVXPY model of 30 random QPs
def test_max_state_violation_matches_cvxpy_slack(compared):
    """The reported violation is the reference plan's largest excursion beyond the soft bounds."""
    for _, sol, (_, p, v) in compared:
        excess = reference_violation(p, v)
        assert sol.max_state_violation == pytest.approx(excess if excess > 1e-4 else 0.0, abs=1e-3)


# ------------------------------------------------------------------------------------------- dynamics
def test_predict_matches_state_space_recursion():
    rng = np.random.default_rng(1)
    x0 = rng.normal(size=6)
    inputs, external = rng.normal(size=(STEPS, 3)), rng.normal(size=(STEPS, 3))
    positions, velocities = predict(
        position_m=x0[:3],
        velocity_mps=x0[3:],
        inputs_mps2=inputs,
        external_inputs_mps2=external,
        params=PARAMS,
    )
    expected = state_space_rollout(x0, inputs, external, PARAMS.dt_s)
    np.testing.assert_allclose(np.hstack([positions, velocities]), expected, atol=1e-12)


def test_plan_obeys_dynamics():
    controller = ModelPredictiveController(PARAMS)
    external = np.tile([1.0, -0.5, 0.0], (STEPS, 1))
    sol = solve(
        controller,
        position_m=np.array([3.0, -2.0, 5.0]),
        velocity_mps=np.array([1.0, 0.5, 0.1]),
        target_position_m=np.array([-4.0, 6.0, 8.0]),
        external_inputs_mps2=external,
    )
    expected = state_space_rollout(np.array([3.0, -2.0, 5.0, 1.0, 0.5, 0.1]), sol.inputs_mps2, external, 0.1)
    assert sol.ok
    np.testing.assert_allclose(np.hstack([sol.positions_m, sol.velocities_mps]), expected, atol=1e-9)


def test_plan_shapes_and_initial_state():
    sol = solve(ModelPredictiveController(PARAMS), position_m=np.array([1.0, 2.0, 4.0]))
    assert sol.inputs_mps2.shape == (N + 1, 3)
    assert sol.positions_m.shape == sol.velocities_mps.shape == (N + 2, 3)
    np.testing.assert_array_equal(sol.positions_m[0], [1.0, 2.0, 4.0])


# ------------------------------------------------------------------------------------------- effort modes
def test_hover_costs_nothing_in_hover_mode():
    sol = solve(ModelPredictiveController(PARAMS))
    assert sol.ok
    np.testing.assert_allclose(sol.inputs_mps2, np.tile(HOVER, (STEPS, 1)), atol=1e-4)
    np.testing.assert_allclose(sol.positions_m, np.tile([0.0, 0.0, 6.0], (N + 2, 1)), atol=1e-4)
    np.testing.assert_allclose(sol.velocities_mps, 0.0, atol=1e-4)
    assert sol.max_state_violation == 0.0


def test_raw_effort_pulls_the_plan_down():
    """The paper's literal u^T W_E u prices the hover thrust itself, so the plan sinks below the target."""
    sol = solve(ModelPredictiveController(MpcParams(effort="raw")))
    assert sol.ok
    assert np.all(sol.inputs_mps2[:, 2] < PARAMS.gravity_mps2 - 0.05)
    assert sol.positions_m[-1, 2] < 6.0 - 0.2


def test_planned_effort_cancels_a_force_within_input_authority():
    force = np.array([1.5, -1.0, 0.0])
    sol = solve(
        ModelPredictiveController(MpcParams(effort="planned")),
        external_inputs_mps2=np.tile(force, (STEPS, 1)),
    )
    assert sol.ok
    np.testing.assert_allclose(sol.inputs_mps2, np.tile(HOVER - force, (STEPS, 1)), atol=1e-4)
    np.testing.assert_allclose(sol.positions_m, np.tile([0.0, 0.0, 6.0], (N + 2, 1)), atol=1e-4)


def test_hover_effort_lets_a_force_move_the_plan():
    """In hover mode f is a free acceleration: only partly cancelled, so the plan drifts along it."""
    sol = solve(ModelPredictiveController(PARAMS), external_inputs_mps2=np.tile([1.0, 0.0, 0.0], (STEPS, 1)))
    assert sol.ok
    assert -1.0 + 0.05 < sol.inputs_mps2[0, 0] < -0.05
    assert sol.positions_m[-1, 0] > 0.05


# ------------------------------------------------------------------------------------------- robustness
def test_persistent_huge_force_gives_bounded_slack():
    """The paper's bound (u alone), f = 20 m/s^2 east over the whole horizon: braking at -3 leaves 17 m/s^2,
    so after 1.6 s the velocity is 1 + 1.6 * 17 = 28.2 m/s, 23.2 m/s over the bound; the plan must be exactly
    that, not garbage."""
    sol = solve(
        ModelPredictiveController(PAPER_BOUND),
        velocity_mps=np.array([1.0, 0.0, 0.0]),
        target_position_m=np.array([5.0, 3.0, 8.0]),
        external_inputs_mps2=np.tile([20.0, 0.0, 0.0], (STEPS, 1)),
    )
    assert sol.ok and sol.status == "solved"
    assert sol.max_state_violation == pytest.approx(23.2, abs=1e-3)
    np.testing.assert_allclose(sol.inputs_mps2[:, 0], -3.0, atol=1e-4)
    assert np.all(np.isfinite(sol.positions_m)) and np.max(np.abs(sol.positions_m)) < 30.0


@pytest.mark.parametrize("solver", SOLVERS)
def test_a_plan_never_accelerates_faster_than_the_input_box_allows(solver):
    """f = 20 m/s^2 east, far beyond the box's 6 m/s^2 width: with the plan's acceleration bounded, u + f is
    held at the box's 3 m/s^2, so after 1.6 s the velocity is 1 + 1.6 * 3 = 5.8 m/s (0.8 over its bound)."""
    sol = solve(
        ModelPredictiveController(MpcParams(solver=solver)),
        velocity_mps=np.array([1.0, 0.0, 0.0]),
        target_position_m=np.array([5.0, 3.0, 8.0]),
        external_inputs_mps2=np.tile([20.0, 0.0, 0.0], (STEPS, 1)),
    )
    assert sol.ok
    np.testing.assert_allclose(sol.inputs_mps2[:, 0] + 20.0, 3.0, atol=1e-6)
    assert sol.max_state_violation == pytest.approx(0.8, abs=1e-3)


@pytest.mark.parametrize("solver", SOLVERS)
@pytest.mark.parametrize(("bounded", "first_u"), [(True, 1.0), (False, 3.0)])
def test_a_field_along_the_way_leaves_the_input_only_the_rest_of_the_box(solver, bounded, first_u):
    """f = 2 m/s^2 east and a target 15 m east: the plan accelerates east as hard as it may. Bounded, u + f
    stays in the box, so u = 3 - 2 = 1 m/s^2; as in the paper (u alone bounded), u = 3 and the plan
    accelerates at 5 m/s^2, more than a vehicle flies."""
    sol = solve(
        ModelPredictiveController(replace(PARAMS if bounded else PAPER_BOUND, solver=solver)),
        target_position_m=np.array([15.0, 0.0, 6.0]),
        external_inputs_mps2=np.tile([2.0, 0.0, 0.0], (STEPS, 1)),
    )
    assert sol.ok
    assert sol.inputs_mps2[0, 0] == pytest.approx(first_u, abs=1e-6)


def test_input_box_holds_the_plans_acceleration_within_its_bounds():
    """Per step and axis: the input box, narrowed so that u + f stays in [a_min, a_max]; a field beyond the
    boxes' reach pins u where u + f is at the bound it pushes against; z's box is [3, 11] before gravity."""
    f = np.array([[0.0, 2.0, 0.0], [-1.0, 7.0, -9.0], [-20.0, 0.5, 1.0]])
    lo, hi = input_box(f, PARAMS)
    np.testing.assert_allclose(lo, [[-3.0, -3.0, 3.0], [-2.0, -4.0, 12.0], [17.0, -3.0, 3.0]])
    np.testing.assert_allclose(hi, [[3.0, 1.0, 11.0], [3.0, -4.0, 12.0], [17.0, 2.5, 10.0]])


def test_input_box_without_a_plan_bound_is_the_papers():
    lo, hi = input_box(np.full((2, 3), 50.0), PAPER_BOUND)
    np.testing.assert_allclose(lo, [[-3.0, -3.0, 3.0]] * 2)
    np.testing.assert_allclose(hi, [[3.0, 3.0, 11.0]] * 2)


@pytest.mark.parametrize(
    "bounds",
    [
        dict(plan_acceleration_min_mps2=None),
        dict(plan_acceleration_min_mps2=(1.0, 0.0, 0.0), plan_acceleration_max_mps2=(0.0, 0.0, 0.0)),
        dict(plan_acceleration_max_mps2=(np.inf, 3.0, 11.0)),
    ],
)
def test_plan_acceleration_bounds_must_be_both_finite_and_ordered(bounds):
    with pytest.raises(ValueError, match="plan acceleration|both or neither"):
        MpcParams(**bounds)


@pytest.mark.parametrize(
    "name",
    [
        "position_m",
        "velocity_mps",
        "target_position_m",
        "target_velocity_mps",
        "external_inputs_mps2",
        "terminal_position_weight",
        "terminal_velocity_weight",
    ],
)
def test_non_finite_argument_gives_not_ok_with_message(name):
    bad = {
        "external_inputs_mps2": np.zeros((STEPS, 3)),
        "terminal_position_weight": 100.0 * np.eye(3),
        "terminal_velocity_weight": 100.0 * np.eye(3),
    }.get(name, np.zeros(3))
    bad = bad.copy()
    bad.flat[-1] = np.nan if name.startswith("terminal") or name == "position_m" else np.inf
    sol = solve(ModelPredictiveController(PARAMS), **{name: bad})
    assert not sol.ok
    assert sol.status == "invalid_input"
    assert sol.message is not None
    assert name in sol.message


def test_implausibly_large_argument_gives_not_ok():
    """1e30 is OSQP's infinity: such numbers must be refused, not passed on to be silently ignored."""
    sol = solve(ModelPredictiveController(PARAMS), target_position_m=np.array([1e30, 0.0, 6.0]))
    assert not sol.ok
    assert sol.status == "invalid_input"
    assert sol.message is not None
    assert "target_position_m is implausibly large" in sol.message


def test_controller_solves_normally_after_invalid_input():
    controller = ModelPredictiveController(PARAMS)
    rejected = solve(controller, position_m=np.array([np.nan, 0.0, 6.0]))
    sol = solve(controller)
    assert not rejected.ok and sol.ok
    np.testing.assert_allclose(sol.inputs_mps2, np.tile(HOVER, (STEPS, 1)), atol=1e-4)


def test_indefinite_terminal_weight_is_rejected():
    sol = solve(ModelPredictiveController(PARAMS), terminal_velocity_weight=np.diag([100.0, 100.0, -1.0]))
    assert not sol.ok
    assert sol.message is not None
    assert "positive semidefinite" in sol.message


def test_asymmetric_terminal_weight_is_rejected():
    weight = 100.0 * np.eye(3)
    weight[0, 1] = 5.0
    sol = solve(ModelPredictiveController(PARAMS), terminal_position_weight=weight)
    assert not sol.ok
    assert sol.message is not None
    assert "symmetric" in sol.message


def test_wrong_shape_raises_value_error():
    with pytest.raises(ValueError, match="external_inputs_mps2"):
        solve(ModelPredictiveController(PARAMS), external_inputs_mps2=np.zeros((N, 3)))


def test_solver_failure_is_not_ok_and_carries_no_numbers():
    params = MpcParams(solver="osqp", max_iterations=10, polishing=False, accept_inaccurate=False)
    sol = solve(ModelPredictiveController(params), target_position_m=np.array([15.0, -12.0, 9.0]))
    assert not sol.ok
    assert sol.status == "maximum iterations reached"
    assert sol.message is not None
    assert "OSQP" in sol.message and sol.iterations == 10
    assert np.all(np.isnan(sol.inputs_mps2)) and np.all(np.isnan(sol.positions_m))


@pytest.mark.parametrize(
    "overrides",
    [
        {"effort": "thrust"},
        {"horizon_steps": 0},
        {"dt_s": 0.0},
        {"position_min_m": (-20.0, -20.0, 11.0)},
        {"input_weight": 0.0},
        {"slack_weight": -1.0},
    ],
)
def test_invalid_params_raise(overrides):
    with pytest.raises(ValueError):
        MpcParams(**overrides)


# ------------------------------------------------------------------------------------------- warm start
@pytest.mark.parametrize("kind", ["nominal", "position_bound", "large_force"])
def test_second_identical_solve_needs_no_more_iterations(kind):
    case = random_case(np.random.default_rng(7), kind)
    controller = ModelPredictiveController(OSQP)
    first = controller.solve(**case)
    second = controller.solve(**case)
    assert first.ok and second.ok
    assert second.iterations <= first.iterations


def test_receding_horizon_warm_start_saves_iterations():
    """Ticking at dt_s and starting each solve where the last plan said the MAV would be, warm starts from the
    shifted plan need far fewer iterations than solving each of the same problems cold."""
    controller = ModelPredictiveController(OSQP)
    position, velocity = np.array([-12.0, 4.0, 4.0]), np.array([1.0, 0.0, 0.0])
    warm, cold = [], []
    for tick in range(20):
        angle = 0.05 * tick
        problem: dict[str, np.ndarray] = dict(
            position_m=position,
            velocity_mps=velocity,
            target_position_m=np.array([8.0 * np.cos(angle), 8.0 * np.sin(angle), 8.0]),
            target_velocity_mps=np.array([-np.sin(angle), np.cos(angle), 0.0]),
            external_inputs_mps2=np.tile([0.5 * np.sin(angle), 0.3, 0.0], (STEPS, 1)),
        )
        sol = solve(controller, **problem)
        warm.append(sol.iterations)
        cold.append(solve(ModelPredictiveController(OSQP), **problem).iterations)
        position, velocity = sol.positions_m[1], sol.velocities_mps[1]
    assert sum(warm[1:]) < 0.6 * sum(cold[1:])


def test_reset_makes_the_next_solves_those_of_a_fresh_controller():
    rng = np.random.default_rng(3)
    cases = [random_case(rng, kind) for kind in ("nominal", "formation")]
    fresh = ModelPredictiveController(OSQP)
    expected = [fresh.solve(**case) for case in cases]
    used = ModelPredictiveController(OSQP)
    used.solve(**random_case(rng, "large_force"))
    used.reset()
    again = [used.solve(**case) for case in cases]
    assert [s.iterations for s in again] == [s.iterations for s in expected]
    for a, b in zip(again, expected, strict=True):
        np.testing.assert_array_equal(a.inputs_mps2, b.inputs_mps2)


# ------------------------------------------------------------------------------------------- braking
def brake(position, velocity) -> tuple[np.ndarray, np.ndarray]:
    return braking_plan(
        position_m=np.asarray(position, float), velocity_mps=np.asarray(velocity, float), params=PARAMS
    )


def test_braking_plan_comes_to_rest_and_holds():
    positions, velocities = brake([0.0, 0.0, 5.0], [4.0, -3.0, 0.4])
    assert positions.shape == velocities.shape == (N + 2, 3)
    assert np.all(np.diff(np.abs(velocities), axis=0) <= 1e-12)
    # vx = 4 m/s at 3 m/s^2 is at rest after 14 steps of 0.1 s; rows 14..16 hold
    np.testing.assert_allclose(velocities[-3:], 0.0, atol=1e-12)
    np.testing.assert_allclose(positions[-3:], np.tile(positions[-1], (3, 1)), atol=1e-12)
    assert abs(velocities[-4, 0]) > 0.05


def test_braking_plan_decelerates_at_the_input_bound():
    """vx = 4 m/s needs 1.33 s at 3 m/s^2: the first steps brake at exactly the bound."""
    _, velocities = brake([0.0, 0.0, 5.0], [4.0, -3.0, 0.0])
    acc = np.diff(velocities, axis=0) / PARAMS.dt_s
    np.testing.assert_allclose(acc[:9, 0], -3.0, atol=1e-9)
    np.testing.assert_allclose(acc[:9, 1], 3.0, atol=1e-9)


def test_braking_plan_respects_input_bounds():
    rng = np.random.default_rng(11)
    for _ in range(20):
        _, velocities = brake(rng.uniform(-15, 15, 3) + [0, 0, 20], rng.normal(0.0, 4.0, 3))
        inputs = np.diff(velocities, axis=0) / PARAMS.dt_s - G
        assert np.all(inputs >= np.array(PARAMS.input_min_mps2) - 1e-9)
        assert np.all(inputs <= np.array(PARAMS.input_max_mps2) + 1e-9)


def test_braking_plan_is_finite_for_finite_input():
    rng = np.random.default_rng(12)
    for _ in range(20):
        positions, velocities = brake(rng.normal(0.0, 1e3, 3), rng.normal(0.0, 1e3, 3))
        assert np.all(np.isfinite(positions)) and np.all(np.isfinite(velocities))


def test_braking_plan_clips_positions_into_bounds():
    positions, _ = brake([19.5, 0.0, 3.2], [5.0, 0.0, -0.5])
    assert np.max(positions[:, 0]) == pytest.approx(20.0)
    assert np.min(positions[:, 2]) >= 3.0


def test_compiled_half_plane_rows_are_the_numpy_rows_bit_for_bit():
    """mpc_kernels.half_plane_rows against `_half_plane_rows` on 200 random sets of 1-120 tilted rows at
    random steps, states and external inputs: the same bits, so a seeded simulation does not move."""
    rng = np.random.default_rng(7)
    controller = ModelPredictiveController(MpcParams())
    for _ in range(200):
        count = int(rng.integers(1, 121))
        planes = (
            rng.integers(1, STEPS + 1, count).astype(np.int64),
            rng.normal(size=(count, 3)),
            rng.normal(scale=10.0, size=count),
            (rng.random(count) < 0.8).astype(float),
        )
        position, velocity = rng.normal(scale=10.0, size=3), rng.normal(scale=3.0, size=3)
        external = rng.normal(size=(STEPS, 3))
        reference = controller._half_plane_rows(planes, position, velocity, external)
        compiled = controller._half_plane_rows_compiled(planes, position, velocity, external)
        for ref, fast in zip(reference, compiled, strict=True):
            np.testing.assert_array_equal(fast, ref)


def test_compiled_plane_shortfall_is_the_numpy_violation():
    """mpc_kernels.plane_shortfall against `_plane_violation` on 200 random plans and sets of 1-120 tilted
    half-planes: the same largest shortfall (positive when a row fails), so the closed form's check of the
    half-planes agrees with the violation the solution reports."""
    rng = np.random.default_rng(8)
    failing = 0
    for _ in range(200):
        count = int(rng.integers(1, 121))
        steps = rng.integers(1, STEPS + 1, count).astype(np.int64)  # 1..N+1
        normals, positions = rng.normal(size=(count, 3)), rng.normal(scale=10.0, size=(N + 2, 3))
        offsets = np.einsum("ri,ri->r", normals, positions[steps]) - rng.uniform(0.0, 1.0, count)
        if rng.random() < 0.5:  # one row fails by up to 2 m
            offsets[rng.integers(count)] += rng.uniform(1.0, 3.0)
        shortfall = plane_shortfall(steps, normals, offsets, positions)
        reference = _plane_violation((steps, normals, offsets, np.ones(count)), positions)
        assert max(0.0, shortfall) == pytest.approx(reference, rel=1e-12, abs=1e-12)
        failing += shortfall > 0.0
    assert 50 < failing < 150  # both verdicts were exercised


def test_plane_shortfall_is_nan_for_a_non_finite_half_plane():
    positions = np.zeros((N + 2, 3))
    steps, normals = np.array([1, 2], dtype=np.int64), np.array([[1.0, 0.0, 0.0], [0.0, np.inf, 0.0]])
    assert np.isnan(plane_shortfall(steps, normals, np.array([-1.0, -1.0]), positions))
    assert np.isnan(plane_shortfall(steps[:1], normals[:1], np.array([np.nan]), positions))

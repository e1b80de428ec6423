"""`skyring bench controller`: one MAV's control tick, and our MPC against CVXPY on the same QPs.

A tick is what one MAV computes per control period: fuse one detection in its person tracker, then the
formation controller's step (teammates' plans on our horizon, every external input, the MPC solve, the
way-point). It is timed for K = 3, 8, 16 MAVs (K - 1 teammates' plans, the paper's 13 trees, the person on the
paper's path) in a running closed loop, so plans and inputs look like a flight. Target
(docs/architecture.md#performance-targets): median <= 0.2 ms per tick at K = 16. Speed is measured here, never
in tests.
"""

from __future__ import annotations

import time

import numpy as np

from controller.formation import FormationController
from controller.measurement import NoiseParams, sample_detection
from controller.messages import Detection, HorizonPlan, PersonEstimate, VehicleState
from controller.mpc import ModelPredictiveController, MpcParams
from controller.params import ControllerParams, FormationParams
from controller.reference import input_displacement, terminal_reference
from controller.tracker import PersonTracker
from vehicles.sim.person import PathPerson, paper_path
from vehicles.sim.trees import paper_trees

TARGET_MEDIAN_MS = 0.2
TEAM_SIZES = (3, 8, 16)
RATE_HZ = 10.0
WARMUP_S = 20.0


def _start(team_size: int) -> np.ndarray:
    """(K, 3) the team spread round the person's start (the origin), 8.9 m up, clear of the paper's trees."""
    th = np.radians(10.0) + 2.0 * np.pi * np.arange(team_size) / team_size
    return np.stack([8.0 * np.cos(th), 8.0 * np.sin(th), np.full(team_size, 8.9)], axis=1)


def _fly(team_size: int, ticks: int, *, record: bool):
    """Run a K-MAV closed loop (vehicles follow their plans exactly); time MAV 0's ticks once `record`.

    Returns ((T, 3) times in s of [tracker, controller step, whole tick], MPC instances of MAV 0 as solve()
    keyword dicts)."""
    params = ControllerParams()
    formation = FormationParams()
    person = PathPerson(path_xy_m=paper_path())
    trees = paper_trees()
    rng = np.random.default_rng(1)
    noise = NoiseParams()
    ctrls = [FormationController(vehicle_id=k, params=params) for k in range(team_size)]
    tracker = PersonTracker(params.tracker)
    pos, vel = _start(team_size), np.zeros((team_size, 3))
    plans: list[HorizonPlan | None] = [None] * team_size
    warm = int(WARMUP_S * RATE_HZ)
    times, instances = [], []
    for tick in range(warm + ticks):
        now = tick / RATE_HZ
        truth = person.truth(now)
        det_p, det_cov = sample_detection(
            rng, camera_position_m=pos[0], target_position_m=truth.position_m, noise=noise
        )
        detection = Detection(source_id=0, stamp_s=now, position_m=det_p, cov_m2=det_cov)
        exact = PersonEstimate(
            stamp_s=now, position_m=truth.position_m, velocity_mps=truth.velocity_mps, cov=np.eye(6) * 0.01
        )
        outs = []
        for k, ctrl in enumerate(ctrls):
            own = VehicleState(vehicle_id=k, stamp_s=now, position_m=pos[k], velocity_mps=vel[k])
            mates = [p for j, p in enumerate(plans) if j != k and p is not None]
            if k == 0:
                t0 = time.perf_counter()
                tracker.update(detection)
                estimate = tracker.estimate(now)
                t1 = time.perf_counter()
                out = ctrl.step(
                    now_s=now, own=own, person=estimate, teammates=mates, obstacles=trees, formation=formation
                )
                t2 = time.perf_counter()
                if record and tick >= warm:
                    times.append((t1 - t0, t2 - t1, t2 - t0))
                    if estimate is not None:
                        instances.append(_instance(out, estimate, formation, params))
            else:
                out = ctrl.step(
                    now_s=now, own=own, person=exact, teammates=mates, obstacles=trees, formation=formation
                )
            outs.append(out)
        plans = [out.plan for out in outs]
        pos = np.array([out.plan.positions_m[1] for out in outs])
        vel = np.array([out.plan.velocities_mps[1] for out in outs])
    return np.array(times).reshape(-1, 3), instances


def _instance(out, estimate: PersonEstimate, formation: FormationParams, params: ControllerParams) -> dict:
    """The QP MAV 0 just solved, rebuilt from its output with the controller's public reference functions."""
    mp = params.mpc
    start_p, start_v = out.plan.positions_m[0], out.plan.velocities_mps[0]
    target, target_v = terminal_reference(
        position_m=start_p,
        person_position_m=estimate.position_m,
        person_velocity_mps=estimate.velocity_mps,
        d_des_m=formation.d_des_m,
        h_des_m=formation.h_des_m,
        horizon_s=(mp.horizon_steps + 1) * mp.dt_s,
        params=params.reference,
    )
    shift_p, shift_v = input_displacement(out.external_inputs, dt_s=mp.dt_s)
    target = np.clip(target + shift_p, mp.position_min_m, mp.position_max_m)
    return dict(
        position_m=np.array(start_p),
        velocity_mps=np.array(start_v),
        target_position_m=target,
        target_velocity_mps=target_v + shift_v,
        external_inputs_mps2=np.array(out.external_inputs),
    )


def _cvxpy_problem(params: MpcParams):
    """The MPC's QP written from the equations with CVXPY parameters (states as variables), built once."""
    import cvxpy as cp  # a test extra: imported only when this benchmark runs

    dt, m = params.dt_s, params.horizon_steps + 1
    g = np.array([0.0, 0.0, -params.gravity_mps2])
    x0, v0 = cp.Parameter(3), cp.Parameter(3)
    p_ref, v_ref = cp.Parameter(3), cp.Parameter(3)
    f = cp.Parameter((m, 3))
    u, p, v, s = cp.Variable((m, 3)), cp.Variable((m + 1, 3)), cp.Variable((m + 1, 3)), cp.Variable(6)
    ones = np.ones((m, 1))
    acc = u + f + ones @ g[None, :]
    s_pos = ones @ cp.reshape(s[:3], (1, 3), order="C")
    s_vel = ones @ cp.reshape(s[3:], (1, 3), order="C")
    constraints = [
        p[0] == x0,
        v[0] == v0,
        p[1:] == p[:-1] + dt * v[:-1] + 0.5 * dt * dt * acc,
        v[1:] == v[:-1] + dt * acc,
        u >= ones @ np.atleast_2d(params.input_min_mps2),
        u <= ones @ np.atleast_2d(params.input_max_mps2),
        p[1:] <= ones @ np.atleast_2d(params.position_max_m) + s_pos,
        p[1:] >= ones @ np.atleast_2d(params.position_min_m) - s_pos,
        v[1:] <= ones @ np.atleast_2d(params.velocity_max_mps) + s_vel,
        v[1:] >= ones @ np.atleast_2d(params.velocity_min_mps) - s_vel,
        s >= 0,
    ]
    cost = (
        params.input_weight * cp.sum_squares(u + ones @ g[None, :])
        + params.terminal_position_weight * cp.sum_squares(p[m] - p_ref)
        + params.terminal_velocity_weight * cp.sum_squares(v[m] - v_ref)
        + params.slack_weight * cp.sum(s)
        + params.slack_quadratic_weight * cp.sum_squares(s)
    )
    problem = cp.Problem(cp.Minimize(cost), constraints)

    def solve(case: dict, solver: str) -> tuple[float, np.ndarray]:
        x0.value, v0.value = case["position_m"], case["velocity_mps"]
        p_ref.value, v_ref.value = case["target_position_m"], case["target_velocity_mps"]
        f.value = case["external_inputs_mps2"]
        t0 = time.perf_counter()
        problem.solve(solver=solver)
        return time.perf_counter() - t0, np.asarray(u.value)

    return solve


def _compare_with_cvxpy(instances: list[dict]) -> None:
    params = MpcParams()
    try:
        solve_cvx = _cvxpy_problem(params)
    except ImportError:
        print("  CVXPY is not installed (a test extra): comparison skipped")
        return
    ours = ModelPredictiveController(params)
    ours_s, ours_u = [], []
    for case in instances:
        t0 = time.perf_counter()
        sol = ours.solve(**case)
        ours_s.append(time.perf_counter() - t0)
        ours_u.append(sol.inputs_mps2)
    print(f"MPC solve vs CVXPY, the same {len(instances)} QPs (K = 16 flight, warm-started in sequence):")
    print(f"  ours (OSQP, built once, updated)   median {1e3 * np.median(ours_s):7.3f} ms")
    for solver in ("OSQP", "CLARABEL"):
        results = [solve_cvx(case, solver) for case in instances]
        cvx_s = [r[0] for r in results]
        diff = max(float(np.abs(r[1] - u).max()) for r, u in zip(results, ours_u, strict=True))
        ratio = np.median(ours_s) / np.median(cvx_s)
        print(
            f"  CVXPY + {solver:<8}                median {1e3 * np.median(cvx_s):7.3f} ms   "
            f"ours / CVXPY = {ratio:.3f}   max |u_ours - u_cvxpy| = {diff:.1e} m/s^2"
        )


def run(*, repeats: int) -> None:
    """Time `repeats` ticks of MAV 0 for each team size, then compare the K = 16 QPs with CVXPY."""
    ticks = max(int(repeats), 20)
    print(
        f"controller tick (tracker update + teammates + external inputs + MPC + way-point), one MAV, "
        f"{RATE_HZ:g} Hz, paper path and 13 trees, {ticks} ticks after {WARMUP_S:g} s:"
    )
    print("     K   tick median ms   tick p99 ms   (tracker median ms, controller step median ms)")
    instances: list[dict] = []
    median_16 = float("nan")
    for team_size in TEAM_SIZES:
        times, recorded = _fly(team_size, ticks, record=True)
        median, p99 = 1e3 * np.median(times[:, 2]), 1e3 * np.percentile(times[:, 2], 99)
        parts = 1e3 * np.median(times[:, :2], axis=0)
        print(f"  {team_size:4d}   {median:14.3f}   {p99:11.3f}   ({parts[0]:.3f}, {parts[1]:.3f})")
        if team_size == 16:
            instances, median_16 = recorded, median
    verdict = "met" if median_16 <= TARGET_MEDIAN_MS else "NOT met"
    print(f"  target: median <= {TARGET_MEDIAN_MS} ms per tick at K = 16: {verdict}")
    _compare_with_cvxpy(instances[: max(20, min(len(instances), ticks))])

"""`skyring bench controller`: one MAV's control tick at the paper's 100 Hz, and the MPC against CVXPY.

A tick is what one MAV computes per control period: fuse the person detections that arrived (its own camera
and every teammate's, each at 4 Hz, so about K / 25 per tick), predict the estimate to now, then the formation
controller's step (teammates' plans on our horizon from the plan table, every external input, the MPC solve,
the way-point). It is timed for K = 3, 8, 16 MAVs (K - 1 teammates publishing plans at 10 Hz, the paper's 13
trees, the person on the paper's path) in a running closed loop, so plans and inputs look like a flight. In
that loop the other K - 1 controllers run between two of MAV 0's ticks, as in the simulator; a second K = 16
row replays MAV 0's ticks with the same inputs and nothing in between, as an onboard agent runs them. The
verdict is on the first. Targets (docs/architecture.md#performance-targets): median <= 0.1 ms and p99 <= 0.5
ms per tick at K = 16; the MPC >= 100x faster than the same QP through CVXPY + OSQP, with the same first
input to 1e-6. Speed is measured here, never in tests.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from controller.formation import FormationController
from controller.measurement import NoiseParams, sample_detection
from controller.messages import ControlOutput, Detection, HorizonPlan, Obstacle, PersonEstimate, VehicleState
from controller.mpc import HalfPlanes, ModelPredictiveController, MpcParams, input_box
from controller.params import ControllerParams, FormationParams
from controller.reference import plan_state_at
from controller.teammates import TeammateTable, TeammateView
from controller.tracker import PersonTracker, TrackerParams
from vehicles.agent import AgentParams
from vehicles.sim.person import PathPerson, paper_path
from vehicles.sim.trees import paper_trees

TARGET_MEDIAN_MS = 0.1
TARGET_P99_MS = 0.5
TARGET_MPC_RATIO = 100.0
TEAM_SIZES = (3, 8, 16)
RATE_HZ = 100.0
PLAN_PERIOD_TICKS = 10  # plans are published at 10 Hz
DETECTOR_HZ = 4.0
WARMUP_S = 20.0
TEAMMATE_WINDOW_S = AgentParams().teammate_timeout_s  # older plans are left out, as the agent forgets them


def _start(team_size: int) -> np.ndarray:
    """(K, 3) the team spread round the person's start (the origin), 8.9 m up, clear of the paper's trees."""
    th = np.radians(10.0) + 2.0 * np.pi * np.arange(team_size) / team_size
    return np.stack([8.0 * np.cos(th), 8.0 * np.sin(th), np.full(team_size, 8.9)], axis=1)


@dataclass(frozen=True)
class _TickInputs:
    """What MAV 0 was given on one tick of a flight, for replaying its ticks alone: the time (s), its state,
    the detections it fused, the teammates' plans its table took in after the tick, and the way-point (3,)
    it answered (m), to check that the replay does the same work."""

    now_s: float
    own: VehicleState
    detections: tuple[Detection, ...]
    plans_after: tuple[HorizonPlan, ...]
    waypoint_m: np.ndarray


def _fly(
    team_size: int,
    ticks: int,
    *,
    record: bool,
    capture: bool = False,
    active_set: str = "compiled",
    kalman_filter: str = "filterpy",
    log: list[_TickInputs] | None = None,
):
    """Run a K-MAV closed loop at RATE_HZ (vehicles follow their plans exactly); time MAV 0's ticks once
    `record`; with `capture`, keep every MPC problem MAV 0 solves then, as its solve() keyword arguments
    (half-planes and escapes included; the recording wraps the solver, so a capturing flight is not timed).
    active_set: the MPC's active-set step (`MpcParams.active_set`); kalman_filter: what moves MAV 0's track
    (`TrackerParams.kalman_filter`); log: when given, MAV 0's inputs of every tick are appended to it
    (`_replay_alone`).

    Returns ((T, 5) [tracker s, controller step s, whole tick s, detections fused, whole tick CPU s], MPC
    instances of MAV 0 as solve() keyword dicts)."""
    params = _params(active_set, kalman_filter)
    formation = FormationParams()
    person = PathPerson(path_xy_m=paper_path())
    trees = paper_trees()
    rng = np.random.default_rng(1)
    noise = NoiseParams()
    ctrls = [FormationController(vehicle_id=k, params=params) for k in range(team_size)]
    tables = [_table(k, params) for k in range(team_size)]
    tracker = PersonTracker(params.tracker)
    pos, vel = _start(team_size), np.zeros((team_size, 3))
    next_frame = np.arange(team_size) / (DETECTOR_HZ * team_size)  # staggered cameras
    warm = int(WARMUP_S * RATE_HZ)
    dt = 1.0 / RATE_HZ
    times: list[tuple] = []
    instances: list[dict] = []
    if capture:
        mpc = ctrls[0]._mpc  # noqa: SLF001 - the benchmark records the exact QPs the controller solves
        solve = mpc.solve

        def recording_solve(**kwargs):
            instances.append({k: v.copy() if isinstance(v, np.ndarray) else v for k, v in kwargs.items()})
            return solve(**kwargs)

        mpc.solve = recording_solve  # type: ignore[method-assign]
    for tick in range(warm + ticks):
        if capture and tick == warm:
            instances.clear()
        now = tick * dt
        truth = person.truth(now)
        detections = []
        for k in np.flatnonzero(next_frame <= now + 1e-9):
            det_p, det_cov = sample_detection(
                rng, camera_position_m=pos[k], target_position_m=truth.position_m, noise=noise
            )
            detections.append(Detection(source_id=int(k), stamp_s=now, position_m=det_p, cov_m2=det_cov))
            next_frame[k] += 1.0 / DETECTOR_HZ
        exact = PersonEstimate(
            stamp_s=now, position_m=truth.position_m, velocity_mps=truth.velocity_mps, cov=np.eye(6) * 0.01
        )
        outs = []
        states = [
            VehicleState(vehicle_id=k, stamp_s=now, position_m=pos[k], velocity_mps=vel[k])
            for k in range(team_size)
        ]
        for k, (ctrl, own) in enumerate(zip(ctrls, states, strict=True)):
            mates = tables[k].view(now - TEAMMATE_WINDOW_S)
            if k == 0:
                out, row = _timed_tick(tracker, ctrl, now, own, detections, mates, trees, formation)
                if record and tick >= warm:
                    times.append(row)
            else:
                out = ctrl.step(
                    now_s=now, own=own, person=exact, teammates=mates, obstacles=trees, formation=formation
                )
            outs.append(out)
        published = tuple(out.plan for out in outs) if tick % PLAN_PERIOD_TICKS == 0 else ()
        for k, plan in enumerate(published):
            for j, table in enumerate(tables):
                if j != k:
                    table.update(plan)
        if log is not None:
            log.append(
                _TickInputs(now, states[0], tuple(detections), published[1:], outs[0].waypoint_position_m)
            )
        for k, out in enumerate(outs):
            p, v = plan_state_at(
                out.plan.positions_m, out.plan.velocities_mps, elapsed_s=dt, dt_s=out.plan.dt_s
            )
            pos[k], vel[k] = p, v
    return np.array(times).reshape(-1, 5), instances


def _timed_tick(
    tracker: PersonTracker,
    ctrl: FormationController,
    now_s: float,
    own: VehicleState,
    detections: Sequence[Detection],
    mates: TeammateView,
    obstacles: Sequence[Obstacle],
    formation: FormationParams,
) -> tuple[ControlOutput, tuple[float, float, float, int, float]]:
    """One timed tick of MAV 0: fuse the detections, estimate, step. Returns (the controller's output,
    (tracker s, controller step s, whole tick s, detections fused, whole tick CPU s))."""
    c0 = time.thread_time()
    t0 = time.perf_counter()
    for det in detections:
        tracker.update(det)
    estimate = tracker.estimate(now_s)
    t1 = time.perf_counter()
    out = ctrl.step(
        now_s=now_s, own=own, person=estimate, teammates=mates, obstacles=obstacles, formation=formation
    )
    t2 = time.perf_counter()
    c2 = time.thread_time()
    return out, (t1 - t0, t2 - t1, t2 - t0, len(detections), c2 - c0)


def _params(active_set: str, kalman_filter: str) -> ControllerParams:
    return ControllerParams(
        mpc=MpcParams(active_set=active_set), tracker=TrackerParams(kalman_filter=kalman_filter)
    )


def _table(own_id: int, params: ControllerParams) -> TeammateTable:
    return TeammateTable(own_id=own_id, plan_length=params.mpc.horizon_steps + 2)


def _replay_alone(log: list[_TickInputs], *, active_set: str, kalman_filter: str) -> tuple[np.ndarray, bool]:
    """MAV 0's ticks of a logged flight again, with nothing else running in between: its tick as an onboard
    agent sees it (one controller per process; the agent's messaging is left out), where the flight runs the
    other K - 1 controllers between two of MAV 0's ticks. Same inputs, same controller, so the same work:
    returns ((T, 5) as `_fly`'s times for the ticks after the warm-up, whether every way-point was the
    flight's, bit for bit)."""
    params = _params(active_set, kalman_filter)
    formation = FormationParams()
    trees = paper_trees()
    ctrl, table, tracker = (
        FormationController(vehicle_id=0, params=params),
        _table(0, params),
        PersonTracker(params.tracker),
    )
    warm = int(WARMUP_S * RATE_HZ)
    times: list[tuple] = []
    same = True
    for tick, given in enumerate(log):
        mates = table.view(given.now_s - TEAMMATE_WINDOW_S)
        out, row = _timed_tick(
            tracker, ctrl, given.now_s, given.own, given.detections, mates, trees, formation
        )
        if tick >= warm:
            times.append(row)
        same = same and np.array_equal(out.waypoint_position_m, given.waypoint_m)
        for plan in given.plans_after:
            table.update(plan)
    return np.array(times).reshape(-1, 5), same


def _cvxpy_problem(params: MpcParams, max_rows: int):
    """The MPC's QP written from the equations with CVXPY parameters (states as variables), built once, with
    room for max_rows half-plane rows (unused rows are 0 >= -1): a^T p(n) + soft w(n) >= b, w >= 0, one slack
    w(n) per plan step."""
    import cvxpy as cp  # a test extra: imported only when this benchmark runs

    dt, m = params.dt_s, params.horizon_steps + 1
    g = np.array([0.0, 0.0, -params.gravity_mps2])
    x0, v0 = cp.Parameter(3), cp.Parameter(3)
    p_ref, v_ref = cp.Parameter(3), cp.Parameter(3)
    f = cp.Parameter((m, 3))
    u_lo, u_hi = cp.Parameter((m, 3)), cp.Parameter((m, 3))  # each step's input box (mpc.input_box)
    rows = max(int(max_rows), 1)
    coeffs = cp.Parameter((rows, 3 * (m + 1)))  # row r's normal at the columns of p(steps[r]), row-major
    offsets = cp.Parameter(rows)
    slack_of_row = cp.Parameter((rows, m), nonneg=True)  # soft_r at the column of row r's step
    u, p, v, s = cp.Variable((m, 3)), cp.Variable((m + 1, 3)), cp.Variable((m + 1, 3)), cp.Variable(6)
    w = cp.Variable(m)
    ones = np.ones((m, 1))
    acc = u + f + ones @ g[None, :]
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
        coeffs @ cp.reshape(p, (3 * (m + 1),), order="C") + slack_of_row @ w >= offsets,
        w >= 0,
    ]
    cost = (
        params.input_weight * cp.sum_squares(u + ones @ g[None, :])
        + params.terminal_position_weight * cp.sum_squares(p[m] - p_ref)
        + params.terminal_velocity_weight * cp.sum_squares(v[m] - v_ref)
        + params.slack_weight * cp.sum(s)
        + params.slack_quadratic_weight * cp.sum_squares(s)
        + params.half_plane_weight * cp.sum(w)
        + params.half_plane_quadratic_weight * cp.sum_squares(w)
    )
    problem = cp.Problem(cp.Minimize(cost), constraints)

    def solve(case: dict, solver: str, *, tight: bool) -> tuple[float, np.ndarray, float]:
        x0.value, v0.value = case["position_m"], case["velocity_mps"]
        p_ref.value, v_ref.value = case["target_position_m"], case["target_velocity_mps"]
        f.value = case["external_inputs_mps2"]
        u_lo.value, u_hi.value = input_box(case["external_inputs_mps2"], params)
        c, b, sf = np.zeros((rows, 3 * (m + 1))), np.full(rows, -1.0), np.zeros((rows, m))
        planes: HalfPlanes | None = case.get("half_planes")
        if planes is not None:
            n = len(planes.steps)
            cols = 3 * np.asarray(planes.steps)[:, None] + np.arange(3)[None, :]
            nz = np.zeros(n) if planes.normals_z is None else planes.normals_z
            np.put_along_axis(c[:n], cols, np.column_stack([planes.normals_xy, nz]), axis=1)
            b[:n] = planes.offsets
            soft = np.ones(n) if planes.soft is None else np.asarray(planes.soft, dtype=float)
            sf[np.arange(n), np.asarray(planes.steps) - 1] = soft
        coeffs.value, offsets.value, slack_of_row.value = c, b, sf
        options = dict(eps_abs=1e-10, eps_rel=1e-10, max_iter=200_000, polishing=True) if tight else {}
        c0, t0 = time.thread_time(), time.perf_counter()
        problem.solve(solver=solver, **options)
        return time.perf_counter() - t0, np.asarray(u.value), time.thread_time() - c0

    return solve


def _compare_with_cvxpy(instances: list[dict]) -> None:
    params = MpcParams()
    max_rows = max((len(c["half_planes"].steps) for c in instances if c.get("half_planes")), default=0)
    try:
        solve_cvx = _cvxpy_problem(params, max_rows)
    except ImportError:
        print("  CVXPY is not installed (a test extra): comparison skipped")
        return
    timed: dict[str, tuple[list[float], list[float], list[np.ndarray]]] = {}
    paths: list[str] = []
    solvers = {
        "exact": MpcParams(active_set="daqp"),
        "compiled": MpcParams(active_set="compiled"),
        "osqp": MpcParams(solver="osqp"),
    }
    for solver, solver_params in solvers.items():
        ours = ModelPredictiveController(solver_params)
        elapsed, cpu, first = [], [], []
        for case in instances:
            c0, t0 = time.thread_time(), time.perf_counter()
            sol = ours.solve(**case)
            elapsed.append(time.perf_counter() - t0)
            cpu.append(time.thread_time() - c0)
            first.append(sol.inputs_mps2[0])
        timed[solver] = (elapsed, cpu, first)
        if solver == "exact":
            paths = [ours.solve(**case).path for case in instances]
    cvx = [solve_cvx(case, "OSQP", tight=False) for case in instances]
    cvx_tight = [solve_cvx(case, "OSQP", tight=True) for case in instances]
    with_rows = sum(1 for c in instances if c.get("half_planes") is not None)
    counts = ", ".join(f"{p} {paths.count(p)}" for p in ("closed_form", "blocks", "active_set"))
    print(
        f"MPC solve vs CVXPY, the {len(instances)} QPs MAV 0 solved (K = 16 flight at 100 Hz, in sequence; "
        f"{with_rows} with separation half-planes, up to {max_rows} rows; exact solver's path: {counts}):"
    )
    groups = (("all", list(range(len(instances)))),) + tuple(
        (p, [i for i, q in enumerate(paths) if q == p]) for p in ("closed_form", "active_set")
    )
    for name, idx in groups:
        if not idx:
            continue
        cvx_median = float(np.median([cvx[i][0] for i in idx]))
        cvx_cpu = float(np.median([cvx[i][2] for i in idx]))
        print(
            f"  {name} ({len(idx)}): CVXPY + OSQP (defaults)   median {1e3 * cvx_median:8.4f} ms  "
            f"(CPU {1e3 * cvx_cpu:.4f} ms)"
        )
        labels = (
            ("exact", "ours, exact (DAQP)"),
            ("compiled", "ours, exact (compiled)"),
            ("osqp", "ours, OSQP (built once)"),
        )
        for solver, label in labels:
            elapsed, cpu, first = timed[solver]
            wall = float(np.median([elapsed[i] for i in idx]))
            cpu_ours = float(np.median([cpu[i] for i in idx]))
            diff = max(float(np.abs(first[i] - cvx_tight[i][1][0]).max()) for i in idx)
            # per QP, the same QP both ways: a ratio of the two medians compares different QPs when the
            # sample mixes the closed form's QPs (CVXPY + OSQP: about 4 ms) and the active set's (about 17 ms)
            ratio = float(np.median([cvx[i][0] / elapsed[i] for i in idx]))
            cpu_ratio = float(np.median([cvx[i][2] / cpu[i] for i in idx]))
            verdict = "met" if ratio >= TARGET_MPC_RATIO and diff <= 1e-6 else "NOT met"
            print(
                f"    {label:<25} median {1e3 * wall:8.4f} ms  (CPU {1e3 * cpu_ours:.4f} ms)   "
                f"CVXPY / ours per QP = {ratio:6.1f}x wall, {cpu_ratio:6.1f}x CPU (medians)   "
                f"max |u(0) - u(0) of CVXPY + OSQP at 1e-10| = {diff:.1e} m/s^2"
                + (f"   target >= {TARGET_MPC_RATIO:g}x and 1e-6: {verdict}" if solver != "osqp" else "")
            )
    loose = max(float(np.abs(f - r[1][0]).max()) for f, r in zip(timed["exact"][2], cvx, strict=True))
    print(f"  (against CVXPY + OSQP at its default tolerances: max |du(0)| = {loose:.1e} m/s^2)")


def _print_row(team_size: int, times: np.ndarray, label: str) -> tuple[float, float]:
    """Print one row of the tick table for times (T, 5) as `_fly`'s; return its wall median and p99 (ms)."""
    median, p99 = 1e3 * np.median(times[:, 2]), 1e3 * np.percentile(times[:, 2], 99)
    cpu_median, cpu_p99 = 1e3 * np.median(times[:, 4]), 1e3 * np.percentile(times[:, 4], 99)
    parts = 1e3 * np.median(times[:, :2], axis=0)
    print(
        f"  {team_size:4d}   {median:14.3f}   {p99:11.3f}   {cpu_median:13.3f}   {cpu_p99:10.3f}   "
        f"({parts[0]:.3f}, {parts[1]:.3f}; {np.mean(times[:, 3]):.2f}){label}"
    )
    return median, p99


def run(*, repeats: int) -> None:
    """Time `repeats` ticks of MAV 0 for each team size, then compare the K = 16 QPs with CVXPY.

    Wall time is what the targets are about; the thread's CPU time is printed beside it because on a shared
    machine the wall time also counts the time other processes had the core."""
    ticks = max(int(repeats), 20)
    print(
        f"controller tick (detections fused + estimate + teammates + external inputs + MPC + way-point), one "
        f"MAV, {RATE_HZ:g} Hz, paper path and 13 trees, {ticks} ticks after {WARMUP_S:g} s:"
    )
    print(
        "     K   wall median ms   wall p99 ms   CPU median ms   CPU p99 ms   (tracker, controller step "
        "wall medians ms; detections per tick)"
    )
    verdicts: dict[str, str] = {}
    rows = [(k, "compiled", "filterpy") for k in TEAM_SIZES] + [
        (16, "daqp", "filterpy"),
        (16, "compiled", "compiled"),
    ]
    labels = {  # (active set, Kalman filter) -> what the row changes
        ("daqp", "filterpy"): "  DAQP's active-set step",
        ("compiled", "compiled"): "  the compiled Kalman filter (filterpy's is of record)",
    }
    for team_size, active_set, kalman_filter in rows:
        # the K = 16 flights on the default active set are also replayed alone, from their log
        log: list[_TickInputs] | None = [] if (team_size, active_set) == (16, "compiled") else None
        times, _ = _fly(
            team_size, ticks, record=True, active_set=active_set, kalman_filter=kalman_filter, log=log
        )
        median, p99 = _print_row(team_size, times, labels.get((active_set, kalman_filter), ""))
        if log is not None:
            verdicts[kalman_filter] = (
                "met" if median <= TARGET_MEDIAN_MS and p99 <= TARGET_P99_MS else "NOT met"
            )
            alone, same = _replay_alone(log, active_set=active_set, kalman_filter=kalman_filter)
            _print_row(
                team_size,
                alone,
                "  MAV 0's ticks replayed alone, as onboard"
                + (", compiled Kalman filter" if kalman_filter == "compiled" else "")
                + ("" if same else " (NOT the flight's way-points: the replay is not the same work)"),
            )
    print(
        f"  target: wall median <= {TARGET_MEDIAN_MS} ms and p99 <= {TARGET_P99_MS} ms at K = 16: "
        f"{verdicts['filterpy']} (with the compiled Kalman filter: {verdicts['compiled']})"
    )
    _, instances = _fly(16, ticks, record=False, capture=True)  # the same flight again, its QPs recorded
    _compare_with_cvxpy(instances[: max(20, min(len(instances), ticks))])

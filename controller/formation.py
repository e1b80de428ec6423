"""One MAV's formation controller: person estimate, teammates' plans and obstacles in; horizon plan and
way-point out.

Per step (paper Sec. III, docs/architecture.md#one-control-tick): check every input; start from the previous
plan's state at `now` on a leash to the measured state (reference.py); compute the external inputs f(0..N)
on the previous plan (fields.py); aim at the terminal reference moved by what the inputs add (pass-through);
solve the MPC (mpc.py); publish the plan; send its state `waypoint_step` ahead with the yaw facing the person.

Methods (docs/method.md#baselines): `active` (every input), `dqmpc` (teammate and obstacle repulsion only,
with its thresholds 1 m / 4 m), `price` (MPC to the d_des circle point with zero terminal velocity, weights
1000 / 0.1, no inputs in the MPC, a field added after it, teammates' current positions only; baselines.py).

Bad input never raises and never yields a NaN way-point: a non-finite (or absurdly large) own state, person
estimate, time or operator parameter gives a braking plan (SolveStatus.BRAKING, the reason in `fault`); such
a teammate plan or obstacle is dropped and counted; no person estimate gives a braking plan to rest
(NO_PERSON).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from controller.baselines import price_field
from controller.fields import (
    SANE_ABS,
    FieldTerms,
    ObstacleSet,
    TeammatePaths,
    covariance_radius_m,
    teammate_paths,
)
from controller.fields_kernel import input_terms, param_vector
from controller.kernel_args import kernel_array
from controller.messages import (
    ControlOutput,
    HorizonPlan,
    Obstacle,
    PersonEstimate,
    SolveStatus,
    VehicleState,
    read_only,
)
from controller.mpc import (
    HalfPlanes,
    ModelPredictiveController,
    MpcParams,
    MpcSolution,
    braking_plan,
    predict,
)
from controller.params import ControllerParams, FormationParams, Method
from controller.reference import (
    bearing_rad,
    clip_into,
    initial_state,
    plan_acceleration_at,
    plan_state_at,
    terminal_reference,
)
from controller.reference_kernel import aim, start_and_horizon, waypoint
from controller.separation import (
    SeparationRows,
    held_rows,
    imminent_miss_m,
    rows_of,
    separation_rows,
    tick_separation_rows,
    trunk_margin_m,
)
from controller.separation_kernel import row_inflation
from controller.teammates import TeammateView, align_rows
from controller.tick_kernel import inputs_and_rows, tick_constants

DEFAULT_COV_M2 = np.eye(3) * 0.25
# A compiled formation-flight tick goes from its start state to its solve in one call (tick_kernel.py). A
# test that records the separate wrappers' calls in a simulation turns this off; the results are the same.
ONE_CALL = True


@dataclass(frozen=True)
class ControllerStats:
    """Counters since construction (or `reset`): what the controller did and what it refused.

    ticks = solved + braking + no_person. rejected_plans / rejected_obstacles: teammate plans and obstacles
    dropped for non-finite numbers (or a plan carrying our own id); rejected_inputs: ticks whose own state,
    person estimate, time or formation parameters were not usable; field_faults: non-finite external-input
    totals replaced by zero; ignored_bearings: non-finite preferred bearings ignored; escapes: of the solved
    ticks, those whose separation rows could not all hold, flown as an escape (docs/safety.md); holds: of the
    solved ticks, those asked to hold (a teammate unheard too long: vehicles/agent.py).
    """

    ticks: int = 0
    solved: int = 0
    braking: int = 0
    no_person: int = 0
    rejected_plans: int = 0
    rejected_obstacles: int = 0
    rejected_inputs: int = 0
    field_faults: int = 0
    ignored_bearings: int = 0
    escapes: int = 0
    holds: int = 0


@dataclass(frozen=True, eq=False)
class _Tick:
    """What one step knows before planning: its time, own state, person, role and the MPC's start state;
    horizon (2, N+1, 3): our previous plan's positions and velocities on this tick's horizon when they were
    computed with the start state (`reference_kernel`), else None (`_own_horizon` computes them)."""

    now_s: float
    own: VehicleState
    person: PersonEstimate | None
    in_formation: bool
    start_p: np.ndarray
    start_v: np.ndarray
    horizon: np.ndarray | None = None


def _aim_bearing(person_p: np.ndarray, start_p: np.ndarray, preferred_rad: float | None) -> float:
    """The ENU bearing (rad) about the person at which the terminal reference lies: the start position's,
    or the preferred one when given (`FormationController.step`)."""
    return bearing_rad(from_m=person_p, to_m=start_p) if preferred_rad is None else float(preferred_rad)


def _finite(*arrays) -> bool:
    """Every number of every array finite (on plain floats: these are (3,) vectors and (3, 3) covariances)."""
    for a in arrays:
        for v in np.asarray(a).ravel().tolist():
            if not math.isfinite(v):
                return False
    return True


def _sane(*arrays) -> bool:
    """Finite and within SANE_ABS (a NaN fails the comparison). On plain floats: these are (3,) vectors."""
    for a in arrays:
        for v in np.asarray(a).ravel().tolist():
            if not abs(v) < SANE_ABS:
                return False
    return True


class FormationController:
    """The formation controller of MAV `vehicle_id`, one per MAV. It keeps the MPC's warm start, its own
    previous plan (the reference it is being flown along) and counters; nothing else."""

    def __init__(self, *, vehicle_id: int, params: ControllerParams, compiled: bool = True) -> None:
        """compiled: the start state, our previous plan on the horizon, the terminal reference and the
        way-point by reference_kernel.py, the separation rows in one call (`separation.tick_separation_rows`):
        the default; or the numpy form and the composition of kernels they replace, their reference (the
        same bits)."""
        self._id = int(vehicle_id)
        self._compiled = bool(compiled)
        self._params = params
        self._method = Method(params.method)
        self._terms = FieldTerms.for_method(self._method)
        mpc_params = params.mpc
        if self._method == Method.PRICE:
            mpc_params = replace(
                mpc_params,
                input_weight=params.price.input_weight,
                terminal_position_weight=params.price.terminal_weight,
                terminal_velocity_weight=params.price.terminal_weight,
            )
        self._mpc_params: MpcParams = mpc_params
        self._mpc = ModelPredictiveController(mpc_params)
        self._steps = mpc_params.horizon_steps + 1
        self._arena_lo_m = np.asarray(mpc_params.position_min_m, dtype=float)  # (3,) the arena's box
        self._arena_hi_m = np.asarray(mpc_params.position_max_m, dtype=float)
        # (N+1, 3) the external inputs of a plan without the fields (holds, escapes, PRICE's MPC, brakes)
        self._no_inputs = np.zeros((self._steps, 3))
        self._no_inputs.setflags(write=False)
        self._unused_inputs = np.zeros((self._steps, 3))  # `aim`'s inputs without the pass-through
        self._obstacle_key: tuple[int, ...] | None = None
        self._obstacle_refs: tuple[Obstacle, ...] = ()
        self._obstacle_set = ObstacleSet.from_obstacles(())
        self._obstacle_dropped = 0
        self._cov_key: bytes | None = None
        self._cov_radius = 0.0
        dt = mpc_params.dt_s
        self._step_times = dt * np.arange(self._steps)  # (N+1,) n dt
        # input_displacement's weights dt^2 (N - n + 1/2), computed once
        self._displacement_weights = dt * dt * (self._steps - 1 - np.arange(self._steps) + 0.5)
        # The previous plan as align_rows' table of two rows (positions, velocities), filled in place when
        # the plan changes (every solved tick): (2, L, 3), lengths (2,), stamps (2,) s, steps (2,) s.
        self._prev_source: np.ndarray | None = None  # the plan's positions_m these were copied from
        self._prev_both = np.empty((2, self._steps + 1, 3))
        self._prev_lengths = np.zeros(2, dtype=np.int64)
        self._prev_stamps = np.zeros(2)
        self._prev_dts = np.zeros(2)
        self._two_rows = np.arange(2)
        # formation flight's tick from the start state to the solve in one call (tick_kernel.py): compiled,
        # with the separation rows, not the price baseline (whose MPC takes no inputs)
        self._one_call = ONE_CALL and compiled and params.separation.enabled and self._method != Method.PRICE
        self._tick_constants = tick_constants(params, mpc_params)
        terms = self._terms
        flags = (terms.tracking, terms.teammates, terms.obstacles, terms.person, terms.approach)
        self._term_flags = np.array([*flags, terms.dqmpc_thresholds], dtype=np.bool_)
        self.reset()

    @property
    def vehicle_id(self) -> int:
        return self._id

    @property
    def params(self) -> ControllerParams:
        return self._params

    @property
    def stats(self) -> ControllerStats:
        return ControllerStats(**self._counts)

    def reset(self) -> None:
        """Forget the previous plan, the warm start and the counters (e.g. after landing)."""
        self._mpc.reset()
        self._prev_plan: HorizonPlan | None = None
        self._last_position: np.ndarray | None = None
        self._formed = False  # flown a tick of formation flight (not a hold) since the last reset
        self._counts = dict.fromkeys(ControllerStats.__dataclass_fields__, 0)

    # ------------------------------------------------------------------------------------------------ step
    def step(
        self,
        *,
        now_s: float,
        own: VehicleState,
        person: PersonEstimate | None,
        teammates: Sequence[HorizonPlan] | TeammateView,
        obstacles: Sequence[Obstacle],
        formation: FormationParams,
        in_formation: bool = True,
        preferred_bearing_rad: float | None = None,
        hold: bool = False,
    ) -> ControlOutput:
        """Plan one control tick at now_s (s, the caller's clock); return the plan and the way-point.

        teammates: the latest plan of each teammate (any age; in_formation ones count for K and the
        spacing), or a view of a `TeammateTable` (plans checked on arrival, kept in arrays: teammates.py);
        obstacles: trees and virtual obstacles; formation: the operator's d_des / h_des; in_formation: False
        for a MAV that left formation control (its plan says so; it neither spaces itself nor steers its
        approach angle); preferred_bearing_rad: when given, the terminal reference lies at this ENU bearing
        about the person (the roster slot 2 pi k / K of a MAV without fresh teammate information) instead of
        at the current bearing; hold: rest where it is (climbing to h_des above the person only before
        formation flight has begun: `_hold_target`), on a plan without the external inputs (whose pushes a
        silent teammate could not foresee), keeping the trunk rows and, once formation flight has begun,
        the teammate rows eased to what braking on the spot keeps (`_hold_rows`), and no escape (the hold
        is one).
        """
        self._counts["ticks"] += 1
        start_p, start_v, horizon = self._start_state(now_s, own)
        tick = _Tick(now_s, own, person, in_formation, start_p, start_v, horizon)
        reason = self._invalid_reason(now_s, own, person, formation)
        if reason is not None:
            self._counts["rejected_inputs"] += 1
            return self._brake(tick, SolveStatus.BRAKING, reason)
        if person is None:
            return self._brake(tick, SolveStatus.NO_PERSON, "no person estimate")
        if preferred_bearing_rad is not None and not np.isfinite(preferred_bearing_rad):
            self._counts["ignored_bearings"] += 1
            preferred_bearing_rad = None

        mp = self._mpc_params
        price = self._method == Method.PRICE
        obstacle_set = self._obstacles(obstacles)
        # the climb after take-off (a hold before formation flight) keeps no teammate rows: see no teammates
        climbing = hold and not self._formed
        rows: SeparationRows | None
        if (
            self._one_call
            and not hold
            and tick.horizon is not None
            and isinstance(teammates, TeammateView)
            and not teammates.extra
        ):
            mates, f_total, target, target_v, rows = self._in_one_call(
                tick, person, teammates, obstacle_set, formation, preferred_bearing_rad
            )
        else:
            mates = self._teammates(() if climbing else teammates, now_s, own)
            own_path, own_vel = self._own_horizon(tick)
            if price or hold:
                f_total = self._no_inputs
            else:
                f_total = self._inputs(tick, person, mates, obstacle_set, formation, own_path, own_vel)
            if hold:
                target, target_v = self._hold_target(tick, person, formation)
            else:
                target, target_v = self._target(
                    tick, person, f_total, formation, preferred_bearing_rad, price
                )
            rows = self._separation(tick, own_path, own_vel, mates, obstacle_set)
            if hold and rows is not None:
                rows = self._hold_rows(tick, rows)
        planes = rows.planes if rows is not None and rows.count else None

        def solve(aim_p: np.ndarray, aim_v: np.ndarray, inputs: np.ndarray) -> MpcSolution:
            return self._mpc.solve(
                position_m=start_p,
                velocity_mps=start_v,
                target_position_m=aim_p,
                target_velocity_mps=aim_v,
                external_inputs_mps2=inputs,
                half_planes=planes,
            )

        sol = solve(target, target_v, f_total)
        escape = None
        miss = self._imminent_miss(sol, planes)
        if not hold and rows is not None and miss > self._params.separation.escape_violation_m:
            escape = f"escape: separation rows of the next steps missed by {miss:.2f} m"
            # An escape flies without the fields, as a hold does: a trunk's push can exceed the input box
            # (6.2 m/s^2 against 3 in run 360 of the safety sweep), and the plan would accelerate with it,
            # beyond any braking the rows ask for, into the next trunk (docs/safety.md).
            f_total = self._no_inputs
            sol = solve(*self._escape_target(tick, mates, rows), f_total)
        if not sol.ok:
            return self._brake(
                tick,
                SolveStatus.BRAKING,
                f"MPC: {sol.message or sol.status}",
                iterations=sol.iterations,
                solve_time_s=sol.solve_time_s,
            )

        positions, velocities = sol.positions_m, sol.velocities_mps
        if price:
            felt = self._teammates((), now_s, own) if hold and not climbing else mates  # a hold feels none
            field = price_field(
                own_position_m=start_p,
                goal_position_m=target,
                teammate_positions_m=felt.positions_m[:, 0, :],
                teammate_d_max_m=felt.d_max_m,
                obstacles=obstacle_set,
                fields=self._params.fields,
                params=self._params.price,
            )
            f_total = np.repeat(field[None, :], self._steps, axis=0)
            positions, velocities = predict(
                position_m=start_p,
                velocity_mps=start_v,
                inputs_mps2=sol.inputs_mps2,
                external_inputs_mps2=f_total,
                params=mp,
            )
        plan = self._plan(tick, positions, velocities)
        wp_p, wp_v, wp_a, finite = self._waypoint(plan)
        if not finite:
            return self._brake(tick, SolveStatus.BRAKING, "the way-point was not finite")
        self._prev_plan = plan
        self._formed = self._formed or not hold
        self._counts["solved"] += 1
        if escape is not None:
            self._counts["escapes"] += 1
        if hold:
            self._counts["holds"] += 1
        status = SolveStatus.HOLD if hold else SolveStatus.SOLVED if escape is None else SolveStatus.ESCAPE
        yaw = bearing_rad(from_m=wp_p, to_m=np.asarray(person.position_m, dtype=float))
        return ControlOutput(
            plan=plan,
            waypoint_position_m=wp_p,
            waypoint_velocity_mps=wp_v,
            waypoint_acceleration_mps2=wp_a,
            yaw_rad=yaw,
            status=status,
            external_inputs=f_total,
            fault=escape,
            solver_iterations=sol.iterations,
            solver_time_s=sol.solve_time_s,
        )

    # ------------------------------------------------------------------------------------------ internals
    def _invalid_reason(
        self, now_s: float, own: VehicleState, person: PersonEstimate | None, formation: FormationParams
    ) -> str | None:
        """Why this tick cannot be planned, or None."""
        if not math.isfinite(now_s):
            return "the time is not finite"
        if not _sane(own.position_m, own.velocity_mps):
            return "own state is not finite (or beyond 1000 km)"
        d_des, h_des = formation.d_des_m, formation.h_des_m
        if not (math.isfinite(d_des) and d_des > 0.0 and math.isfinite(h_des)):
            return f"invalid formation parameters d_des={d_des} h_des={h_des}"
        if person is not None and not _sane(person.position_m, person.velocity_mps):
            return "person estimate is not finite (or beyond 1000 km)"
        return None

    def _reference_state(self, now_s: float) -> tuple[np.ndarray, np.ndarray] | tuple[None, None]:
        """The previous plan's state at now_s, if there is a previous plan that covers now_s."""
        plan = self._prev_plan
        if plan is None or not math.isfinite(now_s):
            return None, None
        elapsed = now_s - plan.stamp_s
        if elapsed < 0.0 or elapsed > (len(plan.positions_m) - 1) * plan.dt_s:
            return None, None
        return plan_state_at(plan.positions_m, plan.velocities_mps, elapsed_s=elapsed, dt_s=plan.dt_s)

    def _start_state(
        self, now_s: float, own: VehicleState
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        """The MPC's initial state: the reference on a leash to the measurement (or a stand-in for it), and
        with a sane measurement at a finite time, our previous plan on the horizon (`_Tick.horizon`) in the
        same compiled call (reference_kernel.py); the numpy form below is its reference and the fallback."""
        pos = np.asarray(own.position_m, dtype=float)
        vel = np.asarray(own.velocity_mps, dtype=float)
        if self._compiled and math.isfinite(now_s) and _sane(pos, vel):
            self._last_position = pos.copy()
            has_plan = self._prev_plan is not None
            if has_plan:
                self._refresh_previous_plan()
            start, horizon = np.empty((2, 3)), np.empty((2, self._steps, 3))
            start_and_horizon(
                float(now_s),
                has_plan,
                self._prev_both,
                self._prev_lengths,
                self._prev_stamps,
                self._prev_dts,
                self._two_rows,
                pos,
                vel,
                self._params.reference.leash_position_m,
                self._params.reference.leash_velocity_mps,
                self._mpc_params.dt_s,
                start,
                horizon,
            )
            return start[0], start[1], horizon
        return (*self._numpy_start_state(now_s, pos, vel), None)

    def _numpy_start_state(
        self, now_s: float, pos: np.ndarray, vel: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """`_start_state`'s start state in numpy: the reference of the compiled call, and the only form for a
        measurement that is not sane."""
        ref_p, ref_v = self._reference_state(now_s)
        if _sane(pos, vel):
            self._last_position = pos.copy()
            return initial_state(
                measured_position_m=pos,
                measured_velocity_mps=vel,
                reference_position_m=ref_p,
                reference_velocity_mps=ref_v,
                params=self._params.reference,
            )
        if ref_p is not None and ref_v is not None:
            return ref_p, ref_v
        if self._last_position is not None:
            return self._last_position.copy(), np.zeros(3)
        return clip_into(np.zeros(3), lower_m=self._arena_lo_m, upper_m=self._arena_hi_m), np.zeros(3)

    def _teammates(
        self, teammates: Sequence[HorizonPlan] | TeammateView, now_s: float, own: VehicleState
    ) -> TeammatePaths:
        """Teammates' plans on our horizon. Plans carrying our id, a non-finite stamp or step, or non-finite
        numbers are dropped and counted (a table refused those on arrival)."""
        if isinstance(teammates, TeammateView):
            mates = teammates.paths(
                now_s=now_s,
                dt_s=self._mpc_params.dt_s,
                steps=self._steps,
                own_cov_radius_m=self._own_cov_radius(own),
                params=self._params.fields,
                current_position_only=self._method == Method.PRICE,
            )
            self._counts["rejected_plans"] += mates.rejected
            return mates
        usable = [
            p
            for p in teammates
            if p.vehicle_id != self._id
            and math.isfinite(p.stamp_s)
            and p.dt_s > 0.0
            and math.isfinite(p.dt_s)
        ]
        mates = teammate_paths(
            usable,
            now_s=now_s,
            dt_s=self._mpc_params.dt_s,
            steps=self._steps,
            own_cov_radius_m=self._own_cov_radius(own),
            params=self._params.fields,
            current_position_only=self._method == Method.PRICE,
        )
        self._counts["rejected_plans"] += len(teammates) - len(usable) + mates.rejected
        return mates

    def _in_one_call(
        self,
        tick: _Tick,
        person: PersonEstimate,
        view: TeammateView,
        obstacle_set: ObstacleSet,
        formation: FormationParams,
        preferred_bearing_rad: float | None,
    ) -> tuple[TeammatePaths, np.ndarray, np.ndarray, np.ndarray, SeparationRows]:
        """`_teammates`, `_inputs`, `_target` and `_separation` of a formation-flight tick (compiled, our
        previous plan on the horizon, no phantom teammates) in one compiled call (tick_kernel.py): the same
        teammates' paths, external inputs (N+1, 3), terminal position and velocity (3,) and separation rows,
        to the bit."""
        assert tick.horizon is not None
        own, prm = tick.own, self._params
        capped = self._row_cov_radius(own)  # our covariance radius, capped as the fields and the rows take it
        person_p = kernel_array(person.position_m, float)
        person_v = kernel_array(person.velocity_mps, float)
        bearing = _aim_bearing(person_p, tick.start_p, preferred_bearing_rad)
        table = view.table
        centers, radii, heights = obstacle_set.kernel_arrays()
        (mates, ids, flying, offsets, d_max, ages), inputs, fault, target, planes, counts = inputs_and_rows(
            table.kernel_columns(),
            table.fresh_rows(view.since_s),
            float(tick.now_s),
            self._tick_constants,
            prm.fields.teammate_d_max_head_m(capped),
            trunk_margin_m(prm.separation, capped),
            tick.start_p,
            tick.horizon,
            kernel_array(own.position_m, float),
            kernel_array(own.gps_offset_m, float),
            person_p,
            person_v,
            self._step_times,
            prm.reference.predict_person,
            prm.reference.pass_through,
            bearing,
            float(formation.d_des_m),
            float(formation.h_des_m),
            param_vector(prm.fields),
            self._term_flags,
            self._id,
            tick.in_formation,
            centers,
            radii,
            heights,
            self._displacement_weights,
            self._arena_lo_m,
            self._arena_hi_m,
        )
        if fault:
            self._counts["field_faults"] += 1
        t, o, f, closest_index, closest = counts
        rows = rows_of(*planes, (t, o, f), closest_index, closest)
        mates_paths = TeammatePaths(mates, ids, flying, d_max, 0, ages, offsets)
        return mates_paths, inputs[0], target[0], target[1], rows

    def _obstacles(self, obstacles: Sequence[Obstacle]) -> ObstacleSet:
        """Obstacles as arrays, rebuilt only when the (immutable) obstacle objects change."""
        key = tuple(id(o) for o in obstacles)
        if key != self._obstacle_key:
            self._obstacle_key = key
            self._obstacle_refs = tuple(obstacles)  # keeps the ids in the key valid
            self._obstacle_set = ObstacleSet.from_obstacles(obstacles)
            self._obstacle_dropped = len(obstacles) - self._obstacle_set.count
        self._counts["rejected_obstacles"] += self._obstacle_dropped
        return self._obstacle_set

    def _own_cov_radius(self, own: VehicleState) -> float:
        """Eq. 15's r_sigma of our own covariance (cached: it rarely changes)."""
        key = own.position_cov_m2.tobytes()
        if key != self._cov_key:
            cov = np.asarray(own.position_cov_m2, dtype=float)
            self._cov_key, self._cov_radius = key, (float(covariance_radius_m(cov)) if _finite(cov) else 0.0)
        return self._cov_radius

    def _row_cov_radius(self, own: VehicleState) -> float:
        """Our covariance radius as the separation rows take it: capped at covariance_radius_cap_m."""
        return min(self._own_cov_radius(own), self._params.fields.covariance_radius_cap_m)

    def _inputs(
        self,
        tick: _Tick,
        person: PersonEstimate,
        mates: TeammatePaths,
        obstacle_set: ObstacleSet,
        formation: FormationParams,
        own_path: np.ndarray,
        own_vel: np.ndarray,
    ) -> np.ndarray:
        """(N+1, 3) clamped external inputs on our previous plan (`_own_horizon`)."""
        prm = self._params
        person_xy = np.asarray(person.position_m, dtype=float)[:2]
        if prm.reference.predict_person:  # the person's constant-velocity prediction at each step
            person_xy = (
                person_xy + np.asarray(person.velocity_mps, dtype=float)[:2] * self._step_times[:, None]
            )
        else:
            person_xy = np.repeat(person_xy[None, :], self._steps, axis=0)
        terms, fault = input_terms(
            own_positions_m=own_path,
            own_velocities_mps=own_vel,
            person_xy_m=person_xy,
            teammates=mates,
            obstacles=obstacle_set,
            team_size=1 + int(np.count_nonzero(mates.in_formation)),
            d_des_m=formation.d_des_m,
            params=prm.fields,
            terms=self._terms,
            own_id=self._id,
            in_formation=tick.in_formation,
        )
        if fault:
            self._counts["field_faults"] += 1
        return terms[0]

    def _own_horizon(self, tick: _Tick) -> tuple[np.ndarray, np.ndarray]:
        """(N+1, 3) positions and velocities of our previous plan on this tick's horizon, moved to begin at
        the start state (a hover there before the first plan). The velocities begin at the measured velocity:
        the braking margins need the vehicle's, and the follower lags the plan."""
        if tick.horizon is not None:  # computed with the start state
            return tick.horizon[0], tick.horizon[1]
        if self._prev_plan is not None:
            own_path, own_vel = self._previous_plan_on_horizon(tick.now_s)
            own_path = own_path + (tick.start_p - own_path[0])
        else:
            own_path = np.repeat(tick.start_p[None, :], self._steps, axis=0)
            own_vel = np.repeat(tick.start_v[None, :], self._steps, axis=0)
        measured_v = np.asarray(tick.own.velocity_mps, dtype=float)
        own_vel = own_vel + ((measured_v if _finite(measured_v) else tick.start_v) - own_vel[0])
        return own_path, own_vel

    def _separation(
        self,
        tick: _Tick,
        own_path: np.ndarray,
        own_vel: np.ndarray,
        mates: TeammatePaths,
        obstacle_set: ObstacleSet,
    ) -> SeparationRows | None:
        """This tick's separation rows (controller/separation.py), or None when they are switched off."""
        prm = self._params
        if not prm.separation.enabled:
            return None
        own = tick.own
        measured = np.asarray(own.position_m, dtype=float)
        lag = measured - tick.start_p if _sane(measured) else np.zeros(3)
        if not self._compiled:  # the composition tick_separation_rows replaces, its reference
            inflation = np.empty(mates.count)
            f = prm.fields
            row_inflation(
                mates.d_max_m,
                mates.ages,
                f.teammate_d_max_base_m,
                f.teammate_speed_mps,
                f.teammate_age_grace_s,
                0.5 * prm.separation.plan_deviation_mps2,
                inflation,
            )
            return separation_rows(
                own_path_m=own_path,
                own_velocities_mps=own_vel,
                mates=mates.placed_by(own.gps_offset_m),
                mate_ages_s=mates.ages,
                inflation_m=inflation,
                obstacles=obstacle_set,
                own_cov_radius_m=self._row_cov_radius(own),
                dt_s=self._mpc_params.dt_s,
                own_id=self._id,
                params=prm.separation,
                lag_m=lag,
                floor_m=self._mpc_params.position_min_m[2],
            )
        return tick_separation_rows(
            own_path_m=own_path,
            own_velocities_mps=own_vel,
            mates=mates,
            own_gps_offset_m=own.gps_offset_m,
            obstacles=obstacle_set,
            own_cov_radius_m=self._row_cov_radius(own),
            dt_s=self._mpc_params.dt_s,
            own_id=self._id,
            params=prm.separation,
            fields=prm.fields,
            lag_m=lag,
            floor_m=self._mpc_params.position_min_m[2],
        )

    def _hold_rows(self, tick: _Tick, rows: SeparationRows) -> SeparationRows:
        """A hold's rows: the teammate rows eased to what braking on the spot at step_brake_mps2 keeps
        (`held_rows`: a hold entered fast must not slide onto a resting teammate, and a neighbour's gap must
        not push a resting MAV about). Before formation flight has begun (the climb after take-off, side by
        side in a cluster) `step` gives a hold no teammates, so only the trunk rows are left. The trunk rows
        keep hold_obstacle_sigmas instead of obstacle_sigmas, as far as that braking allows: a hold has no
        trunk field to keep it off the bark."""
        sep = self._params.separation
        return held_rows(
            rows,
            start_m=tick.start_p,
            velocity_mps=tick.start_v,
            decel_mps2=sep.step_brake_mps2,
            trunk_widening_m=max(0.0, sep.hold_obstacle_sigmas - sep.obstacle_sigmas)
            * self._row_cov_radius(tick.own),
        )

    def _imminent_miss(self, sol: MpcSolution, planes: HalfPlanes | None) -> float:
        """How far a solved plan misses the separation rows of its first steps (0: none missed)."""
        if not sol.ok or planes is None or sol.half_plane_violation_m == 0.0:
            return 0.0
        return imminent_miss_m(planes, sol.positions_m, steps=self._params.separation.escape_steps)

    def _escape_target(
        self, tick: _Tick, mates: TeammatePaths, rows: SeparationRows
    ) -> tuple[np.ndarray, np.ndarray]:
        """Where an escape aims: rest at the start position, moved vertically away from the closest
        teammate when it is within separation_m horizontally (up when level or above it), inside the arena."""
        height = float(tick.start_p[2])
        j = rows.closest_teammate_index
        if j >= 0:
            mate = mates.positions_m[j, 0]
            gap = tick.start_p - mate
            if math.hypot(gap[0], gap[1]) < self._params.separation.separation_m:
                climb = self._params.separation.escape_climb_m
                height = mate[2] + (climb if gap[2] >= 0.0 else -climb)
        return self._rest_at(tick, height)

    def _hold_target(
        self, tick: _Tick, person: PersonEstimate, formation: FormationParams
    ) -> tuple[np.ndarray, np.ndarray]:
        """Where a hold aims: rest at the start position, inside the arena; at h_des above the person while
        formation flight has not begun (after take-off), at the start height once it has: a hold's teammate
        rows only stop it closing in, they do not make room, so it must not climb or sink into the height a
        teammate took to get out of the way (an escape separates vertically)."""
        height = float(tick.start_p[2]) if self._formed else float(person.position_m[2]) + formation.h_des_m
        return self._rest_at(tick, height)

    def _rest_at(self, tick: _Tick, height_m: float) -> tuple[np.ndarray, np.ndarray]:
        """A resting aim (zero velocity) above the start position at height_m, clipped into the arena."""
        target = tick.start_p.copy()
        target[2] = height_m
        return clip_into(target, lower_m=self._arena_lo_m, upper_m=self._arena_hi_m), np.zeros(3)

    def _previous_plan_on_horizon(self, now_s: float) -> tuple[np.ndarray, np.ndarray]:
        """The previous plan's positions and velocities (N+1, 3) at now_s + n dt (fields.plan_path and
        plan_velocities, in one compiled call)."""
        self._refresh_previous_plan()
        out = np.empty((2, self._steps, 3))
        align_rows(
            self._prev_both,
            self._prev_lengths,
            self._prev_stamps,
            self._prev_dts,
            self._two_rows,
            float(now_s),
            self._mpc_params.dt_s,
            False,
            out,
        )
        return out[0], out[1]

    def _refresh_previous_plan(self) -> None:
        """Copy the previous plan into align_rows' table, when it changed since the last copy."""
        plan = self._prev_plan
        assert plan is not None
        if self._prev_source is not plan.positions_m:
            length = len(plan.positions_m)
            if length > self._prev_both.shape[1]:
                self._prev_both = np.empty((2, length, 3))
            self._prev_both[0, :length] = plan.positions_m
            self._prev_both[1, :length] = plan.velocities_mps
            self._prev_lengths[:] = length
            self._prev_stamps[:] = plan.stamp_s
            self._prev_dts[:] = plan.dt_s
            self._prev_source = plan.positions_m

    def _target(
        self,
        tick: _Tick,
        person: PersonEstimate,
        f_total: np.ndarray,
        formation: FormationParams,
        preferred_bearing_rad: float | None,
        price: bool,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Terminal position and velocity reference, moved by the inputs' displacement, inside the arena.

        `price` aims at the d_des point with zero terminal velocity and no prediction (Price et al.).
        """
        mp = self._mpc_params
        ref = self._params.reference
        person_p = kernel_array(person.position_m, float)
        person_v = np.zeros(3) if price else kernel_array(person.velocity_mps, float)
        if self._compiled:
            bearing = _aim_bearing(person_p, tick.start_p, preferred_bearing_rad)
            out = np.empty((2, 3))
            passing = ref.pass_through and not price
            aim(
                tick.start_p,
                person_p,
                person_v,
                bearing,
                formation.d_des_m,
                formation.h_des_m,
                self._steps * mp.dt_s,
                ref.predict_person,
                passing,
                self._displacement_weights,
                f_total if passing else self._unused_inputs,  # not read; `_no_inputs` is read-only
                mp.dt_s,
                self._arena_lo_m,
                self._arena_hi_m,
                out,
            )
            return out[0], out[1]
        target, target_v = terminal_reference(
            position_m=tick.start_p,
            person_position_m=person_p,
            person_velocity_mps=person_v,
            d_des_m=formation.d_des_m,
            h_des_m=formation.h_des_m,
            horizon_s=self._steps * mp.dt_s,
            params=ref,
            preferred_bearing_rad=preferred_bearing_rad,
        )
        if ref.pass_through and not price:
            # reference.input_displacement with its weights computed once
            shift_p, shift_v = self._displacement_weights @ f_total, mp.dt_s * f_total.sum(axis=0)
            target, target_v = target + shift_p, target_v + shift_v
        return clip_into(target, lower_m=self._arena_lo_m, upper_m=self._arena_hi_m), target_v

    def _plan(self, tick: _Tick, positions: np.ndarray, velocities: np.ndarray) -> HorizonPlan:
        cov = np.asarray(tick.own.position_cov_m2, dtype=float)
        stamp = float(tick.now_s) if math.isfinite(tick.now_s) else 0.0
        return HorizonPlan(
            vehicle_id=self._id,
            stamp_s=stamp,
            dt_s=self._mpc_params.dt_s,
            positions_m=positions,
            velocities_mps=velocities,
            in_formation=tick.in_formation,
            position_cov_m2=cov if _finite(cov) else DEFAULT_COV_M2,
            gps_offset_m=tick.own.gps_offset_m,
        )

    def _waypoint(self, plan: HorizonPlan) -> tuple[np.ndarray, np.ndarray, np.ndarray, bool]:
        """The set-point: the plan's position, velocity and acceleration waypoint_step steps ahead, (3,)
        each and read-only (a message takes them without a copy), and whether all are finite."""
        ahead_s = self._params.reference.waypoint_step * plan.dt_s
        if self._compiled:
            p, v, a = np.empty(3), np.empty(3), np.empty(3)
            finite = waypoint(plan.positions_m, plan.velocities_mps, ahead_s, plan.dt_s, p, v, a)
            return read_only(p), read_only(v), read_only(a), finite
        p, v = plan_state_at(plan.positions_m, plan.velocities_mps, elapsed_s=ahead_s, dt_s=plan.dt_s)
        a = plan_acceleration_at(plan.velocities_mps, elapsed_s=ahead_s, dt_s=plan.dt_s)
        return p, v, a, _finite(p, v, a)

    def _brake(
        self, tick: _Tick, status: SolveStatus, fault: str, iterations: int = 0, solve_time_s: float = 0.0
    ) -> ControlOutput:
        """A braking plan from the start state: the fallback of every tick that cannot be solved."""
        positions, velocities = braking_plan(
            position_m=tick.start_p, velocity_mps=tick.start_v, params=self._mpc_params
        )
        plan = self._plan(tick, positions, velocities)
        wp_p, wp_v, wp_a, _ = self._waypoint(plan)
        person = tick.person
        if person is not None and _finite(person.position_m):
            yaw = bearing_rad(from_m=wp_p, to_m=np.asarray(person.position_m, dtype=float))
        else:
            yaw = float(tick.own.yaw_rad) if np.isfinite(tick.own.yaw_rad) else 0.0
        self._prev_plan = plan
        self._counts["no_person" if status == SolveStatus.NO_PERSON else "braking"] += 1
        return ControlOutput(
            plan=plan,
            waypoint_position_m=wp_p,
            waypoint_velocity_mps=wp_v,
            waypoint_acceleration_mps2=wp_a,
            yaw_rad=yaw,
            status=status,
            external_inputs=self._no_inputs,
            fault=fault,
            solver_iterations=iterations,
            solver_time_s=solve_time_s,
        )

"""Specification of the separation constraints (controller/separation.py): the rows' geometry, and the
formation controller keeping MAVs apart with them where the paper's fields alone do not."""

from __future__ import annotations

import numpy as np
import pytest
from test_closed_loop import STILL_PERSON, min_separation_m, simulate

from controller.fields import ObstacleSet, TeammatePaths
from controller.messages import Obstacle
from controller.mpc import HalfPlanes, ModelPredictiveController, MpcParams
from controller.params import ControllerParams
from controller.separation import (
    SeparationParams,
    SeparationRows,
    braking_room_m,
    floor_rows,
    held_rows,
    obstacle_rows,
    row_margins,
    separation_rows,
)

PARAMS = SeparationParams()
DT = 0.1
STEPS = 16


def line(start, velocity, steps: int = STEPS) -> np.ndarray:
    """(steps, 3) positions of a straight constant-velocity plan."""
    return np.asarray(start, float) + DT * np.arange(steps)[:, None] * np.asarray(velocity, float)


def mates(paths, *, in_formation=True, ages_s=0.0, ids=None) -> TeammatePaths:
    paths = np.asarray(paths, float)
    count = paths.shape[0]
    return TeammatePaths(
        positions_m=paths,
        vehicle_ids=np.arange(1, count + 1) if ids is None else np.asarray(ids),
        in_formation=np.full(count, in_formation),
        d_max_m=np.full(count, 3.0),
        ages_s=np.full(count, ages_s),
    )


def rows_for(own_path, own_vel, team: TeammatePaths, *, inflation=0.0, obstacles=None, own_id=0, prm=PARAMS):
    return separation_rows(
        own_path_m=own_path,
        own_velocities_mps=own_vel,
        mates=team,
        mate_ages_s=team.ages,
        inflation_m=np.full(team.count, inflation),
        obstacles=obstacles or ObstacleSet.from_obstacles(()),
        own_cov_radius_m=0.0,
        dt_s=DT,
        own_id=own_id,
        params=prm,
    )


# ------------------------------------------------------------------------------------------- the rows
def test_two_cooperating_mavs_build_mirrored_cells_that_keep_them_the_separation_apart():
    """A's row and B's row from the same two hovering plans: any two points that meet them are at least
    separation_m + inflation apart along the pair's line."""
    a_path, b_path = line([0.0, 0.0, 8.0], [0, 0, 0]), line([3.0, 0.0, 8.0], [0, 0, 0])
    still = np.zeros((STEPS, 3))
    rows_a = rows_for(a_path, still, mates([b_path], ids=[1]), inflation=1.0, own_id=0)
    rows_b = rows_for(b_path, still, mates([a_path], ids=[0]), inflation=1.0, own_id=1)
    # A must keep x <= 1.5 - 1.3 = 0.2, B x >= 1.5 + 1.3 = 2.8: 2.6 m = separation 1.6 + inflation 1.0
    a_limit = rows_a.planes.offsets / rows_a.planes.normals_xy[:, 0]  # n x >= b: x <= b / n for n < 0
    b_limit = rows_b.planes.offsets / rows_b.planes.normals_xy[:, 0]
    np.testing.assert_allclose(a_limit, 0.2, atol=1e-12)
    np.testing.assert_allclose(b_limit, 2.8, atol=1e-12)
    assert rows_a.teammate_rows == STEPS - 1 and rows_a.planes.steps.min() == 1


def test_a_teammate_out_of_formation_gets_the_whole_distance_not_half():
    a_path, b_path = line([0.0, 0.0, 8.0], [0, 0, 0]), line([3.0, 0.0, 8.0], [0, 0, 0])
    rows = rows_for(a_path, np.zeros((STEPS, 3)), mates([b_path], in_formation=False), inflation=1.0)
    np.testing.assert_allclose(rows.planes.offsets / rows.planes.normals_xy[:, 0], 3.0 - 2.6, atol=1e-12)


def test_a_stale_teammate_is_not_trusted_to_yield():
    a_path, b_path = line([0.0, 0.0, 8.0], [0, 0, 0]), line([3.0, 0.0, 8.0], [0, 0, 0])
    fresh = rows_for(a_path, np.zeros((STEPS, 3)), mates([b_path], ages_s=0.2))
    stale = rows_for(a_path, np.zeros((STEPS, 3)), mates([b_path], ages_s=1.0))
    np.testing.assert_allclose(fresh.planes.offsets / fresh.planes.normals_xy[:, 0], 1.5 - 0.8, atol=1e-12)
    np.testing.assert_allclose(stale.planes.offsets / stale.planes.normals_xy[:, 0], 3.0 - 1.6, atol=1e-12)


def test_closing_in_adds_the_braking_distance_of_our_half_of_the_closing_speed():
    """Head-on at 4 m/s each (8 m/s closing): our half, 4 m/s, needs 4^2 / (2 * 3) = 2.67 m before the last
    step and min(4^2 / (2 * 2), 4) = 4 m at it."""
    a_path, b_path = line([0.0, 0.0, 8.0], [4, 0, 0]), line([20.0, 0.0, 8.0], [-4, 0, 0])
    a_vel = np.tile([4.0, 0.0, 0.0], (STEPS, 1))
    prm = SeparationParams(row_reach_m=30.0)
    moving = rows_for(a_path, a_vel, mates([b_path]), prm=prm)
    assert moving.count == STEPS - 1
    np.testing.assert_allclose(moving.planes.normals_xy, [[-1.0, 0.0]] * (STEPS - 1), atol=1e-12)
    mid = 0.5 * (a_path[1:, 0] + b_path[1:, 0])
    room = mid - 0.8 + moving.planes.offsets  # -x >= b means x <= -b = mid - 0.8 - room
    np.testing.assert_allclose(room[:-1], 16.0 / 6.0, atol=1e-9)
    assert room[-1] == pytest.approx(4.0, abs=1e-9)


def test_braking_room_ignores_teammates_moving_apart_and_is_capped():
    np.testing.assert_allclose(
        braking_room_m(np.array([-3.0, 0.0, 3.0, 10.0]), decel_mps2=3.0, cap_m=4.0), [0.0, 0.0, 1.5, 4.0]
    )


def test_teammates_out_of_reach_give_no_rows():
    far = rows_for(line([0, 0, 8], [0, 0, 0]), np.zeros((STEPS, 3)), mates([line([30, 0, 8], [0, 0, 0])]))
    assert far.teammate_rows == 0 and far.closest_teammate_m == pytest.approx(30.0)


def test_coincident_plans_split_along_x_by_vehicle_id():
    here = line([1.0, 1.0, 8.0], [0, 0, 0])
    low = rows_for(here, np.zeros((STEPS, 3)), mates([here], ids=[5]), own_id=2)
    high = rows_for(here, np.zeros((STEPS, 3)), mates([here], ids=[2]), own_id=5)
    assert np.all(low.planes.normals_xy[:, 0] == -1.0) and np.all(high.planes.normals_xy[:, 0] == 1.0)


TRUNK_AT_5_M = ObstacleSet.from_obstacles(
    (Obstacle(obstacle_id="t", center_m=np.array([5.0, 0.0]), radius_m=0.5, height_m=12.0),)
)


def trunk_limit_x_m(*, own_cov_radius_m=0.0, lag_m=None, compiled=True, velocity_mps=(0.0, 0.0, 0.0)):
    """(R,) how far east each trunk row lets a MAV at (0, 0, 8) go (x <= b / n), the trunk 5 m east; its
    previous plan rests there, planned at velocity_mps (the closing speed the rows see)."""
    planes = separation_rows(
        own_path_m=line([0.0, 0.0, 8.0], [0.0, 0.0, 0.0]),
        own_velocities_mps=np.tile(np.asarray(velocity_mps, float), (STEPS, 1)),
        mates=mates(np.zeros((0, STEPS, 3))),
        mate_ages_s=np.zeros(0),
        inflation_m=np.zeros(0),
        obstacles=TRUNK_AT_5_M,
        own_cov_radius_m=own_cov_radius_m,
        dt_s=DT,
        own_id=0,
        params=PARAMS,
        lag_m=lag_m,
        compiled=compiled,
    ).planes
    return planes.offsets / planes.normals_xy[:, 0]


def test_a_trunk_row_is_tangent_to_the_grown_disc_and_keeps_the_whole_disc_behind_it():
    path = line([0.0, 1.0, 8.0], [1.0, 0.0, 0.0])
    unweighted = SeparationParams(obstacle_row_weight=1.0, row_reach_m=30.0, obstacle_sigmas=1.0)
    steps, normals, offsets = obstacle_rows(
        own_path_m=path,
        own_velocities_mps=np.zeros((STEPS, 3)),
        obstacles=TRUNK_AT_5_M,
        own_cov_radius_m=0.2,
        params=unweighted,
    )
    assert steps.tolist() == list(range(1, STEPS))
    angles = np.linspace(0.0, 2.0 * np.pi, 73)
    disc = np.array([5.0, 0.0]) + 0.9 * np.column_stack([np.cos(angles), np.sin(angles)])  # r + 0.2 + 0.2
    for n, b in zip(normals, offsets, strict=True):
        assert np.max(disc @ n[:2] - b) <= 1e-9  # the grown disc lies behind the plane
        assert np.max(disc @ n[:2] - b) == pytest.approx(0.0, abs=0.005)  # and touches it: tangent


@pytest.mark.parametrize("compiled", [True, False])
def test_a_trunk_row_keeps_one_and_a_half_own_covariance_radii_beyond_the_clearance(compiled):
    """The trunk is mapped in the true world, our GPS error along the row is unknown: with a 0.5 m covariance
    radius the plane stands 0.5 (trunk) + 0.2 (clearance) + 1.5 * 0.5 = 1.45 m from the centre."""
    np.testing.assert_allclose(
        trunk_limit_x_m(own_cov_radius_m=0.5, compiled=compiled), 5.0 - 1.45, atol=1e-12
    )


def test_a_trunk_row_weighs_more_than_a_teammate_row():
    """Scaled by obstacle_row_weight: of the rows' shared slack a trunk row gets a fifth of a teammate's."""
    path = line([0.0, 0.0, 8.0], [0.0, 0.0, 0.0])
    _, normals, offsets = obstacle_rows(
        own_path_m=path,
        own_velocities_mps=np.zeros((STEPS, 3)),
        obstacles=TRUNK_AT_5_M,
        own_cov_radius_m=0.0,
        params=PARAMS,
    )
    np.testing.assert_allclose(normals[:, 0], -5.0)
    np.testing.assert_allclose(offsets, -5.0 * (5.0 - 0.7))  # the plane 0.5 + 0.2 m from the centre


def test_a_vehicle_lagging_its_plan_towards_a_trunk_tightens_the_trunk_row_by_that_lag():
    """The follower runs up to the leash behind its plan: a trunk row holds for where the vehicle is, so a
    lag of 0.4 m towards the trunk moves the plane 0.4 m out; a lag away from it leaves the plane alone."""
    limit = {lag: trunk_limit_x_m(lag_m=np.array([lag, 0.0, 0.0])) for lag in (0.0, 0.4, -0.4)}
    np.testing.assert_allclose(limit[0.0], 4.3, atol=1e-12)
    np.testing.assert_allclose(limit[0.4], 3.9, atol=1e-12)
    np.testing.assert_allclose(limit[-0.4], 4.3, atol=1e-12)


@pytest.mark.parametrize("compiled", [True, False])
def test_a_trunk_row_keeps_the_braking_room_of_the_closing_speed(compiled):
    """Planned at 3 m/s east, towards the trunk: each row also keeps v^2 / (2 b), 9 / 6 = 1.5 m at
    step_brake_mps2 before the last step and 9 / 4 = 2.25 m at brake_mps2 at it, so the plan can still stop
    short of the grown disc from every step (run 912 grazed it at speed and cut in)."""
    limit = trunk_limit_x_m(velocity_mps=(3.0, 0.0, 0.0), compiled=compiled)
    np.testing.assert_allclose(limit[:-1], 4.3 - 1.5, atol=1e-12)
    np.testing.assert_allclose(limit[-1], 4.3 - 2.25, atol=1e-12)


@pytest.mark.parametrize("velocity_mps", [(-3.0, 0.0, 0.0), (0.0, 3.0, 0.0)])
def test_a_trunk_row_keeps_no_braking_room_when_not_closing(velocity_mps):
    """Moving away from the trunk or past it (no closing speed along the row's normal): the plain plane."""
    np.testing.assert_allclose(trunk_limit_x_m(velocity_mps=velocity_mps), 4.3, atol=1e-12)


def test_no_trunk_row_above_the_trunk_top():
    trunk = ObstacleSet.from_obstacles(
        (Obstacle(obstacle_id="t", center_m=np.array([5.0, 0.0]), radius_m=0.5, height_m=6.0),)
    )
    steps, _, _ = obstacle_rows(
        own_path_m=line([0.0, 1.0, 8.0], [1, 0, 0]),
        own_velocities_mps=np.tile([1.0, 0.0, 0.0], (STEPS, 1)),
        obstacles=trunk,
        own_cov_radius_m=0.0,
        params=PARAMS,
    )
    assert steps.size == 0


# ---------------------------------------------------------------------------------------- a hold's rows
TRUNK_3_M_NORTH = ObstacleSet.from_obstacles(
    (Obstacle(obstacle_id="n", center_m=np.array([0.0, 3.0]), radius_m=0.5, height_m=12.0),)
)


def holding_near_a_trunk(mate_x_m: float):
    """Rows of a MAV resting at (0, 0, 8) with a teammate out of formation mate_x_m east (whole gap: 1.6 m)
    and a trunk 3 m north."""
    return rows_for(
        line([0.0, 0.0, 8.0], [0, 0, 0]),
        np.zeros((STEPS, 3)),
        mates([line([mate_x_m, 0.0, 8.0], [0, 0, 0])], in_formation=False),
        obstacles=TRUNK_3_M_NORTH,
    )


def teammate_x_limits(rows: SeparationRows) -> np.ndarray:
    """How far east each teammate row lets the MAV go (rows facing west: x <= b / n)."""
    t = rows.teammate_rows
    return rows.planes.offsets[:t] / rows.planes.normals_xy[:t, 0]


def test_a_hold_eases_a_teammate_row_to_where_braking_at_the_bound_stops():
    """At 3 m/s east, braking at 3 m/s^2 stops 1.5 m on: a teammate 2 m east (its row at x <= 0.4) now
    gets x <= 1.5."""
    rows = holding_near_a_trunk(2.0)
    held = held_rows(
        rows, start_m=np.array([0.0, 0.0, 8.0]), velocity_mps=np.array([3.0, 0, 0]), decel_mps2=3.0
    )
    np.testing.assert_allclose(teammate_x_limits(rows), 0.4, atol=1e-12)
    np.testing.assert_allclose(teammate_x_limits(held), 1.5, atol=1e-12)


def test_a_hold_never_lets_a_teammate_row_push_it_away_from_where_it_rests():
    rows = holding_near_a_trunk(1.0)  # the row wants x <= -0.6: 0.6 m west of where the MAV rests
    held = held_rows(rows, start_m=np.array([0.0, 0.0, 8.0]), velocity_mps=np.zeros(3), decel_mps2=3.0)
    np.testing.assert_allclose(teammate_x_limits(held), 0.0, atol=1e-12)


def test_a_hold_keeps_a_teammate_row_that_braking_keeps_and_every_trunk_row_as_it_is():
    rows = holding_near_a_trunk(4.0)  # the row at x <= 2.4 holds while braking from 1 m/s east
    held = held_rows(
        rows, start_m=np.array([0.0, 0.0, 8.0]), velocity_mps=np.array([1.0, 0, 0]), decel_mps2=3.0
    )
    assert rows.teammate_rows > 0 and rows.obstacle_rows > 0
    np.testing.assert_array_equal(held.planes.offsets, rows.planes.offsets)


def trunk_y_limits(rows: SeparationRows) -> np.ndarray:
    """How far north each trunk row lets the MAV go (rows facing south: y <= b / n)."""
    trunk = slice(rows.teammate_rows, rows.teammate_rows + rows.obstacle_rows)
    return rows.planes.offsets[trunk] / rows.planes.normals_xy[trunk, 1]


def trunk_rows_of_a_hold(*, north_mps: float, widening_m: float) -> np.ndarray:
    """The trunk rows' north limits of a hold at (0, 0, 8) moving north_mps towards the trunk 3 m north
    (radius 0.5: the rows at y <= 3 - 0.5 - 0.2 = 2.3), widened by widening_m."""
    held = held_rows(
        holding_near_a_trunk(4.0),
        start_m=np.array([0.0, 0.0, 8.0]),
        velocity_mps=np.array([0.0, north_mps, 0.0]),
        decel_mps2=3.0,
        trunk_widening_m=widening_m,
    )
    return trunk_y_limits(held)


def test_a_hold_widens_every_trunk_row_by_the_widening():
    np.testing.assert_allclose(trunk_rows_of_a_hold(north_mps=0.0, widening_m=0.0), 2.3, atol=1e-12)
    np.testing.assert_allclose(trunk_rows_of_a_hold(north_mps=0.0, widening_m=0.75), 1.55, atol=1e-12)


def test_a_hold_widens_a_trunk_row_no_further_than_braking_at_the_bound_stops():
    """At 3 m/s north, braking at 3 m/s^2 stops 1.5 m on: a widening to y <= 1.3 gives y <= 1.5."""
    np.testing.assert_allclose(trunk_rows_of_a_hold(north_mps=3.0, widening_m=1.0), 1.5, atol=1e-12)


def test_a_hold_at_rest_is_never_pushed_away_from_a_trunk_by_the_widening():
    """A widening to y <= -0.7 gives y <= 0, where the MAV rests."""
    np.testing.assert_allclose(trunk_rows_of_a_hold(north_mps=0.0, widening_m=3.0), 0.0, atol=1e-12)


def test_parameters_out_of_range_are_refused():
    with pytest.raises(ValueError, match="separation_m"):
        SeparationParams(separation_m=-1.0)
    with pytest.raises(ValueError, match="decelerations"):
        SeparationParams(step_brake_mps2=0.0)


# ---------------------------------------------------------------------------------- closed loop (slow)
def still_person(_t: float):
    return STILL_PERSON, np.zeros(3)


def on_circle(bearings_deg) -> np.ndarray:
    b = np.radians(np.asarray(bearings_deg, float))
    return np.column_stack(
        [STILL_PERSON[0] + 8.0 * np.cos(b), STILL_PERSON[1] + 8.0 * np.sin(b), np.full(b.shape, 8.9)]
    )


def swap_run(params: ControllerParams):
    """Two MAVs 90 degrees apart on the circle (11.3 m) told to take each other's bearing: they meet
    head-on. (40 degrees apart, the fields alone kept 1.86 m once the vehicles fly the plan's acceleration
    forward, as the agents send it: too easy to show what the rows are for.)"""
    return simulate(
        team_size=2,
        duration_s=20.0,
        person=still_person,
        start_m=on_circle([45.0, 135.0]),
        bearings_rad=np.radians([135.0, 45.0]),
        params=params,
    )


@pytest.mark.slow
def test_two_mavs_swapping_slots_head_on_keep_1_5_m():
    """Measured 2.54 m (0.59 m without the rows, next test)."""
    run = swap_run(ControllerParams())
    assert min_separation_m(run, horizontal=False) >= 1.5


@pytest.mark.slow
def test_without_separation_rows_the_head_on_swap_comes_closer():
    """The same swap with the fields alone: what the rows are for (this pins the scenario's difficulty)."""
    run = swap_run(ControllerParams(separation=SeparationParams(enabled=False)))
    assert min_separation_m(run, horizontal=False) < 1.5


# ------------------------------------------------------------------------- the QP with these rows (slow)
def crossing_case(rng: np.random.Generator) -> tuple[dict, HalfPlanes]:
    """A tick of a MAV flying at 1-3 teammates that fly at it or across its path, with the rows built from
    both straight-line plans, and a target beyond them: the free plan runs into the cells."""
    own = rng.uniform([-5.0, -5.0, 7.0], [5.0, 5.0, 9.0])
    heading = rng.uniform(0.0, 2.0 * np.pi)
    speed = rng.uniform(1.0, 4.0)
    velocity = speed * np.array([np.cos(heading), np.sin(heading), 0.0])
    paths = []
    for _ in range(int(rng.integers(1, 4))):
        ahead = own + velocity * rng.uniform(0.8, 1.6) + rng.normal(0.0, 1.0, 3) * np.array([1.0, 1.0, 0.2])
        mate_v = -velocity * rng.uniform(0.0, 1.0) + rng.normal(0.0, 1.0, 3) * np.array([1.0, 1.0, 0.0])
        paths.append(line(ahead, mate_v))
    team = mates(paths, in_formation=True, ages_s=float(rng.uniform(0.0, 0.4)))
    own_path, own_vel = line(own, velocity), np.tile(velocity, (STEPS, 1))
    rows = rows_for(own_path, own_vel, team, inflation=float(rng.uniform(0.0, 1.5)))
    case = dict(
        position_m=own,
        velocity_mps=velocity,
        target_position_m=own + velocity * 2.5,
        target_velocity_mps=velocity,
        external_inputs_mps2=np.zeros((STEPS, 3)),
    )
    return case, rows.planes


@pytest.fixture(scope="module")
def separation_qps():
    """60 crossing ticks solved by the exact solver and by CVXPY + OSQP (tight, polished) with the same soft
    rows written out independently (test_qp.cvxpy_mpc_reference)."""
    from test_qp import cvxpy_mpc_reference

    rng = np.random.default_rng(20261129)
    controller = ModelPredictiveController(MpcParams())
    out = []
    for _ in range(60):
        case, planes = crossing_case(rng)
        ours = controller.solve(**case, half_planes=planes)
        weights = {
            "terminal_position_weight": 100.0 * np.eye(3),
            "terminal_velocity_weight": 100.0 * np.eye(3),
        }
        u, p, _ = cvxpy_mpc_reference(MpcParams(), {**case, **weights}, planes)
        out.append((ours, planes, u, p))
    return out


def _active(planes: HalfPlanes, positions: np.ndarray, tol: float = 1e-6) -> int:
    return int(np.count_nonzero(row_margins(planes, positions) <= tol))


@pytest.mark.slow  # 60 QPs through CVXPY: about 1.5 s
def test_at_least_50_separation_qps_have_active_rows(separation_qps):
    assert sum(_active(planes, ours.positions_m) > 0 for ours, planes, _, _ in separation_qps) >= 50


@pytest.mark.slow
def test_separation_qps_match_cvxpy_to_1e_4(separation_qps):
    assert all(ours.ok for ours, _, _, _ in separation_qps)
    worst_u = max(float(np.max(np.abs(ours.inputs_mps2 - u))) for ours, _, u, _ in separation_qps)
    worst_p = max(float(np.max(np.abs(ours.positions_m - p))) for ours, _, _, p in separation_qps)
    assert worst_u < 1e-4 and worst_p < 1e-4


@pytest.mark.slow
def test_a_teammate_whose_plans_arrive_1_s_late_is_still_kept_1_5_m_away():
    """The head-on swap with MAV 1's plans reaching MAV 0 one second late (MAV 0 sees where MAV 1 meant to
    be a second ago): MAV 0 inflates its row by the age and stops trusting MAV 1 to yield. Measured 2.76 m
    (0.69 m without the rows)."""
    run = simulate(
        team_size=2,
        duration_s=20.0,
        person=still_person,
        start_m=on_circle([45.0, 135.0]),
        bearings_rad=np.radians([135.0, 45.0]),
        plan_delay_s=[0.0, 1.0],
    )
    assert min_separation_m(run, horizontal=False) >= 1.5


TRUNK_ON_THE_CIRCLE = Obstacle(
    obstacle_id="trunk",
    center_m=np.array([STILL_PERSON[0], STILL_PERSON[1] + 8.0]),
    radius_m=0.3,
    height_m=12.0,
)


@pytest.fixture(scope="module")
def sixteen_round_a_trunk():
    """16 MAVs from a clustered start spreading onto the d_des = 8 m circle (50 m round) with a trunk
    standing on it, 30 s. Measured: closest pair 2.00 m, trunk clearance 2.18 m (1.74 m and 2.18 m
    without the rows: the fields alone manage this one)."""
    return simulate(team_size=16, duration_s=30.0, person=still_person, obstacles=(TRUNK_ON_THE_CIRCLE,))


@pytest.mark.slow
def test_sixteen_mavs_on_the_circle_round_a_trunk_keep_1_5_m_from_each_other(sixteen_round_a_trunk):
    assert min_separation_m(sixteen_round_a_trunk, horizontal=False) >= 1.5


@pytest.mark.slow
def test_sixteen_mavs_on_the_circle_round_a_trunk_never_touch_it(sixteen_round_a_trunk):
    xy = sixteen_round_a_trunk.positions_m[..., :2] - TRUNK_ON_THE_CIRCLE.center_m
    clearance = np.sqrt(np.einsum("tki,tki->tk", xy, xy)) - TRUNK_ON_THE_CIRCLE.radius_m
    assert clearance.min() >= 0.5


def test_only_rows_within_reach_of_binding_are_built():
    """Closing head-on from 20 m at 8 m/s: the rows of the early steps, where the pair is still more than
    row_reach_m from needing them, are left out; the late ones are kept."""
    a_path, b_path = line([0.0, 0.0, 8.0], [4, 0, 0]), line([20.0, 0.0, 8.0], [-4, 0, 0])
    rows = rows_for(a_path, np.tile([4.0, 0.0, 0.0], (STEPS, 1)), mates([b_path]))
    kept = rows.planes.steps
    assert 0 < kept.size < STEPS - 1 and kept.max() == STEPS - 1
    assert np.all(np.diff(kept) == 1)  # a contiguous run of the last steps


# ---------------------------------------------------------------------------------------------- the floor
def test_floor_rows_keep_a_descending_plan_above_the_floor_where_it_is_within_reach():
    """A plan sinking from 8 m at 2 m/s: the steps within row_reach_m (4 m) of the 3 m floor get a row
    z >= 3 m, scaled by floor_row_weight; the higher steps none."""
    path = line([0.0, 0.0, 8.0], [0.0, 0.0, -2.0])  # z = 8.0, 7.8, ... 5.0
    steps, normals, offsets = floor_rows(own_path_m=path, floor_m=3.0, params=PARAMS)
    np.testing.assert_array_equal(steps, np.flatnonzero(path[:, 2] < 7.0))
    w = PARAMS.floor_row_weight
    np.testing.assert_allclose(normals, np.tile([0.0, 0.0, w], (len(steps), 1)))
    np.testing.assert_allclose(offsets, 3.0 * w)


def test_floor_rows_never_ask_a_plan_below_the_floor_to_rise():
    """After take-off a plan may start below the floor: its rows ask no more than where it already is."""
    path = line([0.0, 0.0, 1.0], [0.0, 0.0, 0.5])  # z = 1.0 .. 1.75
    steps, _, offsets = floor_rows(own_path_m=path, floor_m=3.0, params=PARAMS)
    np.testing.assert_array_equal(steps, np.arange(1, STEPS))
    np.testing.assert_allclose(offsets / PARAMS.floor_row_weight, path[1:, 2])


def test_separation_rows_append_the_floor_rows_after_the_trunk_rows():
    path = line([0.0, 0.0, 5.0], [0.0, 0.0, 0.0])
    rows = separation_rows(
        own_path_m=path,
        own_velocities_mps=np.zeros((STEPS, 3)),
        mates=mates(np.zeros((0, STEPS, 3))),
        mate_ages_s=np.zeros(0),
        inflation_m=np.zeros(0),
        obstacles=ObstacleSet.from_obstacles(()),
        own_cov_radius_m=0.0,
        dt_s=DT,
        own_id=0,
        params=PARAMS,
        floor_m=3.0,
    )
    assert (rows.teammate_rows, rows.obstacle_rows, rows.floor_rows, rows.count) == (0, 0, 15, 15)
    np.testing.assert_allclose(row_margins(rows.planes, path), 2.0 * PARAMS.floor_row_weight)

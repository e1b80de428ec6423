"""Operator command validation: limits derived from the controller's parameters, and every refusal."""

from __future__ import annotations

import math

import numpy as np
import pytest

from controller.mpc import MpcParams
from controller.params import ControllerParams, FormationParams
from server.station.commands import (
    CommandError,
    CommandLimits,
    check_clearance,
    check_formation,
    check_obstacle,
    clearance_problems,
    limits_from_params,
)

LIMITS = limits_from_params(ControllerParams())
PERSON = [np.array([0.0, 0.0, 0.9])]
MAVS = {1: np.array([8.0, 0.0, 8.9]), 2: np.array([-4.0, 6.93, 8.9]), 3: np.array([-4.0, -6.93, 8.9])}


def obstacle(**kwargs):
    args = {
        "x_m": 10.0,
        "y_m": 10.0,
        "radius_m": 1.0,
        "limits": LIMITS,
        "vehicles_m": MAVS,
        "persons_m": PERSON,
        "virtual_count": 0,
    }
    args.update(kwargs)
    return check_obstacle(**args)


def test_limits_come_from_the_mpc_arena_and_field_thresholds():
    assert LIMITS.arena_min_m == (-20.0, -20.0, 3.0)
    assert LIMITS.arena_max_m == (20.0, 20.0, 10.0)
    assert LIMITS.obstacle_clearance_m == pytest.approx(1.5)
    assert LIMITS.formation_spacing_m == pytest.approx(3.0)


def test_h_des_range_keeps_the_mavs_inside_the_height_band():
    assert LIMITS.h_des_range_m() == pytest.approx((2.1, 9.1))


def test_d_des_upper_limit_keeps_the_circle_d_min_inside_the_arena():
    assert LIMITS.d_des_range_m(3)[1] == pytest.approx(18.5)


@pytest.mark.parametrize(("team_size", "expected_low"), [(1, 1.8), (3, 1.8), (8, 4.0), (16, 7.7)])
def test_d_des_lower_limit_spaces_neighbours_beyond_teammate_repulsion(team_size, expected_low):
    low, _ = LIMITS.d_des_range_m(team_size)
    assert low == pytest.approx(expected_low)
    if team_size >= 2:
        assert 2.0 * low * math.sin(math.pi / team_size) >= 3.0 - 1e-9


def test_a_smaller_arena_narrows_the_limits():
    arena = MpcParams(position_min_m=(-10.0, -15.0, 2.0), position_max_m=(10.0, 15.0, 6.0))
    params = ControllerParams(mpc=arena)
    limits = limits_from_params(params)
    assert limits.d_des_range_m(3)[1] == pytest.approx(8.5)
    assert limits.h_des_range_m() == pytest.approx((1.1, 5.1))


def test_paper_formation_is_accepted():
    assert check_formation(d_des_m=8.0, h_des_m=8.0, limits=LIMITS, team_size=3) == FormationParams(8.0, 8.0)


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf, "eight", None])
def test_non_finite_or_non_numeric_d_des_is_refused(bad):
    with pytest.raises(CommandError, match="d_des_m must be a"):
        check_formation(d_des_m=bad, h_des_m=8.0, limits=LIMITS, team_size=3)


def test_non_finite_h_des_is_refused():
    with pytest.raises(CommandError, match="h_des_m must be a finite number"):
        check_formation(d_des_m=8.0, h_des_m=math.nan, limits=LIMITS, team_size=3)


def test_d_des_below_the_spacing_limit_is_refused_with_the_allowed_range():
    with pytest.raises(CommandError, match=r"between 4 and 18.5 m"):
        check_formation(d_des_m=3.0, h_des_m=8.0, limits=LIMITS, team_size=8)


def test_d_des_beyond_the_arena_is_refused():
    with pytest.raises(CommandError, match="outside what the arena and safety distances allow"):
        check_formation(d_des_m=19.0, h_des_m=8.0, limits=LIMITS, team_size=3)


def test_h_des_above_the_arena_ceiling_is_refused_with_the_allowed_range():
    with pytest.raises(CommandError, match=r"between 2.1 and 9.1 m"):
        check_formation(d_des_m=8.0, h_des_m=9.5, limits=LIMITS, team_size=3)


def test_a_clear_obstacle_is_accepted():
    assert obstacle() == (10.0, 10.0, 1.0)


@pytest.mark.parametrize("radius", [0.0, -1.0])
def test_non_positive_radius_is_refused(radius):
    with pytest.raises(CommandError, match="radius_m must be positive"):
        obstacle(radius_m=radius)


def test_non_finite_obstacle_position_is_refused():
    with pytest.raises(CommandError, match="x_m must be a finite number"):
        obstacle(x_m=math.inf)


def test_oversized_obstacle_is_refused():
    with pytest.raises(CommandError, match="larger than 5 m"):
        obstacle(radius_m=6.0)


@pytest.mark.parametrize(("x", "y"), [(20.5, 0.0), (0.0, -21.0)])
def test_obstacle_outside_the_arena_is_refused(x, y):
    with pytest.raises(CommandError, match="outside the arena"):
        obstacle(x_m=x, y_m=y)


def test_obstacle_covering_the_person_is_refused_with_the_distance_to_keep():
    with pytest.raises(CommandError, match=r"cover the person .* at least 3.0 m from the person \(now 2.0"):
        obstacle(x_m=2.0, y_m=0.0, radius_m=1.5)


def test_obstacle_covering_a_mav_is_refused_naming_it():
    with pytest.raises(CommandError, match=r"cover MAV 2 at \(-4.0, 6.9\) m"):
        obstacle(x_m=-4.0, y_m=5.0, radius_m=1.0)


def test_obstacle_just_beyond_the_clearance_is_accepted():
    assert obstacle(x_m=8.0 + 2.6, y_m=0.0, radius_m=1.0)[0] == pytest.approx(10.6)


def test_obstacle_beyond_the_count_limit_is_refused():
    limits = CommandLimits(max_virtual_obstacles=2)
    with pytest.raises(CommandError, match="already 2 virtual obstacles"):
        obstacle(limits=limits, virtual_count=2)


def clearance(vehicles_m, *, ids=None, persons=PERSON, d_des_m=8.0):
    return clearance_problems(
        vehicle_ids=list(vehicles_m) if ids is None else ids,
        vehicles_m=vehicles_m,
        persons_m=persons,
        limits=LIMITS,
        d_des_m=d_des_m,
    )


def test_keep_out_is_the_person_repulsion_threshold_seven_eighths_of_d_des():
    # 7 m at d_des 8: a MAV 6.9 m away is inside, one 7.1 m away is not
    problems = clearance({1: np.array([6.9, 0.0, 0.0]), 2: np.array([0.0, 7.1, 0.0])})
    assert list(problems) == [1]
    assert "6.9 m from the person, inside the 7.0 m keep-out" in problems[1]


def test_keep_out_grows_with_d_des():
    assert list(clearance({1: np.array([7.5, 0.0, 0.0])}, d_des_m=10.0)) == [1]  # keep-out 8.75 m


def test_keep_out_is_measured_horizontally():
    # right above the person at 8.9 m is still inside: a take-off climbs straight up
    assert list(clearance({1: np.array([3.0, 0.0, 8.9])})) == [1]


def test_teammates_closer_than_d_min_are_both_named():
    problems = clearance({1: np.array([8.0, 0.0, 0.0]), 2: np.array([8.0, 1.2, 0.0])})
    assert sorted(problems) == [1, 2]
    assert "1.2 m from MAV 2, closer than d_min = 1.5 m" in problems[1]


def test_only_the_vehicles_asked_about_are_checked_but_all_count_as_teammates():
    vehicles = {1: np.array([8.0, 0.0, 0.0]), 2: np.array([8.0, 1.0, 8.9])}
    assert list(clearance(vehicles, ids=[1])) == [1]


def test_no_person_known_means_no_keep_out_check():
    assert clearance({1: np.array([1.0, 0.0, 0.0])}, persons=[]) == {}


def test_a_refused_clearance_names_every_vehicle_and_the_override():
    with pytest.raises(CommandError, match="start refused: MAV 3 stands.*MAV 4 stands.*override"):
        check_clearance(
            {4: "stands 1.0 m from MAV 3", 3: "stands 2.0 m from the person"}, action="start", override=False
        )


def test_an_overridden_clearance_returns_what_was_overridden():
    assert check_clearance({3: "stands 2.0 m from the person"}, action="start", override=True) == [
        "MAV 3 stands 2.0 m from the person"
    ]
    assert check_clearance({}, action="start", override=False) == []

"""Separation geometry (server/separation.py): the nearest airborne teammate in 3-D and the horizontal
clearance to the nearest trunk or obstacle a MAV is below the top of; None where not applicable."""

from __future__ import annotations

import math

import numpy as np
import pytest

from controller.messages import Obstacle
from server.separation import Separation, obstacle_clearance_m, obstacle_clearances_m, separations

TREE = Obstacle(obstacle_id="t", center_m=np.array((0.0, -6.0)), radius_m=0.5, height_m=12.0)
SHORT = Obstacle(obstacle_id="s", center_m=np.array((3.0, 6.0)), radius_m=1.0, height_m=2.0, kind="virtual")


def test_the_nearest_teammate_is_the_closest_other_airborne_vehicle_in_3d():
    positions = {1: np.array((0.0, 0.0, 3.0)), 2: np.array((3.0, 4.0, 3.0)), 3: np.array((0.0, 0.0, 9.0))}
    sep = separations(positions_m=positions, airborne_ids={1, 2, 3}, obstacles=())
    assert sep[1].nearest_teammate_m == pytest.approx(5.0, abs=1e-9) and sep[1].nearest_teammate_id == 2
    assert sep[3].nearest_teammate_m == pytest.approx(6.0, abs=1e-9) and sep[3].nearest_teammate_id == 1


def test_a_vehicle_on_the_ground_has_no_separation_and_is_nobody_s_teammate():
    positions = {1: np.array((0.0, 0.0, 3.0)), 2: np.array((3.0, 4.0, 3.0)), 3: np.array((1.0, 0.0, 0.0))}
    sep = separations(positions_m=positions, airborne_ids={1, 2}, obstacles=(TREE,))
    assert sep[3] == Separation()
    assert sep[1].nearest_teammate_id == 2


def test_a_vehicle_alone_in_the_air_has_no_teammate_distance():
    sep = separations(positions_m={1: np.array((0.0, 0.0, 3.0))}, airborne_ids={1}, obstacles=())
    assert sep[1] == Separation()


def test_obstacle_clearance_is_horizontal_to_the_surface_below_its_top_only():
    points = np.array([[0.0, 0.0, 3.0], [3.0, 4.0, 3.0], [3.0, 5.5, 1.0]])
    clearances = obstacle_clearances_m(points, (TREE, SHORT))
    assert clearances[0] == pytest.approx(5.5, abs=1e-9)
    assert clearances[1] == pytest.approx(math.hypot(3.0, 10.0) - 0.5, abs=1e-9)  # above the short one
    assert clearances[2] == pytest.approx(-0.5, abs=1e-9)  # inside the short one, below its top
    assert obstacle_clearance_m(points, (TREE, SHORT)) == pytest.approx(-0.5, abs=1e-9)


def test_without_an_obstacle_beside_it_the_clearance_is_none():
    high = {1: np.array((0.0, -6.0, 13.0)), 2: np.array((5.0, 0.0, 3.0))}
    sep = separations(positions_m=high, airborne_ids={1, 2}, obstacles=(TREE,))
    assert sep[1].nearest_obstacle_m is None  # above the trunk's top
    assert separations(positions_m=high, airborne_ids={1, 2}, obstacles=())[2].nearest_obstacle_m is None
    assert obstacle_clearance_m(np.zeros((1, 3)), ()) == math.inf

"""The person models: paper path, seeded random walker, standing still."""

import numpy as np
import pytest

from vehicles.sim.person import (
    PAPER_PATH_RADIUS_M,
    PERSON_CENTRE_HEIGHT_M,
    PathPerson,
    RandomPerson,
    StillPerson,
    paper_path,
)
from vehicles.sim.trees import PAPER_TREES_XY, _distance_to_polyline


def test_still_person_stays_at_its_spot_with_centre_at_0_9_m():
    person = StillPerson((1.0, -2.0))
    for t in (0.0, 5.0, 300.0):
        truth = person.truth(t)
        np.testing.assert_allclose(truth.position_m, [1.0, -2.0, PERSON_CENTRE_HEIGHT_M])
        np.testing.assert_allclose(truth.velocity_mps, 0.0)


def test_feet_on_the_ground_and_head_at_1_75_m():
    truth = StillPerson().truth(0.0)
    assert truth.feet_m[2] == pytest.approx(0.0)
    assert truth.head_m[2] == pytest.approx(1.75)


def test_paper_person_stands_still_for_10_s_then_walks_at_0_7_mps():
    person = PathPerson(path_xy_m=paper_path())
    np.testing.assert_allclose(person.truth(9.99).position_m[:2], [0.0, 0.0])
    for t in (12.0, 40.0, 75.0):
        assert np.linalg.norm(person.truth(t).velocity_mps) == pytest.approx(0.7, abs=1e-9)
    # 0.1 s of walking covers 0.07 m along the path (chord of a dense polyline)
    step = np.linalg.norm(person.truth(30.1).position_m - person.truth(30.0).position_m)
    assert step == pytest.approx(0.07, abs=2e-3)


def test_paper_path_is_a_closed_loop_inside_the_scaled_arena():
    path = paper_path()
    np.testing.assert_allclose(path[0], [0.0, 0.0], atol=1e-9)
    np.testing.assert_allclose(path[-1], [0.0, 0.0], atol=1e-9)
    assert np.max(np.hypot(path[:, 0], path[:, 1])) <= PAPER_PATH_RADIUS_M + 1e-9
    # it reaches the arc's far end (0, -R) and the sine's end (R, 0)
    assert np.min(np.hypot(path[:, 0], path[:, 1] + PAPER_PATH_RADIUS_M)) < 1e-6
    assert np.min(np.hypot(path[:, 0] - PAPER_PATH_RADIUS_M, path[:, 1])) < 1e-6


def test_paper_path_passes_every_paper_tree_at_least_a_metre_away():
    path = paper_path()
    assert min(_distance_to_polyline(np.array(xy), path) for xy in PAPER_TREES_XY) >= 1.0


def test_paper_person_loops_back_to_the_start():
    person = PathPerson(path_xy_m=paper_path())
    loop_s = person.loop_length_m / 0.7
    np.testing.assert_allclose(person.truth(10.0 + loop_s).position_m[:2], [0.0, 0.0], atol=1e-6)


def _random_track(seed, duration_s=400.0, dt=0.5):
    person = RandomPerson(np.random.default_rng(seed))
    times = np.arange(0.0, duration_s, dt)
    pos = np.array([person.truth(t).position_m for t in times])
    vel = np.array([person.truth(t).velocity_mps for t in times])
    return pos, vel


def test_random_person_is_reproducible_from_its_seed_and_differs_between_seeds():
    a, _ = _random_track(3)
    b, _ = _random_track(3)
    c, _ = _random_track(4)
    np.testing.assert_array_equal(a, b)
    assert np.max(np.abs(a - c)) > 1.0


def test_random_person_answers_the_same_whatever_order_times_are_asked():
    forward = RandomPerson(np.random.default_rng(9))
    late_first = RandomPerson(np.random.default_rng(9))
    p_late = late_first.truth(80.0).position_m
    p_early = late_first.truth(30.0).position_m
    np.testing.assert_array_equal(forward.truth(30.0).position_m, p_early)
    np.testing.assert_array_equal(forward.truth(80.0).position_m, p_late)


def test_random_person_walks_runs_stops_and_stays_in_the_arena():
    pos, vel = _random_track(11, duration_s=600.0, dt=0.25)
    speed = np.hypot(vel[:, 0], vel[:, 1])
    assert np.max(np.hypot(pos[:, 0], pos[:, 1])) <= 11.0 + 1e-9
    assert np.max(speed) <= 3.0 + 1e-9
    assert np.max(speed) > 2.0  # it ran
    moving = speed[40:] > 0.05  # after the 10 s still start
    assert 0.05 < 1.0 - moving.mean() < 0.6  # it stopped sometimes, but mostly moved

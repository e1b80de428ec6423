"""Issue 3's acceptance runs: the paper's world for 120 s, K = 3, 5, 8, seeds 1-4, and total link loss.

The control rate is 10 Hz here, the MPC's own step (dt = 0.1 s): the controller re-plans every step as at
100 Hz, only the way-point follower sees set-points less often. At the paper's 100 Hz the same runs take ten
times longer (see `skyring bench sim` for that rate's speed). Each run is made once in the suite and shared by
the tests that read its numbers.
"""

from collections.abc import Callable
from functools import cache

import pytest

from server.lab.simulation import SimConfig, run_simulation

RATE_HZ = 10.0
DURATION_S = 120.0
SEEDS = (1, 2, 3, 4)  # the formation's bounds hold for every seed, not for one lucky draw
TEAMS = [(k, seed) for k in (3, 5, 8) for seed in SEEDS]


@cache
def _paper_run(vehicles: int, comm_loss: float = 0.0, seed: int = 1) -> dict:
    config = SimConfig(
        vehicles=vehicles,
        duration_s=DURATION_S,
        seed=seed,
        person="paper",
        trees="paper",
        comm_loss=comm_loss,
        rate_hz=RATE_HZ,
    )
    return run_simulation(config).to_json()["metrics"]


@pytest.fixture(scope="module")
def paper_run() -> Callable[..., dict]:
    """_paper_run, shared: tests that take a module fixture are kept on one xdist worker (tests/conftest.py),
    so each run is flown once in the suite rather than once per worker."""
    return _paper_run


@pytest.mark.slow
@pytest.mark.parametrize(("k", "seed"), TEAMS)
def test_spacing_error_is_at_most_10_degrees(paper_run, k, seed):
    assert paper_run(k, seed=seed)["spacing_error_deg"] <= 10.0


@pytest.mark.slow
@pytest.mark.parametrize(("k", "seed"), TEAMS)
def test_distance_error_is_at_most_1_m(paper_run, k, seed):
    assert paper_run(k, seed=seed)["distance_error_m"] <= 1.0


@pytest.mark.slow
@pytest.mark.parametrize(("k", "seed"), TEAMS)
def test_the_person_is_in_frame_at_least_90_percent_of_frames(paper_run, k, seed):
    assert paper_run(k, seed=seed)["in_frame_fraction"] >= 0.9


@pytest.mark.slow
@pytest.mark.parametrize(("k", "seed"), TEAMS)
def test_no_two_mavs_come_closer_than_1_5_m(paper_run, k, seed):
    assert paper_run(k, seed=seed)["min_separation_m"] >= 1.5


@pytest.mark.slow
@pytest.mark.parametrize(("k", "seed"), TEAMS)
def test_no_mav_touches_a_trunk(paper_run, k, seed):
    assert paper_run(k, seed=seed)["min_obstacle_clearance_m"] > 0.0


@pytest.mark.slow
def test_with_every_message_lost_the_run_completes_without_collisions(paper_run):
    metrics = paper_run(8, comm_loss=1.0)
    assert metrics["counters"]["messages_delivered"] == 0
    assert metrics["min_separation_m"] >= 1.5


@pytest.mark.slow
def test_with_every_message_lost_each_mav_tracks_with_its_own_detections(paper_run):
    vehicles = paper_run(8, comm_loss=1.0)["vehicles"]
    assert all(v["teammate_detections_fused"] == 0 for v in vehicles)
    assert all(v["own_detections_fused"] > 200 for v in vehicles)
    # Hearing nobody, every MAV holds where it took off and films from there (docs/safety.md, the hold):
    # 1.2-2.3 m as measured. Flying blind to the roster slots kept this run below 2 m, but brought MAVs of
    # the safety sweep within 0.2 m of each other.
    assert all(v["tracking_error_m_mean"] < 2.5 for v in vehicles)

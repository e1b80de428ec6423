"""The hold (docs/safety.md#link-loss-the-hold): MAVs that cannot hear each other rest, and stay apart.

A clustered start (spots 2.5 m apart) with 16 MAVs is the case where flying blind to the roster slots brought
MAVs within 0.2 m of each other: every transit path crosses a teammate's that nobody can see.
"""

from functools import cache

import pytest

from server.lab.simulation import SimConfig, run_simulation


@cache
def _cluster_run(comm_loss: float) -> dict:
    config = SimConfig(
        vehicles=16,
        duration_s=40.0,
        warmup_s=10.0,
        seed=3,
        person="random",
        trees="paper",
        start="cluster",
        comm_loss=comm_loss,
        rate_hz=10.0,
    )
    return run_simulation(config).to_json()["metrics"]


@pytest.fixture(scope="module")
def cluster_run():
    """_cluster_run, shared by the tests of this module (kept on one xdist worker: tests/conftest.py)."""
    return _cluster_run


def test_a_team_that_hears_nothing_holds_from_take_off_to_the_end(cluster_run):
    metrics = cluster_run(1.0)
    assert metrics["counters"]["messages_delivered"] == 0
    assert metrics["counters"]["escape_ticks"] == 0
    # every MAV holds whenever it has a person estimate (without one it brakes to rest anyway): 208-350 of
    # its 10 Hz ticks from the end of its climb to 40 s
    assert all(v["hold_ticks"] > 150 for v in metrics["vehicles"])


def test_a_team_that_hears_nothing_keeps_its_start_spacing(cluster_run):
    metrics = cluster_run(1.0)
    assert metrics["min_believed_separation_m"] >= 2.0  # start spots 2.5 m apart, GPS-frame spots >= 2 m
    assert metrics["min_separation_m"] >= 1.0


def test_a_team_that_hears_nothing_touches_no_trunk(cluster_run):
    assert cluster_run(1.0)["min_obstacle_clearance_m"] > 0.0


def test_a_team_that_hears_everything_never_holds(cluster_run):
    metrics = cluster_run(0.0)
    assert metrics["counters"]["hold_ticks"] == 0
    assert metrics["min_believed_separation_m"] >= 1.5

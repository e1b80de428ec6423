"""A 40-run sample of the safety sweep (docs/safety.md) with the sweep's zero-violation thresholds.

Runs 0-39 of `skyring experiment safety` as the sweep flies them (base seed 0: 3 to 16 MAVs, trees, link loss
up to 100 %, the random runner, half of them from clustered starts; 90 s each at 10 Hz, metrics from the first
motor spin to the end). All 1000 runs are `skyring experiment safety` (docs/safety.md), too long for the
suite. The runs are dealt to eight tests of about the same cost so that the suite's workers share them.
"""

import pytest

from server.lab.experiments import RunResult
from server.lab.safety_sweep import SweepRun, Thresholds, outcome, plan_sweep
from server.lab.simulation import SimConfig, run_simulation

SAMPLE = plan_sweep(base_seed=0, runs=40)
CHUNKS = 8


def dealt(runs: list[SweepRun], chunks: int) -> list[list[SweepRun]]:
    """The runs in `chunks` lists of about equal cost: largest team first, each to the list with the fewest
    MAVs so far (a run's cost grows with its team size, 1.3 s at 3 MAVs to 19 s at 16 on one core)."""
    lists: list[list[SweepRun]] = [[] for _ in range(chunks)]
    for run in sorted(runs, key=lambda r: (-r.vehicles, r.index)):
        min(lists, key=lambda chosen: sum(r.vehicles for r in chosen)).append(run)
    return lists


def test_the_sample_flies_the_sweeps_whole_runs_each_once():
    assert sorted(r.index for chunk in dealt(SAMPLE, CHUNKS) for r in chunk) == list(range(40))
    assert {(r.duration_s, r.rate_hz) for r in SAMPLE} == {(90.0, 10.0)}
    assert sum(r.start == "cluster" for r in SAMPLE) == 20


@pytest.mark.slow
@pytest.mark.parametrize("chunk", range(CHUNKS))
def test_a_sample_of_the_sweep_breaks_no_threshold(chunk):
    """No closest believed pair below 1.5 m, no closest true pair below 1.0 m, no trunk contact."""
    broken = []
    for run in dealt(SAMPLE, CHUNKS)[chunk]:
        spec = run.spec()
        report = run_simulation(SimConfig(**spec.config_fields())).to_json()
        result = outcome(run, RunResult(spec=spec, report=report))
        assert result.error is None and result.separation.distance_m is not None
        if result.violations(Thresholds()):
            broken.append(
                f"run {run.index} ({run.label}): true {result.separation.distance_m:.3f} m, believed "
                f"{result.believed_separation.distance_m} m, trunk {result.obstacle_clearance.distance_m} m"
                f" -- {run.sim_command()}"
            )
    assert broken == []

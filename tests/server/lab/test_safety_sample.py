"""A 40-run sample of the safety sweep (docs/safety.md) with the sweep's zero-violation thresholds.

Runs 0-39 of `skyring experiment safety` (base seed 0: 3 to 16 MAVs, trees, link loss up to 100 %, the
random runner, half of them from clustered starts), each flown for its first 20 s at 10 Hz: take-off,
spreading out from the cluster and the first seconds of formation flight, where MAVs came closest before the
separation rows. The whole 90 s runs, and all 1000 of them, are `skyring experiment safety` (6387 s on 2
cores, docs/safety.md: too long for the suite). The runs are split in four tests so that the suite's
workers share them.
"""

import pytest

from server.lab.experiments import RunResult
from server.lab.safety_sweep import Thresholds, outcome, plan_sweep
from server.lab.simulation import SimConfig, run_simulation

SAMPLE = plan_sweep(base_seed=0, runs=40, duration_s=20.0)
CHUNKS = 4


@pytest.mark.slow
@pytest.mark.parametrize("chunk", range(CHUNKS))
def test_a_sample_of_the_sweep_breaks_no_threshold(chunk):
    """No closest believed pair below 1.5 m, no closest true pair below 1.0 m, no trunk contact."""
    broken = []
    for run in SAMPLE[chunk::CHUNKS]:
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

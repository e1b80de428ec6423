"""The protocol benchmark's arithmetic: each condition's sampled cost scaled to the whole protocol."""

import pytest

from server.lab import experiments as exp
from server.lab.bench_protocol import TAKEOFF_S, SampledCost, protocol_cpu_s


def test_every_run_of_the_protocol_costs_a_take_off_and_its_flight_after_it():
    methods = exp.paper_protocol("methods")  # 4 conditions, 10 runs of 120 s and 20 of 180 s each
    costs = [SampledCost(takeoff_cpu_s=2.0, cpu_per_simulated_s=0.1 * (i + 1)) for i in range(4)]
    flight_s = 10 * (120.0 - TAKEOFF_S) + 20 * (180.0 - TAKEOFF_S)
    expected = 4 * 30 * 2.0 + (0.1 + 0.2 + 0.3 + 0.4) * flight_s
    assert protocol_cpu_s(methods, costs) == pytest.approx(expected, rel=1e-12)


def test_protocol_cpu_time_needs_one_cost_per_condition():
    with pytest.raises(ValueError, match="one cost per condition: 4, got 3"):
        protocol_cpu_s(exp.paper_protocol("methods"), [SampledCost(1.0, 0.1)] * 3)

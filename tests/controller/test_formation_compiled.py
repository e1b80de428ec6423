"""The formation controller's compiled tick against its numpy form, to the bit, on ticks recorded from
simulated flights: `FormationController(compiled=True)` (the default: the start state, our previous plan on
the horizon, the terminal reference and the way-point by controller/reference_kernel.py, the separation rows
in one call) against `compiled=False` (the numpy form and the composition of kernels they replace). Each
MAV's recorded calls replay in order on one controller of each kind: every tick starts from the same previous
plan."""

from __future__ import annotations

import copy
from collections import Counter

import numpy as np
import pytest

import controller.formation as formation
from controller.formation import FormationController
from controller.messages import SolveStatus
from controller.params import Method
from server.lab.simulation import SimConfig, run_simulation

pytestmark = pytest.mark.slow  # four simulated flights record the ticks: about 6 s of CPU

FLIGHTS = (
    # clustered starts that spread out among the paper's trees: leash, lag, trunk, floor and teammate rows
    SimConfig(vehicles=8, duration_s=20.0, warmup_s=19.0, rate_hz=10.0, start="cluster", seed=3),
    # the price baseline: its terminal reference aims without the person's velocity or the pass-through
    SimConfig(vehicles=4, duration_s=14.0, warmup_s=13.0, rate_hz=10.0, method=Method.PRICE, trees="none"),
    # a lossy link: holds, phantom teammates, stale plans
    SimConfig(vehicles=10, duration_s=12.0, warmup_s=11.0, rate_hz=10.0, seed=4, comm_loss=0.6),
    # the paper's 100 Hz: the previous plan a hundredth of a second old at every tick
    SimConfig(vehicles=4, duration_s=12.0, warmup_s=11.0, rate_hz=100.0, seed=2),
)


@pytest.fixture(scope="module")
def recorded() -> dict[tuple[int, int], tuple]:
    """(flight, vehicle id) -> (controller params, the kwargs of each of its steps in order)."""
    calls: dict[tuple[int, int], tuple] = {}
    flying = [0]  # the index of the flight being flown
    original = FormationController.step

    def recording(self, **kwargs):
        key = (flying[0], self.vehicle_id)
        calls.setdefault(key, (self.params, []))[1].append(copy.deepcopy(kwargs))
        return original(self, **kwargs)

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(FormationController, "step", recording)
        for index, flight in enumerate(FLIGHTS):
            flying[0] = index
            run_simulation(flight)
    return calls


@pytest.fixture(scope="module")
def replayed(recorded):
    """Each MAV's ticks stepped by a compiled and a numpy controller: [(compiled, numpy) outputs], and how
    often the compiled controller called each kernel."""
    pairs, kernel_calls = [], Counter()
    with pytest.MonkeyPatch.context() as mp:
        for name in ("start_and_horizon", "aim", "tick_separation_rows", "inputs_and_rows", "waypoint"):
            kernel = getattr(formation, name)

            def counted(*args, _kernel=kernel, _name=name, **kwargs):
                kernel_calls[_name] += 1
                return _kernel(*args, **kwargs)

            mp.setattr(formation, name, counted)
        for (_, vehicle_id), (params, steps) in recorded.items():
            fast = FormationController(vehicle_id=vehicle_id, params=params)
            reference = FormationController(vehicle_id=vehicle_id, params=params, compiled=False)
            for kwargs in steps:
                pairs.append((fast.step(**kwargs), reference.step(**kwargs)))
    return pairs, kernel_calls


def test_more_than_three_thousand_ticks_were_recorded(replayed):
    pairs, _ = replayed
    assert len(pairs) > 3000


def test_the_recorded_ticks_take_every_path_of_the_compiled_tick(replayed):
    """Formation flight and holds are among them (3,850 and 57 of 3,928 measured, and 21 escapes), and each
    kernel ran on most ticks: formation flight from the start state to the solve in one call
    (`inputs_and_rows`, 3,034 measured), the price baseline, holds and ticks with phantom teammates through
    the wrappers (`aim` 837, `tick_separation_rows` 894)."""
    pairs, kernel_calls = replayed
    statuses = Counter(fast.status for fast, _ in pairs)
    assert statuses[SolveStatus.SOLVED] > 3000
    assert statuses[SolveStatus.HOLD] > 10
    assert kernel_calls["start_and_horizon"] > 0.95 * len(pairs)
    assert kernel_calls["inputs_and_rows"] > 0.7 * len(pairs)
    assert kernel_calls["aim"] > 0.15 * len(pairs)
    assert kernel_calls["tick_separation_rows"] > 0.15 * len(pairs)
    assert kernel_calls["inputs_and_rows"] + kernel_calls["tick_separation_rows"] > 0.95 * len(pairs)
    assert kernel_calls["waypoint"] > 0.95 * len(pairs)


def test_the_compiled_tick_gives_the_numpy_ticks_outputs_to_the_bit(replayed):
    pairs, _ = replayed
    differ = 0
    for fast, ref in pairs:
        same = (
            fast.status == ref.status
            and fast.fault == ref.fault
            and fast.yaw_rad == ref.yaw_rad
            and np.array_equal(fast.plan.positions_m, ref.plan.positions_m)
            and np.array_equal(fast.plan.velocities_mps, ref.plan.velocities_mps)
            and np.array_equal(fast.waypoint_position_m, ref.waypoint_position_m)
            and np.array_equal(fast.waypoint_velocity_mps, ref.waypoint_velocity_mps)
            and np.array_equal(fast.waypoint_acceleration_mps2, ref.waypoint_acceleration_mps2)
            and np.array_equal(fast.external_inputs, ref.external_inputs)
        )
        differ += not same
    assert differ == 0

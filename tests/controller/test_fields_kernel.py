"""The compiled external inputs (controller/fields_kernel.py) against the numpy reference (fields.py) on
instances recorded from simulated flights: clustered starts that spread out among the paper's trees, the dqmpc
baseline, virtual obstacles, and 16 MAVs over a lossy link (phantom teammates)."""

from __future__ import annotations

import copy
from typing import Any

import numpy as np
import pytest

import controller.formation as formation
from controller.fields import FieldParams, external_inputs
from controller.fields_kernel import (
    P_GAIN,
    P_OBSTACLE_PEAK,
    TERMS,
    external_inputs_compiled,
    input_terms,
    param_vector,
)
from controller.params import Method
from server.lab.simulation import SimConfig, run_simulation

pytestmark = pytest.mark.slow  # four simulated flights record the instances: about 20 s of CPU

FLIGHTS = (
    SimConfig(vehicles=8, duration_s=16.0, warmup_s=15.0, rate_hz=10.0, start="cluster", seed=3),
    SimConfig(
        vehicles=5,
        duration_s=14.0,
        warmup_s=13.0,
        rate_hz=10.0,
        method=Method.DQMPC,
        start="cluster",
        trees="none",
    ),
    SimConfig(
        vehicles=5, duration_s=14.0, warmup_s=13.0, rate_hz=10.0, virtual_obstacles="paper", trees="none"
    ),
    SimConfig(vehicles=16, duration_s=11.0, warmup_s=10.0, rate_hz=10.0, seed=4, comm_loss=0.5),
)


@pytest.fixture(scope="module")
def recorded() -> list[dict]:
    """Every external-input call of the flights above, flown with the numpy reference."""
    calls: list[dict] = []

    def reference(*, person_xy_m, **kwargs):
        """The controller's call (`input_terms`), answered by the numpy form: the person's horizontal
        positions (N+1, 2) as (N+1, 3) positions (the inputs read only x and y)."""
        person = np.zeros((person_xy_m.shape[0], 3))
        person[:, :2] = person_xy_m
        call: dict[str, Any] = copy.deepcopy(kwargs)
        call["person_position_m"] = person
        calls.append(call)
        inputs = external_inputs(**call)
        return np.stack([getattr(inputs, name) for name in TERMS]), inputs.fault

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(formation, "ONE_CALL", False)  # every tick through `input_terms`
        mp.setattr(formation, "input_terms", reference)
        for flight in FLIGHTS:
            run_simulation(flight)
    return calls


def test_at_least_a_thousand_instances_were_recorded(recorded):
    assert len(recorded) >= 1000


def test_recorded_instances_exercise_every_term(recorded):
    """Each term is non-zero in at least 2 % of the instances, so every branch of the kernel is compared."""
    counts = {name: 0 for name in TERMS}
    for kwargs in recorded[::5]:
        ref = external_inputs(**kwargs)
        for name in TERMS:
            counts[name] += bool(np.any(getattr(ref, name)))
    assert min(counts.values()) >= 0.02 * len(recorded[::5]), counts


def test_compiled_inputs_equal_the_reference_on_every_recorded_instance(recorded):
    worst = dict.fromkeys(TERMS, 0.0)
    for kwargs in recorded:
        ref, fast = external_inputs(**kwargs), external_inputs_compiled(**kwargs)
        assert fast.fault == ref.fault
        for name in TERMS:
            worst[name] = max(worst[name], float(np.max(np.abs(getattr(fast, name) - getattr(ref, name)))))
    assert max(worst.values()) < 1e-9, worst


def test_the_ticks_call_gives_the_terms_and_fault_of_the_full_call_to_the_bit(recorded):
    """`input_terms` (what formation.py calls) against `external_inputs_compiled` on every recorded
    instance: the same total and terms, bit for bit, and the same fault flag."""
    for kwargs in recorded:
        full = external_inputs_compiled(**kwargs)
        person_xy = np.ascontiguousarray(kwargs["person_position_m"][:, :2])
        rest = {k: v for k, v in kwargs.items() if k != "person_position_m"}
        terms, fault = input_terms(**rest, person_xy_m=person_xy)
        assert fault == full.fault
        for index, name in enumerate(TERMS):  # the total first
            np.testing.assert_array_equal(terms[index], getattr(full, name))


def test_non_finite_total_is_a_fault_with_zero_inputs(recorded):
    kwargs = dict(recorded[0])
    own = np.array(kwargs["own_positions_m"], dtype=float)
    own[3, 0] = np.nan
    kwargs["own_positions_m"] = own
    ref, fast = external_inputs(**kwargs), external_inputs_compiled(**kwargs)
    assert ref.fault and fast.fault
    np.testing.assert_array_equal(fast.total, 0.0)


def test_the_parameter_vector_is_made_once_per_params_object_and_carries_its_values():
    """The kernel's parameters are remembered by FieldParams object (not by value): the same object gives
    the same array, another object its own values, even after 20 others have pushed the first one out."""
    base = FieldParams()
    first = param_vector(base)
    assert param_vector(base) is first
    others = [FieldParams(gain=1.0 + i, obstacle_peak_mps2=3.0 + i) for i in range(20)]
    for i, params in enumerate(others):
        vector = param_vector(params)
        assert (vector[P_GAIN], vector[P_OBSTACLE_PEAK]) == (1.0 + i, 3.0 + i)
    again = param_vector(base)
    assert (again[P_GAIN], again[P_OBSTACLE_PEAK]) == (base.gain, base.obstacle_peak_mps2)

"""controller/tick_kernel.py: a formation-flight tick from its start state to its solve in one compiled call
gives, on every tick recorded from simulated flights, the same teammates' paths, external inputs, terminal
reference and separation rows, to the bit, as the four wrappers it stands for (`_teammates`, `_inputs`,
`_target`, `_separation`)."""

from __future__ import annotations

from collections import Counter

import numpy as np
import pytest

from controller.formation import FormationController
from controller.params import Method
from server.lab.simulation import SimConfig, run_simulation

pytestmark = pytest.mark.slow  # four simulated flights: about 10 s of CPU

FLIGHTS = (
    # clustered starts that spread out among the paper's trees: teammate, trunk and floor rows, the lag
    SimConfig(vehicles=8, duration_s=16.0, warmup_s=15.0, rate_hz=10.0, start="cluster", seed=3),
    # the dqmpc baseline: its own terms and thresholds
    SimConfig(vehicles=5, duration_s=14.0, warmup_s=13.0, rate_hz=10.0, method=Method.DQMPC, start="cluster"),
    # virtual obstacles
    SimConfig(
        vehicles=5, duration_s=14.0, warmup_s=13.0, rate_hz=10.0, virtual_obstacles="paper", trees="none"
    ),
    # 16 MAVs at the paper's 100 Hz
    SimConfig(vehicles=16, duration_s=10.6, warmup_s=10.0, rate_hz=100.0, seed=1),
)


def _same_paths(one, ref) -> bool:
    return (
        np.array_equal(one.positions_m, ref.positions_m)
        and np.array_equal(one.vehicle_ids, ref.vehicle_ids)
        and np.array_equal(one.in_formation, ref.in_formation)
        and np.array_equal(one.d_max_m, ref.d_max_m)
        and np.array_equal(one.ages_s, ref.ages_s)
        and np.array_equal(one.gps_offsets_m, ref.gps_offsets_m)
        and one.rejected == ref.rejected
    )


def _same_rows(one, ref) -> bool:
    a, b = one.planes, ref.planes
    return (
        (one.teammate_rows, one.obstacle_rows, one.floor_rows, one.closest_teammate_index)
        == (ref.teammate_rows, ref.obstacle_rows, ref.floor_rows, ref.closest_teammate_index)
        and (one.closest_teammate_m == ref.closest_teammate_m or np.isnan(ref.closest_teammate_m))
        and np.array_equal(a.steps, b.steps)
        and np.array_equal(a.normals_xy, b.normals_xy)
        and np.array_equal(a.normals_z, b.normals_z)
        and np.array_equal(a.offsets, b.offsets)
        and a.soft is None
        and b.soft is None
    )


@pytest.fixture(scope="module")
def compared() -> Counter:
    """Every one-call tick of the flights, answered also by the wrappers: how many agreed in each part, how
    many raised a field fault, how many there were, and how many had trunk and floor rows."""
    counts: Counter = Counter()
    one_call = FormationController._in_one_call

    def both(self, tick, person, view, obstacle_set, formation, preferred):
        faults = self._counts["field_faults"]
        mates, f_total, target, target_v, rows = one_call(
            self, tick, person, view, obstacle_set, formation, preferred
        )
        fault_once = self._counts["field_faults"] - faults
        ref_mates = self._teammates(view, tick.now_s, tick.own)
        own_path, own_vel = self._own_horizon(tick)
        ref_f = self._inputs(tick, person, ref_mates, obstacle_set, formation, own_path, own_vel)
        ref_target, ref_target_v = self._target(tick, person, ref_f, formation, preferred, False)
        ref_rows = self._separation(tick, own_path, own_vel, ref_mates, obstacle_set)
        fault_twice = self._counts["field_faults"] - faults
        self._counts["field_faults"] = faults + fault_once  # the tick counts its fault once
        counts["ticks"] += 1
        counts["paths"] += _same_paths(mates, ref_mates)
        counts["inputs"] += np.array_equal(f_total, ref_f)
        counts["target"] += np.array_equal(target, ref_target) and np.array_equal(target_v, ref_target_v)
        counts["rows"] += ref_rows is not None and _same_rows(rows, ref_rows)
        counts["faults"] += fault_twice == 2 * fault_once
        counts["trunk rows"] += rows.obstacle_rows > 0
        counts["floor rows"] += rows.floor_rows > 0
        counts["moving person"] += bool(np.any(person.velocity_mps))
        return mates, f_total, target, target_v, rows

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(FormationController, "_in_one_call", both)
        for flight in FLIGHTS:
            run_simulation(flight)
    return counts


def test_more_than_a_thousand_ticks_went_in_one_call_and_reached_every_kind_of_row(compared):
    assert compared["ticks"] > 1000
    assert compared["trunk rows"] > 100 and compared["floor rows"] > 0  # 4,627, 1,000-odd and 7 measured
    assert compared["moving person"] > 0.5 * compared["ticks"]


@pytest.mark.parametrize("part", ["paths", "inputs", "target", "rows", "faults"])
def test_the_one_call_gives_what_the_wrappers_give_to_the_bit(compared, part):
    assert compared[part] == compared["ticks"]

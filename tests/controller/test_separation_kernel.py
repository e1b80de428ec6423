"""The compiled separation rows (controller/separation_kernel.py) against the numpy reference
(controller/separation.py): the same rows, in the same order, to round-off, on 1,200 random ticks (teammate,
trunk and floor rows, with and without the vehicle's lag behind its plan)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from controller.fields import FieldParams, ObstacleSet, TeammatePaths, teammate_age_term_m
from controller.messages import Obstacle
from controller.separation import SeparationParams, age_margin_m, separation_rows, tick_separation_rows
from controller.separation_kernel import row_inflation

STEPS = 16
DT = 0.1


def random_tick(rng: np.random.Generator) -> dict:
    """A MAV among 0-15 teammates (some out of formation, some stale, some coincident with us) and 0-20
    trunks, all within a few metres, moving at up to 5 m/s."""
    own = rng.uniform([-6.0, -6.0, 4.0], [6.0, 6.0, 10.0])
    own_v = rng.normal(0.0, 2.0, 3) * np.array([1.0, 1.0, 0.1])
    own_path = own + DT * np.arange(STEPS)[:, None] * own_v
    count = int(rng.integers(0, 16))
    starts = own + rng.normal(0.0, 4.0, (count, 3)) * np.array([1.0, 1.0, 0.3])
    if count and rng.random() < 0.2:
        starts[0] = own  # a coincident plan: the tie-break by id
    velocities = rng.normal(0.0, 2.0, (count, 3)) * np.array([1.0, 1.0, 0.1])
    paths = starts[:, None, :] + DT * np.arange(STEPS)[None, :, None] * velocities[:, None, :]
    mates = TeammatePaths(
        positions_m=paths,
        vehicle_ids=rng.permutation(np.arange(2, 2 + count)),
        in_formation=rng.random(count) < 0.8,
        d_max_m=np.full(count, 3.0),
        ages_s=rng.uniform(0.0, 1.5, count),
    )
    trees = tuple(
        Obstacle(
            obstacle_id=f"t{i}",
            center_m=own[:2] + rng.normal(0.0, 4.0, 2),
            radius_m=float(rng.uniform(0.2, 1.0)),
            height_m=float(rng.uniform(5.0, 12.0)),
        )
        for i in range(int(rng.integers(0, 21)))
    )
    return dict(
        own_path_m=own_path,
        own_velocities_mps=np.tile(own_v, (STEPS, 1)),
        mates=mates,
        mate_ages_s=mates.ages,
        inflation_m=rng.uniform(0.0, 3.0, count),
        obstacles=ObstacleSet.from_obstacles(trees),
        own_cov_radius_m=float(rng.uniform(0.0, 1.0)),
        dt_s=DT,
        own_id=1,
        params=SeparationParams(),
        lag_m=rng.normal(0.0, 0.3, 3) if rng.random() < 0.5 else None,
        floor_m=float(rng.uniform(2.0, 5.0)) if rng.random() < 0.5 else None,
    )


@pytest.fixture(scope="module")
def pairs():
    rng = np.random.default_rng(112926)
    out = []
    for _ in range(1200):
        tick = random_tick(rng)
        out.append((separation_rows(**tick), separation_rows(**tick, compiled=False)))
    return out


def test_compiled_rows_are_the_reference_rows_in_the_same_order(pairs):
    for fast, ref in pairs:
        assert (fast.teammate_rows, fast.obstacle_rows, fast.floor_rows) == (
            ref.teammate_rows,
            ref.obstacle_rows,
            ref.floor_rows,
        )
        np.testing.assert_array_equal(fast.planes.steps, ref.planes.steps)
        np.testing.assert_allclose(fast.planes.normals_xy, ref.planes.normals_xy, rtol=0, atol=1e-12)
        np.testing.assert_allclose(fast.planes.normals_z, ref.planes.normals_z, rtol=0, atol=1e-12)
        np.testing.assert_allclose(fast.planes.offsets, ref.planes.offsets, rtol=1e-12, atol=1e-10)
        assert fast.closest_teammate_index == ref.closest_teammate_index
        assert fast.closest_teammate_m == pytest.approx(ref.closest_teammate_m, abs=1e-12)


def test_the_random_ticks_exercise_every_kind_of_row(pairs):
    """Enough rows of each kind for the comparison to mean something: teammate rows, trunk rows, floor rows,
    and ticks with none."""
    assert sum(ref.teammate_rows for _, ref in pairs) > 50_000  # measured 99,657
    assert sum(ref.obstacle_rows for _, ref in pairs) > 50_000  # 72,406
    assert sum(ref.floor_rows for _, ref in pairs) > 2_000  # 5,049
    assert sum(ref.count == 0 for _, ref in pairs) >= 5  # 7


def test_row_inflation_is_the_numpy_forms_to_the_bit():
    """separation_kernel.row_inflation against the numpy form it replaces in formation.py (d_max less the
    base and r_comm, plus age_margin_m) on 200 random teams: ages of 0, within and on the edge of the grace
    period and far beyond it, d_max from 0 to 20 m, and NaN in both; the same bits, zeros' signs included."""
    rng = np.random.default_rng(2026_12_07)
    fields, sep = FieldParams(), SeparationParams()
    grace = fields.teammate_age_grace_s
    for _ in range(200):
        count = int(rng.integers(0, 17))
        ages = rng.choice([0.0, 0.05, grace, grace + 1e-9, 0.7, 3.0, 40.0], count) * rng.uniform(
            0.5, 1.5, count
        )
        ages[rng.random(count) < 0.2] = grace
        ages[rng.random(count) < 0.05] = np.nan
        d_max = rng.uniform(0.0, 20.0, count)
        d_max[rng.random(count) < 0.05] = np.nan
        got = np.empty(count)
        row_inflation(
            d_max,
            ages,
            fields.teammate_d_max_base_m,
            fields.teammate_speed_mps,
            grace,
            0.5 * sep.plan_deviation_mps2,
            got,
        )
        speed_term = teammate_age_term_m(ages, fields)
        want = (d_max - fields.teammate_d_max_base_m - speed_term) + age_margin_m(
            ages, speed_term_m=speed_term, params=sep
        )
        np.testing.assert_array_equal(got, want)
        np.testing.assert_array_equal(np.signbit(got), np.signbit(want))


def test_a_ticks_rows_in_one_call_are_the_composition_they_replace_to_the_bit():
    """separation.tick_separation_rows against what formation.py composed before it (row_inflation, the
    teammates placed by the GPS offsets, separation_rows with the row kernels, the lag and the floor) on 1,200
    random ticks, a third of them with every GPS offset 0 (no placing) and some with -0.0 coordinates: the
    same rows, counts and closest teammate, every number the same bits."""
    rng = np.random.default_rng(2026_12_08)
    fields = FieldParams()
    for index in range(1200):
        tick = random_tick(rng)
        mates = tick["mates"]
        count = mates.count
        placed_offsets = index % 3 != 0
        mates = replace(
            mates,
            d_max_m=rng.uniform(0.5, 6.0, count),
            gps_offsets_m=rng.normal(0.0, 1.0, (count, 3)) if placed_offsets else None,
        )
        if count and rng.random() < 0.2:
            mates.positions_m[0, :, 0] = -0.0
        own_offset = rng.normal(0.0, 1.0, 3) if placed_offsets else np.zeros(3)
        lag = tick["lag_m"] if tick["lag_m"] is not None else np.zeros(3)
        floor = tick["floor_m"] if tick["floor_m"] is not None else 0.5
        inflation = np.empty(count)
        row_inflation(
            mates.d_max_m,
            mates.ages,
            fields.teammate_d_max_base_m,
            fields.teammate_speed_mps,
            fields.teammate_age_grace_s,
            0.5 * tick["params"].plan_deviation_mps2,
            inflation,
        )
        kept = ("own_path_m", "own_velocities_mps", "obstacles", "own_cov_radius_m", "dt_s", "own_id")
        kept += ("params",)
        common = {key: tick[key] for key in kept} | {"lag_m": lag, "floor_m": floor}
        want = separation_rows(
            **common, mates=mates.placed_by(own_offset), mate_ages_s=mates.ages, inflation_m=inflation
        )
        got = tick_separation_rows(**common, mates=mates, own_gps_offset_m=own_offset, fields=fields)
        assert (got.teammate_rows, got.obstacle_rows, got.floor_rows) == (
            want.teammate_rows,
            want.obstacle_rows,
            want.floor_rows,
        )
        assert (got.closest_teammate_index, got.closest_teammate_m) == (
            want.closest_teammate_index,
            want.closest_teammate_m,
        )
        for name in ("steps", "normals_xy", "normals_z", "offsets"):
            a, b = getattr(got.planes, name), getattr(want.planes, name)
            np.testing.assert_array_equal(a, b)
            np.testing.assert_array_equal(np.signbit(a), np.signbit(b))

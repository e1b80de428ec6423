"""Specification of the teammates' plan table (controller/teammates.py): the same TeammatePaths as
fields.teammate_paths builds from the plans, with each plan checked once when it arrives."""

from __future__ import annotations

import numpy as np
import pytest

from controller.fields import FieldParams, teammate_age_term_m, teammate_paths
from controller.messages import HorizonPlan
from controller.teammates import TeammateTable, align_rows, fresh_paths

PARAMS = FieldParams()
STEPS = 16


def plan(rng: np.random.Generator, vid: int, stamp: float, *, length: int = 17) -> HorizonPlan:
    a = rng.normal(size=(3, 3))
    return HorizonPlan(
        vehicle_id=vid,
        stamp_s=stamp,
        dt_s=rng.choice([0.1, 0.05]),
        positions_m=rng.uniform(-15.0, 15.0, (length, 3)),
        velocities_mps=rng.normal(size=(length, 3)),
        in_formation=bool(rng.integers(2)),
        position_cov_m2=a @ a.T * 0.1,
        gps_offset_m=rng.normal(0.0, 0.5, 3),
    )


@pytest.mark.parametrize("seed", range(20))
@pytest.mark.parametrize("price", [False, True])
def test_paths_equal_teammate_paths_of_the_fresh_plans(seed, price):
    rng = np.random.default_rng(seed)
    table = TeammateTable(own_id=0, plan_length=17, capacity=2)  # grows as teammates appear
    latest: dict[int, HorizonPlan] = {}
    for _ in range(40):  # plans arrive in random order of vehicles and ages, some out of date
        p = plan(
            rng, int(rng.integers(1, 9)), float(rng.uniform(0.0, 10.0)), length=int(rng.choice([17, 12]))
        )
        table.update(p)
        if p.vehicle_id not in latest or p.stamp_s >= latest[p.vehicle_id].stamp_s:
            latest[p.vehicle_id] = p
    now, since = 10.2, float(rng.uniform(0.0, 8.0))
    fresh = [latest[v] for v in sorted(latest) if latest[v].stamp_s >= since]
    expected = teammate_paths(
        fresh,
        now_s=now,
        dt_s=0.1,
        steps=STEPS,
        own_cov_radius_m=0.4,
        params=PARAMS,
        current_position_only=price,
    )
    got = table.paths(
        since_s=since,
        now_s=now,
        dt_s=0.1,
        steps=STEPS,
        own_cov_radius_m=0.4,
        params=PARAMS,
        current_position_only=price,
    )
    np.testing.assert_allclose(got.positions_m, expected.positions_m, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(got.vehicle_ids, expected.vehicle_ids)
    np.testing.assert_array_equal(got.in_formation, expected.in_formation)
    np.testing.assert_allclose(got.d_max_m, expected.d_max_m, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(got.gps_offsets_m, expected.gps_offsets_m)
    assert table.plans() == tuple(latest[v] for v in sorted(latest))


def test_extra_plans_come_after_the_stored_ones():
    rng = np.random.default_rng(1)
    table = TeammateTable(own_id=0, plan_length=17)
    stored, extra = plan(rng, 5, 1.0), plan(rng, 2, 1.0)
    table.update(stored)
    got = table.view(0.0, (extra,)).paths(
        now_s=1.0, dt_s=0.1, steps=STEPS, own_cov_radius_m=0.0, params=PARAMS
    )
    np.testing.assert_array_equal(got.vehicle_ids, [5, 2])
    np.testing.assert_array_equal(got.gps_offsets_m, [stored.gps_offset_m, extra.gps_offset_m])
    assert tuple(table.view(0.0, (extra,))) == (stored, extra)


def test_placed_by_our_offset_each_path_moves_by_ours_less_its_senders():
    rng = np.random.default_rng(3)
    table = TeammateTable(own_id=0, plan_length=17)
    for vid in (4, 7):
        table.update(plan(rng, vid, 1.0))
    got = table.paths(since_s=0.0, now_s=1.0, dt_s=0.1, steps=STEPS, own_cov_radius_m=0.0, params=PARAMS)
    ours = np.array([0.3, -0.2, 0.1])
    placed = got.placed_by(ours)
    for j, vid in enumerate((4, 7)):
        shift = ours - table.plans()[j].gps_offset_m
        np.testing.assert_allclose(placed.positions_m[j] - got.positions_m[j], np.tile(shift, (STEPS, 1)))
        assert placed.vehicle_ids[j] == vid
    np.testing.assert_array_equal(placed.d_max_m, got.d_max_m)


def test_placed_by_an_offset_equal_to_every_senders_the_paths_stay():
    rng = np.random.default_rng(4)
    table = TeammateTable(own_id=0, plan_length=17)
    same = np.array([0.5, 0.5, 0.0])
    for vid in (2, 3):
        p = plan(rng, vid, 1.0)
        table.update(
            HorizonPlan(
                vehicle_id=vid,
                stamp_s=1.0,
                dt_s=p.dt_s,
                positions_m=p.positions_m,
                velocities_mps=p.velocities_mps,
                gps_offset_m=same,
            )
        )
    got = table.paths(since_s=0.0, now_s=1.0, dt_s=0.1, steps=STEPS, own_cov_radius_m=0.0, params=PARAMS)
    assert got.placed_by(same) is got


def test_own_absurd_and_older_plans_are_not_stored():
    rng = np.random.default_rng(2)
    table = TeammateTable(own_id=3, plan_length=17)
    assert table.update(plan(rng, 3, 1.0)) == "refused"
    absurd = plan(rng, 4, 1.0)
    absurd = HorizonPlan(
        vehicle_id=4,
        stamp_s=1.0,
        dt_s=0.1,
        positions_m=absurd.positions_m,
        velocities_mps=absurd.velocities_mps,
        position_cov_m2=np.full((3, 3), np.nan),
    )
    assert table.update(absurd) == "refused"
    newer, older = plan(rng, 4, 2.0), plan(rng, 4, 1.5)
    assert table.update(newer) == "stored" and table.update(older) == "older"
    assert table.plans() == (newer,)


@pytest.mark.parametrize("bad", [np.nan, np.inf, -2.0e6])
def test_a_plan_with_a_non_finite_or_wild_position_is_refused_and_nothing_is_stored(bad):
    rng = np.random.default_rng(4)
    good = plan(rng, 4, 1.0)
    positions = good.positions_m.copy()
    positions[-1, 2] = bad
    table = TeammateTable(own_id=3, plan_length=17)
    wild = HorizonPlan(
        vehicle_id=4, stamp_s=1.0, dt_s=0.1, positions_m=positions, velocities_mps=good.velocities_mps
    )
    assert table.update(wild) == "refused"
    assert table.count == 0 and table.plans() == ()


def test_fresh_count_and_ids_count_in_formation_plans_only():
    rng = np.random.default_rng(3)
    table = TeammateTable(own_id=0, plan_length=17)
    plans = [plan(rng, v, float(v)) for v in range(1, 7)]
    for p in plans:
        table.update(p)
    expected = {p.vehicle_id for p in plans if p.in_formation and p.stamp_s >= 3.0}
    assert table.fresh_ids(3.0) == expected and table.fresh_count(3.0) == len(expected)


def test_fresh_paths_gives_the_numpy_forms_columns_to_the_bit():
    """teammates.fresh_paths against the numpy expressions it replaces, on 200 random tables of 1-16 rows:
    stamps in the past and the future (negative ages), ages on the grace period's edge, radii on both sides
    of the cap and NaN: the same d_max, ages, ids, flags and offsets to the bit, the same aligned paths as
    align_rows."""
    rng = np.random.default_rng(2026_12_07)
    cap, base, speed, grace = 0.5, PARAMS.teammate_d_max_base_m, PARAMS.teammate_speed_mps, 0.3
    for _ in range(200):
        n, length, now = int(rng.integers(1, 17)), 17, 10.0
        positions = rng.uniform(-20.0, 20.0, (n, length, 3))
        lengths = rng.integers(2, length + 1, n).astype(np.int64)
        stamps = now - rng.choice([-0.05, 0.0, grace, 0.3000001, 1.0, 7.5], n) - rng.uniform(0.0, 0.01, n)
        stamps[rng.random(n) < 0.2] = now - grace  # exactly on the grace period's edge: late = 0
        dts = rng.choice([0.1, 0.05], n)
        radii = rng.choice([0.0, 0.2, cap, 0.9, np.nan], n)
        ids, flying, offsets = rng.integers(1, 99, n), rng.random(n) < 0.5, rng.normal(size=(n, 3))
        rows = np.flatnonzero(rng.random(n) < 0.8)
        own = float(rng.uniform(0.0, 1.0))
        got = [
            np.empty((len(rows), STEPS, 3)),
            np.empty(len(rows), np.int64),
            np.empty(len(rows), np.bool_),
            np.empty((len(rows), 3)),
            np.empty(len(rows)),
            np.empty(len(rows)),
        ]
        head = base + min(own, cap)
        fresh_paths(
            positions,
            lengths,
            stamps,
            dts,
            radii,
            ids,
            flying,
            offsets,
            rows,
            now,
            0.1,
            False,
            cap,
            head,
            speed,
            grace,
            *got,
        )
        aligned = np.empty((len(rows), STEPS, 3))
        align_rows(positions, lengths, stamps, dts, rows, now, 0.1, False, aligned)
        since = now - stamps[rows]
        params = FieldParams(teammate_speed_mps=speed, teammate_age_grace_s=grace)
        d_max = base + min(own, cap) + np.minimum(radii[rows], cap) + teammate_age_term_m(since, params)
        expected = [aligned, ids[rows], flying[rows], offsets[rows], d_max, np.maximum(since, 0.0)]
        for column, want in zip(got, expected, strict=True):
            np.testing.assert_array_equal(column, want)
            if column.dtype.kind == "f":  # zeros of the same sign too
                np.testing.assert_array_equal(np.signbit(column), np.signbit(want))

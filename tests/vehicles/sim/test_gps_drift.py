"""GPS random-walk drift of self-localisation."""

import numpy as np
import pytest

from vehicles.sim.gps_drift import DriftParams, GpsDrift


def test_initial_offsets_have_the_papers_standard_deviation():
    offsets = np.array([GpsDrift(np.random.default_rng(s)).offset_m for s in range(2000)])
    np.testing.assert_allclose(offsets.std(axis=0), [0.5, 0.5, 1.0], rtol=0.08)
    np.testing.assert_allclose(offsets.mean(axis=0), 0.0, atol=0.06)


def test_drift_is_reproducible_from_its_seed():
    a, b = GpsDrift(np.random.default_rng(7)), GpsDrift(np.random.default_rng(7))
    a.advance_to(300.0)
    b.advance_to(300.0)
    np.testing.assert_array_equal(a.offset_m, b.offset_m)


def test_drift_moves_slowly_and_stays_bounded_over_ten_minutes():
    worst_speed = worst_offset = 0.0
    moved = []
    for seed in range(20):
        d = GpsDrift(np.random.default_rng(seed))
        start = d.offset_m.copy()
        for t in np.arange(1.0, 601.0, 1.0):
            d.advance_to(t)
            worst_speed = max(worst_speed, float(np.linalg.norm(d.velocity_mps)))
            worst_offset = max(worst_offset, float(np.max(np.abs(d.offset_m) / [0.5, 0.5, 1.0])))
        moved.append(np.linalg.norm(d.offset_m - start))
    assert worst_speed < 0.1  # centimetres per second, as GPS drift
    assert worst_offset < 5.0  # within 5 initial standard deviations
    assert np.median(moved) > 0.2  # but it does drift


def test_disabled_drift_is_exactly_zero():
    d = GpsDrift(np.random.default_rng(0), DriftParams(enabled=False))
    d.advance_to(100.0)
    np.testing.assert_array_equal(d.offset_m, 0.0)
    assert d.velocity_mps == pytest.approx(np.zeros(3))

"""The GPS offset estimator: a random-walk Kalman filter on the MAV's offset relative to its team."""

import numpy as np
import pytest

from controller.gps_offset import GpsOffsetEstimator, GpsOffsetParams


def _fed(offset_m, *, n, std_m=1.0, seed=3, dt_s=0.25, params=None):
    """An estimator fed n residuals, one every dt_s: offset_m plus white noise of std_m."""
    rng = np.random.default_rng(seed)
    est = GpsOffsetEstimator(params)
    for k in range(n):
        est.update(np.asarray(offset_m) + rng.normal(0.0, std_m, 3), np.eye(3) * std_m**2, k * dt_s)
    return est


def test_the_estimate_converges_on_a_constant_offset_through_noise_twice_its_size():
    est = _fed((0.8, -0.6, 1.2), n=400)
    np.testing.assert_allclose(est.offset_m, (0.8, -0.6, 1.2), atol=0.15)
    assert est.used + est.gated == 400 and est.gated <= 4  # 4 sigma (3 dof): about 1 in 1000 gated


def test_the_covariance_shrinks_from_the_prior_as_residuals_come_in():
    est = _fed((0.0, 0.0, 0.0), n=100)
    assert np.all(np.diag(est.cov_m2) < np.diag(GpsOffsetEstimator().cov_m2) / 4)


def test_with_no_residuals_the_offset_is_zero_with_the_gps_prior_as_covariance():
    est = GpsOffsetEstimator()
    np.testing.assert_array_equal(est.offset_m, np.zeros(3))
    np.testing.assert_allclose(np.diag(est.cov_m2), (0.25, 0.25, 1.0))


def test_the_first_residual_moves_the_estimate_by_the_prior_against_its_covariance():
    est = GpsOffsetEstimator()
    assert est.update(np.array([0.4, -0.2, 1.0]), np.eye(3) * 0.25, 0.0)
    np.testing.assert_allclose(est.offset_m, [0.2, -0.1, 0.8], atol=1e-12)  # 0.25/(0.25+0.25), 1/(1+0.25)


def test_time_between_residuals_grows_the_covariance_by_the_drift():
    est = GpsOffsetEstimator()
    est.update(np.zeros(3), np.eye(3), 0.0)
    before = est.cov_m2
    est.update(np.zeros(3), np.eye(3) * 1e9, 100.0)  # a useless measurement: only the time step counts
    grown = np.diag(est.cov_m2 - before)
    np.testing.assert_allclose(grown, np.square((0.01, 0.01, 0.02)) * 100.0, rtol=1e-6)


def test_a_drifting_offset_is_followed():
    rng = np.random.default_rng(4)
    est = GpsOffsetEstimator()
    for k in range(2400):  # 10 minutes at 4 Hz, the offset drifting east at 2 mm/s
        t = k * 0.25
        est.update(np.array([0.002 * t, 0.0, 0.0]) + rng.normal(0.0, 1.0, 3), np.eye(3), t)
    assert est.offset_m[0] == pytest.approx(1.2, abs=0.25)


def test_a_residual_beyond_the_gate_is_counted_and_changes_nothing():
    est = _fed((0.5, 0.0, 0.0), n=50)
    offset, cov = est.offset_m, est.cov_m2
    assert not est.update(np.array([40.0, 0.0, 0.0]), np.eye(3), 100.0)
    np.testing.assert_array_equal(est.offset_m, offset)
    np.testing.assert_array_equal(est.cov_m2, cov)
    assert est.gated == 1


@pytest.mark.parametrize(
    "residual, cov, stamp",
    [
        (np.array([np.nan, 0.0, 0.0]), np.eye(3), 1.0),
        (np.zeros(3), np.full((3, 3), np.inf), 1.0),
        (np.zeros(3), np.eye(3), float("nan")),
        (np.zeros(2), np.eye(3), 1.0),
        (np.zeros(3), np.zeros((3, 3)) - np.eye(3) * 0.25, 1.0),  # S = P + R singular
    ],
)
def test_a_bad_residual_is_counted_and_changes_nothing(residual, cov, stamp):
    est = GpsOffsetEstimator()
    assert not est.update(residual, cov, stamp)
    np.testing.assert_array_equal(est.offset_m, np.zeros(3))
    assert (est.gated, est.used) == (1, 0)


def test_the_estimate_is_clipped_to_max_offset_per_axis():
    est = _fed((2.0, 0.0, 0.0), n=50, std_m=0.1, params=GpsOffsetParams(max_offset_m=0.3, gate_sigma=100.0))
    assert est.offset_m[0] == pytest.approx(0.3, abs=1e-12)


@pytest.mark.parametrize(
    "kwargs",
    [
        {"initial_std_m": (0.5, 0.5)},
        {"initial_std_m": (0.5, 0.0, 1.0)},
        {"drift_mps": (0.01, float("nan"), 0.02)},
        {"gate_sigma": 0.0},
        {"max_offset_m": -1.0},
        {"max_age_s": -0.1},
        {"teammate_within_s": float("nan")},
    ],
)
def test_bad_parameters_are_refused(kwargs):
    with pytest.raises(ValueError):
        GpsOffsetParams(**kwargs)

"""Specification of the detection measurement model (controller/measurement.py, paper eqs. 1-3)."""

from __future__ import annotations

import numpy as np
import pytest

from controller.measurement import (
    NoiseParams,
    fuse_covariances,
    paper_trace_m2,
    sample_detection,
    spherical_covariance,
)

NOISE = NoiseParams()  # 10 % range, 1 degree bearing and inclination
PERSON = np.array([2.0, -3.0, 0.9])
# a MAV of the formation: 8 m out at 30 degrees, 8 m above the person (range 11.3 m, looking 45 degrees down)
CAMERA = PERSON + np.array([8.0 * np.cos(np.pi / 6), 8.0 * np.sin(np.pi / 6), 8.0])


def _cov(camera, target, noise=NOISE) -> np.ndarray:
    return spherical_covariance(camera_position_m=camera, target_position_m=target, noise=noise)


def _samples(rng, n, *, camera=CAMERA, target=PERSON, noise=NOISE):
    draws = [
        sample_detection(rng, camera_position_m=camera, target_position_m=target, noise=noise)
        for _ in range(n)
    ]
    return np.array([d[0] for d in draws]), np.array([d[1] for d in draws])


def test_covariance_is_symmetric_positive_definite_over_random_geometries():
    rng = np.random.default_rng(0)
    offsets = np.vstack(
        [
            rng.normal(scale=20.0, size=(500, 3)),
            [[0.0, 0.0, 0.0], [0.0, 0.0, -9.0], [0.0, 0.0, 9.0], [1e4, 0.0, 0.0]],
        ]
    )
    for offset in offsets:
        cov = _cov(np.zeros(3), offset)
        np.testing.assert_array_equal(cov, cov.T)
        assert np.linalg.eigvalsh(cov).min() > 0.0


@pytest.mark.parametrize("range_m", [5.0, 11.3, 30.0])
def test_level_view_trace_is_kappa_r_squared(range_m):
    """Paper eq. 3 under its assumptions (bearing 0, inclination pi/2): the exact trace is
    (C1 + exp(C2 + C3) - 1) r^2, within 2e-5 relative of kappa r^2 for 1-degree angles; tolerance 1e-4."""
    cov = _cov([-range_m, 0.0, 0.0], [0.0, 0.0, 0.0])
    kappa = 0.1**2 + 2 * np.deg2rad(1.0) ** 2
    assert np.trace(cov) == pytest.approx(kappa * range_m**2, rel=1e-4)
    assert paper_trace_m2(range_m=range_m, noise=NOISE) == pytest.approx(kappa * range_m**2, rel=1e-12)


def test_level_view_covariance_is_diagonal_with_c1_c2_c3_r_squared():
    """Paper eq. 2: no cross terms in the camera's range/cross/up axes; diagonal close to (C1, C2, C3) r^2
    (within 1.1 %: the cross-range terms carry E[r^2] = r^2 (1 + C1))."""
    r = 11.3
    cov = _cov([-r, 0.0, 0.0], [0.0, 0.0, 0.0])
    np.testing.assert_allclose(cov[~np.eye(3, dtype=bool)], 0.0, atol=1e-12)
    np.testing.assert_allclose(
        np.diag(cov) / r**2, [0.01, np.deg2rad(1.0) ** 2, np.deg2rad(1.0) ** 2], rtol=0.011
    )


def test_range_direction_variance_grows_as_range_squared():
    direction = (PERSON - CAMERA) / np.linalg.norm(PERSON - CAMERA)
    per_r2 = []
    for r in (2.0, 8.0, 32.0, 128.0):
        cov = _cov(PERSON - r * direction, PERSON)
        per_r2.append(direction @ cov @ direction / r**2)
    np.testing.assert_allclose(per_r2, per_r2[0], rtol=1e-6)
    assert per_r2[0] == pytest.approx(0.1**2, rel=0.01)


def test_horizontal_cross_range_standard_deviation_is_bearing_sigma_times_horizontal_range():
    """Bearing is an azimuth about the vertical: looking 45 degrees down, sigma = sigma_a r cos 45."""
    direction = (PERSON - CAMERA) / np.linalg.norm(PERSON - CAMERA)
    horizontal_cross = np.array([-direction[1], direction[0], 0.0]) / np.hypot(direction[0], direction[1])
    for r in (4.0, 40.0):
        cov = _cov(PERSON - r * direction, PERSON)
        sigma = np.sqrt(horizontal_cross @ cov @ horizontal_cross)
        assert sigma == pytest.approx(np.deg2rad(1.0) * r * np.cos(np.pi / 4), rel=0.01)


def test_sampled_detections_have_the_spherical_covariance():
    """Monte Carlo, 20000 seeded samples: every element within 10 % of sqrt(C_ii C_jj)."""
    positions, _ = _samples(np.random.default_rng(1), 20000)
    sample = np.cov(positions.T)
    model = _cov(CAMERA, PERSON)
    scale = np.sqrt(np.outer(np.diag(model), np.diag(model)))
    assert np.max(np.abs(sample - model) / scale) < 0.10


def test_sampled_detections_are_unbiased_within_one_percent_of_range():
    positions, _ = _samples(np.random.default_rng(2), 20000)
    bias = np.linalg.norm(positions.mean(axis=0) - PERSON)
    assert bias < 0.01 * np.linalg.norm(CAMERA - PERSON)


def test_debiasing_keeps_large_angle_noise_unbiased():
    """With 15/10 degree angle noise a plain conversion would be off by 3.6 % of the range (cos bias);
    the unbiased conversion stays within 1 %."""
    noise = NoiseParams(
        range_sigma_fraction=0.1, bearing_sigma_rad=np.deg2rad(15.0), inclination_sigma_rad=np.deg2rad(10.0)
    )
    positions, _ = _samples(np.random.default_rng(3), 20000, noise=noise)
    bias = np.linalg.norm(positions.mean(axis=0) - PERSON)
    assert bias < 0.01 * np.linalg.norm(CAMERA - PERSON)


def test_sampled_covariance_is_evaluated_at_the_measured_point():
    """A real system only knows the measured range: a detection measured short reports a smaller range
    variance, scaling as the measured range squared."""
    positions, covs = _samples(np.random.default_rng(4), 200)
    direction = (PERSON - CAMERA) / np.linalg.norm(PERSON - CAMERA)
    measured_range = (positions - CAMERA) @ direction
    range_variance = np.einsum("i,nij,j->n", direction, covs, direction)
    ratio = range_variance / measured_range**2
    assert np.ptp(measured_range) > 2.0
    np.testing.assert_allclose(ratio, 0.01, rtol=0.02)


def test_normalised_errors_of_sampled_detections_average_three():
    """The reported (measured-point) covariance describes the error: mean NEES of 20000 samples is 3, +-5 %
    (measured 3.12: short-measured ranges report a smaller variance)."""
    positions, covs = _samples(np.random.default_rng(5), 20000)
    errors = positions - PERSON
    nees = np.einsum("ni,nij,nj->n", errors, np.linalg.inv(covs), errors)
    assert nees.mean() == pytest.approx(3.0, rel=0.05)


def test_same_seed_gives_same_detections():
    a = _samples(np.random.default_rng(6), 5)
    b = _samples(np.random.default_rng(6), 5)
    np.testing.assert_array_equal(a[0], b[0])
    np.testing.assert_array_equal(a[1], b[1])


def test_non_finite_geometry_is_rejected_with_a_clear_error():
    with pytest.raises(ValueError, match="camera_position_m"):
        _cov([np.nan, 0.0, 0.0], PERSON)
    with pytest.raises(ValueError, match="target_position_m"):
        sample_detection(
            np.random.default_rng(0), camera_position_m=CAMERA, target_position_m=[1.0, 2.0], noise=NOISE
        )


def test_negative_noise_parameter_is_rejected():
    with pytest.raises(ValueError, match="bearing_sigma_rad"):
        NoiseParams(bearing_sigma_rad=-0.1)


# ---------------------------------------------------------------- fusion


def _random_spd(rng) -> np.ndarray:
    a = rng.normal(size=(3, 3))
    return a @ a.T + 0.1 * np.eye(3)


def test_fusion_equals_smith_cheeseman_recursive_merging():
    rng = np.random.default_rng(7)
    covs = [_random_spd(rng) for _ in range(4)]
    merged = covs[0]
    for c in covs[1:]:
        merged = merged - merged @ np.linalg.inv(merged + c) @ merged
    np.testing.assert_allclose(fuse_covariances(covs), merged, rtol=1e-9, atol=1e-12)


def test_fusing_k_equal_covariances_divides_by_k():
    cov = _cov(CAMERA, PERSON)
    np.testing.assert_allclose(fuse_covariances([cov] * 5), cov / 5, rtol=1e-10)


def test_fused_covariance_is_symmetric_and_no_larger_than_any_input():
    rng = np.random.default_rng(8)
    covs = [_random_spd(rng) for _ in range(3)]
    fused = fuse_covariances(covs)
    np.testing.assert_array_equal(fused, fused.T)
    for c in covs:
        assert np.linalg.eigvalsh(c - fused).min() > -1e-12


@pytest.mark.parametrize(
    "covs",
    [
        [],
        [np.diag([1.0, -1.0, 1.0])],
        [np.eye(3), np.full((3, 3), np.nan)],
        [np.ones((2, 2))],
        [np.array([[1.0, 0.5, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])],
    ],
    ids=["empty", "indefinite", "nan", "wrong-shape", "asymmetric"],
)
def test_fusion_rejects_bad_input_with_value_error(covs):
    with pytest.raises(ValueError):
        fuse_covariances(covs)

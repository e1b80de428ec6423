"""Geometry behind the 3-D view: covariance ellipsoids, ground picks, frustum and body orientations."""

from __future__ import annotations

import numpy as np
import pytest
from viser import transforms as tf

from webui.geometry import (
    box_segments,
    camera_wxyz,
    circle_segments,
    ellipsoid_pose,
    ground_point,
    polyline_segments,
    yaw_wxyz,
)


def rotation(wxyz: np.ndarray) -> np.ndarray:
    return tf.SO3(np.asarray(wxyz)).as_matrix()


def test_ellipsoid_of_a_diagonal_covariance_has_sigma_scaled_standard_deviations():
    axes, _ = ellipsoid_pose(np.diag([4.0, 1.0, 0.25]), sigma=2.0)
    assert sorted(axes) == pytest.approx([1.0, 2.0, 4.0])


def test_ellipsoid_pose_reconstructs_a_rotated_covariance():
    rng = np.random.default_rng(7)
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    cov = q @ np.diag([3.0, 0.5, 0.1]) @ q.T
    axes, wxyz = ellipsoid_pose(cov, sigma=2.0)
    r = rotation(wxyz)
    assert np.linalg.det(r) == pytest.approx(1.0)
    assert r @ np.diag((axes / 2.0) ** 2) @ r.T == pytest.approx(cov, abs=1e-9)


def test_ellipsoid_of_a_slightly_negative_covariance_clips_to_zero():
    axes, _ = ellipsoid_pose(np.diag([1.0, 1.0, -1e-12]), sigma=2.0)
    assert min(axes) == pytest.approx(0.0)


def test_non_finite_covariance_is_refused():
    with pytest.raises(ValueError, match="finite"):
        ellipsoid_pose(np.full((3, 3), np.nan), sigma=2.0)


def test_downward_ray_hits_the_ground_where_expected():
    assert ground_point(np.array([0.0, -10.0, 10.0]), np.array([0.5, 1.0, -1.0])) == pytest.approx([5.0, 0.0])


@pytest.mark.parametrize("direction", [[1.0, 0.0, 0.0], [0.0, 1.0, 0.3]])
def test_level_or_upward_ray_misses_the_ground(direction):
    assert ground_point(np.array([0.0, 0.0, 10.0]), np.array(direction)) is None


def test_ray_from_below_the_ground_pointing_down_misses():
    assert ground_point(np.array([0.0, 0.0, -1.0]), np.array([0.0, 0.0, -1.0])) is None


def test_yaw_rotates_the_body_x_axis_counter_clockwise_from_east():
    assert rotation(yaw_wxyz(np.pi / 2.0)) @ [1.0, 0.0, 0.0] == pytest.approx([0.0, 1.0, 0.0], abs=1e-12)


def test_camera_looks_forward_and_45_degrees_down_with_image_right_to_starboard():
    r = rotation(camera_wxyz(np.deg2rad(45.0)))
    s = np.sqrt(0.5)
    assert r @ [0.0, 0.0, 1.0] == pytest.approx([s, 0.0, -s], abs=1e-12)
    assert r @ [1.0, 0.0, 0.0] == pytest.approx([0.0, -1.0, 0.0], abs=1e-12)


def test_circle_segments_lie_on_the_circle_and_close():
    segments = circle_segments(np.array([1.0, 2.0, 9.0]), 8.0, count=36)
    assert segments.shape == (36, 2, 3)
    assert np.linalg.norm(segments[:, :, :2] - [1.0, 2.0], axis=2) == pytest.approx(np.full((36, 2), 8.0))
    assert segments[:, :, 2] == pytest.approx(np.full((36, 2), 9.0))
    assert segments[-1, 1] == pytest.approx(segments[0, 0])


def test_polyline_of_one_point_has_no_segments():
    assert polyline_segments(np.zeros((1, 3))).shape == (0, 2, 3)


def test_arena_outline_has_four_sides_at_ground_level():
    segments = box_segments(np.array([-20.0, -20.0, 3.0]), np.array([20.0, 20.0, 10.0]))
    assert segments.shape == (4, 2, 3)
    assert np.abs(segments[:, :, :2]).max() == pytest.approx(20.0)
    assert segments[:, :, 2] == pytest.approx(np.zeros((4, 2)))

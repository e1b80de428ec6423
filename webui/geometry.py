"""Pure geometry for drawing the scene: ellipsoid poses, ground picks, orientations, line segments, colours.

Quaternions are (w, x, y, z) as viser expects; every rotation maps a node's local frame into its parent frame.
"""

from __future__ import annotations

import numpy as np
from viser import transforms as tf

# One colour per MAV, 16 of them (cycled beyond): distinct on a light background, and none of them the red of
# virtual obstacles, the brown of trees, the greys and black of the person, or the amber of the ellipsoid.
VEHICLE_COLORS: tuple[tuple[int, int, int], ...] = (
    (31, 119, 180),  # blue
    (255, 127, 14),  # orange
    (44, 160, 44),  # green
    (148, 103, 189),  # purple
    (23, 190, 207),  # cyan
    (227, 119, 194),  # pink
    (188, 189, 34),  # olive
    (31, 60, 130),  # navy
    (174, 199, 232),  # light blue
    (255, 187, 120),  # light orange
    (152, 223, 138),  # light green
    (197, 176, 213),  # light purple
    (158, 218, 229),  # light cyan
    (247, 182, 210),  # light pink
    (219, 219, 141),  # light olive
    (0, 128, 128),  # teal
)


def vehicle_color(vehicle_id: int) -> tuple[int, int, int]:
    """The colour of MAV `vehicle_id` (body, frustum, horizon plan, its row in the team table and its plot
    lines): MAV 1 has the first colour, MAV 16 the sixteenth."""
    return VEHICLE_COLORS[(vehicle_id - 1) % len(VEHICLE_COLORS)]


def ellipsoid_pose(cov_m2: np.ndarray, *, sigma: float) -> tuple[np.ndarray, np.ndarray]:
    """Semi-axes (3,) in metres and orientation wxyz (4,) of the `sigma`-sigma ellipsoid of a (3, 3)
    covariance.

    A unit sphere scaled by the semi-axes and rotated by wxyz is the set {x : x^T cov^-1 x = sigma^2}: the
    semi-axes are sigma * sqrt(eigenvalues) along the eigenvectors. The covariance is symmetrised and
    negative eigenvalues (round-off) clipped to zero; a non-finite covariance raises ValueError.
    """
    cov = np.asarray(cov_m2, dtype=float)
    if cov.shape != (3, 3) or not np.all(np.isfinite(cov)):
        raise ValueError(f"covariance must be a finite (3, 3) array, got shape {cov.shape}")
    eigenvalues, eigenvectors = np.linalg.eigh(0.5 * (cov + cov.T))
    if np.linalg.det(eigenvectors) < 0.0:
        eigenvectors[:, 2] = -eigenvectors[:, 2]
    semi_axes = sigma * np.sqrt(np.clip(eigenvalues, 0.0, None))
    return semi_axes, tf.SO3.from_matrix(eigenvectors).wxyz


def ground_point(origin: np.ndarray, direction: np.ndarray, *, height_m: float = 0.0) -> np.ndarray | None:
    """(2,) x, y where the ray origin + t * direction (t > 0) meets the plane z = height_m, or None if it
    never does (pointing level or upwards, or starting below the plane and pointing down)."""
    o = np.asarray(origin, dtype=float)
    d = np.asarray(direction, dtype=float)
    if not (np.all(np.isfinite(o)) and np.all(np.isfinite(d))) or abs(d[2]) < 1e-9:
        return None
    t = (height_m - o[2]) / d[2]
    if t <= 0.0:
        return None
    return (o + t * d)[:2]


def yaw_wxyz(yaw_rad: float) -> np.ndarray:
    """(4,) rotation about +z by the ENU yaw (0 = facing east, counter-clockwise positive)."""
    return np.array([np.cos(yaw_rad / 2.0), 0.0, 0.0, np.sin(yaw_rad / 2.0)])


def camera_wxyz(pitch_down_rad: float) -> np.ndarray:
    """(4,) rotation of a camera frustum in the body frame (x forward, y left, z up).

    viser draws a frustum looking along its local +z with +x right and +y down in the image (OpenCV); the
    camera looks along the body x axis pitched down by pitch_down_rad, image right is body -y.
    """
    c, s = np.cos(pitch_down_rad), np.sin(pitch_down_rad)
    forward = np.array([c, 0.0, -s])
    right = np.array([0.0, -1.0, 0.0])
    down = np.cross(forward, right)
    return tf.SO3.from_matrix(np.column_stack([right, down, forward])).wxyz


def polyline_segments(points_m: np.ndarray) -> np.ndarray:
    """(M-1, 2, 3) consecutive segments of an (M, 3) polyline (empty (0, 2, 3) for M < 2)."""
    p = np.asarray(points_m, dtype=float).reshape(-1, 3)
    if len(p) < 2:
        return np.zeros((0, 2, 3))
    return np.stack([p[:-1], p[1:]], axis=1)


def circle_segments(center_m: np.ndarray, radius_m: float, *, count: int = 72) -> np.ndarray:
    """(count, 2, 3) segments of a horizontal circle of radius_m about center_m (3,), closed."""
    angles = np.linspace(0.0, 2.0 * np.pi, count + 1)
    c = np.asarray(center_m, dtype=float)
    ring = c + radius_m * np.stack([np.cos(angles), np.sin(angles), np.zeros_like(angles)], axis=1)
    return polyline_segments(ring)


def box_segments(low_m: np.ndarray, high_m: np.ndarray) -> np.ndarray:
    """(4, 2, 3) the rectangle outline of the box [low, high] at z = 0 (the arena's footprint)."""
    (x0, y0), (x1, y1) = np.asarray(low_m, dtype=float)[:2], np.asarray(high_m, dtype=float)[:2]
    corners = np.array([[x0, y0, 0.0], [x1, y0, 0.0], [x1, y1, 0.0], [x0, y1, 0.0], [x0, y0, 0.0]])
    return polyline_segments(corners)


def ellipse_outline_segments(
    center_m: np.ndarray, semi_axes_m: np.ndarray, wxyz: np.ndarray, *, count: int = 48
) -> np.ndarray:
    """(3 * count, 2, 3) the three principal ellipses of an ellipsoid (semi-axes (3,) along the columns of the
    rotation wxyz (4,), centred at center_m (3,)): its outline, drawn on top of the transparent fill."""
    rotation = tf.SO3(np.asarray(wxyz, dtype=float)).as_matrix()
    a = np.asarray(semi_axes_m, dtype=float)
    angles = np.linspace(0.0, 2.0 * np.pi, count + 1)
    c, s = np.cos(angles), np.sin(angles)
    rings = []
    for i, j in ((0, 1), (1, 2), (0, 2)):
        local = np.zeros((count + 1, 3))
        local[:, i] = a[i] * c
        local[:, j] = a[j] * s
        rings.append(polyline_segments(np.asarray(center_m, dtype=float) + local @ rotation.T))
    return np.concatenate(rings)


def north_arrow_segments(base_m: np.ndarray, length_m: float) -> np.ndarray:
    """(3, 2, 3) an arrow on the ground from base_m (3,) pointing north (+y): shaft and two barbs."""
    b = np.asarray(base_m, dtype=float)
    tip = b + np.array([0.0, length_m, 0.0])
    barb = 0.3 * length_m
    return np.array(
        [
            [b, tip],
            [tip, tip + np.array([-0.5 * barb, -barb, 0.0])],
            [tip, tip + np.array([0.5 * barb, -barb, 0.0])],
        ]
    )

"""A compiled Kalman filter with filterpy's equations, for the person tracker's state measured in position.

filterpy's `KalmanFilter` is the tracker's filter of record (tracker.py). Each of its predicts and updates
makes a dozen numpy calls on 3x3 and 6x6 arrays, and at K = 16 they are most of the tracker's cost: numpy's
per-call overhead, not arithmetic. `CompiledKalman` computes the same equations, for the tracker's x (6, 1)
= [p, v] and H = [I 0] (the position is measured), in one compiled call each:

    predict:  x = F x,  P = F P F^T + Q
    update:   y = z - H x,  S = H P H^T + R,  K = P H^T S^-1,  x = x + K y,
              P = (I - K H) P (I - K H)^T + K R K^T   (Joseph form, as filterpy)

Only round-off differs from filterpy: S^-1 by the adjugate instead of LAPACK, and products summed in index
order instead of by BLAS (tests/controller/test_kalman.py holds the two together). It is selected by
`TrackerParams.kalman_filter = "compiled"`; filterpy stays the default, so every seeded report stays as
flown.
"""

from __future__ import annotations

import numba
import numpy as np


class CompiledKalman:
    """The part of filterpy's `KalmanFilter(dim_x=6, dim_z=3)` the tracker uses, with H = [I 0]: the state
    x (6, 1) and covariance P (6, 6) as attributes (set by the tracker to start or restore a track; each
    predict and update replaces them with new arrays, as filterpy does), predict(F=, Q=) and update(z, R=)."""

    def __init__(self) -> None:
        self.x = np.zeros((6, 1))
        self.P = np.eye(6)

    def predict(self, *, F: np.ndarray, Q: np.ndarray) -> None:
        """Move the state over one step: F (6, 6) the transition, Q (6, 6) its process noise."""
        self.x, self.P = predicted(F, Q, self.x, self.P)

    def update(self, z: np.ndarray, *, R: np.ndarray) -> None:
        """Fuse a position z (3, 1) measured with covariance R (3, 3), symmetric positive definite (the
        tracker checks every detection's R), so that S = P[:3, :3] + R is invertible."""
        self.x, self.P = updated(z, R, self.x, self.P)


@numba.njit(cache=True)
def innovation_upper(P, R):  # pragma: no cover - compiled
    """(a, b, c, d, e, f): the upper triangle of the innovation covariance S = H P H^T + R = P[:3, :3] + R
    (S = [[a, b, c], [b, d, e], [c, e, f]]), for the update and for the tracker's gate."""
    return (
        P[0, 0] + R[0, 0],
        P[0, 1] + R[0, 1],
        P[0, 2] + R[0, 2],
        P[1, 1] + R[1, 1],
        P[1, 2] + R[1, 2],
        P[2, 2] + R[2, 2],
    )


@numba.njit(cache=True)
def symmetric_adjugate(a, b, c, d, e, f):  # pragma: no cover - compiled
    """(aa, ab, ac, bb, bc, cc, det): the upper triangle of the adjugate of the symmetric S = [[a, b, c],
    [b, d, e], [c, e, f]] and its determinant, on plain floats (S^-1 = adj / det): the update's gain and the
    tracker's gate (tracker._mahalanobis_sq) both invert S this way."""
    aa, ab, ac = d * f - e * e, c * e - b * f, b * e - c * d
    det = a * aa + b * ab + c * ac
    return aa, ab, ac, a * f - c * c, b * c - a * e, a * d - b * b, det


@numba.njit(cache=True)
def predicted(F, Q, x, P):  # pragma: no cover - compiled; tested against filterpy
    """(F x (6, 1), F P F^T + Q (6, 6)) as new arrays."""
    x_new = np.zeros((6, 1))
    fp = np.zeros((6, 6))
    for i in range(6):
        for k in range(6):
            x_new[i, 0] += F[i, k] * x[k, 0]
            for j in range(6):
                fp[i, j] += F[i, k] * P[k, j]
    p_new = np.empty((6, 6))
    for i in range(6):
        for j in range(6):
            acc = 0.0
            for k in range(6):
                acc += fp[i, k] * F[j, k]
            p_new[i, j] = acc + Q[i, j]
    return x_new, p_new


@numba.njit(cache=True)
def updated(z, R, x, P):  # pragma: no cover - compiled; tested against filterpy
    """(x, P) after fusing the position z (3, 1) measured with covariance R (3, 3), as new arrays (module
    docstring)."""
    # S = P[:3, :3] + R and its inverse by the adjugate (S symmetric positive definite)
    aa, ab, ac, bb, bc, cc, det = symmetric_adjugate(*innovation_upper(P, R))
    adj = np.empty((3, 3))
    adj[0, 0], adj[0, 1], adj[0, 2] = aa, ab, ac
    adj[1, 0], adj[1, 1], adj[1, 2] = ab, bb, bc
    adj[2, 0], adj[2, 1], adj[2, 2] = ac, bc, cc
    # K = P H^T S^-1 = P[:, :3] S^-1 (6, 3)
    gain = np.zeros((6, 3))
    for i in range(6):
        for j in range(3):
            for k in range(3):
                gain[i, j] += P[i, k] * adj[k, j]
            gain[i, j] /= det
    x_new = np.empty((6, 1))
    for i in range(6):
        acc = 0.0
        for k in range(3):
            acc += gain[i, k] * (z[k, 0] - x[k, 0])
        x_new[i, 0] = x[i, 0] + acc
    # I - K H: the identity less K in the position columns
    i_kh = np.eye(6)
    for i in range(6):
        for k in range(3):
            i_kh[i, k] -= gain[i, k]
    ap = np.zeros((6, 6))  # (I - K H) P
    kr = np.zeros((6, 3))  # K R
    for i in range(6):
        for k in range(6):
            for j in range(6):
                ap[i, j] += i_kh[i, k] * P[k, j]
        for k in range(3):
            for j in range(3):
                kr[i, j] += gain[i, k] * R[k, j]
    p_new = np.empty((6, 6))
    for i in range(6):
        for j in range(6):
            joseph, noise = 0.0, 0.0
            for k in range(6):
                joseph += ap[i, k] * i_kh[j, k]
            for k in range(3):
                noise += kr[i, k] * gain[j, k]
            p_new[i, j] = joseph + noise
    return x_new, p_new

"""The compiled Kalman filter (controller/kalman.py) against filterpy, the tracker's filter of record: the
same predict and update on 1000 random instances each, to round-off."""

from __future__ import annotations

import numpy as np
import pytest
from filterpy.kalman import KalmanFilter

from controller.kalman import CompiledKalman
from controller.tracker import TrackerParams, _kalman_filter, transition

INSTANCES = 1000
RTOL = 1e-12  # relative to the largest entry of the compared array (measured: at most 4.4e-14)


def _spd(rng: np.random.Generator, n: int, scale: float) -> np.ndarray:
    """A random symmetric positive definite (n, n) matrix whose eigenvalues span about 1e-3 to 1 of scale."""
    q, _ = np.linalg.qr(rng.standard_normal((n, n)))
    return scale * (q * np.logspace(-3, 0, n)[rng.permutation(n)]) @ q.T


def _instance(rng: np.random.Generator):
    """(x (6, 1), P (6, 6)) of a track: a position tens of metres out, a walking speed, covariances from
    centimetres to metres."""
    x = np.vstack([rng.uniform(-50.0, 50.0, (3, 1)), rng.uniform(-3.0, 3.0, (3, 1))])
    return x, _spd(rng, 6, 10.0 ** rng.uniform(-3.0, 1.0))


def _started(kind: str, x: np.ndarray, P: np.ndarray):
    """The tracker's filter of `kind` (tracker._kalman_filter) holding x (6, 1), P (6, 6): filterpy's own
    KalmanFilter for "filterpy", so the reference is never the code under test."""
    kf = _kalman_filter(kind)
    assert type(kf) is {"filterpy": KalmanFilter, "compiled": CompiledKalman}[kind]
    kf.x, kf.P = x.copy(), P.copy()
    return kf


def _worst(ours: np.ndarray, reference: np.ndarray) -> float:
    """max |ours - reference| relative to reference's largest entry."""
    return float(np.abs(ours - reference).max() / np.abs(reference).max())


def test_predict_is_filterpys_on_1000_random_steps():
    rng = np.random.default_rng(11)
    params = TrackerParams()
    worst_x = worst_p = 0.0
    for _ in range(INSTANCES):
        x, P = _instance(rng)
        F, Q = transition(dt_s=float(rng.uniform(1e-3, 2.0)), params=params)
        reference, ours = _started("filterpy", x, P), _started("compiled", x, P)
        reference.predict(F=F, Q=Q)
        ours.predict(F=F, Q=Q)
        worst_x = max(worst_x, _worst(ours.x, reference.x))
        worst_p = max(worst_p, _worst(ours.P, reference.P))
    assert worst_x < RTOL
    assert worst_p < RTOL


def test_update_is_filterpys_on_1000_random_detections():
    rng = np.random.default_rng(12)
    worst_x = worst_p = 0.0
    for _ in range(INSTANCES):
        x, P = _instance(rng)
        z = x[:3] + rng.normal(0.0, 1.0, (3, 1))
        R = _spd(rng, 3, 10.0 ** rng.uniform(-2.0, 1.0))
        reference, ours = _started("filterpy", x, P), _started("compiled", x, P)
        reference.update(z, R=R)
        ours.update(z, R=R)
        worst_x = max(worst_x, _worst(ours.x, reference.x))
        worst_p = max(worst_p, _worst(ours.P, reference.P))
    assert worst_x < RTOL
    assert worst_p < RTOL


def test_predict_and_update_replace_the_state_arrays_as_filterpy_does():
    """The tracker keeps the arrays it had before a step to restore them (a gated detection, a late one):
    a step must not write into them."""
    kf = _started("compiled", np.ones((6, 1)), np.eye(6))
    x_before, P_before = kf.x, kf.P
    F, Q = transition(dt_s=0.1, params=TrackerParams())
    kf.predict(F=F, Q=Q)
    kf.update(np.zeros((3, 1)), R=np.eye(3))
    assert kf.x is not x_before and kf.P is not P_before
    np.testing.assert_array_equal(x_before, np.ones((6, 1)))
    np.testing.assert_array_equal(P_before, np.eye(6))


@pytest.mark.parametrize("scale", [1e-6, 1e6])
def test_update_holds_at_extreme_covariance_scales(scale):
    """Centimetre-sure and kilometre-vague tracks alike: the adjugate's products reach scale^3 without
    losing the answer."""
    rng = np.random.default_rng(13)
    x, P = _instance(rng)
    P = P / np.abs(P).max() * scale
    R = _spd(rng, 3, scale)
    z = x[:3] + 0.1
    reference, ours = _started("filterpy", x, P), _started("compiled", x, P)
    reference.update(z, R=R)
    ours.update(z, R=R)
    assert _worst(ours.x, reference.x) < RTOL
    assert _worst(ours.P, reference.P) < RTOL

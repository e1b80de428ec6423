"""Specification of the person tracker (controller/tracker.py): motion model, consistency on a walking person,
out-of-order merging, gating, invalid input and expiry."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from filterpy.kalman import KalmanFilter
from scipy import stats

from controller.measurement import NoiseParams, sample_detection
from controller.messages import Detection, PersonEstimate
from controller.tracker import (
    PersonTracker,
    TrackerParams,
    Verdict,
    _gate_distance_sq,
    _inverse,
    _kalman_filter,
    _mahalanobis_sq,
    transition,
)

RUNS = 20
GRID_S = np.arange(10.0, 119.0, 5.0)  # 22 evaluation times after a 10 s burn-in, 5 s apart
DETECTION_RATE_HZ = 4.0
NOISE = NoiseParams()


def _walk(
    rng: np.random.Generator, *, duration_s: float = 120.0, dt_s: float = 0.02, speed_mps: float = 1.0
) -> tuple[np.ndarray, np.ndarray]:
    """(t (n,), p (n, 3)): a person walking at speed_mps with a gently wandering heading (turn rate: an
    Ornstein-Uhlenbeck process, 5 s correlation time, about 0.08 rad/s standard deviation) across gently
    undulating ground (+-0.6 m over tens of metres, slopes below 10 %); body centre 0.9 m above the ground."""
    n = int(round(duration_s / dt_s)) + 1
    heading = np.empty(n)
    heading[0], turn = rng.uniform(-np.pi, np.pi), 0.0
    kicks = 0.05 * np.sqrt(dt_s) * rng.standard_normal(n)
    for i in range(1, n):
        turn += -turn * dt_s / 5.0 + kicks[i]
        heading[i] = heading[i - 1] + turn * dt_s
    p = np.zeros((n, 3))
    p[:, 2] = 0.9
    p[1:, 0] = np.cumsum(speed_mps * np.cos(heading[:-1]) * dt_s)
    p[1:, 1] = np.cumsum(speed_mps * np.sin(heading[:-1]) * dt_s)
    p[:, 2] += 0.6 * np.sin(2 * np.pi * p[:, 0] / 40.0) * np.cos(2 * np.pi * p[:, 1] / 50.0)
    return np.arange(n) * dt_s, p


def _at(t: np.ndarray, p: np.ndarray, s: float) -> np.ndarray:
    return np.array([np.interp(s, t, p[:, i]) for i in range(3)])


def _detections(seed: int, *, n_mavs: int = 3, duration_s: float = 120.0):
    """(walk t, walk p, detections in stamp order): n_mavs MAVs 8 m out and 8 m up (11.3 m range), spread
    evenly and circling slowly, each detecting at 4 Hz (staggered) with sample_detection noise."""
    rng = np.random.default_rng(seed)
    t, p = _walk(rng, duration_s=duration_s)
    events = sorted(
        (k / (n_mavs * DETECTION_RATE_HZ) + n / DETECTION_RATE_HZ, k)
        for k in range(n_mavs)
        for n in range(int(duration_s * DETECTION_RATE_HZ))
    )
    detections = []
    for stamp, k in events:
        if stamp > t[-1]:
            continue
        person = _at(t, p, stamp)
        angle = 2 * np.pi * k / n_mavs + 0.02 * stamp
        camera = person + np.array([8.0 * np.cos(angle), 8.0 * np.sin(angle), 8.0])
        z, cov = sample_detection(rng, camera_position_m=camera, target_position_m=person, noise=NOISE)
        detections.append(Detection(source_id=k, stamp_s=stamp, position_m=z, cov_m2=cov))
    return t, p, detections


def _track_errors(t, p, detections) -> tuple[np.ndarray, np.ndarray]:
    """(errors (T, 3), covariances (T, 3, 3)) of the position estimate at the GRID_S times."""
    tracker = PersonTracker(TrackerParams())
    errors, covs, g = [], [], 0
    for det in detections:
        while g < len(GRID_S) and GRID_S[g] < det.stamp_s:
            est = tracker.estimate(GRID_S[g])
            assert est is not None
            errors.append(est.position_m - _at(t, p, GRID_S[g]))
            covs.append(est.position_cov_m2)
            g += 1
        tracker.update(det)
    return np.array(errors), np.array(covs)


@pytest.fixture(scope="module")
def walking_runs():
    """Per run: fused errors (T, 3), NEES (T,), and the errors of a tracker fed only MAV 0's detections."""
    fused, nees, single = [], [], []
    for seed in range(RUNS):
        t, p, dets = _detections(seed)
        err, cov = _track_errors(t, p, dets)
        fused.append(err)
        nees.append(np.einsum("ti,tij,tj->t", err, np.linalg.inv(cov), err))
        single.append(_track_errors(t, p, [d for d in dets if d.source_id == 0])[0])
    return np.array(fused), np.array(nees), np.array(single)


def _det(stamp: float, pos, cov=None, source: int = 0) -> Detection:
    return Detection(
        source_id=source, stamp_s=stamp, position_m=pos, cov_m2=np.eye(3) * 0.25 if cov is None else cov
    )


def _settled_tracker(seed: int = 7, duration_s: float = 20.0) -> tuple[PersonTracker, list[Detection]]:
    tracker = PersonTracker()
    _, _, dets = _detections(seed, duration_s=duration_s)
    for det in dets:
        tracker.update(det)
    return tracker, dets


def _same_estimate(a, b) -> bool:
    return (
        a.stamp_s == b.stamp_s
        and np.array_equal(a.position_m, b.position_m)
        and np.array_equal(a.velocity_mps, b.velocity_mps)
        and np.array_equal(a.cov, b.cov)
    )


# ---------------------------------------------------------------- motion model


def test_velocity_decays_to_ten_percent_over_three_seconds():
    F, _ = transition(dt_s=3.0, params=TrackerParams())
    np.testing.assert_allclose(np.diag(F)[3:], 0.1, rtol=1e-12)


def test_position_advances_by_integral_of_decaying_velocity():
    params = TrackerParams()
    F, _ = transition(dt_s=3.0, params=params)
    tau = 3.0 / np.log(10.0)
    np.testing.assert_allclose(F[0, 3], tau * 0.9, rtol=1e-12)
    assert F[0, 3] == pytest.approx(1.1725, abs=1e-4)


def test_velocity_variance_grows_by_noise_std_squared_per_second_for_short_steps():
    _, Q = transition(dt_s=1e-4, params=TrackerParams())
    np.testing.assert_allclose(np.diag(Q)[3:] / 1e-4, [0.25, 0.25, 0.01], rtol=1e-3)


def test_process_noise_matches_monte_carlo_of_the_decaying_velocity_model():
    """Q over 1 s equals the covariance of many fine Euler steps of dv = -v/tau dt + sigma dW."""
    params = TrackerParams()
    _, Q = transition(dt_s=1.0, params=params)
    rng = np.random.default_rng(3)
    tau, sigma, steps, n = params.velocity_time_constant_s, 0.5, 1000, 20000
    h = 1.0 / steps
    p = np.zeros(n)
    v = np.zeros(n)
    for _ in range(steps):
        p += v * h
        v += -v / tau * h + sigma * np.sqrt(h) * rng.standard_normal(n)
    sample = np.cov(np.stack([p, v]))
    np.testing.assert_allclose(sample, Q[np.ix_([0, 3], [0, 3])], rtol=0.05)


def test_first_detection_starts_track_at_it_with_initial_covariance():
    tracker = PersonTracker()
    assert tracker.update(_det(5.0, [1.0, 2.0, 0.9])) is Verdict.ACCEPTED
    est = tracker.estimate(5.0)
    assert est is not None
    np.testing.assert_array_equal(est.position_m, [1.0, 2.0, 0.9])
    np.testing.assert_array_equal(est.velocity_mps, 0.0)
    np.testing.assert_array_equal(est.cov, np.diag([100.0, 100.0, 10.0, 1.0, 1.0, 0.5]))


def test_estimate_is_none_before_first_detection():
    assert PersonTracker().estimate(0.0) is None


def test_estimate_does_not_change_the_filter():
    tracker, dets = _settled_tracker(duration_s=5.0)
    quiet, _ = _settled_tracker(duration_s=5.0)
    for now in (4.0, 9.0, 5.3, 14.0):
        tracker.estimate(now)
    nxt = _det(dets[-1].stamp_s + 0.1, dets[-1].position_m, dets[-1].cov_m2, source=1)
    tracker.update(nxt)
    quiet.update(nxt)
    assert _same_estimate(tracker.estimate(6.0), quiet.estimate(6.0))


# ---------------------------------------------------------------- consistency on a walking person


@pytest.mark.slow  # 100 Monte-Carlo runs
def test_average_position_nees_of_walking_person_lies_in_95_percent_chi_square_interval(walking_runs):
    """Statistics: 20 independent runs x 22 times 5 s apart (after 10 s burn-in) = 440 NEES samples. The
    filter's error decorrelates within about a second (see the next test), so the samples are independent and
    under consistency their sum is chi-square with 3 * 440 dof; the mean must lie in [2.775, 3.233]."""
    _, nees, _ = walking_runs
    n = nees.size
    lo, hi = stats.chi2.ppf([0.025, 0.975], 3 * n) / n
    assert (lo, hi) == pytest.approx((2.775, 3.233), abs=1e-3)
    assert lo < nees.mean() < hi


@pytest.mark.slow  # shares the Monte-Carlo runs above
def test_nees_samples_five_seconds_apart_are_uncorrelated(walking_runs):
    """Backs the independence assumption of the previous test: lag-1 correlation of NEES on the 5 s grid."""
    _, nees, _ = walking_runs
    rho = np.corrcoef(nees[:, :-1].ravel(), nees[:, 1:].ravel())[0, 1]
    assert abs(rho) < 0.2


@pytest.mark.slow  # shares the Monte-Carlo runs above
def test_three_mav_fused_track_beats_single_mav_track_on_the_same_data(walking_runs):
    fused, _, single = walking_runs
    rms_fused = np.sqrt(np.mean(np.sum(fused**2, axis=-1)))
    rms_single = np.sqrt(np.mean(np.sum(single**2, axis=-1)))
    assert rms_fused < 0.25
    assert rms_fused < 0.5 * rms_single


# ---------------------------------------------------------------- out-of-order detections


def test_shuffled_detections_within_latency_window_give_same_estimate_as_in_order():
    _, _, dets = _detections(11, duration_s=30.0)
    rng = np.random.default_rng(12)
    arrival = [d.stamp_s + rng.uniform(0.0, 1.0) for d in dets]  # link latency up to 1 s < 20 detections
    shuffled = [dets[i] for i in np.argsort(arrival, kind="stable")]
    in_order, late = PersonTracker(), PersonTracker()
    for det in dets:
        in_order.update(det)
    verdicts = [late.update(det) for det in shuffled]
    assert verdicts.count(Verdict.ACCEPTED) == len(dets)
    assert late.stats().out_of_order > 100
    a, b = in_order.estimate(30.0), late.estimate(30.0)
    assert a is not None and b is not None
    np.testing.assert_allclose(b.position_m, a.position_m, atol=1e-9)
    np.testing.assert_allclose(b.velocity_mps, a.velocity_mps, atol=1e-9)
    np.testing.assert_allclose(b.cov, a.cov, atol=1e-9)


def test_detection_older_than_the_cache_is_stale_and_changes_nothing():
    tracker, dets = _settled_tracker(duration_s=10.0)  # 120 detections, the cache keeps the last 20
    before = tracker.estimate(10.0)
    old = dets[-21]
    verdict = tracker.update(_det(old.stamp_s + 0.01, old.position_m, old.cov_m2, source=5))
    assert verdict is Verdict.STALE
    assert tracker.stats().stale == 1
    assert _same_estimate(tracker.estimate(10.0), before)


def test_detection_inside_the_cache_window_is_merged():
    tracker, dets = _settled_tracker(duration_s=10.0)
    inside = dets[-19]
    assert (
        tracker.update(_det(inside.stamp_s + 0.01, inside.position_m, inside.cov_m2, source=5))
        is Verdict.ACCEPTED
    )
    assert tracker.stats().out_of_order == 1


def test_repeated_detection_is_stale_and_changes_nothing():
    tracker, dets = _settled_tracker(duration_s=10.0)
    before = tracker.estimate(10.0)
    assert tracker.update(dets[-3]) is Verdict.STALE
    assert _same_estimate(tracker.estimate(10.0), before)


# ---------------------------------------------------------------- gating and invalid input


def _offset_detection(tracker: PersonTracker, stamp: float, sigmas: float) -> Detection:
    """A detection sigmas Mahalanobis units from the prediction, along the innovation's widest axis."""
    cov = np.diag([1.0, 0.2, 0.1])
    pred = tracker.estimate(stamp)
    assert pred is not None
    S = pred.position_cov_m2 + cov
    w, V = np.linalg.eigh(S)
    return _det(stamp, pred.position_m + sigmas * np.sqrt(w[-1]) * V[:, -1], cov, source=9)


def test_twenty_sigma_outlier_is_gated_and_estimate_unchanged():
    tracker, dets = _settled_tracker()
    stamp = dets[-1].stamp_s + 0.05
    before = tracker.estimate(stamp + 1.0)
    assert tracker.update(_offset_detection(tracker, stamp, 20.0)) is Verdict.GATED
    assert tracker.stats().gated == 1
    assert _same_estimate(tracker.estimate(stamp + 1.0), before)


def test_gate_lies_between_five_and_a_half_and_six_and_a_half_sigma():
    tracker, dets = _settled_tracker()
    stamp = dets[-1].stamp_s + 0.05
    assert tracker.update(_offset_detection(tracker, stamp, 6.5)) is Verdict.GATED
    assert tracker.update(_offset_detection(tracker, stamp, 5.5)) is Verdict.ACCEPTED


def test_late_outlier_is_gated_against_the_state_at_its_time():
    tracker, dets = _settled_tracker()
    before = tracker.estimate(25.0)
    old = dets[-10]
    far = _det(old.stamp_s + 0.01, old.position_m + np.array([30.0, 0.0, 0.0]), old.cov_m2, source=9)
    assert tracker.update(far) is Verdict.GATED
    assert _same_estimate(tracker.estimate(25.0), before)


def test_compiled_gate_distance_is_the_python_formula_to_the_bit():
    """_gate_distance_sq (one compiled call) against _mahalanobis_sq's Python source on the same S and y, on
    3,000 random gates: well and badly conditioned, indefinite and singular S; and against numpy's solve."""
    rng = np.random.default_rng(3)
    finite = 0
    for i in range(3000):
        a = rng.normal(size=(6, 6)) * rng.uniform(0.01, 10.0)
        P = a @ a.T + rng.uniform(0.0, 1.0) * np.eye(6)
        b = rng.normal(size=(3, 3))
        R = b @ b.T * rng.uniform(1e-6, 5.0)
        if i % 5 == 0:
            R = R - rng.uniform(0.0, 3.0) * np.abs(np.linalg.eigvalsh(P[:3, :3] + R)).max() * np.eye(3)
        if i % 7 == 0:
            R = -P[:3, :3]  # S singular
        x, z = rng.normal(size=(6, 1)) * 10.0, rng.normal(size=(3, 1)) * 10.0
        S, y = (P[:3, :3] + R).tolist(), (z - x[:3]).ravel().tolist()
        want = _mahalanobis_sq.py_func(S[0][0], S[0][1], S[0][2], S[1][1], S[1][2], S[2][2], *y)
        got = _gate_distance_sq(x, P, z, R)
        assert got == want
        if np.isfinite(got):
            finite += 1
            dy = np.asarray(y)
            assert got == pytest.approx(float(dy @ np.linalg.solve(np.asarray(S), dy)), rel=1e-6)
    assert 1500 < finite < 3000


def test_a_detection_shared_by_trackers_is_checked_once_and_fused_by_each():
    """The links hand one Detection object to every teammate; its checked form is shared, read-only."""
    _, _, dets = _detections(5, duration_s=3.0)
    a, b = PersonTracker(), PersonTracker()
    assert [a.update(d) for d in dets] == [b.update(d) for d in dets]
    assert a._cache[-1].z is b._cache[-1].z and not a._cache[-1].z.flags.writeable
    assert not a._cache[-1].R.flags.writeable
    assert _same_estimate(a.estimate(3.0), b.estimate(3.0))


@pytest.mark.parametrize(
    ("position", "cov"),
    [
        ([np.nan, 0.0, 0.9], np.eye(3)),
        ([0.0, np.inf, 0.9], np.eye(3)),
        ([0.0, 0.0, 0.9], np.diag([1.0, np.nan, 1.0])),
        ([0.0, 0.0, 0.9], np.diag([1.0, -1.0, 1.0])),  # not positive definite
        ([0.0, 0.0, 0.9], np.zeros((3, 3))),  # singular
        ([0.0, 0.0, 0.9], np.array([[1.0, 0.5, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])),  # not symmetric
    ],
    ids=["nan-position", "inf-position", "nan-cov", "indefinite-cov", "zero-cov", "asymmetric-cov"],
)
def test_invalid_detection_is_rejected_counted_and_changes_nothing(position, cov):
    tracker, dets = _settled_tracker(duration_s=5.0)
    before = tracker.estimate(6.0)
    assert tracker.update(_det(dets[-1].stamp_s + 0.1, position, cov, source=4)) is Verdict.INVALID
    assert tracker.stats().invalid == 1
    assert _same_estimate(tracker.estimate(6.0), before)


def test_detection_with_nan_stamp_is_invalid():
    tracker = PersonTracker()
    assert tracker.update(_det(float("nan"), [0.0, 0.0, 0.9])) is Verdict.INVALID
    assert tracker.estimate(0.0) is None
    assert tracker.stats().invalid == 1


def test_detection_stamped_after_the_receivers_clock_is_invalid():
    tracker, dets = _settled_tracker(duration_s=5.0)
    before = tracker.estimate(6.0)
    now = dets[-1].stamp_s + 0.1
    assert tracker.update(_det(now + 3600.0, [0.0, 0.0, 0.9], source=4), now_s=now) is Verdict.INVALID
    assert tracker.stats().invalid == 1
    assert _same_estimate(tracker.estimate(6.0), before)
    assert (
        tracker.update(_det(now + 0.4, dets[-1].position_m, dets[-1].cov_m2, source=4), now_s=now)
        is Verdict.ACCEPTED
    )


def test_invalid_detection_does_not_start_a_track():
    tracker = PersonTracker()
    assert tracker.update(_det(1.0, [0.0, 0.0, 0.9], np.diag([1.0, -1.0, 1.0]))) is Verdict.INVALID
    assert tracker.estimate(1.0) is None


# ---------------------------------------------------------------- expiry and reset


def test_estimate_expires_ten_seconds_after_the_last_detection():
    tracker = PersonTracker()
    tracker.update(_det(3.0, [1.0, 1.0, 0.9]))
    assert tracker.estimate(12.99) is not None
    assert tracker.estimate(13.01) is None


def test_next_detection_after_expiry_resets_the_track_at_it():
    tracker, dets = _settled_tracker(duration_s=5.0)
    stamp = dets[-1].stamp_s + 10.5
    assert tracker.update(_det(stamp, [40.0, -3.0, 0.9])) is Verdict.RESET
    est = tracker.estimate(stamp)
    assert est is not None
    np.testing.assert_array_equal(est.position_m, [40.0, -3.0, 0.9])
    np.testing.assert_array_equal(est.cov, np.diag([100.0, 100.0, 10.0, 1.0, 1.0, 0.5]))
    counts = tracker.stats()
    assert (counts.resets, counts.accepted) == (1, len(dets))


def test_stats_count_each_verdict():
    tracker = PersonTracker()
    tracker.update(_det(0.0, [0.0, 0.0, 0.9]))
    tracker.update(_det(0.1, [0.1, 0.0, 0.9], source=1))
    tracker.update(_det(0.2, [np.nan, 0.0, 0.9]))
    tracker.update(_det(0.05, [0.0, 0.0, 0.9], source=2))  # late: merged
    tracker.update(_det(-1.0, [0.0, 0.0, 0.9]))  # before the track began: stale
    tracker.update(_det(0.3, [500.0, 0.0, 0.9]))  # outlier
    tracker.update(_det(20.0, [0.0, 0.0, 0.9]))  # after expiry
    s = tracker.stats()
    assert (s.accepted, s.gated, s.stale, s.invalid, s.resets, s.out_of_order) == (3, 1, 1, 1, 1, 1)


def test_estimate_is_filterpys_prediction_of_the_filter_state():
    """estimate() extrapolates with a compiled kernel; it equals filterpy's own predict of the same state."""
    rng = np.random.default_rng(11)
    params = TrackerParams()
    for _ in range(50):
        tracker = PersonTracker(params)
        a = rng.normal(size=(6, 6))
        tracker._kf.x = rng.normal(size=(6, 1)) * 5.0
        tracker._kf.P = a @ a.T + np.eye(6)
        tracker._t = 1.0
        dt = float(rng.uniform(0.001, 5.0))
        F, Q = transition(dt_s=dt, params=params)
        reference = KalmanFilter(dim_x=6, dim_z=3)
        reference.x, reference.P = tracker._kf.x.copy(), tracker._kf.P.copy()
        reference.predict(F=F, Q=Q)
        x, P = reference.x, reference.P
        est = tracker.estimate(1.0 + dt)
        assert est is not None
        np.testing.assert_allclose(est.position_m, x[:3, 0], rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(est.velocity_mps, x[3:, 0], rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(est.cov, 0.5 * (P + P.T), rtol=1e-12, atol=1e-12)


def test_the_compiled_filter_gives_filterpys_verdicts_and_estimates_with_late_and_outlying_detections():
    """TrackerParams(kalman_filter="compiled") moves the track with controller/kalman.py instead of filterpy:
    every verdict the same and every estimate within round-off, through merges of late detections, gated
    outliers and a reset."""
    _, _, dets = _detections(21, n_mavs=4, duration_s=40.0)
    rng = np.random.default_rng(22)
    outlying = {i: replace(d, position_m=d.position_m + 30.0) for i, d in enumerate(dets) if i % 40 == 7}
    stream = [outlying.get(i, d) for i, d in enumerate(dets)]
    stream += [replace(d, stamp_s=d.stamp_s + 15.0) for d in dets[-20:]]  # after 15 s of silence: a reset
    arrival = [d.stamp_s + rng.uniform(0.0, 0.5) for d in stream]
    shuffled = [stream[i] for i in np.argsort(arrival, kind="stable")]
    reference, compiled = PersonTracker(), PersonTracker(TrackerParams(kalman_filter="compiled"))
    worst = 0.0
    for det in shuffled:
        assert compiled.update(det) is reference.update(det)
        a, b = reference.estimate(det.stamp_s), compiled.estimate(det.stamp_s)
        assert a is not None and b is not None
        worst = max(
            worst,
            *(
                float(np.abs(x - y).max())
                for x, y in ((a.position_m, b.position_m), (a.velocity_mps, b.velocity_mps), (a.cov, b.cov))
            ),
        )
    stats = reference.stats()
    assert compiled.stats() == stats
    assert stats.out_of_order > 50 and stats.gated == len(outlying) and stats.resets == 1
    assert worst < 1e-11  # m, m/s, m^2 (measured: 1.3e-14)


def test_an_unknown_kalman_filter_is_refused_naming_the_choices():
    with pytest.raises(ValueError, match="filterpy.*compiled"):
        TrackerParams(kalman_filter="ukf")


def test_filterpys_inverse_hook_is_numpys_inverse_to_the_bit():
    """filterpy's update inverts S through `_inverse`: numpy's own inverse, bit for bit, on innovation
    covariances from 1e-6 to 1e6 m^2."""
    rng = np.random.default_rng(7)
    kf = _kalman_filter("filterpy")
    assert isinstance(kf, KalmanFilter) and kf.inv is _inverse
    for scale in (1e-6, 1.0, 1e6):
        for _ in range(300):
            a = rng.normal(size=(3, 3))
            s = scale * (a @ a.T + 0.01 * np.eye(3))
            assert np.array_equal(_inverse(s), np.linalg.inv(s))


def test_a_singular_innovation_covariance_raises_as_numpys_inverse_does():
    with pytest.warns(RuntimeWarning), pytest.raises(np.linalg.LinAlgError, match="Singular"):
        _inverse(np.ones((3, 3)))


def test_the_estimates_position_trace_is_numpys_trace_to_the_bit():
    """`position_cov_trace_m2` adds the diagonal itself (the simulator asks it of every MAV every tick): the
    same bits as np.trace over covariances whose entries span 16 orders of magnitude."""
    rng = np.random.default_rng(7)
    for _ in range(2000):
        cov = rng.random((6, 6)) * 10.0 ** rng.integers(-8, 8, (6, 6)).astype(float)
        estimate = PersonEstimate(stamp_s=0.0, position_m=np.zeros(3), velocity_mps=np.zeros(3), cov=cov)
        assert estimate.position_cov_trace_m2 == float(np.trace(cov[:3, :3]))

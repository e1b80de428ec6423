"""The cooperative person tracker (paper Sec. III-B): one MAV's Kalman-filter replica of the person's state.

Every MAV fuses its own and its teammates' world-frame detections, each with its own covariance
(measurement.py), in a linear Kalman filter on x = [p (3), v (3)] (ENU, m and m/s): filterpy's, the filter of
record, unless `TrackerParams.kalman_filter` selects its compiled twin (kalman.py).

Motion model (docs/method.md#person-tracker, from the authors' code): the velocity decays exponentially, to
`velocity_decay_fraction` of itself over `velocity_decay_time_s` (time constant tau = T / ln(1 / fraction),
1.30 s by default), driven by white noise given as a standard deviation per square-root second, sigma_q
(m/s/sqrt(s)): over a short dt the velocity's variance grows by sigma_q^2 dt (spectral density q = sigma_q^2,
m^2/s^3). Read that way the authors' "(0.5, 0.5, 0.1) per second" is consistent (average NEES in its 95 %
interval, tests/controller/test_tracker.py).

Exact discretisation over dt, per axis, with b = exp(-dt / tau):

    F = [[1, tau (1 - b)], [0, b]]
    Q_vv = q tau (1 - b^2) / 2,   Q_pv = q tau^2 [(1 - b) - (1 - b^2) / 2],
    Q_pp = q tau^2 [dt - 2 tau (1 - b) + tau (1 - b^2) / 2].

A new track starts at its first detection with zero velocity and the covariance initial_cov_diag.

Robustness: a detection with non-finite values or a covariance that is not symmetric positive definite is
INVALID; one whose Mahalanobis distance from the prediction exceeds gate_sigma is GATED; neither changes the
filter. Out-of-order detections (link latency) are merged by re-filtering: the tracker keeps the last
`cache_size` accepted detections in time order (ties broken by source id), each with the filter state just
before it was applied. A late detection is gated against the state before the first cached detection that
follows it; if accepted, the filter is restored to that state and the late detection and all later cached ones
are applied again in order (the later ones are not gated again: they were accepted before). A detection older
than the oldest cached one, or one already applied (same source and stamp), is STALE. After reset_after_s
without an accepted detection the track expires and the next detection starts a new one (RESET).
"""

from __future__ import annotations

import bisect
import functools
import math
from dataclasses import dataclass
from enum import StrEnum

import numba
import numpy as np
from filterpy.kalman import KalmanFilter

from controller.kalman import CompiledKalman, innovation_upper, symmetric_adjugate
from controller.messages import Detection, PersonEstimate, read_only

# numpy's LAPACK gufunc behind np.linalg.inv (`_inverse`): a private module, so without it np.linalg.inv
_LAPACK_INVERSE = getattr(getattr(np.linalg, "_umath_linalg", None), "inv", None)

KALMAN_FILTERS = ("filterpy", "compiled")


@dataclass(frozen=True)
class TrackerParams:
    """Motion model, gating and reset of the person tracker (docs/method.md#person-tracker).

    gate_sigma: Mahalanobis distance (3 dof, in sigmas) beyond which a detection is rejected;
    reset_after_s: the track expires after this long without an accepted detection;
    velocity_decay_fraction, velocity_decay_time_s: the velocity decays to this fraction of itself in this
    time;
    velocity_noise_mps_per_sqrt_s: (3,) white-noise standard deviation on the velocity per sqrt(second)
    (the velocity's variance grows by its square per second);
    initial_cov_diag: (6,) diagonal of a new track's covariance about its first detection (m^2, m^2/s^2);
    cache_size: how many accepted detections are kept for re-filtering out-of-order ones;
    max_future_s: when update() is told the current time, a detection stamped more than this after it is
    INVALID (a clock error that would otherwise start a track no later detection could follow);
    kalman_filter: what moves the track: "filterpy" (the filter of record) or "compiled" (kalman.py: the
    same equations in one compiled call each; round-off differs, so seeded reports do too).
    """

    gate_sigma: float = 6.0
    reset_after_s: float = 10.0
    velocity_decay_fraction: float = 0.1
    velocity_decay_time_s: float = 3.0
    velocity_noise_mps_per_sqrt_s: tuple[float, float, float] = (0.5, 0.5, 0.1)
    initial_cov_diag: tuple[float, float, float, float, float, float] = (100.0, 100.0, 10.0, 1.0, 1.0, 0.5)
    cache_size: int = 20
    max_future_s: float = 0.5
    kalman_filter: str = "filterpy"

    def __post_init__(self) -> None:
        if not (self.gate_sigma > 0 and self.reset_after_s > 0 and self.velocity_decay_time_s > 0):
            raise ValueError("gate_sigma, reset_after_s and velocity_decay_time_s must be > 0")
        if not 0.0 < self.velocity_decay_fraction < 1.0:
            raise ValueError(f"velocity_decay_fraction must be in (0, 1), got {self.velocity_decay_fraction}")
        noise = self.velocity_noise_mps_per_sqrt_s
        if len(noise) != 3 or not all(np.isfinite(q) and q >= 0 for q in noise):
            raise ValueError(f"velocity_noise_mps_per_sqrt_s must be 3 finite values >= 0, got {noise}")
        cov0 = self.initial_cov_diag
        if len(cov0) != 6 or not all(np.isfinite(c) and c > 0 for c in cov0):
            raise ValueError(f"initial_cov_diag must be 6 finite values > 0, got {self.initial_cov_diag}")
        if self.cache_size < 2:
            raise ValueError(f"cache_size must be >= 2, got {self.cache_size}")
        if not self.max_future_s >= 0:
            raise ValueError(f"max_future_s must be >= 0, got {self.max_future_s}")
        if self.kalman_filter not in KALMAN_FILTERS:
            raise ValueError(f"kalman_filter must be one of {KALMAN_FILTERS}, got {self.kalman_filter!r}")

    @property
    def velocity_time_constant_s(self) -> float:
        """tau of the exponential velocity decay, s."""
        return self.velocity_decay_time_s / float(np.log(1.0 / self.velocity_decay_fraction))


class Verdict(StrEnum):
    """What the tracker did with one detection."""

    ACCEPTED = "accepted"  # fused (the very first detection starts the track)
    GATED = "gated"  # farther than gate_sigma from the prediction: ignored
    STALE = "stale"  # older than the re-filtering cache, or already applied: ignored
    INVALID = "invalid"  # non-finite values, a covariance that is not symmetric positive definite, or a stamp
    # in the future of the receiver's clock: ignored
    RESET = "reset"  # the track had expired (reset_after_s without data): a new track starts here


@dataclass(frozen=True)
class TrackerStats:
    """How many detections got each verdict (disjoint counts; `resets` counts RESET). out_of_order counts the
    ACCEPTED ones that arrived after a later-stamped one and were merged by re-filtering."""

    accepted: int = 0
    gated: int = 0
    stale: int = 0
    invalid: int = 0
    resets: int = 0
    out_of_order: int = 0


@numba.njit(cache=True)
def _coefficients(b, dt_s, tau_s):  # pragma: no cover - compiled
    """(f_pv, q_pp, q_pv, q_vv) of the decaying-velocity model over dt_s for b = exp(-dt_s / tau_s):
    F = [[I, f_pv I], [0, b I]], Q = [[q_pp D, q_pv D], [q_pv D, q_vv D]] with D = diag(psd)."""
    one_b, one_b2 = 1.0 - b, 1.0 - b * b
    q_pp = tau_s * tau_s * (dt_s - 2.0 * tau_s * one_b + 0.5 * tau_s * one_b2)
    q_pv = tau_s * tau_s * (one_b - 0.5 * one_b2)
    return tau_s * one_b, q_pp, q_pv, 0.5 * tau_s * one_b2


@numba.njit(cache=True)
def _transition_into(b, dt_s, tau_s, psd, F, Q):  # pragma: no cover - compiled
    """Write F (6, 6) and Q (6, 6) over dt_s (`_coefficients`) into F = I and Q = 0, psd (3,) the velocity
    noise densities. One compiled call: every detection at a new stamp asks for a new pair."""
    f_pv, q_pp, q_pv, q_vv = _coefficients(b, dt_s, tau_s)
    f_vv = 1.0 - (1.0 - b)  # not b: the bits of I - (1 - b) I that the tracker's filter always got
    for a in range(3):
        F[a, 3 + a] = f_pv
        F[3 + a, 3 + a] = f_vv
        Q[a, a] = q_pp * psd[a]
        Q[a, 3 + a] = q_pv * psd[a]
        Q[3 + a, a] = q_pv * psd[a]
        Q[3 + a, 3 + a] = q_vv * psd[a]


def _transition(dt_s: float, tau_s: float, psd: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(F (6, 6), Q (6, 6)) over dt_s; psd (3,) the velocity noise densities."""
    F, Q = np.eye(6), np.zeros((6, 6))
    _transition_into(float(np.exp(-dt_s / tau_s)), dt_s, tau_s, psd, F, Q)
    return F, Q


@numba.njit(cache=True)
def _predicted(dt_s, tau_s, psd, x, p, position_out, velocity_out, p_out):  # pragma: no cover - compiled
    """(position_out (3,), velocity_out (3,)) = F x, p_out (6, 6) = sym(F P F^T + Q) for F, Q of `_transition`
    over dt_s: what `estimate` hands out every tick, in one compiled call, in the arrays the estimate keeps.
    Only the filter's own predict and update ever move it."""
    b = math.exp(-dt_s / tau_s)
    f_pv, q_pp, q_pv, q_vv = _coefficients(b, dt_s, tau_s)
    fp = np.empty((6, 6))  # F P
    for i in range(3):
        position_out[i] = x[i, 0] + f_pv * x[3 + i, 0]
        velocity_out[i] = b * x[3 + i, 0]
        for j in range(6):
            fp[i, j] = p[i, j] + f_pv * p[3 + i, j]
            fp[3 + i, j] = b * p[3 + i, j]
    for i in range(6):
        for j in range(3):
            p_out[i, j] = fp[i, j] + f_pv * fp[i, 3 + j]
            p_out[i, 3 + j] = b * fp[i, 3 + j]
    for a in range(3):
        p_out[a, a] += q_pp * psd[a]
        p_out[a, 3 + a] += q_pv * psd[a]
        p_out[3 + a, a] += q_pv * psd[a]
        p_out[3 + a, 3 + a] += q_vv * psd[a]
    for i in range(6):
        for j in range(i + 1, 6):
            mean = 0.5 * (p_out[i, j] + p_out[j, i])
            p_out[i, j] = mean
            p_out[j, i] = mean


@functools.lru_cache(maxsize=256)
def _shared_transition(
    dt_s: float, tau_s: float, psd: tuple[float, float, float]
) -> tuple[np.ndarray, np.ndarray]:
    """`_transition`, remembered and read-only: the steps between detections take a few values only (16 MAVs
    at 100 Hz: 18 distinct ones in 8 s, over 4000 predictions), and every MAV's tracker has the same model."""
    F, Q = _transition(dt_s, tau_s, np.asarray(psd))
    F.setflags(write=False)
    Q.setflags(write=False)
    return F, Q


def transition(*, dt_s: float, params: TrackerParams) -> tuple[np.ndarray, np.ndarray]:
    """(F (6, 6), Q (6, 6)) of the decaying-velocity model over dt_s >= 0 (module docstring)."""
    psd = np.square(np.asarray(params.velocity_noise_mps_per_sqrt_s, dtype=float))
    return _transition(dt_s, params.velocity_time_constant_s, psd)


@dataclass
class _Entry:
    """A cached accepted detection: sort key (stamp s, source id), z (3, 1), R (3, 3), and the filter state
    (time, x (6, 1), P (6, 6)) just before it was applied (None for the detection that started the track)."""

    key: tuple[float, int]
    z: np.ndarray
    R: np.ndarray
    t_before: float | None = None
    x_before: np.ndarray | None = None
    P_before: np.ndarray | None = None


def _inverse(s: np.ndarray) -> np.ndarray:
    """np.linalg.inv of filterpy's (3, 3) innovation covariance S, to the bit: the same LAPACK gufunc without
    the wrapper's checks and error-state context (2.5 against 6.6 us a call; every detection of every teammate
    is fused). filterpy's update takes it through its `inv` hook. The gate lets only a positive definite S
    through; were S singular, the gufunc's NaN sends it to np.linalg.inv, which raises LinAlgError as before
    (after numpy's "invalid value" warning)."""
    if _LAPACK_INVERSE is None:
        return np.linalg.inv(s)
    out = _LAPACK_INVERSE(s, signature="d->d")
    return out if math.isfinite(sum(out.ravel().tolist())) else np.linalg.inv(s)


def _kalman_filter(kind: str) -> KalmanFilter | CompiledKalman:
    """The filter that moves the track, x = [p, v] measured through H = [I 0]: filterpy's (inverting S with
    `_inverse`), or its compiled twin (`TrackerParams.kalman_filter`)."""
    if kind == "compiled":
        return CompiledKalman()
    kf = KalmanFilter(dim_x=6, dim_z=3)
    kf.H = np.hstack([np.eye(3), np.zeros((3, 3))])
    kf.inv = _inverse  # pyright: ignore[reportAttributeAccessIssue] - typed from np.linalg.inv, same use
    return kf


def _entry_key(entry: _Entry) -> tuple[float, int]:
    return entry.key


class PersonTracker:
    """One MAV's replica of the person's state, fed by world-frame detections from every teammate.

    Pure and deterministic: time comes only from detection stamps and from the now_s given to estimate().
    """

    def __init__(self, params: TrackerParams | None = None) -> None:
        self.params = params or TrackerParams()
        self._tau = self.params.velocity_time_constant_s
        psd = np.square(np.asarray(self.params.velocity_noise_mps_per_sqrt_s, dtype=float))
        self._psd = psd
        self._psd_key = tuple(psd.tolist())  # the same values, hashable (`_shared_transition`)
        self._P0 = np.diag(np.asarray(self.params.initial_cov_diag, dtype=float))
        self._kf = _kalman_filter(self.params.kalman_filter)
        self._t: float | None = None  # time of the filter's state; None before the first detection
        self._cache: list[_Entry] = []
        self._counts = dict.fromkeys(("accepted", "gated", "stale", "invalid", "resets", "out_of_order"), 0)
        self._stats = TrackerStats()  # the counts as last reported by stats(), kept while none changes
        self._stats_stale = False

    def stats(self) -> TrackerStats:
        """The verdict counters so far (the same object until a count changes: it is asked every tick)."""
        if self._stats_stale:
            self._stats, self._stats_stale = TrackerStats(**self._counts), False
        return self._stats

    def estimate(self, now_s: float) -> PersonEstimate | None:
        """The person's state predicted to now_s, without changing the filter.

        None before the first detection, for a non-finite now_s, and once the last accepted detection is more
        than reset_after_s older than now_s. A now_s before the filter's time gives the filter's own state,
        stamped at its own time (the tracker never predicts backwards).
        """
        if self._t is None or not np.isfinite(now_s) or now_s - self._t > self.params.reset_after_s:
            return None
        if now_s > self._t:
            position, velocity, cov = np.empty(3), np.empty(3), np.empty((6, 6))
            _predicted(now_s - self._t, self._tau, self._psd, self._kf.x, self._kf.P, position, velocity, cov)
            stamp = float(now_s)
        else:
            x, P, stamp = self._kf.x[:, 0], self._kf.P, self._t
            position, velocity, cov = x[:3].copy(), x[3:].copy(), 0.5 * (P + P.T)
        return PersonEstimate(
            stamp_s=stamp,
            position_m=read_only(position),
            velocity_mps=read_only(velocity),
            cov=read_only(cov),
        )

    def update(self, detection: Detection, *, now_s: float | None = None) -> Verdict:
        """Fuse one detection. Never raises for bad data; a rejected detection leaves the filter unchanged.

        now_s, if given, is the receiver's current time: a detection stamped more than max_future_s after it
        is INVALID.
        """
        checked = _checked_message(detection) if type(detection) is Detection else _checked(detection)
        if checked is None:
            return self._count(Verdict.INVALID)
        key, z, R = checked
        if now_s is not None and not key[0] <= now_s + self.params.max_future_s:
            return self._count(Verdict.INVALID)
        if self._t is None or key[0] - self._t > self.params.reset_after_s:
            verdict = Verdict.ACCEPTED if self._t is None else Verdict.RESET
            self._kf.x = np.vstack([z, np.zeros((3, 1))])
            self._kf.P = self._P0.copy()
            self._t = key[0]
            self._cache = [_Entry(key, z, R)]
            return self._count(verdict)
        cache = self._cache
        index = bisect.bisect_left(cache, key, key=_entry_key)  # no list of every key for each detection
        if index == 0 or (index < len(cache) and cache[index].key == key):
            return self._count(Verdict.STALE)
        if index < len(cache):
            return self._count(self._merge_late(index, key, z, R))
        before = (self._t, self._kf.x.copy(), self._kf.P.copy())
        self._predict_to(key[0])
        if not self._within_gate(self._kf.x, self._kf.P, z, R):
            self._t, self._kf.x, self._kf.P = before
            return self._count(Verdict.GATED)
        self._kf.update(z, R=R)
        self._append(_Entry(key, z, R, *before))
        return self._count(Verdict.ACCEPTED)

    def _merge_late(self, index: int, key: tuple[float, int], z: np.ndarray, R: np.ndarray) -> Verdict:
        """Gate a detection that belongs before cache[index] and, if it passes, re-filter from there."""
        cache = self._cache
        following = cache[index]
        t_before, x_before, P_before = following.t_before, following.x_before, following.P_before
        if t_before is None or x_before is None or P_before is None:  # the track's first detection
            return Verdict.STALE
        x, P = x_before, P_before
        if key[0] > t_before:
            F, Q = self._fq(key[0] - t_before)
            x, P = F @ x, F @ P @ F.T + Q
        if not self._within_gate(x, P, z, R):
            return Verdict.GATED
        self._t = t_before
        self._kf.x, self._kf.P = x_before.copy(), P_before.copy()
        cache.insert(index, _Entry(key, z, R))
        replay = cache[index:]
        del cache[index:]
        for entry in replay:
            entry.t_before, entry.x_before, entry.P_before = self._t, self._kf.x.copy(), self._kf.P.copy()
            self._predict_to(entry.key[0])
            self._kf.update(entry.z, R=entry.R)
            self._append(entry)
        self._counts["out_of_order"] += 1
        self._stats_stale = True
        return Verdict.ACCEPTED

    def _append(self, entry: _Entry) -> None:
        self._cache.append(entry)
        if len(self._cache) > self.params.cache_size:
            del self._cache[0]

    def _predict_to(self, t_s: float) -> None:
        if self._t is not None and t_s > self._t:
            F, Q = self._fq(t_s - self._t)
            self._kf.predict(F=F, Q=Q)
            self._t = t_s

    def _count(self, verdict: Verdict) -> Verdict:
        self._counts["resets" if verdict is Verdict.RESET else verdict.value] += 1
        self._stats_stale = True
        return verdict

    def _fq(self, dt_s: float) -> tuple[np.ndarray, np.ndarray]:
        """F, Q over dt_s, read-only and shared (`_shared_transition`)."""
        return _shared_transition(dt_s, self._tau, self._psd_key)

    def _within_gate(self, x: np.ndarray, P: np.ndarray, z: np.ndarray, R: np.ndarray) -> bool:
        """Whether z (3, 1) lies within gate_sigma (Mahalanobis) of the predicted state x (6, 1), P (6, 6)."""
        return _gate_distance_sq(x, P, z, R) <= self.params.gate_sigma**2


@numba.njit(cache=True)
def _gate_distance_sq(x, P, z, R):  # pragma: no cover - compiled
    """`_mahalanobis_sq` of z (3, 1) from the predicted x (6, 1), P (6, 6), with S = P[:3, :3] + R
    (`kalman.innovation_upper`) and y = z - x[:3]: one compiled call, as every detection of every teammate is
    gated."""
    return _mahalanobis_sq(*innovation_upper(P, R), z[0, 0] - x[0, 0], z[1, 0] - x[1, 0], z[2, 0] - x[2, 0])


@numba.njit(cache=True)
def _mahalanobis_sq(a, b, c, d, e, f, u, v, w):  # pragma: no cover - compiled; tested against its py_func
    """y^T S^-1 y for the symmetric S = [[a, b, c], [b, d, e], [c, e, f]] and y = (u, v, w) by the adjugate of
    S (`kalman.symmetric_adjugate`); inf when S is not positive definite (Sylvester: a, the leading 2x2 minor
    adj_cc and det all > 0). Plain floats: for 3x3 this is far cheaper than numpy.linalg."""
    adj_aa, adj_ab, adj_ac, adj_bb, adj_bc, adj_cc, det = symmetric_adjugate(a, b, c, d, e, f)
    if not (a > 0.0 and adj_cc > 0.0 and det > 0.0):
        return math.inf
    quad = (
        adj_aa * u * u
        + adj_bb * v * v
        + adj_cc * w * w
        + 2.0 * (adj_ab * u * v + adj_ac * u * w + adj_bc * v * w)
    )
    return quad / det


def _is_spd(m: list[list[float]]) -> bool:
    """Whether a symmetric 3x3 matrix is positive definite (Sylvester: all leading principal minors > 0)."""
    (a, b, c), (_, d, e), (_, _, f) = m
    det = a * (d * f - e * e) - b * (b * f - c * e) + c * (b * e - c * d)
    return a > 0.0 and a * d - b * b > 0.0 and det > 0.0


@functools.lru_cache(maxsize=256)
def _checked_message(detection: Detection) -> tuple[tuple[float, int], np.ndarray, np.ndarray] | None:
    """`_checked` of a Detection, remembered: the links hand the same Detection object to every teammate (each
    of K trackers checks it), and a Detection cannot change (frozen, its arrays read-only)."""
    return _checked(detection)


def _checked(detection: Detection) -> tuple[tuple[float, int], np.ndarray, np.ndarray] | None:
    """(sort key (stamp s, source id), z (3, 1), R (3, 3)) of a usable detection, or None; z and R read-only
    (`_checked_message` hands them to every tracker)."""
    try:
        key = (float(detection.stamp_s), int(detection.source_id))
        z_list = np.asarray(detection.position_m, dtype=float).reshape(3).tolist()
        r_list = np.asarray(detection.cov_m2, dtype=float).reshape(3, 3).tolist()
    except (TypeError, ValueError, AttributeError, OverflowError):
        return None
    # a sum is finite only if every term is (values near the float limit count as invalid too)
    if not math.isfinite(key[0] + sum(z_list) + sum(sum(row) for row in r_list)):
        return None
    (a, b, c), (d, e, f), (g, h, i) = r_list
    if max(abs(b - d), abs(c - g), abs(f - h)) > 1e-9 * max(abs(v) for row in r_list for v in row):
        return None
    b, c, f = 0.5 * (b + d), 0.5 * (c + g), 0.5 * (f + h)
    sym = [[a, b, c], [b, e, f], [c, f, i]]
    if not _is_spd(sym):
        return None
    return key, read_only(np.array(z_list).reshape(3, 1)), read_only(np.array(sym))

"""The MAV's own GPS offset relative to its team, estimated from its person detections.

The original tracker estimated each MAV's self-localisation offset in its filter (optional there:
docs/method.md#person-tracker). skyring keeps the estimate beside the tracker and uses it for one thing:
where the teammates are relative to this MAV, for the separation rows.

An own detection, placed in the world with the reported pose, sees the person plus this MAV's GPS offset
o_i; the fused estimate, built from every teammate's detections, sees the person plus a weighted mean of the
team's offsets. Their difference, the residual, measures o_i relative to the team (about (K - 1)/K of it:
the own detections weigh about 1/K of the fused estimate). Each MAV publishes its estimate b_i with its
plan, and its separation rows shift a teammate's plan by b_own - b_j (fields.TeammatePaths.placed_by): two
MAVs then keep apart where they are relative to each other, up to the estimation error, not where their GPS
fixes put them (docs/safety.md#gps-drift-and-the-true-separation-threshold).

The estimate is a 3-state Kalman filter on b: a random walk (GPS drift changes by mm/s to cm/s) about a
zero prior, each residual a measurement of b with covariance R_z + P_x_hat. Pure and deterministic: time
comes only from the detections' stamps.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class GpsOffsetParams:
    """initial_std_m (x, y, z): the prior of the offset about zero (the simulated GPS's initial spread);
    drift_mps (x, y, z): the random walk's process noise, std per sqrt(second) (m/s^0.5);
    gate_sigma: a residual beyond this many sigmas (3 dof) from the estimate is not used;
    max_offset_m: the estimate is clipped to this per axis, so a run of bad residuals cannot move a
    teammate far; max_age_s: a fused estimate stamped further than this from the detection is not used;
    teammate_within_s: a detection is compared only while the fused estimate holds a teammate's detection
    this recent (alone, the estimate is the MAV's own detections: the residual says nothing of the offset)."""

    initial_std_m: tuple[float, float, float] = (0.5, 0.5, 1.0)
    drift_mps: tuple[float, float, float] = (0.01, 0.01, 0.02)
    gate_sigma: float = 4.0
    max_offset_m: float = 3.0
    max_age_s: float = 0.3
    teammate_within_s: float = 1.0

    def __post_init__(self) -> None:
        for name in ("initial_std_m", "drift_mps"):
            value = getattr(self, name)
            if len(value) != 3 or not all(np.isfinite(v) and v > 0 for v in value):
                raise ValueError(f"{name} must be 3 finite values > 0, got {value}")
        if not (self.gate_sigma > 0 and self.max_offset_m > 0):
            raise ValueError("gate_sigma and max_offset_m must be > 0")
        if not (self.max_age_s >= 0 and self.teammate_within_s >= 0):
            raise ValueError("max_age_s and teammate_within_s must be >= 0")


class GpsOffsetEstimator:
    """b (3,), m: this MAV's GPS offset relative to its team (its reported position less b is where it is
    among its teammates). `update(residual_m, residual_cov_m2, stamp_s)` takes one own detection's residual
    against the fused estimate; `offset_m` (3,) and `cov_m2` (3, 3) read the estimate; `used` and `gated`
    count the residuals taken and refused."""

    def __init__(self, params: GpsOffsetParams | None = None) -> None:
        self.params = p = params or GpsOffsetParams()
        self._b = np.zeros(3)
        self._P = np.diag(np.square(np.asarray(p.initial_std_m, dtype=float)))
        self._q = np.square(np.asarray(p.drift_mps, dtype=float))
        self._t: float | None = None
        self.used = 0
        self.gated = 0

    @property
    def offset_m(self) -> np.ndarray:
        return self._b.copy()

    @property
    def cov_m2(self) -> np.ndarray:
        return self._P.copy()

    def update(self, residual_m: np.ndarray, residual_cov_m2: np.ndarray, stamp_s: float) -> bool:
        """Fuse one residual (3,), a measurement of b with covariance (3, 3) (the detection's plus the fused
        estimate's); False when it is refused (not finite, or beyond the gate) and counted."""
        y = np.asarray(residual_m, dtype=float)
        R = np.asarray(residual_cov_m2, dtype=float)
        if not (y.shape == (3,) and R.shape == (3, 3) and np.all(np.isfinite(y)) and np.all(np.isfinite(R))):
            self.gated += 1
            return False
        if not np.isfinite(stamp_s):
            self.gated += 1
            return False
        P = self._P
        if self._t is not None and stamp_s > self._t:
            P = P + np.diag(self._q * (stamp_s - self._t))
        S = P + R
        innovation = y - self._b
        try:
            distance_sq = float(innovation @ np.linalg.solve(S, innovation))
            K = np.linalg.solve(S, P).T  # P S^-1 (S, P symmetric)
        except np.linalg.LinAlgError:
            distance_sq, K = np.inf, None
        if K is None or not distance_sq <= self.params.gate_sigma**2:
            self.gated += 1
            return False
        limit = self.params.max_offset_m
        self._b = np.clip(self._b + K @ innovation, -limit, limit)
        I_K = np.eye(3) - K
        self._P = I_K @ P @ I_K.T + K @ R @ K.T
        self._t = stamp_s if self._t is None else max(self._t, stamp_s)
        self.used += 1
        return True

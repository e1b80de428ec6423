"""A short history of the MAV's own pose, to know where the camera was when a frame was captured.

A frame reaches the agent tens to hundreds of milliseconds after its capture (exposure, transfer, detection);
at 5 m/s and 1 rad/s of yaw that is metres and tens of degrees, so a detection must be placed with the pose
at its capture time, not with the latest one. Poses are interpolated linearly between the two readings that
bracket the time (angles along the shorter arc); a time before the oldest reading, after the newest, or
between two readings further apart than `max_gap_s` (a telemetry gap) has no pose.
"""

from __future__ import annotations

import bisect
import math
from collections import deque
from dataclasses import dataclass, field

import numpy as np

from controller.messages import frozen_array


@dataclass(frozen=True, eq=False)
class PoseSample:
    """The body's believed pose at stamp_s: position_m (3,) ENU, attitude (aviation sense, radians),
    position_cov_m2 (3, 3) the self-localisation covariance."""

    stamp_s: float
    position_m: np.ndarray
    yaw_rad: float
    pitch_rad: float = 0.0
    roll_rad: float = 0.0
    position_cov_m2: np.ndarray = field(default_factory=lambda: np.eye(3) * 0.25)

    def __post_init__(self) -> None:
        object.__setattr__(self, "position_m", frozen_array(self.position_m, (3,), "position_m"))
        object.__setattr__(
            self, "position_cov_m2", frozen_array(self.position_cov_m2, (3, 3), "position_cov_m2")
        )


def _lerp_angle(a: float, b: float, w: float) -> float:
    d = (b - a + math.pi) % (2.0 * math.pi) - math.pi
    return (a + w * d + math.pi) % (2.0 * math.pi) - math.pi


class PoseHistory:
    """The last `horizon_s` seconds of pose samples, oldest first; `at(t)` interpolates."""

    def __init__(self, *, horizon_s: float = 3.0, max_gap_s: float = 0.5) -> None:
        if not (horizon_s > 0 and max_gap_s > 0):
            raise ValueError("horizon_s and max_gap_s must be positive")
        self._horizon_s = float(horizon_s)
        self._max_gap_s = float(max_gap_s)
        self._samples: deque[PoseSample] = deque()
        self._stamps: deque[float] = deque()

    def __len__(self) -> int:
        return len(self._samples)

    @property
    def newest_s(self) -> float | None:
        return self._stamps[-1] if self._stamps else None

    def add(self, sample: PoseSample) -> bool:
        """Append a sample; a non-finite one or one not newer than the newest is ignored (returns False)."""
        if not (
            math.isfinite(sample.stamp_s)
            and np.all(np.isfinite(sample.position_m))
            and math.isfinite(sample.yaw_rad)
            and math.isfinite(sample.pitch_rad)
            and math.isfinite(sample.roll_rad)
        ):
            return False
        if self._stamps and sample.stamp_s <= self._stamps[-1]:
            return False
        self._samples.append(sample)
        self._stamps.append(sample.stamp_s)
        limit = sample.stamp_s - self._horizon_s
        while len(self._stamps) > 2 and self._stamps[1] < limit:
            self._samples.popleft()
            self._stamps.popleft()
        return True

    def at(self, t_s: float) -> PoseSample | None:
        """The interpolated pose at t_s, or None when t_s is outside the history or inside a gap."""
        stamps = self._stamps
        if not stamps or not math.isfinite(t_s) or t_s < stamps[0] or t_s > stamps[-1]:
            return None
        i = bisect.bisect_left(stamps, t_s)
        hi = self._samples[i]
        if hi.stamp_s == t_s:
            return hi
        lo = self._samples[i - 1]
        gap = hi.stamp_s - lo.stamp_s
        if gap > self._max_gap_s:
            return None
        w = (t_s - lo.stamp_s) / gap
        return PoseSample(
            stamp_s=t_s,
            position_m=(1.0 - w) * lo.position_m + w * hi.position_m,
            yaw_rad=_lerp_angle(lo.yaw_rad, hi.yaw_rad, w),
            pitch_rad=_lerp_angle(lo.pitch_rad, hi.pitch_rad, w),
            roll_rad=_lerp_angle(lo.roll_rad, hi.roll_rad, w),
            position_cov_m2=(1.0 - w) * lo.position_cov_m2 + w * hi.position_cov_m2,
        )

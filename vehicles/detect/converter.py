"""The agent's side of onboard detection: camera detections in, world-frame Detections out, never waiting.

The agent records its own pose every tick (`record_pose`) and hands over the camera detections received
since the last tick (`convert`). Each is placed with the pose interpolated at its capture time. One captured
after the newest pose (telemetry lags the camera) is kept, without blocking, until a newer pose covers it or
`max_wait_s` passes; one older than `max_age_s` is dropped (the tracker's out-of-order window is short).
Every outcome is counted by reason, and the capture-to-conversion latency of accepted ones is kept.
"""

from __future__ import annotations

import math
from collections import Counter, deque
from collections.abc import Iterable
from dataclasses import dataclass, field

import numpy as np

from controller.messages import Detection
from vehicles.autopilot import AutopilotState
from vehicles.detect.calibration import Calibration
from vehicles.detect.localize import LocalizeParams, localize
from vehicles.detect.pixels import CameraDetection
from vehicles.detect.pose_history import PoseHistory, PoseSample


@dataclass(frozen=True)
class ConverterParams:
    """pose_horizon_s: pose history kept; max_pose_gap_s: a longer telemetry gap has no pose inside it;
    max_wait_s: how long a detection newer than the newest pose may wait for it; max_age_s: older captures
    are dropped; max_pending: bound on waiting detections (the oldest go first); localize: the geometry."""

    pose_horizon_s: float = 3.0
    max_pose_gap_s: float = 0.5
    max_wait_s: float = 0.3
    max_age_s: float = 2.0
    max_pending: int = 32
    localize: LocalizeParams = field(default_factory=LocalizeParams)

    def __post_init__(self) -> None:
        for name in ("pose_horizon_s", "max_pose_gap_s", "max_wait_s", "max_age_s"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be a positive finite number of seconds, got {value}")
        if self.max_pending < 1:
            raise ValueError("max_pending must be at least 1")


@dataclass(frozen=True)
class ConverterStats:
    """received: camera detections handed in; converted: became Detections; rejected: by reason (the
    localize Rejection values plus "foreign" (another vehicle's), "too_old" and "overflow"); pending: waiting
    for a pose; latency_p50_s / latency_max_s: capture-to-conversion latency of the last 200 converted."""

    received: int = 0
    converted: int = 0
    rejected: tuple[tuple[str, int], ...] = ()
    pending: int = 0
    latency_p50_s: float = math.nan
    latency_max_s: float = math.nan

    @property
    def rejected_total(self) -> int:
        return sum(n for _, n in self.rejected)


class DetectionConverter:
    """Converts vehicle_id's camera detections with its pose history and calibration."""

    def __init__(
        self, *, vehicle_id: int, calibration: Calibration, params: ConverterParams | None = None
    ) -> None:
        self.vehicle_id = int(vehicle_id)
        self._calibration = calibration
        self._p = params or ConverterParams()
        self._history = PoseHistory(horizon_s=self._p.pose_horizon_s, max_gap_s=self._p.max_pose_gap_s)
        self._pending: deque[CameraDetection] = deque()
        self._received = 0
        self._converted = 0
        self._rejected: Counter[str] = Counter()
        self._latencies: deque[float] = deque(maxlen=200)

    @property
    def calibration(self) -> Calibration:
        return self._calibration

    def record_pose(self, state: AutopilotState) -> None:
        """Add the MAV's believed pose from a telemetry reading (one older than the newest is ignored)."""
        self._history.add(
            PoseSample(
                stamp_s=state.stamp_s,
                position_m=state.position_m,
                yaw_rad=state.yaw_rad,
                pitch_rad=state.pitch_rad,
                roll_rad=state.roll_rad,
                position_cov_m2=state.position_cov_m2,
            )
        )

    def convert(self, now_s: float, detections: Iterable[CameraDetection]) -> tuple[Detection, ...]:
        """The Detections ready at now_s: from the new camera detections and those that were waiting."""
        for det in detections:
            self._received += 1
            if not isinstance(det, CameraDetection) or det.vehicle_id != self.vehicle_id:
                self._rejected["foreign"] += 1
                continue
            self._pending.append(det)
        while len(self._pending) > self._p.max_pending:
            self._pending.popleft()
            self._rejected["overflow"] += 1
        newest = self._history.newest_s
        out: list[Detection] = []
        waiting: deque[CameraDetection] = deque()
        for det in sorted(self._pending, key=lambda d: d.stamp_s):
            if now_s - det.stamp_s > self._p.max_age_s:
                self._rejected["too_old"] += 1
                continue
            if (newest is None or det.stamp_s > newest) and now_s - det.stamp_s <= self._p.max_wait_s:
                waiting.append(det)
                continue
            result = localize(det, self._history.at(det.stamp_s), self._calibration, self._p.localize)
            if result.detection is None:
                self._rejected[str(result.rejection)] += 1
                continue
            self._converted += 1
            self._latencies.append(now_s - det.stamp_s)
            out.append(result.detection)
        self._pending = waiting
        return tuple(out)

    def stats(self) -> ConverterStats:
        lat = np.array(self._latencies) if self._latencies else None
        return ConverterStats(
            received=self._received,
            converted=self._converted,
            rejected=tuple(sorted(self._rejected.items())),
            pending=len(self._pending),
            latency_p50_s=float(np.median(lat)) if lat is not None else math.nan,
            latency_max_s=float(lat.max()) if lat is not None else math.nan,
        )

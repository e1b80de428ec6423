"""The metrics of a simulation run (docs/method.md#experiments), computed from what a `Recorder` collected
after the warm-up.

Names are a public interface (the JSON report, the experiments' tables): keep them, add new ones beside them.

- tracking_error_m {mean, median, p90}: 3-D distance of each MAV's fused estimate to the true person centre,
  pooled over MAVs in formation and control ticks (ticks where a MAV has no estimate are left out and counted
  in estimate_fraction);
- cov_trace_m2 {mean, median}: trace of each such estimate's position covariance;
- in_frame_fraction: camera frames (4 Hz, MAVs in formation, pooled) with head and feet inside the image;
- center_offset_px {mean, median}: pixel distance of the person's centre from the image centre, over the
  frames with the person in frame;
- spacing_error_deg: mean over ticks of the mean absolute deviation of the K neighbouring angular gaps (true
  MAV positions about the true person, K = MAVs in formation >= 2) from 360/K degrees;
- distance_error_m, height_error_m: mean absolute error of the true horizontal distance to the person and of
  the true height above the person's centre, to d_des and h_des;
- min_separation_m (3-D, any two airborne MAVs), min_obstacle_clearance_m (horizontal distance of an
  airborne MAV to a trunk's surface, below its top), min_person_distance_m (horizontal, airborne MAVs), over
  every tick;
- min_believed_separation_m: min_separation_m between the positions the MAVs believe they are at (their
  self-localisation, GPS drift included), which is what the controllers keep apart; the gap to
  min_separation_m is what the drift costs;
- tick_ms {median, p99}: wall time of one agent tick (tracker + controller) of MAVs in formation;
- realtime_factor: simulated seconds per wall-clock second, after the warm-up like everything else
  (simulation, control and this bookkeeping included).
Extras: estimate_fraction (MAV-ticks in formation with an estimate), detected_fraction (frames whose person
was also not hidden by a trunk, so the detector reported it), frames, samples. A metric with no data is
null.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from controller.messages import Obstacle
from server.separation import obstacle_clearance_m


@dataclass(frozen=True, eq=False)
class TickSample:
    """One control tick after the warm-up.

    positions_m (K, 3) true MAV positions; in_formation (K,) and in_air (K,) bool; person_m (3,) true centre;
    estimates_m (K, 3) fused estimates (NaN rows where none); cov_traces_m2 (K,) (NaN where none);
    d_des_m, h_des_m: the operator's values at that tick; believed_positions_m (K, 3): where the MAVs think
    they are (self-localisation; None: the true positions).
    """

    t_s: float
    positions_m: np.ndarray
    in_formation: np.ndarray
    in_air: np.ndarray
    person_m: np.ndarray
    estimates_m: np.ndarray
    cov_traces_m2: np.ndarray
    d_des_m: float
    h_des_m: float
    believed_positions_m: np.ndarray | None = None


class Recorder:
    """Collects tick samples, camera frames and tick timings; `metrics()` reduces them."""

    def __init__(self, *, obstacles: Sequence[Obstacle] = ()) -> None:
        self._obstacles = tuple(obstacles)
        self._samples: list[TickSample] = []
        self._in_frame: list[bool] = []
        self._detected: list[bool] = []
        self._offsets: list[float] = []
        self._tick_s: list[float] = []

    def add_tick(self, sample: TickSample) -> None:
        self._samples.append(sample)

    def add_frame(self, *, in_frame: bool, center_offset_px: float, detected: bool | None = None) -> None:
        """One camera frame; detected defaults to in_frame (no occluder)."""
        self._in_frame.append(bool(in_frame))
        self._detected.append(bool(in_frame if detected is None else detected))
        if in_frame and math.isfinite(center_offset_px):
            self._offsets.append(float(center_offset_px))

    def add_tick_time(self, seconds: float) -> None:
        self._tick_s.append(float(seconds))

    def tracking_error_by_vehicle_m(self) -> list[float | None]:
        return tracking_error_by_vehicle_m(self._samples)

    def metrics(self, *, sim_s: float, wall_s: float) -> dict[str, Any]:
        """The metrics dictionary (issue names first, then extras)."""
        metrics = compute_metrics(
            self._samples,
            in_frame=self._in_frame,
            offsets_px=self._offsets,
            tick_s=self._tick_s,
            obstacles=self._obstacles,
            sim_s=sim_s,
            wall_s=wall_s,
        )
        detected = np.asarray(self._detected, dtype=bool)
        metrics["detected_fraction"] = _num(detected.mean()) if detected.size else None
        return metrics


def _num(x: float | np.floating | None) -> float | None:
    if x is None or not np.isfinite(x):
        return None
    return round(float(x), 6)


def _stats(values: np.ndarray, *, keys: tuple[str, ...]) -> dict[str, float | None]:
    v = np.asarray(values, dtype=float)
    v = v[np.isfinite(v)]
    out: dict[str, float | None] = {}
    for k in keys:
        if v.size == 0:
            out[k] = None
        elif k == "mean":
            out[k] = _num(np.mean(v))
        elif k == "median":
            out[k] = _num(np.median(v))
        else:
            out[k] = _num(np.percentile(v, float(k[1:])))
    return out


def spacing_error_deg(*, positions_xy_m: np.ndarray, person_xy_m: np.ndarray) -> float:
    """Mean absolute deviation (degrees) of the K neighbouring angular gaps of positions (K, 2) about the
    person (2,) from 360/K; NaN for K < 2."""
    k = len(positions_xy_m)
    if k < 2:
        return math.nan
    d = positions_xy_m - person_xy_m
    angles = np.sort(np.arctan2(d[:, 1], d[:, 0]))
    gaps = np.diff(np.concatenate([angles, angles[:1] + 2.0 * np.pi]))
    return float(np.degrees(np.mean(np.abs(gaps - 2.0 * np.pi / k))))


def min_pair_distance_m(points_m: np.ndarray) -> float:
    """Smallest 3-D distance between any two of points (K, 3); inf for K < 2."""
    if len(points_m) < 2:
        return math.inf
    diff = points_m[:, None, :] - points_m[None, :, :]
    dist = np.sqrt(np.einsum("ijk,ijk->ij", diff, diff))
    return float(np.min(dist[np.triu_indices(len(points_m), 1)]))


def tracking_error_by_vehicle_m(samples: Sequence[TickSample]) -> list[float | None]:
    """Mean 3-D tracking error of each vehicle (column) while in formation with an estimate; None if never."""
    if not samples:
        return []
    k = len(samples[0].in_formation)
    sums, counts = np.zeros(k), np.zeros(k, dtype=int)
    for s in samples:
        ok = s.in_formation & np.all(np.isfinite(s.estimates_m), axis=1)
        sums[ok] += np.linalg.norm(s.estimates_m[ok] - s.person_m, axis=1)
        counts[ok] += 1
    return [_num(sums[i] / counts[i]) if counts[i] else None for i in range(k)]


def compute_metrics(
    samples: Sequence[TickSample],
    *,
    in_frame: Sequence[bool],
    offsets_px: Sequence[float],
    tick_s: Sequence[float],
    obstacles: Sequence[Obstacle],
    sim_s: float,
    wall_s: float,
) -> dict[str, Any]:
    """Reduce the recorded run to the report's metrics (module docstring)."""
    errors, traces, spacing, dist_err, height_err = [], [], [], [], []
    min_sep = min_believed_sep = min_clear = min_person = math.inf
    with_estimate = formation_slots = 0
    for s in samples:
        f = s.in_formation
        if np.any(f):
            est = s.estimates_m[f]
            has = np.all(np.isfinite(est), axis=1)
            formation_slots += int(f.sum())
            with_estimate += int(has.sum())
            errors.extend(np.linalg.norm(est[has] - s.person_m, axis=1))
            traces.extend(s.cov_traces_m2[f][has])
            pos = s.positions_m[f]
            rho = np.hypot(pos[:, 0] - s.person_m[0], pos[:, 1] - s.person_m[1])
            dist_err.extend(np.abs(rho - s.d_des_m))
            height_err.extend(np.abs(pos[:, 2] - s.person_m[2] - s.h_des_m))
            sp = spacing_error_deg(positions_xy_m=pos[:, :2], person_xy_m=s.person_m[:2])
            if math.isfinite(sp):
                spacing.append(sp)
        air = s.positions_m[s.in_air]
        if len(air):
            min_sep = min(min_sep, min_pair_distance_m(air))
            believed = s.positions_m if s.believed_positions_m is None else s.believed_positions_m
            min_believed_sep = min(min_believed_sep, min_pair_distance_m(believed[s.in_air]))
            min_clear = min(min_clear, obstacle_clearance_m(air, obstacles))
            min_person = min(
                min_person, float(np.min(np.hypot(air[:, 0] - s.person_m[0], air[:, 1] - s.person_m[1])))
            )
    frames = np.asarray(in_frame, dtype=bool)
    ticks_ms = np.asarray(tick_s, dtype=float) * 1e3
    return {
        "tracking_error_m": _stats(np.asarray(errors), keys=("mean", "median", "p90")),
        "cov_trace_m2": _stats(np.asarray(traces), keys=("mean", "median")),
        "in_frame_fraction": _num(frames.mean()) if frames.size else None,
        "center_offset_px": _stats(np.asarray(offsets_px), keys=("mean", "median")),
        "spacing_error_deg": _num(np.mean(spacing)) if spacing else None,
        "distance_error_m": _num(np.mean(dist_err)) if dist_err else None,
        "height_error_m": _num(np.mean(height_err)) if height_err else None,
        "min_separation_m": _num(min_sep),
        "min_obstacle_clearance_m": _num(min_clear),
        "min_person_distance_m": _num(min_person),
        "tick_ms": _stats(ticks_ms, keys=("median", "p99")),
        "realtime_factor": _num(sim_s / wall_s) if wall_s > 0 else None,
        "estimate_fraction": _num(with_estimate / formation_slots) if formation_slots else None,
        "min_believed_separation_m": _num(min_believed_sep),
        "frames": int(frames.size),
        "samples": len(samples),
    }

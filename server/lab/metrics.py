"""The metrics of a simulation run (docs/method.md#experiments), computed from what a `Recorder` collected:
the safety minima over the whole flight, everything else after the warm-up.

The warm-up (take-off, spreading out to the slots, the filters settling) is left out of formation and
tracking quality only: it is also where MAVs start side by side and cross each other's paths, so a safety
minimum that skipped it would miss the likeliest collisions. The Recorder sees every control tick from the
first one; it keeps running minima of the safety distances over all of them and the full samples only from
warmup_s on.

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
- safety, over the whole flight (every tick from the first, warm-up included; a MAV counts from the moment
  it leaves the ground, in_air, until it has landed): min_separation_m (3-D, any two airborne MAVs),
  min_obstacle_clearance_m (horizontal distance of an airborne MAV to a trunk's surface, below its top;
  negative inside it: contact), min_person_distance_m (horizontal, airborne MAVs);
- min_believed_separation_m: min_separation_m between the positions the MAVs believe they are at (their
  self-localisation less their estimated GPS offsets), which is what the controllers keep apart; the gap
  to min_separation_m is what the drift and its estimate's error cost;
- where and when each safety minimum happened, to reproduce it: min_separation_t_s and min_separation_pair
  [vehicle id, vehicle id], the same for min_believed_separation_, min_obstacle_clearance_t_s and
  min_obstacle_clearance_pair [vehicle id, obstacle id], min_person_distance_t_s and
  min_person_distance_vehicle (the first tick at the minimum; null when the minimum is);
- tick_ms {median, p99}: wall time of one agent tick (tracker + controller) of MAVs in formation;
- realtime_factor: simulated seconds per wall-clock second, after the warm-up like the tracking metrics
  (simulation, control and this bookkeeping included).
Extras: estimate_fraction (MAV-ticks in formation with an estimate), detected_fraction (frames whose person
was also not hidden by a trunk, so the detector reported it), frames, samples (ticks after the warm-up),
flight_ticks (every tick, the safety minima's). A metric with no data is null.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from controller.messages import Obstacle
from server.separation import Cylinders, closest_obstacle

WARMUP_EPS_S = 1e-9  # a tick stamped this close below warmup_s counts as after it (float steps i / rate_hz)


@dataclass(frozen=True, eq=False)
class TickSample:
    """One control tick.

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


@dataclass(frozen=True)
class Closest:
    """The smallest value of one safety distance so far: metres, the first tick it was reached at (s), and
    between what (two vehicle ids, a vehicle id and an obstacle id, or one vehicle id for the person)."""

    distance_m: float = math.inf
    t_s: float | None = None
    between: tuple[int | str, ...] = ()

    def lower(self, distance_m: float, t_s: float, between: tuple[int | str, ...]) -> Closest:
        """This minimum, or the new value if it is strictly lower (ties keep the earlier tick)."""
        return Closest(distance_m, t_s, between) if distance_m < self.distance_m else self


class FlightSafety:
    """Running minima of the safety distances over every tick of a flight: closest true pair, closest believed
    pair, obstacle clearance and closest approach to the person, with when and between whom (module
    docstring). Keeps four `Closest` values, not the samples, so a whole flight costs no memory."""

    def __init__(self, *, obstacles: Sequence[Obstacle] = (), vehicle_ids: Sequence[int] = ()) -> None:
        self._obstacles = tuple(obstacles)
        self._cylinders = Cylinders.of(self._obstacles)
        self._ids = tuple(int(v) for v in vehicle_ids)
        self.separation = Closest()
        self.believed_separation = Closest()
        self.obstacle_clearance = Closest()
        self.person_distance = Closest()
        self.ticks = 0

    def add(self, sample: TickSample) -> None:
        """Take one tick's airborne MAVs into the minima."""
        self.ticks += 1
        air = sample.in_air.nonzero()[0]
        if air.size == 0:
            return
        ids = self._ids if len(self._ids) == len(sample.in_air) else tuple(range(1, len(sample.in_air) + 1))
        t = sample.t_s
        pos = sample.positions_m[air]
        d, i, j = closest_pair(pos)
        if i >= 0:
            self.separation = self.separation.lower(d, t, (ids[air[i]], ids[air[j]]))
        believed = sample.positions_m if sample.believed_positions_m is None else sample.believed_positions_m
        d, i, j = closest_pair(believed[air])
        if i >= 0:
            self.believed_separation = self.believed_separation.lower(d, t, (ids[air[i]], ids[air[j]]))
        d, i, j = closest_obstacle(pos, self._cylinders)
        if i >= 0:
            pair = (ids[air[i]], self._obstacles[j].obstacle_id)
            self.obstacle_clearance = self.obstacle_clearance.lower(d, t, pair)
        rho = np.hypot(pos[:, 0] - sample.person_m[0], pos[:, 1] - sample.person_m[1])
        i = int(rho.argmin())
        self.person_distance = self.person_distance.lower(float(rho[i]), t, (ids[air[i]],))

    def metrics(self) -> dict[str, Any]:
        """The safety metrics by name: the four minima, then when and between whom each happened."""
        sep, bel, clear, person = (
            self.separation,
            self.believed_separation,
            self.obstacle_clearance,
            self.person_distance,
        )
        return {
            "min_separation_m": _num(sep.distance_m),
            "min_obstacle_clearance_m": _num(clear.distance_m),
            "min_person_distance_m": _num(person.distance_m),
            "min_believed_separation_m": _num(bel.distance_m),
            "min_separation_t_s": _num(sep.t_s),
            "min_separation_pair": list(sep.between) or None,
            "min_believed_separation_t_s": _num(bel.t_s),
            "min_believed_separation_pair": list(bel.between) or None,
            "min_obstacle_clearance_t_s": _num(clear.t_s),
            "min_obstacle_clearance_pair": list(clear.between) or None,
            "min_person_distance_t_s": _num(person.t_s),
            "min_person_distance_vehicle": person.between[0] if person.between else None,
            "flight_ticks": self.ticks,
        }


class Recorder:
    """Collects tick samples, camera frames and tick timings; `metrics()` reduces them.

    Every tick goes to `add_tick`, from the first: the safety minima take all of them (`FlightSafety`), the
    tracking metrics only those from warmup_s on (the only samples kept). vehicle_ids: the samples' rows, for
    naming the closest pairs (default 1..K). Frames and tick timings are added by the caller after the
    warm-up only.
    """

    def __init__(
        self, *, obstacles: Sequence[Obstacle] = (), warmup_s: float = 0.0, vehicle_ids: Sequence[int] = ()
    ) -> None:
        self._obstacles = tuple(obstacles)
        self._warmup_s = float(warmup_s)
        self._safety = FlightSafety(obstacles=obstacles, vehicle_ids=vehicle_ids)
        self._samples: list[TickSample] = []
        self._in_frame: list[bool] = []
        self._detected: list[bool] = []
        self._offsets: list[float] = []
        self._tick_s: list[float] = []

    def add_tick(self, sample: TickSample) -> None:
        """One control tick: into the safety minima always, kept for tracking from the warm-up's end on."""
        self._safety.add(sample)
        if sample.t_s >= self._warmup_s - WARMUP_EPS_S:
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
            safety=self._safety,
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


def closest_pair(points_m: np.ndarray) -> tuple[float, int, int]:
    """(distance, i, j) of the two closest of points (K, 3), i < j, 3-D; (inf, -1, -1) for K < 2."""
    if len(points_m) < 2:
        return math.inf, -1, -1
    diff = points_m[:, None, :] - points_m[None, :, :]
    dist = np.sqrt(np.einsum("ijk,ijk->ij", diff, diff))
    rows, cols = _pairs(len(points_m))
    pair_dist = dist[rows, cols]
    best = int(pair_dist.argmin())
    return float(pair_dist[best]), int(rows[best]), int(cols[best])


@functools.cache
def _pairs(k: int) -> tuple[np.ndarray, np.ndarray]:
    """np.triu_indices(k, 1), read-only: the pairs of k points, asked twice a tick for the same k."""
    rows, cols = np.triu_indices(k, 1)
    rows.setflags(write=False)
    cols.setflags(write=False)
    return rows, cols


def min_pair_distance_m(points_m: np.ndarray) -> float:
    """Smallest 3-D distance between any two of points (K, 3); inf for K < 2."""
    return closest_pair(points_m)[0]


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
    safety: FlightSafety | None = None,
) -> dict[str, Any]:
    """Reduce the recorded run to the report's metrics (module docstring). safety: the whole flight's minima;
    None takes them from `samples` alone."""
    if safety is None:
        safety = FlightSafety(obstacles=obstacles)
        for s in samples:
            safety.add(s)
    errors, traces, spacing, dist_err, height_err = [], [], [], [], []
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
    flight = safety.metrics()
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
        "min_separation_m": flight.pop("min_separation_m"),
        "min_obstacle_clearance_m": flight.pop("min_obstacle_clearance_m"),
        "min_person_distance_m": flight.pop("min_person_distance_m"),
        "tick_ms": _stats(ticks_ms, keys=("median", "p99")),
        "realtime_factor": _num(sim_s / wall_s) if wall_s > 0 else None,
        "estimate_fraction": _num(with_estimate / formation_slots) if formation_slots else None,
        **flight,
        "frames": int(frames.size),
        "samples": len(samples),
    }

"""Separation geometry shared by the ground station's state and the runs' safety metrics: how close MAVs are
to each other and to trunks and obstacles. Pure functions of positions and obstacles, so the station's view
and the reports measure clearance with the same maths.

An obstacle is a vertical cylinder standing on the ground; a point's clearance to it is the horizontal
distance to its surface (negative inside), counted only while the point is below its top.
"""

from __future__ import annotations

import math
from collections.abc import Collection, Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from controller.messages import Obstacle


@dataclass(frozen=True)
class Separation:
    """One MAV's separation: 3-D distance to its closest airborne teammate and that teammate's id, and its
    clearance to the nearest trunk or obstacle surface it is below the top of; None where not applicable
    (on the ground, alone in the air, no obstacle beside it)."""

    nearest_teammate_m: float | None = None
    nearest_teammate_id: int | None = None
    nearest_obstacle_m: float | None = None


@dataclass(frozen=True, eq=False)
class Cylinders:
    """Obstacles as the arrays the clearance maths reads: axis centres (M, 2), radii (M,) and tops (M,).
    Built once for a flight's per-tick safety minima, so a tick does not rebuild them from the `Obstacle`
    objects."""

    centers_m: np.ndarray
    radii_m: np.ndarray
    tops_m: np.ndarray

    @classmethod
    def of(cls, obstacles: Sequence[Obstacle]) -> Cylinders:
        return cls(
            centers_m=np.array([o.center_m for o in obstacles]),
            radii_m=np.array([o.radius_m for o in obstacles]),
            tops_m=np.array([o.height_m for o in obstacles]),
        )

    def __len__(self) -> int:
        return len(self.radii_m)


def _clearances_m(points_m: np.ndarray, cylinders: Cylinders) -> np.ndarray:
    """(K, M) horizontal distance of each of points (K, 3) to each cylinder's surface (negative inside),
    inf where the point is not below the cylinder's top."""
    centers, radii, tops = cylinders.centers_m, cylinders.radii_m, cylinders.tops_m
    d = np.hypot(points_m[:, None, 0] - centers[None, :, 0], points_m[:, None, 1] - centers[None, :, 1])
    return np.where(points_m[:, None, 2] < tops[None, :], d - radii[None, :], np.inf)


def obstacle_clearances_m(points_m: np.ndarray, obstacles: Sequence[Obstacle]) -> np.ndarray:
    """(K,) horizontal distance of each of points (K, 3) to the nearest surface of a vertical cylinder it is
    below the top of (negative inside one); inf where there is none."""
    points_m = np.asarray(points_m, dtype=float).reshape(-1, 3)
    if not obstacles or len(points_m) == 0:
        return np.full(len(points_m), math.inf)
    return np.min(_clearances_m(points_m, Cylinders.of(obstacles)), axis=1)


def closest_obstacle(points_m: np.ndarray, cylinders: Cylinders) -> tuple[float, int, int]:
    """(clearance, point, cylinder) of the smallest clearance of points (K, 3) to the cylinders (as
    `obstacle_clearances_m`); (inf, -1, -1) if none counts."""
    points_m = np.asarray(points_m, dtype=float).reshape(-1, 3)
    if not len(cylinders) or len(points_m) == 0:
        return math.inf, -1, -1
    clearance = _clearances_m(points_m, cylinders)
    i, j = divmod(int(clearance.argmin()), clearance.shape[1])
    if not math.isfinite(clearance[i, j]):
        return math.inf, -1, -1
    return float(clearance[i, j]), i, j


def obstacle_clearance_m(points_m: np.ndarray, obstacles: Sequence[Obstacle]) -> float:
    """Smallest horizontal distance of points (K, 3) to the surface of a vertical cylinder they are below the
    top of (negative inside one); inf without obstacles."""
    clearances = obstacle_clearances_m(points_m, obstacles)
    return float(np.min(clearances)) if clearances.size else math.inf


def separations(
    *,
    positions_m: Mapping[int, np.ndarray],
    airborne_ids: Collection[int],
    obstacles: Sequence[Obstacle],
) -> dict[int, Separation]:
    """Separation of every vehicle in positions_m (vehicle id -> (3,) ENU position): to the nearest other
    airborne vehicle (3-D) and to the nearest obstacle (`obstacle_clearances_m`). Only airborne vehicles with
    a finite position count, as subjects and as teammates; the others get an empty `Separation`."""
    ids = sorted(
        vid
        for vid, p in positions_m.items()
        if vid in airborne_ids and np.all(np.isfinite(np.asarray(p, dtype=float)))
    )
    out = {vid: Separation() for vid in positions_m}
    if not ids:
        return out
    points = np.array([np.asarray(positions_m[vid], dtype=float) for vid in ids])
    diff = points[:, None, :] - points[None, :, :]
    dist = np.sqrt(np.einsum("ijk,ijk->ij", diff, diff))
    np.fill_diagonal(dist, math.inf)
    clearance = obstacle_clearances_m(points, obstacles)
    for i, vid in enumerate(ids):
        j = int(np.argmin(dist[i]))
        alone = not math.isfinite(dist[i, j])
        out[vid] = Separation(
            nearest_teammate_m=None if alone else float(dist[i, j]),
            nearest_teammate_id=None if alone else ids[j],
            nearest_obstacle_m=float(clearance[i]) if math.isfinite(clearance[i]) else None,
        )
    return out

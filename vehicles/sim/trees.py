"""Tree trunks as vertical-cylinder obstacles: the paper's 13, none, or N placed at random with a seed."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from controller.messages import Obstacle

# The paper's Gazebo world (docs/method.md#simulated-world), ENU x, y in metres.
PAPER_TREES_XY: tuple[tuple[float, float], ...] = (
    (-14.0, -7.0),
    (-15.0, -3.5),
    (13.0, -3.0),
    (13.0, 3.0),
    (-12.0, 6.0),
    (-10.0, 10.0),
    (-2.0, 9.0),
    (3.0, 9.5),
    (4.0, -9.0),
    (8.0, -9.0),
    (12.0, 10.0),
    (0.0, 5.0),
    (-5.0, -7.0),
)
TREE_RADIUS_M = 0.3
TREE_HEIGHT_M = 12.0  # taller than the arena ceiling (10 m): a trunk is always an obstacle and an occluder


@dataclass(frozen=True)
class TreeSpec:
    """Which trees to plant: kind "paper", "none" or "random" (with `count`)."""

    kind: str
    count: int = 0

    @classmethod
    def parse(cls, text: str) -> TreeSpec:
        """Parse "paper", "none" or a non-negative integer N; raise ValueError with the accepted forms."""
        t = str(text).strip().lower()
        if t in ("paper", "none"):
            return cls(kind=t)
        try:
            n = int(t)
        except ValueError:
            raise ValueError(
                f"trees must be 'paper', 'none' or a number of random trees, got {text!r}"
            ) from None
        if not 0 <= n <= 200:
            raise ValueError(f"the number of random trees must be between 0 and 200, got {n}")
        return cls(kind="random", count=n)

    def __str__(self) -> str:
        return str(self.count) if self.kind == "random" else self.kind


def paper_trees(*, radius_m: float = TREE_RADIUS_M, height_m: float = TREE_HEIGHT_M) -> tuple[Obstacle, ...]:
    """The paper's 13 trees, ids tree-1..tree-13."""
    return tuple(
        Obstacle(
            obstacle_id=f"tree-{i + 1}",
            center_m=np.array(xy),
            radius_m=radius_m,
            height_m=height_m,
            kind="tree",
        )
        for i, xy in enumerate(PAPER_TREES_XY)
    )


def _distance_to_polyline(p: np.ndarray, path: np.ndarray) -> float:
    """Shortest distance from point p (2,) to the polyline path (M, 2)."""
    a, b = path[:-1], path[1:]
    ab = b - a
    den = np.maximum(np.einsum("ij,ij->i", ab, ab), 1e-12)
    t = np.clip(np.einsum("ij,ij->i", p - a, ab) / den, 0.0, 1.0)
    closest = a + t[:, None] * ab
    return float(np.min(np.hypot(*(closest - p).T)))


def random_trees(
    rng: np.random.Generator,
    *,
    count: int,
    arena_half_m: float = 19.0,
    keep_clear: Sequence[tuple[Sequence[float] | np.ndarray, float]] = (),
    keep_clear_path_xy_m: np.ndarray | None = None,
    path_clearance_m: float = 1.5,
    min_spacing_m: float = 2.0,
    radius_m: float = TREE_RADIUS_M,
    height_m: float = TREE_HEIGHT_M,
    max_attempts: int = 20000,
) -> tuple[Obstacle, ...]:
    """`count` trees placed uniformly in the square +-arena_half_m, rejecting spots that are within
    `min_spacing_m` of another tree, inside any keep_clear circle ((x, y), clearance_m) (the person's start,
    the MAVs' starts), or within `path_clearance_m` of the person's path (M, 2) when one is given.

    Raises ValueError when the trees cannot be placed in max_attempts draws (too many for the space left).
    """
    if count < 0:
        raise ValueError(f"count must be non-negative, got {count}")
    circles = [(np.asarray(c, dtype=float), float(r)) for c, r in keep_clear]
    placed: list[np.ndarray] = []
    attempts = 0
    while len(placed) < count:
        attempts += 1
        if attempts > max_attempts:
            raise ValueError(f"could not place {count} trees with the clearances asked; placed {len(placed)}")
        p = rng.uniform(-arena_half_m, arena_half_m, size=2)
        if any(np.hypot(*(p - c)) < r + radius_m for c, r in circles):
            continue
        if any(np.hypot(*(p - q)) < min_spacing_m for q in placed):
            continue
        if keep_clear_path_xy_m is not None and (
            _distance_to_polyline(p, keep_clear_path_xy_m) < path_clearance_m + radius_m
        ):
            continue
        placed.append(p)
    return tuple(
        Obstacle(obstacle_id=f"tree-{i + 1}", center_m=p, radius_m=radius_m, height_m=height_m, kind="tree")
        for i, p in enumerate(placed)
    )

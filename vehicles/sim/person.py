"""The tracked person: the paper's scripted walk, a seeded random walker, or a person standing still.

Every model answers `truth(t_s)` for any time (in any order), so the simulation, the metrics and a live
ground station can ask for the same instant and get the same answer. The position message of the person is
the body centre, 0.9 m above flat ground at z = 0; the person is 1.75 m tall (feet at 0, head at 1.75 m).
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from controller.angles import wrap_angle
from controller.messages import read_only
from vehicles.world import PERSON_CENTRE_HEIGHT_M, PersonTruth

STAND_STILL_S = 10.0  # the paper's person stands at the origin for 10 s before walking
PAPER_WALK_SPEED_MPS = 0.7
# The paper's path has a 15 m radius. With d_des = 8 m the MAVs then fly up to 23 m from the origin, outside
# the MPC's arena of +-20 m, so skyring scales the path to an 11 m radius: person + d_des + 1 m margin < 20 m.
PAPER_PATH_RADIUS_M = 11.0
RANDOM_ARENA_RADIUS_M = 11.0
PERSON_MODES = ("paper", "random", "still")  # the models below, by name


def _truth(t_s: float, xy: Sequence[float] | np.ndarray, vxy: Sequence[float] | np.ndarray) -> PersonTruth:
    """The truth at t_s from the ground position xy (2,) and velocity vxy (2,), in read-only arrays (which
    the truth takes without a copy)."""
    return PersonTruth(
        stamp_s=t_s,
        position_m=read_only(np.array([xy[0], xy[1], PERSON_CENTRE_HEIGHT_M], dtype=float)),
        velocity_mps=read_only(np.array([vxy[0], vxy[1], 0.0], dtype=float)),
    )


class StillPerson:
    """A person standing at position_xy_m (2,) for ever."""

    def __init__(self, position_xy_m=(0.0, 0.0)) -> None:
        self._xy = np.asarray(position_xy_m, dtype=float)
        if self._xy.shape != (2,) or not np.all(np.isfinite(self._xy)):
            raise ValueError("position_xy_m must be two finite numbers")

    def truth(self, t_s: float) -> PersonTruth:
        return _truth(t_s, self._xy, np.zeros(2))


def paper_path(*, radius_m: float = PAPER_PATH_RADIUS_M, points_per_m: float = 4.0) -> np.ndarray:
    """(M, 2) the paper's walk as a dense closed polyline from the origin back to it.

    Shape in units of the radius R (docs/method.md#simulated-world, scaled from R = 15 m): a sine
    (x, R/3 sin(2 pi x / R)) for x in 0..R; a clockwise arc of radius R about the origin from (R, 0) to
    (0, -R); an oscillating return (R/5 sin(4 pi y / R), y) from y = -R to 0.
    """
    if not (np.isfinite(radius_m) and radius_m > 0):
        raise ValueError(f"radius_m must be positive, got {radius_m}")
    r = radius_m
    n = max(int(points_per_m * r * 3), 16)
    x = np.linspace(0.0, r, n)
    sine = np.stack([x, r / 3.0 * np.sin(2.0 * np.pi * x / r)], axis=1)
    ang = np.linspace(0.0, -np.pi / 2.0, n)
    arc = np.stack([r * np.cos(ang), r * np.sin(ang)], axis=1)
    y = np.linspace(-r, 0.0, n)
    ret = np.stack([r / 5.0 * np.sin(4.0 * np.pi * y / r), y], axis=1)
    return np.concatenate([sine, arc[1:], ret[1:]])


class PathPerson:
    """A person who stands still for `start_delay_s`, then walks `path_xy_m` (M, 2) at `speed_mps`,
    looping."""

    def __init__(
        self,
        *,
        path_xy_m: np.ndarray,
        speed_mps: float = PAPER_WALK_SPEED_MPS,
        start_delay_s: float = STAND_STILL_S,
    ) -> None:
        path = np.asarray(path_xy_m, dtype=float)
        if path.ndim != 2 or path.shape[1] != 2 or len(path) < 2 or not np.all(np.isfinite(path)):
            raise ValueError("path_xy_m must be a finite (M >= 2, 2) array")
        if not (speed_mps > 0 and start_delay_s >= 0):
            raise ValueError("speed_mps must be positive and start_delay_s non-negative")
        seg = np.diff(path, axis=0)
        seg_len = np.hypot(seg[:, 0], seg[:, 1])
        keep = np.concatenate([[True], seg_len > 1e-9])
        self._path = path[keep]
        seg = np.diff(self._path, axis=0)
        seg_len = np.hypot(seg[:, 0], seg[:, 1])
        self._s = np.concatenate([[0.0], np.cumsum(seg_len)])
        # truth() works on plain-float copies: numpy's per-call cost on one segment was most of its work
        self._s_list: list[float] = self._s.tolist()
        self._path_xy: list[list[float]] = self._path.tolist()
        self._dir_xy: list[list[float]] = (seg / seg_len[:, None]).tolist()
        self._speed = float(speed_mps)
        self._delay = float(start_delay_s)

    @property
    def path_xy_m(self) -> np.ndarray:
        """(M, 2) the polyline walked."""
        return self._path

    @property
    def loop_length_m(self) -> float:
        return float(self._s[-1])

    def truth(self, t_s: float) -> PersonTruth:
        walked = max(t_s - self._delay, 0.0) * self._speed
        if walked <= 0.0:
            return _truth(t_s, self._path_xy[0], (0.0, 0.0))
        s = float(walked % self._s[-1])  # numpy's remainder, as a float64 is the right operand
        i = min(bisect.bisect_right(self._s_list, s) - 1, len(self._dir_xy) - 1)  # np.searchsorted, "right"
        (px, py), (dx, dy) = self._path_xy[i], self._dir_xy[i]
        along = s - self._s_list[i]
        return _truth(t_s, (px + dx * along, py + dy * along), (dx * self._speed, dy * self._speed))


@dataclass(frozen=True)
class RandomWalkParams:
    """Behaviour mix of the random person: speeds m/s, durations s, turn and acceleration limits."""

    walk_speed_mps: tuple[float, float] = (0.5, 1.4)
    run_speed_mps: tuple[float, float] = (2.0, 3.0)
    walk_s: tuple[float, float] = (4.0, 12.0)
    run_s: tuple[float, float] = (2.0, 6.0)
    stop_s: tuple[float, float] = (2.0, 6.0)
    turn_max_rad: float = 2.0 * np.pi / 3.0
    turn_rate_radps: float = np.pi / 2.0
    accel_mps2: float = 1.5
    arena_radius_m: float = RANDOM_ARENA_RADIUS_M
    step_s: float = 0.05


class RandomPerson:
    """A seeded random walker: stands still, then mixes walking, running (up to 3 m/s), stops and turns.

    It steers back towards the centre when it comes within 2 m of `arena_radius_m` and never leaves that disc.
    The trajectory is generated lazily on a fixed grid of `step_s` and linearly interpolated, so `truth(t)` is
    the same whatever order the times are asked in.
    """

    _BEHAVIOURS = ("walk", "walk", "run", "stop", "turn")

    def __init__(
        self,
        rng: np.random.Generator,
        *,
        params: RandomWalkParams = RandomWalkParams(),
        start_delay_s: float = STAND_STILL_S,
    ) -> None:
        self._rng = rng
        self._p = params
        self._delay = float(start_delay_s)
        # The trajectory on its grid, (x, y) and (vx, vy) as plain floats: truth() interpolates it for every
        # camera frame, and numpy's per-call cost on two numbers was most of the work.
        self._xy: list[tuple[float, float]] = [(0.0, 0.0)]
        self._v: list[tuple[float, float]] = [(0.0, 0.0)]
        self._heading = float(rng.uniform(-np.pi, np.pi))
        self._speed = 0.0
        self._target_speed = 0.0
        self._behaviour_left_s = 0.0
        self._target_heading = self._heading

    def _next_behaviour(self) -> None:
        p, rng = self._p, self._rng
        kind = self._BEHAVIOURS[int(rng.integers(len(self._BEHAVIOURS)))]
        if kind == "walk":
            self._target_speed = float(rng.uniform(*p.walk_speed_mps))
            self._behaviour_left_s = float(rng.uniform(*p.walk_s))
        elif kind == "run":
            self._target_speed = float(rng.uniform(*p.run_speed_mps))
            self._behaviour_left_s = float(rng.uniform(*p.run_s))
        elif kind == "stop":
            self._target_speed = 0.0
            self._behaviour_left_s = float(rng.uniform(*p.stop_s))
        else:
            self._target_heading = self._heading + float(rng.uniform(-p.turn_max_rad, p.turn_max_rad))
            self._target_speed = float(rng.uniform(*p.walk_speed_mps))
            self._behaviour_left_s = float(rng.uniform(*p.walk_s))

    def _step(self) -> None:
        p = self._p
        dt = p.step_s
        x, y = self._xy[-1]
        if self._behaviour_left_s <= 0.0:
            self._next_behaviour()
        self._behaviour_left_s -= dt
        r = float(np.hypot(x, y))
        if r > p.arena_radius_m - 2.0:
            self._target_heading = math.atan2(-y, -x)
        err = wrap_angle(self._target_heading - self._heading)
        self._heading += float(np.clip(err, -p.turn_rate_radps * dt, p.turn_rate_radps * dt))
        dv = np.clip(self._target_speed - self._speed, -p.accel_mps2 * dt, p.accel_mps2 * dt)
        self._speed = float(self._speed + dv)
        vx, vy = self._speed * math.cos(self._heading), self._speed * math.sin(self._heading)
        x, y = x + vx * dt, y + vy * dt
        rn = float(np.hypot(x, y))
        if rn > p.arena_radius_m:
            scale = p.arena_radius_m / rn
            x, y = x * scale, y * scale
        self._xy.append((x, y))
        self._v.append((vx, vy))

    def truth(self, t_s: float) -> PersonTruth:
        if not np.isfinite(t_s):
            raise ValueError(f"time must be finite, got {t_s}")
        walked_s = max(t_s - self._delay, 0.0)
        k = walked_s / self._p.step_s
        i = int(k)
        while len(self._xy) < i + 2:
            self._step()
        a = k - i
        (x0, y0), (x1, y1) = self._xy[i], self._xy[i + 1]
        xy = ((1.0 - a) * x0 + a * x1, (1.0 - a) * y0 + a * y1)
        return _truth(t_s, xy, self._v[i + 1] if walked_s > 0 else (0.0, 0.0))

"""The teammates' latest horizon plans, kept in preallocated arrays updated when a plan arrives.

`fields.teammate_paths` builds the same `TeammatePaths` from a list of plans, stacking and checking every plan
again on every tick; at 100 Hz that re-does for each tick what only changes when a message arrives (10 Hz per
teammate). `TeammateTable` checks a plan once, on arrival, stores it in a row of fixed arrays (rows in vehicle
id order, the order `teammate_paths` sees them in), and per tick aligns the fresh rows to our horizon with one
compiled kernel. Same numbers as `teammate_paths` (tests/controller/test_teammates.py).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence

import numba
import numpy as np

from controller.fields import (
    SANE_ABS,
    FieldParams,
    TeammatePaths,
    covariance_radius_m,
    teammate_paths,
)
from controller.messages import HorizonPlan
from controller.scalar_kernels import age_term_m, maximum, minimum

# A TeammateTable's columns as `fresh_paths` reads them (`TeammateTable.kernel_columns`)
TableColumns = tuple[
    np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray
]


@numba.njit(cache=True)
def align_rows(
    positions, lengths, stamps, plan_dts, rows, now_s, dt_s, current_only, out
):  # pragma: no cover - compiled; tested against fields._aligned
    """out[i] (steps, 3) = plan rows[i] (positions (R, L, 3), valid length lengths[row]) sampled at our times
    now_s + n dt_s: shifted by its age and linearly interpolated, held before x(0) and after its end (the
    arithmetic of fields._aligned); current_only holds x(0) over the horizon (the price baseline)."""
    steps = out.shape[1]
    for i in range(rows.shape[0]):
        r = rows[i]
        last = lengths[r] - 1
        for n in range(steps):
            if current_only:
                lo, hi, a = 0, 0, 0.0
            else:
                t = now_s + dt_s * n
                k = (t - stamps[r]) / plan_dts[r]
                if k < 0.0:
                    k = 0.0
                elif k > last:
                    k = float(last)
                lo = min(int(k), last)
                hi = min(lo + 1, last)
                a = k - lo
            for c in range(3):
                out[i, n, c] = (1.0 - a) * positions[r, lo, c] + a * positions[r, hi, c]


@numba.njit(cache=True)
def fresh_paths(
    positions,
    lengths,
    stamps,
    plan_dts,
    radii,
    row_ids,
    in_formation,
    offsets,
    rows,
    now_s,
    dt_s,
    current_only,
    radius_cap,
    d_max_head,
    speed,
    grace,
    out,
    ids_out,
    in_formation_out,
    offsets_out,
    d_max_out,
    ages_out,
):  # pragma: no cover - compiled; tested against the numpy form in tests/controller/test_teammates.py
    """Everything `TeammateTable.paths` gives for the table's rows `rows` (R,), in one call: their plans
    aligned to our horizon into out (R, steps, 3) (`align_rows`), their ids, in-formation flags and GPS
    offsets, eq. 15's d_max = (d_max_head + min(r_j, radius_cap)) + speed * max(age - grace, 0) with
    d_max_head = base + our own capped radius, and the ages max(now - stamp, 0). numpy's operations in numpy's
    order, its minimum and maximum included (`scalar_kernels`): the same bits."""
    align_rows(positions, lengths, stamps, plan_dts, rows, now_s, dt_s, current_only, out)
    for i in range(rows.shape[0]):
        r = rows[i]
        ids_out[i] = row_ids[r]
        in_formation_out[i] = in_formation[r]
        for c in range(3):
            offsets_out[i, c] = offsets[r, c]
        age = now_s - stamps[r]
        d_max_out[i] = (d_max_head + minimum(radii[r], radius_cap)) + age_term_m(age, speed, grace)
        ages_out[i] = maximum(age, 0.0)


@numba.njit(cache=True)
def _all_below(values, limit):  # pragma: no cover - compiled
    """Whether every |value| of a 2-D array is below limit (False for a NaN), without numpy's per-call cost:
    every plan of every teammate is checked on arrival."""
    for row in values:
        for v in row:
            if not abs(v) < limit:
                return False
    return True


@functools.lru_cache(maxsize=256)
def _usable(plan: HorizonPlan) -> bool:
    """Whether a plan's numbers can be stored: a finite stamp, a finite step > 0, at least 2 states, every
    position and covariance entry finite and within SANE_ABS. Remembered: the links hand the same plan
    object to every teammate (each of K tables checks it), and a plan cannot change (frozen, read-only
    arrays)."""
    return (
        math.isfinite(plan.stamp_s)
        and math.isfinite(plan.dt_s)
        and plan.dt_s > 0.0
        and plan.positions_m.shape[0] >= 2
        and _all_below(plan.positions_m, SANE_ABS)
        and _all_below(plan.position_cov_m2, SANE_ABS)
    )


class TeammateView:
    """What the formation controller gets of a `TeammateTable` for one tick: the plans stamped at or after
    since_s, then the extra plans (the agent's phantoms, stand-ins for unheard teammates)."""

    __slots__ = ("table", "since_s", "extra")

    def __init__(self, table: TeammateTable, since_s: float, extra: Sequence[HorizonPlan] = ()) -> None:
        self.table = table
        self.since_s = since_s
        self.extra = extra

    def plans(self) -> tuple[HorizonPlan, ...]:
        """The plans this view stands for, as messages: the fresh stored ones by id, then the extra ones."""
        fresh = tuple(p for p in self.table.plans() if p.stamp_s >= self.since_s)
        return fresh + tuple(self.extra)

    def __iter__(self):
        return iter(self.plans())

    def paths(
        self,
        *,
        now_s: float,
        dt_s: float,
        steps: int,
        own_cov_radius_m: float,
        params: FieldParams,
        current_position_only: bool = False,
    ) -> TeammatePaths:
        return self.table.paths(
            now_s=now_s,
            dt_s=dt_s,
            steps=steps,
            since_s=self.since_s,
            own_cov_radius_m=own_cov_radius_m,
            params=params,
            extra=self.extra,
            current_position_only=current_position_only,
        )


class TeammateTable:
    """The latest plan of each teammate of MAV `own_id`, checked once and kept in arrays.

    `update(plan)` stores a plan (or refuses it: False); `paths(...)` gives the `TeammatePaths` of the plans
    not older than a limit, plus optional extra plans (the agent's phantoms), for the formation controller.
    """

    _COLUMNS = (
        "_positions",
        "_offsets",
        "_lengths",
        "_stamps",
        "_dts",
        "_radii",
        "_in_formation",
        "_row_ids",
    )

    def __init__(self, *, own_id: int, plan_length: int, capacity: int = 16) -> None:
        self._own = int(own_id)
        self._plans: dict[int, HorizonPlan] = {}
        self._row_of: dict[int, int] = {}  # vehicle id -> its row
        self._count = 0
        capacity, length = max(int(capacity), 1), max(int(plan_length), 2)
        # Row r holds one teammate's latest plan: positions (capacity, length, 3), the sender's GPS offset
        # relative to the team (capacity, 3), its valid length, stamp, step, covariance radius, in-formation
        # flag and vehicle id; rows sorted by vehicle id.
        self._positions = np.zeros((capacity, length, 3))
        self._offsets = np.zeros((capacity, 3))
        self._lengths = np.zeros(capacity, dtype=np.int64)
        self._stamps = np.zeros(capacity)
        self._dts = np.ones(capacity)
        self._radii = np.zeros(capacity)
        self._in_formation = np.zeros(capacity, dtype=np.bool_)
        self._row_ids = np.zeros(capacity, dtype=np.int64)
        # (vehicle id, stamp, in formation) of each row as Python values: what the agent asks of the table
        # every tick (fresh_count, fresh_ids), answered without numpy's per-call cost on a few rows.
        self._heard: list[tuple[int, float, bool]] = []

    def _grow(self, capacity: int, length: int) -> None:
        """Re-allocate every column for `capacity` rows of `length` states, keeping the stored rows."""
        old = self._count
        for name in self._COLUMNS:
            column = getattr(self, name)
            shape = (capacity, length, 3) if name == "_positions" else (capacity, *column.shape[1:])
            grown = (np.ones if name == "_dts" else np.zeros)(shape, dtype=column.dtype)
            grown[(slice(old), *map(slice, column.shape[1:]))] = column[:old]
            setattr(self, name, grown)

    @property
    def count(self) -> int:
        return self._count

    def plans(self) -> tuple[HorizonPlan, ...]:
        """The stored plans, by vehicle id."""
        return tuple(self._plans[int(v)] for v in self._row_ids[: self._count])

    def view(self, since_s: float, extra: Sequence[HorizonPlan] = ()) -> TeammateView:
        return TeammateView(self, since_s, extra)

    def fresh_ids(self, since_s: float, *, in_formation: bool = True) -> set[int]:
        """Vehicle ids of the plans stamped at or after since_s (only in-formation ones by default)."""
        return {
            vid for vid, stamp, flying in self._heard if stamp >= since_s and (flying or not in_formation)
        }

    def update(self, plan: HorizonPlan) -> str:
        """Store `plan` as its teammate's latest: "stored"; "older" (an older plan than the stored one, not an
        error: nothing changes); "refused" (ours, or unusable: non-finite or beyond 1000 km numbers, a
        non-positive step, fewer than 2 states)."""
        vid = int(plan.vehicle_id)
        if vid == self._own or not _usable(plan):
            return "refused"
        positions, cov = plan.positions_m, plan.position_cov_m2
        old = self._plans.get(vid)
        if old is not None and plan.stamp_s < old.stamp_s:
            return "older"
        if old is None:
            row = int(np.searchsorted(self._row_ids[: self._count], vid))
            if self._count == self._positions.shape[0]:
                self._grow(2 * self._count, self._positions.shape[1])
            for name in self._COLUMNS:
                arr = getattr(self, name)
                arr[row + 1 : self._count + 1] = arr[row : self._count].copy()
            self._count += 1
            self._row_ids[row] = vid
            self._heard.insert(row, (vid, -math.inf, False))  # filled in below, with the other columns
            self._row_of = {int(v): r for r, v in enumerate(self._row_ids[: self._count].tolist())}
        row = self._row_of[vid]
        length = positions.shape[0]
        if length > self._positions.shape[1]:
            self._grow(self._positions.shape[0], length)
        if old is None or old.position_cov_m2 is not cov:  # the sender's covariance rarely changes
            self._radii[row] = covariance_radius_m(cov)
        self._plans[vid] = plan
        self._positions[row, :length] = positions
        self._lengths[row] = length
        self._stamps[row] = plan.stamp_s
        self._dts[row] = plan.dt_s
        self._in_formation[row] = plan.in_formation
        self._heard[row] = (vid, float(plan.stamp_s), bool(plan.in_formation))
        self._offsets[row] = plan.gps_offset_m
        return "stored"

    def fresh_count(self, since_s: float, *, in_formation: bool = True) -> int:
        """How many stored plans are stamped at or after since_s (only in-formation ones by default)."""
        return len(self.fresh_ids(since_s, in_formation=in_formation))  # one row per vehicle id

    def fresh_rows(self, since_s: float) -> np.ndarray:
        """(J,) int64: the rows whose plans are stamped at or after since_s."""
        return (self._stamps[: self._count] >= since_s).nonzero()[0]  # np.flatnonzero without its wrapper

    def kernel_columns(self) -> TableColumns:
        """The columns `fresh_paths` reads, in its order: positions (C, L, 3), valid lengths (C,), stamps
        (C,) s, steps (C,) s, covariance radii (C,) m, vehicle ids (C,), in-formation flags (C,), GPS
        offsets (C, 3) m (C rows of capacity; rows beyond `count` are unused)."""
        return (
            self._positions,
            self._lengths,
            self._stamps,
            self._dts,
            self._radii,
            self._row_ids,
            self._in_formation,
            self._offsets,
        )

    def paths(
        self,
        *,
        now_s: float,
        dt_s: float,
        steps: int,
        since_s: float,
        own_cov_radius_m: float,
        params: FieldParams,
        extra: Sequence[HorizonPlan] = (),
        current_position_only: bool = False,
    ) -> TeammatePaths:
        """The plans stamped at or after since_s, aligned to our horizon (now_s + n dt_s, n < steps), with
        their eq. 15 d_max (as fields.teammate_paths), then the extra plans (through teammate_paths)."""
        rows = self.fresh_rows(since_s)
        count = rows.shape[0]
        out = np.empty((count, steps, 3))
        ids, flying, offsets = np.empty(count, np.int64), np.empty(count, np.bool_), np.empty((count, 3))
        d_max, ages = np.empty(count), np.empty(count)
        cap = params.covariance_radius_cap_m
        fresh_paths(
            *self.kernel_columns(),
            rows,
            float(now_s),
            float(dt_s),
            current_position_only,
            cap,
            params.teammate_d_max_head_m(own_cov_radius_m),
            params.teammate_speed_mps,
            params.teammate_age_grace_s,
            out,
            ids,
            flying,
            offsets,
            d_max,
            ages,
        )
        mates = TeammatePaths(out, ids, flying, d_max, 0, ages, offsets)
        if not extra:
            return mates
        more = teammate_paths(
            extra,
            now_s=now_s,
            dt_s=dt_s,
            steps=steps,
            own_cov_radius_m=own_cov_radius_m,
            params=params,
            current_position_only=current_position_only,
        )
        more_offsets = more.gps_offsets_m if more.gps_offsets_m is not None else np.zeros((0, 3))
        return TeammatePaths(
            np.concatenate([out, more.positions_m]),
            np.concatenate([mates.vehicle_ids, more.vehicle_ids]),
            np.concatenate([mates.in_formation, more.in_formation]),
            np.concatenate([d_max, more.d_max_m]),
            more.rejected,
            np.concatenate([ages, more.ages]),
            np.concatenate([offsets, more_offsets]),
        )

"""Where the MPC starts, where it aims, and which of its states becomes the way-point.

The paper's terminal reference (eq. 4): the point at horizontal distance d_des from the person along the
person->MAV bearing, h_des above the person, with the person's velocity (vertical 0). Three choices were made
by measurement in closed loop (docs/method.md#terminal-reference-and-way-point):

1. pass-through: the terminal reference is moved by what the external inputs alone add over the horizon
   (`input_displacement`), so the MPC no longer cancels them and the paper's weights keep every direction
   damped;
2. the plan starts from the previous plan's state at `now` while the measured state is within a leash
   (`initial_state`), because the autopilot tracks that plan, not the measurement;
3. the way-point is the plan's state one step ahead: further ahead, the autopilot's position gain turns the
   lead into positive velocity feedback.

All functions are pure; arrays are ENU, metres, seconds.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from controller.messages import read_only


@dataclass(frozen=True)
class ReferenceParams:
    """Choices of the formation controller's reference (docs/method.md#terminal-reference-and-way-point).

    waypoint_step: which plan state x(k), v(k) is sent to the autopilot (1..N+1).
    leash_position_m, leash_velocity_mps: how far the measured state may be from the previous plan's state at
        `now` before the plan is re-anchored towards the measurement (0 = always plan from the measurement).
    pass_through: move the terminal reference by what the external inputs add over the horizon (see 1. above).
    predict_person: aim at the person's constant-velocity prediction at the horizon end (N+1) dt ahead instead
        of the current estimate (else the MAVs trail a walking person's circle).
    """

    waypoint_step: int = 1
    leash_position_m: float = 1.0
    leash_velocity_mps: float = 1.0
    pass_through: bool = True
    predict_person: bool = True

    def __post_init__(self) -> None:
        if self.waypoint_step < 1:
            raise ValueError(f"waypoint_step must be >= 1, got {self.waypoint_step}")
        for name in ("leash_position_m", "leash_velocity_mps"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value >= 0.0):
                raise ValueError(f"ReferenceParams.{name} must be a finite number >= 0, got {value}")


def leashed(measured: np.ndarray, reference: np.ndarray, leash: float) -> np.ndarray:
    """The reference if it lies within `leash` of the measurement, else the point on the leash towards it."""
    gap = reference - measured
    dist = math.sqrt(float(gap @ gap))  # np.linalg.norm's own formula for a vector
    if dist <= leash:
        return reference.copy()
    return measured + gap * (leash / dist)


def initial_state(
    *,
    measured_position_m: np.ndarray,
    measured_velocity_mps: np.ndarray,
    reference_position_m: np.ndarray | None,
    reference_velocity_mps: np.ndarray | None,
    params: ReferenceParams,
) -> tuple[np.ndarray, np.ndarray]:
    """(3,) position and (3,) velocity the MPC starts from: the previous plan's state at now, on a leash.

    reference_*: the previous plan evaluated at now, or None when there is no usable previous plan.
    """
    if reference_position_m is None or reference_velocity_mps is None:
        return measured_position_m.copy(), measured_velocity_mps.copy()
    return (
        leashed(measured_position_m, reference_position_m, params.leash_position_m),
        leashed(measured_velocity_mps, reference_velocity_mps, params.leash_velocity_mps),
    )


def plan_state_at(
    positions_m: np.ndarray, velocities_mps: np.ndarray, *, elapsed_s: float, dt_s: float
) -> tuple[np.ndarray, np.ndarray]:
    """(3,) position and velocity of a plan (float64 (N+2, 3), a HorizonPlan's) `elapsed_s` after its x(0),
    linearly interpolated and held at the last state; read-only, so a message takes them without a copy.

    On Python floats (numpy's own IEEE operations, in its order): it runs twice per controller tick, and
    numpy's per-call cost on two (3,) rows is most of its time.
    """
    last = len(positions_m) - 1
    k = min(max(elapsed_s / dt_s, 0.0), float(last))
    lo = min(math.floor(k), last)
    hi = min(lo + 1, last)
    a = k - lo
    return _blend(positions_m, lo, hi, a), _blend(velocities_mps, lo, hi, a)


def _blend(rows: np.ndarray, lo: int, hi: int, a: float) -> np.ndarray:
    """(1 - a) rows[lo] + a rows[hi] as a read-only (3,) array, computed on Python floats."""
    b = 1.0 - a
    (x0, y0, z0), (x1, y1, z1) = rows[lo].tolist(), rows[hi].tolist()
    return read_only(np.array([b * x0 + a * x1, b * y0 + a * y1, b * z0 + a * z1]))


def plan_acceleration_at(velocities_mps: np.ndarray, *, elapsed_s: float, dt_s: float) -> np.ndarray:
    """(3,) acceleration of a plan (velocities (N+2, 3)) over the step that begins at or before `elapsed_s`
    after its x(0): the plan's u + f + g on that step, what the autopilot is told as feed-forward. Zero from
    the last state on (the plan is held there). Read-only, so a message takes it without a copy."""
    last = len(velocities_mps) - 1
    lo = math.floor(max(elapsed_s / dt_s, 0.0) + 1e-9)  # a whole step's time may land just below it
    if lo >= last:
        return read_only(np.zeros(3))
    return read_only((np.asarray(velocities_mps[lo + 1], dtype=float) - velocities_mps[lo]) / dt_s)


def bearing_rad(*, from_m: np.ndarray, to_m: np.ndarray) -> float:
    """ENU angle of the horizontal direction from `from_m` to `to_m` (0 when they coincide horizontally)."""
    dx, dy = float(to_m[0] - from_m[0]), float(to_m[1] - from_m[1])
    if dx * dx + dy * dy < 1e-18:
        return 0.0
    return float(np.arctan2(dy, dx))


def terminal_reference(
    *,
    position_m: np.ndarray,
    person_position_m: np.ndarray,
    person_velocity_mps: np.ndarray,
    d_des_m: float,
    h_des_m: float,
    horizon_s: float,
    params: ReferenceParams,
    preferred_bearing_rad: float | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """The paper's terminal reference (eq. `cost`): (3,) position and (3,) velocity.

    The bearing is that of the MAV's start position seen from the person's *current* position (or the
    preferred bearing when given); the point lies d_des from the person's position at the horizon end
    (predicted with constant velocity when params.predict_person) and h_des above it; the velocity is the
    person's, vertical 0.
    """
    bearing = (
        bearing_rad(from_m=person_position_m, to_m=position_m)
        if preferred_bearing_rad is None
        else float(preferred_bearing_rad)
    )
    # On Python floats, numpy's own operations in its order (np.cos and np.sin kept): it runs every tick.
    px, py, pz = np.asarray(person_position_m, dtype=float).tolist()
    vx, vy, vz = np.asarray(person_velocity_mps, dtype=float).tolist()
    if params.predict_person:
        cx, cy, cz = px + vx * horizon_s, py + vy * horizon_s, pz + vz * horizon_s
    else:
        cx, cy, cz = px + 0.0, py + 0.0, pz + 0.0  # numpy's position + 0.0 (a -0.0 becomes 0.0)
    target = np.array([cx + d_des_m * np.cos(bearing), cy + d_des_m * np.sin(bearing), cz + h_des_m])
    return target, np.array([vx, vy, 0.0])


def input_displacement(external_inputs_mps2: np.ndarray, *, dt_s: float) -> tuple[np.ndarray, np.ndarray]:
    """(3,) position and (3,) velocity that inputs f(0..N) (N+1, 3) alone add to x(N+1) from rest.

    Each step is x(n+1) = A x(n) + B f(n), so f(n) moves the final position by dt^2 (N - n + 1/2) and the
    final velocity by dt.
    """
    n_steps = external_inputs_mps2.shape[0]
    weights = dt_s * dt_s * (n_steps - 1 - np.arange(n_steps) + 0.5)
    return weights @ external_inputs_mps2, dt_s * external_inputs_mps2.sum(axis=0)


def clip_into(position_m: np.ndarray, *, lower_m, upper_m) -> np.ndarray:
    """(3,) position clipped into the box [lower_m, upper_m]."""
    return np.asarray(position_m, dtype=float).clip(
        np.asarray(lower_m, dtype=float), np.asarray(upper_m, dtype=float)
    )

"""Messages exchanged between a MAV's parts and between teammates.

All positions are in the team's world frame: local ENU (x east, y north, z up), metres, with the origin at
the team's shared geodetic reference. Velocities are m/s in the same frame, times are seconds on the caller's
clock (simulated or wall time), yaw is radians, ENU convention (0 = east, counter-clockwise positive).

The dataclasses are frozen; numpy fields are converted to float arrays and made read-only on construction so a
message cannot change after it was sent.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import Enum

import numpy as np

_FLOAT64 = np.dtype(np.float64)  # what frozen_array takes as it is


def frozen_array(value, shape: tuple[int, ...], name: str) -> np.ndarray:
    """Return `value` as a read-only float64 array of `shape` (-1 = any length), or raise ValueError.

    A float64 array that is read-only already and owns its data is taken as it is (nobody holds a writable
    view of it): the controller hands over the arrays it has just computed this way (`read_only`), without a
    copy. Most fields of the messages built every tick are such arrays.
    """
    # cheapest tests first, and the dtype against a dtype (not the type, which numpy converts on every call)
    if (
        type(value) is np.ndarray
        and value.base is None
        and value.dtype == _FLOAT64
        and not value.flags.writeable
    ):
        arr = value
    else:
        arr = np.array(value, dtype=float)
        arr.setflags(write=False)  # a fresh copy: read-only before anyone sees it, even if it does not fit
    got = arr.shape
    if got != shape and not _fits(got, shape):
        raise ValueError(f"{name} must have shape {shape}, got {got}")
    return arr


def _fits(got: tuple[int, ...], shape: tuple[int, ...]) -> bool:
    """Whether an array of shape `got` has `shape` (-1 = any length). A plain loop: it runs for every field
    of every message whose shape has a -1."""
    if len(got) != len(shape):
        return False
    for want, size in zip(shape, got, strict=True):
        if want != -1 and want != size:
            return False
    return True


def read_only(arr: np.ndarray) -> np.ndarray:
    """Make `arr`, just computed and referenced by nobody else, read-only and return it: a message then takes
    it as it is (`frozen_array`) instead of copying it."""
    arr.setflags(write=False)
    return arr


def _freeze(obj, name: str, shape: tuple[int, ...]) -> None:
    """Replace field `name` of frozen dataclass `obj` by its `frozen_array` (left alone when it is one)."""
    value = getattr(obj, name)
    arr = frozen_array(value, shape, name)
    if arr is not value:
        object.__setattr__(obj, name, arr)


@dataclass(frozen=True, eq=False)
class VehicleState:
    """One MAV's own state as its autopilot reports it, in the world frame.

    position_m: (3,) ENU position; velocity_mps: (3,); yaw_rad: heading of the body (camera) axis;
    position_cov_m2: (3, 3) self-localisation covariance (GPS drift is not in it: it is unknown to the MAV).
    gps_offset_m: (3,) the MAV's estimate of its GPS offset relative to its team (controller/gps_offset.py;
    zeros: none), which places the teammates for the separation rows.
    """

    vehicle_id: int
    stamp_s: float
    position_m: np.ndarray
    velocity_mps: np.ndarray
    yaw_rad: float = 0.0
    position_cov_m2: np.ndarray = field(default_factory=lambda: read_only(np.eye(3) * 0.25))
    gps_offset_m: np.ndarray = field(default_factory=lambda: read_only(np.zeros(3)))

    def __post_init__(self) -> None:
        _freeze(self, "position_m", (3,))
        _freeze(self, "velocity_mps", (3,))
        _freeze(self, "position_cov_m2", (3, 3))
        _freeze(self, "gps_offset_m", (3,))


@dataclass(frozen=True, eq=False)
class Detection:
    """A world-frame measurement of the person's position by one MAV's camera and detector.

    position_m: (3,) the person's measured centre; cov_m2: (3, 3) its covariance (paper eqs. 1-2, converted
    from spherical camera coordinates); source_id: the MAV that made it; stamp_s: the image time.
    """

    source_id: int
    stamp_s: float
    position_m: np.ndarray
    cov_m2: np.ndarray

    def __post_init__(self) -> None:
        _freeze(self, "position_m", (3,))
        _freeze(self, "cov_m2", (3, 3))


@dataclass(frozen=True, eq=False)
class PersonEstimate:
    """The fused estimate of the person's state from one MAV's tracker replica, valid at stamp_s.

    position_m: (3,); velocity_mps: (3,); cov: (6, 6) covariance of [position, velocity] (m^2, m^2/s^2).
    """

    stamp_s: float
    position_m: np.ndarray
    velocity_mps: np.ndarray
    cov: np.ndarray

    def __post_init__(self) -> None:
        _freeze(self, "position_m", (3,))
        _freeze(self, "velocity_mps", (3,))
        _freeze(self, "cov", (6, 6))

    @property
    def position_cov_m2(self) -> np.ndarray:
        """(3, 3) covariance of the position: the fused person covariance shown as an ellipsoid."""
        return self.cov[:3, :3]

    @property
    def position_cov_trace_m2(self) -> float:
        """The position block's trace (m^2): np.trace's sum in its order, left to right (0.2 against 1.5 us;
        the simulator asks it of every MAV on every tick)."""
        cov = self.cov
        return float(cov[0, 0] + cov[1, 1] + cov[2, 2])


@dataclass(frozen=True, eq=False)
class HorizonPlan:
    """A MAV's planned trajectory over the MPC horizon, published to teammates and to the ground station.

    positions_m: (N+2, 3) states x(0)..x(N+1), where x(0) is the position the plan started from at stamp_s and
    x(n) is predicted n * dt_s later; velocities_mps: (N+2, 3) likewise. in_formation is False for a MAV that
    left formation control (landing, landed, link lost): teammates then avoid it but do not space around it.
    position_cov_m2: (3, 3) the sender's self-localisation covariance (for the guarantee's d_max).
    gps_offset_m: (3,) the sender's estimate of its GPS offset relative to its team
    (controller/gps_offset.py; zeros: none): where it is among its teammates is positions_m less this.
    """

    vehicle_id: int
    stamp_s: float
    dt_s: float
    positions_m: np.ndarray
    velocities_mps: np.ndarray
    in_formation: bool = True
    position_cov_m2: np.ndarray = field(default_factory=lambda: read_only(np.eye(3) * 0.25))
    gps_offset_m: np.ndarray = field(default_factory=lambda: read_only(np.zeros(3)))

    def __post_init__(self) -> None:
        _freeze(self, "positions_m", (-1, 3))
        _freeze(self, "velocities_mps", (-1, 3))
        _freeze(self, "position_cov_m2", (3, 3))
        _freeze(self, "gps_offset_m", (3,))
        if self.positions_m.shape != self.velocities_mps.shape or len(self.positions_m) < 1:
            raise ValueError("positions_m and velocities_mps must both be (N+2, 3)")

    def position_at(self, t_s: float) -> np.ndarray:
        """(3,) planned position at time t_s, holding the last state beyond the horizon and x(0) before it."""
        k = (t_s - self.stamp_s) / self.dt_s
        k = min(max(k, 0.0), len(self.positions_m) - 1.0)
        lo = int(np.floor(k))
        hi = min(lo + 1, len(self.positions_m) - 1)
        a = k - lo
        return (1.0 - a) * self.positions_m[lo] + a * self.positions_m[hi]


@dataclass(frozen=True, eq=False)
class Obstacle:
    """A vertical cylinder standing on the ground (a tree trunk, or an operator's virtual obstacle).

    center_m: (2,) ENU x, y of the axis; radius_m > 0; height_m > 0; kind: "tree", "virtual" or "vehicle".
    """

    obstacle_id: str
    center_m: np.ndarray
    radius_m: float
    height_m: float = 10.0
    kind: str = "tree"

    def __post_init__(self) -> None:
        _freeze(self, "center_m", (2,))
        if not (np.isfinite(self.radius_m) and self.radius_m > 0):
            raise ValueError(
                f"obstacle radius must be a positive finite number of metres, got {self.radius_m}"
            )
        if not (np.isfinite(self.height_m) and self.height_m > 0):
            raise ValueError(
                f"obstacle height must be a positive finite number of metres, got {self.height_m}"
            )


class SolveStatus(str, Enum):  # noqa: UP042 - str() and format() must stay as they are in reports
    """What the controller did this tick."""

    SOLVED = "solved"  # the MPC solved; its plan is applied
    BRAKING = "braking"  # the solver failed or an input was not finite: a braking plan is applied instead
    NO_PERSON = "no_person"  # no person estimate yet: hold position
    ESCAPE = "escape"  # the separation rows could not all hold: braking (and separating vertically) instead
    HOLD = "hold"  # a teammate unheard too long: rest where it is (vehicles/agent.py)


@dataclass(frozen=True, eq=False)
class ControlOutput:
    """One formation-controller step's result.

    plan: the horizon plan (published); waypoint_position_m (3,), waypoint_velocity_mps (3,) and
    waypoint_acceleration_mps2 (3,): the set-point for the autopilot, the plan's state waypoint_step ahead and
    its acceleration on the step from there (feed-forward); yaw_rad: heading that points the camera at the
    person; external_inputs: (N+1, 3) f(n) used in the plan (m/s^2); fault: a one-line reason when status is
    not SOLVED; solver_iterations and solver_time_s come from the solver's own report.
    """

    plan: HorizonPlan
    waypoint_position_m: np.ndarray
    waypoint_velocity_mps: np.ndarray
    yaw_rad: float
    status: SolveStatus
    external_inputs: np.ndarray
    fault: str | None = None
    solver_iterations: int = 0
    solver_time_s: float = 0.0
    waypoint_acceleration_mps2: np.ndarray = field(default_factory=lambda: read_only(np.zeros(3)))

    def __post_init__(self) -> None:
        _freeze(self, "waypoint_position_m", (3,))
        _freeze(self, "waypoint_velocity_mps", (3,))
        _freeze(self, "waypoint_acceleration_mps2", (3,))
        _freeze(self, "external_inputs", (-1, 3))

"""The autopilot interface every back-end implements (simulated, PX4 through MAVSDK).

Commands are requests: they return at once and their effect shows in later `state()` readings, so the same
synchronous agent core drives a stepped simulation and an asyncio PX4 link alike. Everything is in the team's
ENU world frame; conversion to NED/geodetic happens inside the PX4 back-end only.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from enum import Enum
from typing import Protocol

import numpy as np

from controller.messages import _freeze, read_only


class FlightMode(str, Enum):  # noqa: UP042 - str() and format() must stay as they are in reports
    """The autopilot's flight mode as skyring understands it (PX4 custom modes map onto these)."""

    UNKNOWN = "unknown"
    READY = "ready"  # on the ground, waiting
    TAKEOFF = "takeoff"
    HOLD = "hold"  # loiter at the current position
    OFFBOARD = "offboard"  # following skyring's set-points
    LAND = "land"
    RETURN = "return"
    MANUAL = "manual"  # a pilot (position/altitude/manual/stabilized): skyring does not fight for control


@dataclass(frozen=True, eq=False)
class AutopilotState:
    """One reading of a vehicle's telemetry, world ENU frame.

    position_m (3,), velocity_mps (3,), yaw_rad (ENU), roll_rad/pitch_rad (body attitude),
    position_cov_m2 (3, 3) self-localisation covariance; battery_fraction in [0, 1] or None when unknown;
    stamp_s: when this reading was taken (the caller's clock).
    link_lost: no telemetry for longer than the back-end's limit (PX4: 1 s); the other fields are the last
    known values and stamp_s says how old they are. released: a pilot or the autopilot's own failsafe took the
    vehicle out of offboard; skyring does not fight for control and ignores set-points until re-engaged
    (takeoff).

    What the autopilot itself says, beyond skyring's reading of it (empty or None when a back-end cannot
    tell): autopilot_mode: the autopilot's own mode name (PX4: "OFFBOARD", "LAND", "HOLD",
    "RETURN_TO_LAUNCH", ...), shown even where `mode` reads READY on the ground; failsafe: the autopilot runs
    one of its own failsafes now (PX4: a critical system status while armed), or the vehicle lands because of
    one the autopilot has already left, and failsafe_reason its words for it; can_arm: its pre-arm checks
    pass in its current mode (None: unknown); arming_refusal: its words for why the last arming or takeoff
    skyring asked for was refused (None once one succeeds).
    """

    vehicle_id: int
    stamp_s: float
    position_m: np.ndarray
    velocity_mps: np.ndarray
    yaw_rad: float
    armed: bool
    in_air: bool
    mode: FlightMode
    roll_rad: float = 0.0
    pitch_rad: float = 0.0
    battery_fraction: float | None = None
    healthy: bool = True
    position_cov_m2: np.ndarray = field(default_factory=lambda: read_only(np.eye(3) * 0.25))
    link_lost: bool = False
    released: bool = False
    autopilot_mode: str = ""
    failsafe: bool = False
    failsafe_reason: str | None = None
    can_arm: bool | None = None
    arming_refusal: str | None = None

    def __post_init__(self) -> None:
        _freeze(self, "position_m", (3,))
        _freeze(self, "velocity_mps", (3,))
        _freeze(self, "position_cov_m2", (3, 3))


@dataclass(frozen=True, eq=False)
class Setpoint:
    """An offboard set-point: ENU position_m (3,), velocity_mps (3,) and acceleration_mps2 (3,) feed-forward,
    yaw_rad (ENU), made at stamp_s. The acceleration is the plan's own (gravity not included): without it the
    cascade learns of a planned brake only from the position and velocity it falls behind by."""

    stamp_s: float
    position_m: np.ndarray
    velocity_mps: np.ndarray
    yaw_rad: float
    acceleration_mps2: np.ndarray = field(default_factory=lambda: read_only(np.zeros(3)))

    def __post_init__(self) -> None:
        _freeze(self, "position_m", (3,))
        _freeze(self, "velocity_mps", (3,))
        _freeze(self, "acceleration_mps2", (3,))
        # Plain floats: one set-point a tick per MAV, and numpy's per-call cost is most of a 10-value check.
        values = (
            *self.position_m.tolist(),
            *self.velocity_mps.tolist(),
            *self.acceleration_mps2.tolist(),
            self.yaw_rad,
        )
        if not all(map(math.isfinite, values)):
            raise ValueError("a set-point must be finite")


class Autopilot(Protocol):
    """What the agent and the ground station need from a vehicle's autopilot."""

    vehicle_id: int

    def state(self) -> AutopilotState | None:
        """The latest telemetry, or None before the first reading."""
        ...

    def send_setpoint(self, setpoint: Setpoint) -> None:
        """Follow this set-point (entering offboard if needed and allowed)."""

    def takeoff(self, height_m: float) -> None:
        """Arm and climb to height_m above the ground, then hold."""

    def hold(self) -> None:
        """Stop following set-points and hold position."""

    def land(self) -> None:
        """Land where it is and disarm."""

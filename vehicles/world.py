"""The world a mission flies in, as the mission and the cameras see it: the `World` and `Body` interfaces, and
the truth types they hand out (the person's true state, a body's true pose).

The embedded simulator implements them in `vehicles.sim.world`; a real deployment has no `World` truth (the
person is only known through detections).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from controller.messages import Detection, Obstacle, _freeze

PERSON_HEIGHT_M = 1.75
PERSON_CENTRE_HEIGHT_M = 0.9


@dataclass(frozen=True, eq=False)
class PersonTruth:
    """Where the person really is at stamp_s: position_m (3,) the body centre, velocity_mps (3,), height_m."""

    stamp_s: float
    position_m: np.ndarray
    velocity_mps: np.ndarray
    height_m: float = PERSON_HEIGHT_M

    def __post_init__(self) -> None:
        _freeze(self, "position_m", (3,))
        _freeze(self, "velocity_mps", (3,))

    @property
    def feet_m(self) -> np.ndarray:
        """(3,) the point on the ground below the body centre."""
        return np.array([self.position_m[0], self.position_m[1], self.position_m[2] - PERSON_CENTRE_HEIGHT_M])

    @property
    def head_m(self) -> np.ndarray:
        """(3,) the top of the head."""
        return self.feet_m + np.array([0.0, 0.0, self.height_m])


class PersonModel(Protocol):
    """A person's motion: the truth at any time t_s >= 0."""

    def truth(self, t_s: float) -> PersonTruth:
        """The person's true state at t_s."""
        ...


@dataclass(frozen=True, eq=False)
class BodyPose:
    """The true pose of a vehicle's body (what a camera on it sees from), world ENU.

    position_m (3,) true; believed_offset_m (3,) = reported - true position (the GPS drift); yaw_rad ENU;
    roll_rad, pitch_rad in the aviation sense (pitch > 0 nose up, roll > 0 right side down); in_air;
    position_cov_m2 (3, 3) the self-localisation covariance the vehicle reports (its own idea of its error).
    """

    vehicle_id: int
    stamp_s: float
    position_m: np.ndarray
    believed_offset_m: np.ndarray
    yaw_rad: float
    roll_rad: float
    pitch_rad: float
    in_air: bool
    position_cov_m2: np.ndarray = field(default_factory=lambda: np.diag([0.25, 0.25, 1.0]))

    def __post_init__(self) -> None:
        _freeze(self, "position_m", (3,))
        _freeze(self, "believed_offset_m", (3,))
        _freeze(self, "position_cov_m2", (3, 3))


class World(Protocol):
    """What a mission needs from the world."""

    @property
    def obstacles(self) -> tuple[Obstacle, ...]:
        """The static obstacles (tree trunks)."""
        ...

    def advance(self, now_s: float) -> None:
        """Move the world (person, simulated physics, cameras) forward to now_s."""

    def detections(self, vehicle_id: int) -> tuple[Detection, ...]:
        """The person detections made by vehicle_id's camera since the last call, oldest first."""
        ...

    def person_truth(self) -> PersonTruth | None:
        """Where the person really is, when the world knows it (simulation); None in the field."""
        ...


class Body(Protocol):
    """A vehicle's body as the cameras see it."""

    vehicle_id: int

    def advance(self, now_s: float) -> None:
        """Integrate physics to now_s (nothing for a real vehicle)."""

    def pose(self) -> BodyPose | None:
        """The body's true pose now, or None when unknown."""
        ...

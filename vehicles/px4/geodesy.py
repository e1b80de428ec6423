"""Frames at the PX4 edge: ENU <-> NED, yaw conventions, and geodetic <-> the team's ENU frame.

The team flies in one local ENU frame (x east, y north, z up) whose origin is a shared geodetic reference
(`--origin`, or the first vehicle's home). Every PX4 vehicle reports and accepts positions in its own local
NED frame, whose origin is its estimator origin (GPS_GLOBAL_ORIGIN, where it booted; not "home", which moves
at every arming). Both frames are tangent planes of the WGS-84 ellipsoid, so the map from one vehicle's local
NED to the team ENU is a rigid transform, computed once per vehicle (`LocalFrame`); pymap3d supplies the
ellipsoid.

Altitudes are treated as heights on the ellipsoid. PX4 reports AMSL; using AMSL for every point shifts all of
them by the local geoid height together, which changes relative geometry by about 1e-5 (a millimetre over
100 m). PX4 itself projects local <-> global azimuthally about the origin; within 300 m of it the two
projections differ by less than a centimetre.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pymap3d

from controller.angles import wrap_angle
from controller.messages import frozen_array

# ENU <-> NED swaps x and y and flips z; the matrix is its own inverse.
_SWAP = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])


@dataclass(frozen=True)
class GeodeticPoint:
    """A WGS-84 position: latitude_deg in [-90, 90], longitude_deg in [-180, 180], altitude_m (module doc)."""

    latitude_deg: float
    longitude_deg: float
    altitude_m: float

    def __post_init__(self) -> None:
        values = (self.latitude_deg, self.longitude_deg, self.altitude_m)
        if not all(math.isfinite(v) for v in values):
            raise ValueError(f"a geodetic point must be finite, got {values}")
        if not -90.0 <= self.latitude_deg <= 90.0:
            raise ValueError(f"latitude must be within [-90, 90] degrees, got {self.latitude_deg}")
        if not -180.0 <= self.longitude_deg <= 180.0:
            raise ValueError(f"longitude must be within [-180, 180] degrees, got {self.longitude_deg}")


def parse_geodetic(text: str) -> GeodeticPoint:
    """Parse "lat,lon,alt" (degrees, degrees, metres) as given to `--origin`; ValueError says what is off."""
    parts = [p.strip() for p in text.split(",")]
    if len(parts) != 3:
        raise ValueError(f"expected 'lat,lon,alt' (degrees, degrees, metres), got {text!r}")
    try:
        lat, lon, alt = (float(p) for p in parts)
    except ValueError:
        raise ValueError(f"expected three numbers 'lat,lon,alt', got {text!r}") from None
    return GeodeticPoint(lat, lon, alt)


def enu_to_ned(vectors_enu) -> np.ndarray:
    """(..., 3) ENU vectors -> (..., 3) NED vectors (north = y, east = x, down = -z)."""
    v = np.asarray(vectors_enu, dtype=float)
    return v @ _SWAP.T


def ned_to_enu(vectors_ned) -> np.ndarray:
    """(..., 3) NED vectors -> (..., 3) ENU vectors (the same swap: it is its own inverse)."""
    v = np.asarray(vectors_ned, dtype=float)
    return v @ _SWAP.T


def yaw_enu_to_ned(yaw_enu_rad: float) -> float:
    """ENU yaw (0 = east, counter-clockwise) -> NED yaw (0 = north, clockwise), wrapped into [-pi, pi)."""
    return wrap_angle(math.pi / 2.0 - yaw_enu_rad)


def yaw_ned_to_enu(yaw_ned_rad: float) -> float:
    """NED yaw (0 = north, clockwise) -> ENU yaw (0 = east, counter-clockwise), wrapped into [-pi, pi)."""
    return wrap_angle(math.pi / 2.0 - yaw_ned_rad)


def geodetic_to_enu(point: GeodeticPoint, *, reference: GeodeticPoint) -> np.ndarray:
    """(3,) ENU position of `point` in the tangent frame at `reference`, metres."""
    e, n, u = pymap3d.geodetic2enu(
        point.latitude_deg,
        point.longitude_deg,
        point.altitude_m,
        reference.latitude_deg,
        reference.longitude_deg,
        reference.altitude_m,
    )
    return np.array([e, n, u], dtype=float)


def enu_to_geodetic(position_enu_m, *, reference: GeodeticPoint) -> GeodeticPoint:
    """The geodetic point at (3,) ENU position_enu_m of the tangent frame at `reference`."""
    e, n, u = frozen_array(position_enu_m, (3,), "position_enu_m")
    lat, lon, alt = pymap3d.enu2geodetic(
        e, n, u, reference.latitude_deg, reference.longitude_deg, reference.altitude_m
    )
    return GeodeticPoint(float(lat), float(lon), float(alt))


def ecef_to_enu_rotation(point: GeodeticPoint) -> np.ndarray:
    """(3, 3) rotation taking ECEF vectors to the ENU axes of the tangent frame at `point`."""
    lat, lon = math.radians(point.latitude_deg), math.radians(point.longitude_deg)
    sl, cl, sp, cp = math.sin(lat), math.cos(lat), math.sin(lon), math.cos(lon)
    return np.array([[-sp, cp, 0.0], [-sl * cp, -sl * sp, cl], [cl * cp, cl * sp, sl]])


@dataclass(frozen=True, eq=False)
class LocalFrame:
    """One vehicle's local NED frame placed in the team's ENU frame: enu = rotation @ ned + offset_m.

    rotation: (3, 3), close to the NED->ENU swap (the tangent planes tilt by ~1.6e-4 rad per km apart);
    offset_m: (3,) the vehicle's local origin in team ENU. Build it with `from_origin` (exact, from the
    estimator origin) or `from_fix` (from one simultaneous global and local position reading).
    """

    rotation: np.ndarray
    offset_m: np.ndarray

    def __post_init__(self) -> None:
        object.__setattr__(self, "rotation", frozen_array(self.rotation, (3, 3), "rotation"))
        object.__setattr__(self, "offset_m", frozen_array(self.offset_m, (3,), "offset_m"))

    @classmethod
    def from_origin(cls, *, local_origin: GeodeticPoint, reference: GeodeticPoint) -> LocalFrame:
        """The transform for a vehicle whose local NED origin is `local_origin`, in the frame at reference."""
        ned_from_ecef = _SWAP @ ecef_to_enu_rotation(local_origin)
        rotation = ecef_to_enu_rotation(reference) @ ned_from_ecef.T
        return cls(rotation=rotation, offset_m=geodetic_to_enu(local_origin, reference=reference))

    @classmethod
    def from_fix(cls, *, position: GeodeticPoint, local_ned_m, reference: GeodeticPoint) -> LocalFrame:
        """The transform inferred from one reading of the same point in both frames (global and local NED).

        Used when the vehicle does not answer for its estimator origin; good to millimetres within a few
        hundred metres of the origin (the tangent plane at the fix stands in for the one at the origin).
        """
        n, e, d = frozen_array(local_ned_m, (3,), "local_ned_m")
        lat, lon, alt = pymap3d.ned2geodetic(
            -n, -e, -d, position.latitude_deg, position.longitude_deg, position.altitude_m
        )
        origin = GeodeticPoint(float(lat), float(lon), float(alt))
        return cls.from_origin(local_origin=origin, reference=reference)

    def to_enu(self, position_ned_m) -> np.ndarray:
        """(3,) local NED position -> (3,) team ENU position."""
        return self.rotation @ frozen_array(position_ned_m, (3,), "position_ned_m") + self.offset_m

    def to_ned(self, position_enu_m) -> np.ndarray:
        """(3,) team ENU position -> (3,) local NED position (the inverse of `to_enu`)."""
        return self.rotation.T @ (frozen_array(position_enu_m, (3,), "position_enu_m") - self.offset_m)

    def vector_to_enu(self, vector_ned) -> np.ndarray:
        """(3,) local NED vector (a velocity) -> (3,) team ENU vector."""
        return self.rotation @ frozen_array(vector_ned, (3,), "vector_ned")

    def vector_to_ned(self, vector_enu) -> np.ndarray:
        """(3,) team ENU vector -> (3,) local NED vector."""
        return self.rotation.T @ frozen_array(vector_enu, (3,), "vector_enu")

    def yaw_to_enu(self, yaw_ned_rad: float) -> float:
        """Local NED yaw -> team ENU yaw, including the small tilt between the two tangent planes."""
        h = self.rotation @ np.array([math.cos(yaw_ned_rad), math.sin(yaw_ned_rad), 0.0])
        return wrap_angle(math.atan2(h[1], h[0]))

    def yaw_to_ned(self, yaw_enu_rad: float) -> float:
        """Team ENU yaw -> local NED yaw (the inverse of `yaw_to_enu`)."""
        h = self.rotation.T @ np.array([math.cos(yaw_enu_rad), math.sin(yaw_enu_rad), 0.0])
        return wrap_angle(math.atan2(h[1], h[0]))

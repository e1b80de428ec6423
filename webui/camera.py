"""Where the operator's 3-D camera looks: framing the formation, following the person, straight down.

The poses are pure functions of the view (`formation_frame`, `orbit_pose`, `top_down_pose`); `CameraDirector`
applies them to viser clients and, for the clients that asked to follow the person, moves their camera with
the person every frame, keeping whatever angle and zoom the operator chose. World frame: ENU, metres.
"""

from __future__ import annotations

import math
import threading
from dataclasses import dataclass

import numpy as np
import viser

from webui.view import SceneView

FOV_RAD = math.radians(50.0)  # vertical field of view of the operator's camera (viser's default is 75 deg)
MARGIN_M = 3.0  # around the formation's circle: a MAV off its slot and its label stay in the picture
ELEVATION_RAD = math.radians(40.0)  # the default view looks down at the formation from this elevation
AZIMUTH_RAD = math.radians(-90.0)  # ... from the south (bearing of the camera from the centre, ENU)
TOP_DOWN_TILT_RAD = math.radians(1.0)  # a hair off vertical, so that north stays up on the screen


@dataclass(frozen=True)
class CameraPose:
    """position_m (3,), look_at_m (3,) and up (3,) of a camera, ENU."""

    position_m: np.ndarray
    look_at_m: np.ndarray
    up: tuple[float, float, float] = (0.0, 0.0, 1.0)


def person_center(view: SceneView) -> np.ndarray | None:
    """(3,) where the person is believed to be: the fused estimate, else the truth (simulation), else None."""
    estimate = view.person_estimate
    if estimate is not None and np.all(np.isfinite(estimate.position_m)):
        return np.array(estimate.position_m, dtype=float)
    if view.person_truth_m is not None:
        return np.array(view.person_truth_m, dtype=float)
    return None


def formation_frame(view: SceneView) -> tuple[np.ndarray, float]:
    """The centre (3,) and radius (m) of the sphere the formation fits in: about the person (else the team's
    centroid, else the arena's centre) at half the flying height, wide enough for the d_des circle and every
    MAV, plus a margin."""
    positions = np.array([v.position_m for v in view.vehicles if np.all(np.isfinite(v.position_m))])
    center = person_center(view)
    if center is None:
        center = positions.mean(axis=0) if len(positions) else 0.5 * (view.arena_min_m + view.arena_max_m)
    height = view.formation.h_des_m
    if len(positions):
        height = max(height, float(np.max(positions[:, 2])))
    target = np.array([center[0], center[1], 0.5 * height])
    reach = view.formation.d_des_m
    if len(positions):
        reach = max(reach, float(np.max(np.hypot(*(positions[:, :2] - target[:2]).T))))
    radius = math.hypot(reach, 0.5 * height) + MARGIN_M
    return target, radius


def fit_distance_m(radius_m: float, fov_rad: float, aspect: float) -> float:
    """Distance at which a sphere of radius_m fills the narrower of the vertical and horizontal fields of view
    (fov_rad vertical, aspect = width / height)."""
    horizontal = 2.0 * math.atan(math.tan(fov_rad / 2.0) * max(aspect, 1e-3))
    return radius_m / math.sin(min(fov_rad, horizontal) / 2.0)


def orbit_pose(
    center_m: np.ndarray,
    radius_m: float,
    *,
    fov_rad: float = FOV_RAD,
    aspect: float = 1.5,
    elevation_rad: float = ELEVATION_RAD,
    azimuth_rad: float = AZIMUTH_RAD,
) -> CameraPose:
    """Looking at center_m from azimuth/elevation, just far enough to see the whole sphere."""
    d = fit_distance_m(radius_m, fov_rad, aspect)
    direction = np.array(
        [
            math.cos(elevation_rad) * math.cos(azimuth_rad),
            math.cos(elevation_rad) * math.sin(azimuth_rad),
            math.sin(elevation_rad),
        ]
    )
    center = np.asarray(center_m, dtype=float)
    return CameraPose(position_m=center + d * direction, look_at_m=center)


def top_down_pose(
    center_m: np.ndarray, radius_m: float, *, fov_rad: float = FOV_RAD, aspect: float = 1.5
) -> CameraPose:
    """Straight down onto the ground under center_m, north up on the screen."""
    ground = np.array([center_m[0], center_m[1], 0.0])
    return orbit_pose(
        ground,
        radius_m,
        fov_rad=fov_rad,
        aspect=aspect,
        elevation_rad=math.pi / 2.0 - TOP_DOWN_TILT_RAD,
        azimuth_rad=-math.pi / 2.0,
    )


class CameraDirector:
    """Applies camera poses to viser clients and keeps the following ones on the person."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._following: dict[int, np.ndarray] = {}  # client id -> person position last followed

    def frame_formation(self, client: viser.ClientHandle, view: SceneView) -> None:
        center, radius = formation_frame(view)
        self._apply(client, orbit_pose(center, radius, aspect=_aspect(client)))

    def top_down(self, client: viser.ClientHandle, view: SceneView) -> None:
        self.set_following(client, None, view)
        center, radius = formation_frame(view)
        self._apply(client, top_down_pose(center, radius, aspect=_aspect(client)))

    def set_following(self, client: viser.ClientHandle, follow: bool | None, view: SceneView) -> None:
        """Start (True) or stop (False, None) moving this client's camera with the person."""
        with self._lock:
            person = person_center(view)
            if follow and person is not None:
                self._following[client.client_id] = person
                self._follow_start(client, person)
            else:
                self._following.pop(client.client_id, None)

    def following(self, client_id: int) -> bool:
        with self._lock:
            return client_id in self._following

    def forget(self, client_id: int) -> None:
        with self._lock:
            self._following.pop(client_id, None)

    def update(self, clients: dict[int, viser.ClientHandle], view: SceneView) -> None:
        """Every frame: shift each following client's camera by how far the person moved since the last."""
        person = person_center(view)
        if person is None:
            return
        with self._lock:
            for client_id, last in list(self._following.items()):
                client = clients.get(client_id)
                if client is None:
                    del self._following[client_id]
                    continue
                shift = person - last
                if float(np.linalg.norm(shift)) < 1e-3:
                    continue
                self._following[client_id] = person
                camera = client.camera  # moving the position moves the look-at point with it
                camera.position = np.asarray(camera.position) + shift

    def _follow_start(self, client: viser.ClientHandle, person: np.ndarray) -> None:
        """Aim at the person, keeping the camera's distance and direction of view."""
        camera = client.camera
        offset = np.asarray(camera.position) - np.asarray(camera.look_at)
        with client.atomic():
            camera.position = person + offset  # moves the look-at point along ...
            camera.look_at = person  # ... which then lands exactly on the person

    @staticmethod
    def _apply(client: viser.ClientHandle, pose: CameraPose) -> None:
        camera = client.camera
        with client.atomic():
            camera.up_direction = pose.up
            camera.position = pose.position_m  # translates the look-at point with it ...
            camera.look_at = pose.look_at_m  # ... so the look-at point is set last


def _aspect(client: viser.ClientHandle) -> float:
    try:
        aspect = float(client.camera.aspect)
    except Exception:  # noqa: BLE001 - a client that has not reported its camera yet
        return 1.5
    return aspect if math.isfinite(aspect) and aspect > 0 else 1.5

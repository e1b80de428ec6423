"""From head and feet pixels to a world-frame `Detection` with its covariance (docs/detection.md#geometry).

Geometry. The raw pixels are undistorted with the calibration and turned into two unit rays d_h (head) and
d_f (feet) from the camera centre c, in world ENU, with the camera's pose at the capture time. The person is
taken as a vertical segment of known height H (the athlete's, `person_height_m`): feet F = c + s d_f and head
c + t d_h with (c + t d_h) - F = (0, 0, H). Those are three equations in (s, t), solved in the least-squares
sense (they are consistent when the person stands upright and the pose is right). The measured point is the
body centre F + (0, 0, centre_height_fraction H), the point the simulated detector and the tracker use.

Noise, in the measurement model's own terms (controller/measurement.py, the paper's eqs. 1-2): the range
comes from the angle the person subtends, r ~ H f / h_px, so its relative error is
sqrt((sigma_H / H)^2 + 2 sigma_px^2 / h_px^2); the bearing and inclination errors are the centre pixel's error
over f, with the attitude's error added. sigma_px is `point_sigma_px + point_sigma_fraction * h_px` (a pose
model's head-top and soles are off by a fraction of the person's size) divided by the detection's
confidence: a half-visible point is trusted half as much. These become the spherical NoiseParams at this
detection, converted to a Cartesian covariance by the existing unbiased conversion, plus the MAV's own
self-localisation covariance (its GPS error moves the whole detection). Below `min_confidence` a detection
is rejected, not widened: a pose model's low visibility means the point is guessed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import StrEnum

import numpy as np

from controller.measurement import NoiseParams, spherical_covariance
from controller.messages import Detection
from vehicles.detect.calibration import Calibration
from vehicles.detect.pixels import CameraDetection
from vehicles.detect.pose_history import PoseSample
from vehicles.world import PERSON_CENTRE_HEIGHT_M, PERSON_HEIGHT_M


class Rejection(StrEnum):
    """Why a camera detection did not become a Detection (each is counted by the agent)."""

    LOW_CONFIDENCE = "low_confidence"  # head or feet below min_confidence
    BAD_PIXELS = "bad_pixels"  # non-finite, outside the image, head not above feet, too small
    IMAGE_SIZE = "image_size"  # the frame's size is not the calibration's
    NO_POSE = "no_pose"  # no pose of the MAV at the capture time (too old, too new, telemetry gap)
    GEOMETRY = "geometry"  # the rays do not meet a vertical person in front of the camera
    RANGE = "range"  # the person would be nearer or further than the plausible range


@dataclass(frozen=True)
class LocalizeParams:
    """person_height_m, person_height_sigma_m: the athlete's height and how well it is known;
    centre_height_fraction: the measured centre's height over the height; point_sigma_px and
    point_sigma_fraction: pixel noise of a head or feet point at full confidence, sigma = point_sigma_px +
    point_sigma_fraction * person's pixel height; attitude_sigma_rad: the MAV's attitude error (it turns the
    whole view); min_confidence: below this a detection is rejected; min_height_px: smaller persons are
    rejected (the pose model does not resolve them); min_range_m, max_range_m: plausible ranges;
    image_margin_px: how far outside the image a point may be (a pose model extrapolates cut-off feet);
    add_pose_covariance: add the MAV's self-localisation covariance to the detection's."""

    person_height_m: float = PERSON_HEIGHT_M
    person_height_sigma_m: float = 0.10
    centre_height_fraction: float = PERSON_CENTRE_HEIGHT_M / PERSON_HEIGHT_M
    point_sigma_px: float = 2.0
    point_sigma_fraction: float = 0.02
    attitude_sigma_rad: float = math.radians(1.0)
    min_confidence: float = 0.3
    min_height_px: float = 24.0
    min_range_m: float = 1.0
    max_range_m: float = 150.0
    image_margin_px: float = 0.0
    add_pose_covariance: bool = True

    def __post_init__(self) -> None:
        positive = ("person_height_m", "point_sigma_px", "min_height_px", "min_range_m", "max_range_m")
        for name in positive:
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be a positive finite number, got {value}")
        for name in (
            "person_height_sigma_m",
            "point_sigma_fraction",
            "attitude_sigma_rad",
            "image_margin_px",
        ):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise ValueError(f"{name} must be a finite number >= 0, got {value}")
        if not 0.0 < self.centre_height_fraction < 1.0:
            raise ValueError("centre_height_fraction must be in (0, 1)")
        if not 0.0 <= self.min_confidence <= 1.0:
            raise ValueError("min_confidence must be in [0, 1]")
        if self.min_range_m >= self.max_range_m:
            raise ValueError("min_range_m must be below max_range_m")


@dataclass(frozen=True, eq=False)
class Localized:
    """The outcome of one conversion: detection (None when rejected), rejection (None when accepted), and
    the range and noise used (for logs and tests)."""

    detection: Detection | None
    rejection: Rejection | None = None
    range_m: float = math.nan
    noise: NoiseParams | None = None


def _rays(calibration: Calibration, pose_rotation: np.ndarray, pixels: np.ndarray) -> np.ndarray:
    """(M, 3) unit world-frame rays through raw pixels (M, 2)."""
    xy = calibration.normalized(pixels)
    cam = np.concatenate([xy, np.ones((len(xy), 1))], axis=1)
    world = cam @ pose_rotation  # rotation is world -> camera, so world = R^T cam, row-wise cam @ R
    return world / np.linalg.norm(world, axis=1, keepdims=True)


def localize(
    detection: CameraDetection,
    pose: PoseSample | None,
    calibration: Calibration,
    params: LocalizeParams = LocalizeParams(),
) -> Localized:
    """Turn one camera detection into a world-frame Detection placed with `pose` (the body's believed pose at
    the capture time), or say why not."""
    person = detection.person
    if tuple(int(v) for v in detection.image_size_px) != (calibration.width_px, calibration.height_px):
        return Localized(None, Rejection.IMAGE_SIZE)
    if person.confidence < params.min_confidence:
        return Localized(None, Rejection.LOW_CONFIDENCE)
    pixels = np.stack([person.head_px, person.feet_px])
    m = params.image_margin_px
    inside = (
        np.all(np.isfinite(pixels))
        and np.all(pixels >= -m - 0.5)
        and np.all(pixels[:, 0] <= calibration.width_px - 0.5 + m)
        and np.all(pixels[:, 1] <= calibration.height_px - 0.5 + m)
    )
    height_px = person.height_px
    if not inside or person.head_px[1] >= person.feet_px[1] or height_px < params.min_height_px:
        return Localized(None, Rejection.BAD_PIXELS)
    if pose is None:
        return Localized(None, Rejection.NO_POSE)
    cam = calibration.camera_pose(
        body_position_m=pose.position_m,
        yaw_rad=pose.yaw_rad,
        pitch_rad=pose.pitch_rad,
        roll_rad=pose.roll_rad,
    )
    d_h, d_f = _rays(calibration, cam.rotation, pixels)
    big_h = params.person_height_m
    a = np.stack([d_h, -d_f], axis=1)  # [t, s] -> t d_h - s d_f
    normal = a.T @ a
    if np.linalg.cond(normal) > 1e10:
        return Localized(None, Rejection.GEOMETRY)
    t, s = np.linalg.solve(normal, a.T @ np.array([0.0, 0.0, big_h]))
    if not (t > 0 and s > 0):
        return Localized(None, Rejection.GEOMETRY)
    feet = cam.position_m + s * d_f
    centre = feet + np.array([0.0, 0.0, params.centre_height_fraction * big_h])
    range_m = float(np.linalg.norm(centre - cam.position_m))
    if not params.min_range_m <= range_m <= params.max_range_m:
        return Localized(None, Rejection.RANGE, range_m=range_m)
    sigma_px = (params.point_sigma_px + params.point_sigma_fraction * height_px) / person.confidence
    f_px = 0.5 * (calibration.fx_px + calibration.fy_px)
    range_fraction = math.hypot(params.person_height_sigma_m / big_h, math.sqrt(2.0) * sigma_px / height_px)
    angle = math.hypot(sigma_px / math.sqrt(2.0) / f_px, params.attitude_sigma_rad)
    noise = NoiseParams(
        range_sigma_fraction=range_fraction, bearing_sigma_rad=angle, inclination_sigma_rad=angle
    )
    cov = spherical_covariance(camera_position_m=cam.position_m, target_position_m=centre, noise=noise)
    if params.add_pose_covariance:
        cov = cov + pose.position_cov_m2
    det = Detection(source_id=detection.vehicle_id, stamp_s=detection.stamp_s, position_m=centre, cov_m2=cov)
    return Localized(det, None, range_m=range_m, noise=noise)

"""Geometry on real pixels: a person cut from vtest.avi, pasted into each MAV's 2040 x 1086 frame where and
as large as the camera model says a 1.75 m person stands 8-11 m away under the 45-degree camera; the
detector finds head and feet, the agents' conversion makes world detections, and their fusion must hold the
true position within 3 sigma."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from detect_footage import LABELS, read_frame

from controller.measurement import fuse_covariances
from vehicles.camera import CameraParams, camera_pose, project
from vehicles.detect.backends import HogPoseDetector
from vehicles.detect.calibration import Calibration
from vehicles.detect.localize import localize
from vehicles.detect.pixels import CameraDetection
from vehicles.detect.pose_history import PoseSample

pytestmark = pytest.mark.slow  # tens of seconds of HOG and pose model on real frames

FEET = np.array([2.0, -1.0, 0.0])
TRUE_CENTRE = FEET + [0.0, 0.0, 0.9]
SOURCE = ("vtest.avi", 640, "F")  # a woman walking on the grass, 131 px tall, seen from above


def _source_person() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    doc = json.loads(LABELS.read_text())
    frame = next(f for f in doc["frames"] if f["file"] == SOURCE[0] and f["frame"] == SOURCE[1])
    person = next(p for p in frame["persons"] if p["id"] == SOURCE[2])
    return (
        read_frame(SOURCE[0], SOURCE[1]),
        np.array(person["head_px"], float),
        np.array(person["feet_px"], float),
    )


def _similarity(src: tuple[np.ndarray, np.ndarray], dst: tuple[np.ndarray, np.ndarray]) -> np.ndarray:
    """(2, 3) the scale-rotation-translation mapping src[0] -> dst[0] and src[1] -> dst[1]."""
    s = complex(*(src[1] - src[0]))
    d = complex(*(dst[1] - dst[0]))
    z = d / s
    a, b = z.real, z.imag
    rot = np.array([[a, -b], [b, a]])
    return np.hstack([rot, (dst[0] - rot @ src[0])[:, None]])


def _scene(body_m: np.ndarray, yaw: float, background: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The MAV's 2040 x 1086 frame with the person pasted at the projected head and feet; their pixels."""
    import cv2

    cam = CameraParams()
    pose = camera_pose(body_position_m=body_m, yaw_rad=yaw)
    px, _ = project(np.stack([FEET + [0, 0, 1.75], FEET]), pose)
    image, head, feet = _source_person()
    m = _similarity((head, feet), (px[0], px[1]))
    h = float(np.hypot(*(feet - head)))
    patch = np.zeros(image.shape[:2], np.uint8)
    cx = 0.5 * (head[0] + feet[0])
    x0, x1 = int(cx - 0.45 * h), int(cx + 0.45 * h)
    y0, y1 = int(head[1] - 0.15 * h), int(feet[1] + 0.1 * h)
    patch[y0:y1, x0:x1] = 255  # a rectangle of footage round her: the person with her own background
    size = (cam.width_px, cam.height_px)
    warped = cv2.warpAffine(image, m, size, flags=cv2.INTER_LINEAR)
    mask = cv2.warpAffine(patch, m, size, flags=cv2.INTER_NEAREST)
    frame = background.copy()
    frame[mask > 0] = warped[mask > 0]
    return frame, px


def _background() -> np.ndarray:
    """Grass and path from the same footage (vtest.avi frame 0, lower half), stretched to 2040 x 1086."""
    import cv2

    base = read_frame("vtest.avi", 0)[300:576, :]
    return cv2.resize(base, (2040, 1086), interpolation=cv2.INTER_LINEAR)


def test_fused_estimate_from_three_views_of_a_real_person_holds_the_truth_within_3_sigma(pose_model):
    calibration = Calibration.from_camera_params()
    detector = HogPoseDetector(pose=pose_model)
    background = _background()
    detections = []
    for k, distance_m in enumerate((8.0, 9.5, 11.0)):
        bearing = 2.0 * math.pi * k / 3.0 + 0.4
        # At 45 degrees of camera pitch the person is in the image centre when the MAV is as high above the
        # person's centre as it is far from it horizontally.
        body = FEET + [distance_m * math.cos(bearing), distance_m * math.sin(bearing), 0.9 + distance_m]
        yaw = math.atan2(FEET[1] - body[1], FEET[0] - body[0])
        frame, truth_px = _scene(body, yaw, background)
        found = detector.find(frame)
        assert found, f"nobody found in view {k}"
        person = min(found, key=lambda p: float(np.hypot(*(p.feet_px - truth_px[1]))))
        assert np.hypot(*(person.feet_px - truth_px[1])) < 0.1 * (truth_px[1][1] - truth_px[0][1])
        det = CameraDetection(
            vehicle_id=k + 1, stamp_s=1.0, frame_seq=0, image_size_px=(2040, 1086), person=person
        )
        pose = PoseSample(
            stamp_s=1.0, position_m=body, yaw_rad=yaw, position_cov_m2=np.diag([0.01, 0.01, 0.01])
        )
        result = localize(det, pose, calibration)
        assert result.detection is not None, result.rejection
        detections.append(result.detection)
    info = [np.linalg.inv(d.cov_m2) for d in detections]
    cov = fuse_covariances([d.cov_m2 for d in detections])
    estimate = cov @ sum(i @ d.position_m for i, d in zip(info, detections, strict=True))
    error = estimate - TRUE_CENTRE
    mahalanobis = float(np.sqrt(error @ np.linalg.solve(cov, error)))
    assert mahalanobis <= 3.0, (estimate, np.sqrt(np.diag(cov)))
    assert np.linalg.norm(error) < 0.6

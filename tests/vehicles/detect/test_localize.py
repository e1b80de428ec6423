"""Pixel detections to world-frame Detections: geometry, noise, rejections, calibration files."""

from __future__ import annotations

import math

import numpy as np
import pytest

from vehicles.camera import camera_pose, project
from vehicles.detect.calibration import Calibration, CalibrationError, mount_rotation
from vehicles.detect.localize import LocalizeParams, Rejection, localize
from vehicles.detect.pixels import CameraDetection, PersonPixels
from vehicles.detect.pose_history import PoseHistory, PoseSample

CAL = Calibration.from_camera_params()
BODY = np.array([-8.0, 1.0, 8.9])
FEET = np.array([0.3, 0.2, 0.0])


def _pixels(body=BODY, yaw=0.1, pitch=0.05, roll=-0.03, feet=FEET, height=1.75) -> np.ndarray:
    pose = camera_pose(body_position_m=body, yaw_rad=yaw, pitch_rad=pitch, roll_rad=roll)
    px, _ = project(np.stack([feet + [0, 0, height], feet]), pose)
    return px


def _det(px: np.ndarray, head_conf=1.0, feet_conf=1.0, size=(2040, 1086)) -> CameraDetection:
    person = PersonPixels(
        head_px=px[0],
        feet_px=px[1],
        head_conf=head_conf,
        feet_conf=feet_conf,
        box_px=np.array([0.0, 0.0, 1.0, 1.0]),
    )
    return CameraDetection(vehicle_id=2, stamp_s=5.0, frame_seq=7, image_size_px=size, person=person)


def _pose(yaw=0.1, pitch=0.05, roll=-0.03, body=BODY) -> PoseSample:
    return PoseSample(stamp_s=5.0, position_m=body, yaw_rad=yaw, pitch_rad=pitch, roll_rad=roll)


def test_calibration_camera_pose_matches_the_simulated_camera():
    for yaw, pitch, roll in ((0.0, 0.0, 0.0), (2.0, 0.1, -0.2), (-1.0, -0.15, 0.05)):
        a = camera_pose(body_position_m=BODY, yaw_rad=yaw, pitch_rad=pitch, roll_rad=roll)
        b = CAL.camera_pose(body_position_m=BODY, yaw_rad=yaw, pitch_rad=pitch, roll_rad=roll)
        np.testing.assert_allclose(b.rotation, a.rotation, atol=1e-12)
        np.testing.assert_allclose(b.position_m, a.position_m, atol=1e-12)


def test_exact_pixels_give_the_true_body_centre():
    result = localize(_det(_pixels()), _pose(), CAL)
    assert result.detection is not None
    np.testing.assert_allclose(result.detection.position_m, FEET + [0, 0, 0.9], atol=1e-6)
    assert result.detection.source_id == 2 and result.detection.stamp_s == 5.0


def test_a_taller_person_than_assumed_is_placed_nearer():
    params = LocalizeParams(person_height_m=1.60)
    result = localize(_det(_pixels()), _pose(), CAL, params)
    assert result.detection is not None
    cam = CAL.camera_pose(body_position_m=BODY, yaw_rad=0.1, pitch_rad=0.05, roll_rad=-0.03).position_m
    true_range = float(np.linalg.norm(FEET + [0, 0, 0.9] - cam))
    assert result.range_m == pytest.approx(true_range * 1.60 / 1.75, rel=0.02)


def test_range_noise_follows_pixel_height_and_height_prior():
    result = localize(_det(_pixels()), _pose(), CAL)
    assert result.noise is not None
    h_px = float(np.hypot(*(_pixels()[1] - _pixels()[0])))
    sigma_px = 2.0 + 0.02 * h_px
    expected = math.hypot(0.10 / 1.75, math.sqrt(2) * sigma_px / h_px)
    assert result.noise.range_sigma_fraction == pytest.approx(expected, rel=1e-9)


def test_low_visibility_widens_the_covariance():
    sure = localize(_det(_pixels()), _pose(), CAL).detection
    unsure = localize(_det(_pixels(), feet_conf=0.5), _pose(), CAL).detection
    assert sure is not None and unsure is not None
    assert np.trace(unsure.cov_m2) > 1.5 * np.trace(sure.cov_m2)


def test_below_min_confidence_is_rejected():
    result = localize(_det(_pixels(), head_conf=0.2), _pose(), CAL)
    assert result.detection is None and result.rejection == Rejection.LOW_CONFIDENCE


def test_points_outside_the_image_or_upside_down_are_rejected():
    px = _pixels()
    assert localize(_det(px + [3000, 0]), _pose(), CAL).rejection == Rejection.BAD_PIXELS
    assert localize(_det(px[::-1]), _pose(), CAL).rejection == Rejection.BAD_PIXELS


def test_a_frame_of_another_size_than_the_calibration_is_rejected():
    assert localize(_det(_pixels(), size=(1920, 1080)), _pose(), CAL).rejection == Rejection.IMAGE_SIZE


def test_no_pose_is_rejected():
    assert localize(_det(_pixels()), None, CAL).rejection == Rejection.NO_POSE


def test_the_pose_at_capture_time_is_interpolated_from_history():
    history = PoseHistory()
    # The MAV turns at 1 rad/s and moves east at 4 m/s; the frame was taken between two readings.
    for k in range(11):
        t = 4.5 + 0.1 * k
        history.add(PoseSample(stamp_s=t, position_m=BODY + [4.0 * (t - 5.0), 0, 0], yaw_rad=0.1 + (t - 5.0)))
    pose = history.at(5.0)
    assert pose is not None
    np.testing.assert_allclose(pose.position_m, BODY, atol=1e-9)
    result = localize(_det(_pixels(pitch=0.0, roll=0.0)), pose, CAL)
    assert result.detection is not None
    np.testing.assert_allclose(result.detection.position_m, FEET + [0, 0, 0.9], atol=1e-6)
    # The newest pose (0.5 s later) would put the person metres away.
    late = history.at(5.5)
    assert late is not None
    wrong = localize(_det(_pixels(pitch=0.0, roll=0.0)), late, CAL).detection
    assert wrong is not None and np.linalg.norm(wrong.position_m - (FEET + [0, 0, 0.9])) > 2.0


def test_history_has_no_pose_outside_it_or_in_a_gap():
    history = PoseHistory(max_gap_s=0.5)
    history.add(PoseSample(stamp_s=1.0, position_m=BODY, yaw_rad=0.0))
    history.add(PoseSample(stamp_s=2.0, position_m=BODY, yaw_rad=0.0))
    assert history.at(0.9) is None and history.at(2.1) is None and history.at(1.5) is None


def test_yaw_interpolates_along_the_shorter_arc():
    history = PoseHistory()
    history.add(PoseSample(stamp_s=0.0, position_m=BODY, yaw_rad=math.pi - 0.1))
    history.add(PoseSample(stamp_s=0.2, position_m=BODY, yaw_rad=-math.pi + 0.1))
    pose = history.at(0.1)
    assert pose is not None and abs(abs(pose.yaw_rad) - math.pi) < 1e-9


def test_calibration_round_trips_through_opencv_yaml(tmp_path):
    cal = Calibration(
        width_px=1280,
        height_px=720,
        camera_matrix=np.array([[900.0, 0.0, 640.5], [0.0, 905.0, 360.2], [0.0, 0.0, 1.0]]),
        distortion=np.array([-0.21, 0.05, 0.001, -0.0005, 0.0]),
        camera_to_body_rotation=mount_rotation(math.radians(30)),
        camera_to_body_translation_m=np.array([0.1, 0.0, -0.05]),
    )
    path = tmp_path / "cam.yaml"
    cal.save(path)
    text = path.read_text()
    assert text.startswith("%YAML:1.0") and "!!opencv-matrix" in text
    back = Calibration.load(path)
    np.testing.assert_allclose(back.camera_matrix, cal.camera_matrix)
    np.testing.assert_allclose(back.distortion, cal.distortion)
    np.testing.assert_allclose(back.camera_to_body_rotation, cal.camera_to_body_rotation)
    assert (back.width_px, back.height_px) == (1280, 720)


def test_distorted_pixels_are_undistorted_before_the_geometry():
    import cv2

    cal = Calibration(
        width_px=2040,
        height_px=1086,
        camera_matrix=np.array([[1470.33, 0, 1020.5], [0, 1470.33, 543.5], [0, 0, 1.0]]),
        distortion=np.array([-0.25, 0.08, 0.0, 0.0, 0.0]),
        camera_to_body_rotation=mount_rotation(math.radians(45)),
        camera_to_body_translation_m=np.array([0.18, 0.0, 0.0]),
    )
    pose = cal.camera_pose(body_position_m=BODY, yaw_rad=0.3)
    pts = np.stack([FEET + [0, 0, 1.75], FEET]) - pose.position_m
    rvec, _ = cv2.Rodrigues(pose.rotation)
    px, _ = cv2.projectPoints(pts, rvec, np.zeros(3), cal.camera_matrix, cal.distortion)
    result = localize(_det(px.reshape(2, 2)), _pose(yaw=0.3, pitch=0.0, roll=0.0), cal)
    assert result.detection is not None
    np.testing.assert_allclose(result.detection.position_m, FEET + [0, 0, 0.9], atol=1e-3)


def test_a_calibration_file_missing_a_node_names_it(tmp_path):
    path = tmp_path / "bad.yaml"
    Calibration.from_camera_params().save(path)
    path.write_text(path.read_text().replace("camera_to_body_rotation", "camera_to_body_rot"))
    with pytest.raises(CalibrationError, match="camera_to_body_rotation"):
        Calibration.load(path)


def test_a_calibration_with_a_non_rotation_is_refused(tmp_path):
    with pytest.raises(CalibrationError, match="rotation"):
        Calibration(
            width_px=10,
            height_px=10,
            camera_matrix=np.eye(3),
            distortion=np.zeros(5),
            camera_to_body_rotation=np.eye(3) * 2,
            camera_to_body_translation_m=np.zeros(3),
        )

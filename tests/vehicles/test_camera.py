"""The body-fixed camera: pose, projection, field of view, occlusion by trunks."""

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from controller.messages import Obstacle
from vehicles.camera import (
    CameraParams,
    attitude_from_acceleration,
    body_rotation,
    body_rotations,
    camera_pose,
    inside_image,
    line_of_sight_clear,
    project,
    view_person,
)

PERSON = np.array([0.0, 0.0, 0.9])
FEET = np.array([0.0, 0.0, 0.0])
HEAD = np.array([0.0, 0.0, 1.75])


def _looking_at_person(yaw_offset_rad=0.0, pitch_rad=0.0, roll_rad=0.0):
    """A MAV 8 m east of the person and 8 m above its centre, facing it (yaw pi) plus an offset."""
    return camera_pose(
        body_position_m=np.array([8.18, 0.0, 8.9]),
        yaw_rad=math.pi + yaw_offset_rad,
        pitch_rad=pitch_rad,
        roll_rad=roll_rad,
    )


def test_person_45_degrees_below_straight_ahead_projects_to_the_principal_point():
    pixels, depth = project(PERSON[None, :], _looking_at_person())
    np.testing.assert_allclose(pixels[0], [1020.5, 543.5], atol=1e-6)
    assert depth[0] == pytest.approx(8.0 * math.sqrt(2.0), rel=1e-9)


def test_camera_sits_0_18_m_ahead_of_the_body_centre():
    pose = camera_pose(body_position_m=np.array([1.0, 2.0, 5.0]), yaw_rad=math.pi / 2)
    np.testing.assert_allclose(pose.position_m, [1.0, 2.18, 5.0], atol=1e-12)


def test_horizontal_field_of_view_is_69_5_degrees():
    params = CameraParams()
    hfov = 2.0 * math.degrees(math.atan(params.cx_px / params.fx_px))
    assert hfov == pytest.approx(69.5, abs=0.1)


def test_yawing_the_body_60_degrees_away_puts_the_person_out_of_frame_and_30_keeps_it_in():
    # With the camera pitched 45 deg down, a body yaw psi shows the person at atan(sqrt(2) tan(psi / 2)) off
    # the image's vertical centre line: 22 deg for 30, 39 deg for 60 (half the field of view is 34.75 deg).
    out = view_person(
        pose=_looking_at_person(math.radians(60.0)), center_m=PERSON, feet_m=FEET, head_m=HEAD, obstacles=()
    )
    inside = view_person(
        pose=_looking_at_person(math.radians(30.0)), center_m=PERSON, feet_m=FEET, head_m=HEAD, obstacles=()
    )
    assert not out.in_frame
    assert inside.in_frame


def test_pitching_nose_down_moves_the_person_up_in_the_image():
    level, _ = project(PERSON[None, :], _looking_at_person())
    nose_down, _ = project(PERSON[None, :], _looking_at_person(pitch_rad=math.radians(-10.0)))
    assert nose_down[0, 1] < level[0, 1] - 200.0
    assert nose_down[0, 0] == pytest.approx(level[0, 0], abs=1e-6)


def test_rolling_right_side_down_moves_the_person_right_in_the_image():
    level, _ = project(PERSON[None, :], _looking_at_person())
    rolled, _ = project(PERSON[None, :], _looking_at_person(roll_rad=math.radians(10.0)))
    # The optical axis points below the horizon, so rolling right side down swings it to the left (the body's
    # underside moves left): the scene moves right in the image, by about fx tan(10 deg) sin(45 deg) px.
    expected_px = 1470.33 * math.tan(math.radians(10.0)) * math.sqrt(0.5)
    assert rolled[0, 0] - level[0, 0] == pytest.approx(expected_px, rel=0.1)


def test_points_behind_the_camera_are_never_inside_the_image():
    pose = _looking_at_person()
    pixels, depth = project(np.array([[20.0, 0.0, 8.9]]), pose)
    assert depth[0] < 0
    assert not inside_image(pixels)[0]


def test_forward_acceleration_pitches_nose_down_and_leftward_rolls_left_side_down():
    roll, pitch = attitude_from_acceleration(acceleration_mps2=np.array([3.0, 0.0, 0.0]), yaw_rad=0.0)
    assert pitch == pytest.approx(-math.atan2(3.0, 9.81), abs=1e-12)
    assert roll == pytest.approx(0.0, abs=1e-12)
    roll, pitch = attitude_from_acceleration(
        acceleration_mps2=np.array([-3.0, 0.0, 0.0]), yaw_rad=math.pi / 2
    )
    assert roll == pytest.approx(-math.atan2(3.0, 9.81), abs=1e-12)  # -x is the body's left at yaw 90 deg
    assert pitch == pytest.approx(0.0, abs=1e-12)


def test_a_trunk_between_camera_and_person_blocks_the_line_of_sight():
    trunk = Obstacle(obstacle_id="t", center_m=np.array((4.0, 0.05)), radius_m=0.3, height_m=12.0)
    beside = Obstacle(obstacle_id="b", center_m=np.array((4.0, 1.0)), radius_m=0.3, height_m=12.0)
    short = Obstacle(obstacle_id="s", center_m=np.array((4.0, 0.0)), radius_m=0.3, height_m=3.0)
    cam = np.array([8.0, 0.0, 8.9])
    assert not line_of_sight_clear(cam, PERSON, (trunk,))
    assert line_of_sight_clear(cam, PERSON, (beside,))
    assert line_of_sight_clear(cam, PERSON, (short,))  # the ray passes 4.9 m up, above its 3 m top
    assert line_of_sight_clear(cam, PERSON, ())


def test_a_blocked_person_is_in_frame_but_not_visible():
    trunk = Obstacle(obstacle_id="t", center_m=np.array((4.0, 0.0)), radius_m=0.3, height_m=12.0)
    view = view_person(
        pose=_looking_at_person(), center_m=PERSON, feet_m=FEET, head_m=HEAD, obstacles=(trunk,)
    )
    assert view.in_frame and not view.visible
    # the principal point (1020.5, 543.5) is half a pixel off the image centre (1020, 543)
    assert view.center_offset_px == pytest.approx(math.sqrt(0.5), abs=1e-6)


def test_body_rotation_is_yaw_then_pitch_then_roll_in_the_aviation_sense():
    yaw, pitch, roll = 0.7, 0.2, -0.3
    cy, sy = np.cos(yaw), np.sin(yaw)
    cp, sp = np.cos(-pitch), np.sin(-pitch)
    cr, sr = np.cos(roll), np.sin(roll)
    rz = np.array([[cy, -sy, 0.0], [sy, cy, 0.0], [0.0, 0.0, 1.0]])
    ry = np.array([[cp, 0.0, sp], [0.0, 1.0, 0.0], [-sp, 0.0, cp]])
    rx = np.array([[1.0, 0.0, 0.0], [0.0, cr, -sr], [0.0, sr, cr]])
    rotation = body_rotation(yaw_rad=yaw, pitch_rad=pitch, roll_rad=roll)
    np.testing.assert_allclose(rotation, rz @ ry @ rx, atol=1e-12)
    nose = body_rotation(yaw_rad=0.0, pitch_rad=0.1)[:, 0]
    assert nose[2] > 0.0  # pitch > 0 lifts the nose


def test_rotations_made_together_are_each_single_rotation_to_the_bit():
    # The simulated world makes the rotations of a step's frames in one scipy call (body_rotations); each must
    # be the matrix a single Rotation.from_euler gives, bit for bit, or the reports would change.
    rng = np.random.default_rng(11)
    for count in (1, 2, 3, 7, 16, 40) * 20:
        scale = rng.choice([1e-9, 0.05, 0.5, 1.5], size=(count, 2))
        attitudes = np.column_stack(
            [rng.uniform(-4.0, 4.0, count), *(rng.uniform(-1.0, 1.0, (2, count)) * scale.T)]
        ).tolist()
        together = body_rotations(attitudes)
        for (yaw, pitch, roll), matrix in zip(attitudes, together, strict=True):
            single = Rotation.from_euler("ZYX", [yaw, -pitch, roll]).as_matrix()
            assert matrix.tobytes() == single.tobytes()
            assert matrix.tobytes() == body_rotation(yaw_rad=yaw, pitch_rad=pitch, roll_rad=roll).tobytes()

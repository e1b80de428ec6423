"""The operator's camera poses: the formation fits the picture, top-down keeps north up."""

from __future__ import annotations

import math

import numpy as np
import pytest

from controller.params import FormationParams
from webui.camera import FOV_RAD, fit_distance_m, formation_frame, orbit_pose, top_down_pose
from webui.view import Range, SceneView, VehicleView


def view(positions, person=(3.0, -2.0, 0.9)) -> SceneView:
    vehicles = tuple(
        VehicleView(
            vehicle_id=i + 1,
            phase="formation",
            mode="offboard",
            armed=True,
            in_air=True,
            in_formation=True,
            position_m=np.array(p, dtype=float),
            yaw_rad=0.0,
            link_age_s=0.0,
            link_stale=False,
        )
        for i, p in enumerate(positions)
    )
    return SceneView(
        time_s=1.0,
        vehicles=vehicles,
        obstacles=(),
        formation=FormationParams(d_des_m=8.0, h_des_m=8.0),
        formation_enabled=True,
        arena_min_m=np.array([-20.0, -20.0, 3.0]),
        arena_max_m=np.array([20.0, 20.0, 10.0]),
        d_des_range_m=Range(3.0, 18.5),
        h_des_range_m=Range(2.1, 9.1),
        person_truth_m=None if person is None else np.array(person),
    )


def project(pose, point, aspect):
    """(x, y) of a world point in normalised image coordinates (-1..1 spans the picture), OpenGL-like camera
    looking from pose.position_m to pose.look_at_m with +z up."""
    forward = pose.look_at_m - pose.position_m
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, np.array(pose.up))
    right /= np.linalg.norm(right)
    up = np.cross(right, forward)
    d = np.asarray(point) - pose.position_m
    depth = d @ forward
    t = math.tan(FOV_RAD / 2.0)
    return (d @ right) / depth / (t * aspect), (d @ up) / depth / t


def test_the_frame_is_centred_on_the_person_and_reaches_every_mav():
    ring = [(3.0 + 8.0 * math.cos(a), -2.0 + 8.0 * math.sin(a), 9.0) for a in (0.0, 2.1, 4.2)]
    center, radius = formation_frame(view(ring))
    assert center[:2] == pytest.approx([3.0, -2.0])
    assert all(np.linalg.norm(np.asarray(p) - center) < radius for p in ring)


def test_without_a_person_the_frame_is_centred_on_the_team():
    center, _ = formation_frame(view([(10.0, 0.0, 9.0), (12.0, 0.0, 9.0)], person=None))
    assert center[:2] == pytest.approx([11.0, 0.0])


@pytest.mark.parametrize("aspect", [0.8, 1.0, 1.6])
def test_the_default_view_shows_the_whole_formation_and_the_person(aspect):
    ring = [(3.0 + 8.0 * math.cos(a), -2.0 + 8.0 * math.sin(a), 9.0) for a in np.linspace(0, 6, 16)]
    center, radius = formation_frame(view(ring))
    pose = orbit_pose(center, radius, aspect=aspect)
    for point in [*ring, (3.0, -2.0, 0.0)]:
        x, y = project(pose, point, aspect)
        assert abs(x) < 1.0 and abs(y) < 1.0


def test_the_formation_fills_a_good_part_of_the_picture():
    ring = [(8.0 * math.cos(a), 8.0 * math.sin(a), 9.0) for a in np.linspace(0, 6, 16)]
    center, radius = formation_frame(view(ring, person=(0.0, 0.0, 0.9)))
    pose = orbit_pose(center, radius, aspect=1.0)
    xs = [project(pose, p, 1.0)[0] for p in ring]
    assert max(xs) - min(xs) > 1.0  # the circle spans more than half the width (the old view: 15-20 %)


def test_fit_distance_uses_the_narrower_field_of_view():
    wide, tall = fit_distance_m(10.0, FOV_RAD, 2.0), fit_distance_m(10.0, FOV_RAD, 0.5)
    assert wide == pytest.approx(10.0 / math.sin(FOV_RAD / 2.0))
    assert tall > wide


def test_top_down_looks_straight_down_with_north_up_on_the_screen():
    pose = top_down_pose(np.array([2.0, 3.0, 4.0]), 10.0, aspect=1.0)
    direction = pose.look_at_m - pose.position_m
    assert direction[2] < 0 and math.degrees(math.acos(-direction[2] / np.linalg.norm(direction))) < 2.0
    north = project(pose, (2.0, 8.0, 0.0), 1.0)
    east = project(pose, (7.0, 3.0, 0.0), 1.0)
    assert north[1] > 0.2 and abs(north[0]) < 0.05  # up on the screen
    assert east[0] > 0.2 and abs(east[1]) < 0.05  # to the right

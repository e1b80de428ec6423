"""The 3-D scene and the panel text drawn from a view, against a real viser server (no browser)."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
import viser
from scene_views import scene_view

from controller.messages import Obstacle, PersonEstimate
from webui.geometry import VEHICLE_COLORS, vehicle_color
from webui.scene import (
    CIRCLE_COLOR,
    COVARIANCE_COLOR,
    PERSON_ESTIMATE_COLOR,
    PERSON_TRUTH_COLOR,
    TREE_COLOR,
    VIRTUAL_OBSTACLE_COLOR,
    SceneRenderer,
    ellipsoid_label,
    vehicle_label,
)
from webui.view import GeodeticOrigin, PersonEstimateView, Range, SceneView, VehicleView

README = Path(__file__).resolve().parents[2] / "README.md"


def vehicle(vehicle_id: int, *, phase: str = "formation", stale: bool = False) -> VehicleView:
    position = np.array([8.0 * np.cos(vehicle_id), 8.0 * np.sin(vehicle_id), 8.9])
    return VehicleView(
        vehicle_id=vehicle_id,
        phase=phase,
        mode="offboard",
        armed=True,
        in_air=True,
        in_formation=phase == "formation",
        position_m=position,
        yaw_rad=0.3,
        link_age_s=2.5,
        link_stale=stale,
        solve_status="solved",
        solver_time_s=2.5e-4,
        battery_fraction=0.8,
        plan_positions_m=position + np.outer(np.arange(17) * 0.1, [1.0, 0.0, 0.0]),
    )


def view(*, obstacles=(), variances=(0.25, 0.04, 0.01), origin=None) -> SceneView:
    full = np.eye(6)
    full[:3, :3] = np.diag(variances)
    estimate = PersonEstimate(
        stamp_s=1.0, position_m=np.array([0.5, 0.0, 0.9]), velocity_mps=np.array([0.0, 0.0, 0.0]), cov=full
    )
    return scene_view(
        (vehicle(1), vehicle(2, phase="landing")),
        obstacles=tuple(obstacles),
        d_des_range_m=Range(1.8, 18.5),
        person_truth_m=np.array([0.0, 0.0, 0.9]),
        person_estimate=PersonEstimateView.of(estimate),
        estimate_source_id=1,
        tracking_error_m=0.5,
        origin=origin,
    )


@pytest.fixture
def scene():
    server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    yield server.scene
    server.stop()


def test_every_vehicle_gets_a_body_frustum_label_and_plan(scene):
    SceneRenderer(scene).draw(view())
    for vid in (1, 2):
        for part in ("", "/body", "/camera", "/label"):
            assert scene.get_handle_by_name(f"/mav/{vid}{part}") is not None
        assert scene.get_handle_by_name(f"/plan/{vid}") is not None
    assert scene.get_handle_by_name("/mav/1").position == pytest.approx(vehicle(1).position_m)


def test_trees_and_virtual_obstacles_are_drawn_in_different_colours(scene):
    tree = Obstacle("t1", np.array([4.0, -9.0]), 0.3, 8.0, "tree")
    virtual = Obstacle("v1", np.array([-5.0, 5.0]), 1.5, 12.0, "virtual")
    SceneRenderer(scene).draw(view(obstacles=(tree, virtual)))
    drawn_tree = scene.get_handle_by_name("/obstacle/t1")
    drawn_virtual = scene.get_handle_by_name("/obstacle/v1")
    assert tuple(drawn_tree.color) != tuple(drawn_virtual.color)
    assert drawn_virtual.position == pytest.approx([-5.0, 5.0, 6.0])  # standing on the ground


def test_a_removed_obstacle_disappears(scene):
    renderer = SceneRenderer(scene)
    renderer.draw(view(obstacles=(Obstacle("v1", np.array([-5.0, 5.0]), 1.5, 12.0, "virtual"),)))
    renderer.draw(view())
    assert scene.get_handle_by_name("/obstacle/v1") is None


def test_the_covariance_ellipsoid_has_two_sigma_semi_axes(scene):
    SceneRenderer(scene, sigma=2.0).draw(view(variances=(0.25, 0.04, 0.01)))
    ellipsoid = scene.get_handle_by_name("/person/covariance")
    assert sorted(ellipsoid.scale) == pytest.approx([0.2, 0.4, 1.0])
    assert ellipsoid.position == pytest.approx([0.5, 0.0, 0.9])


def test_the_desired_circle_sits_at_h_des_above_the_estimate(scene):
    SceneRenderer(scene).draw(view())
    points = scene.get_handle_by_name("/formation/circle").points
    radii = np.hypot(points[..., 0] - 0.5, points[..., 1])
    assert radii == pytest.approx(np.full(points.shape[:2], 8.0), abs=1e-4)
    assert points[..., 2] == pytest.approx(np.full(points.shape[:2], 8.9), abs=1e-4)


def test_label_shows_the_phase_of_a_mav_out_of_formation():
    assert vehicle_label(vehicle(1)) == "MAV 1"
    assert vehicle_label(vehicle(2, phase="landing")) == "MAV 2 (landing)"


def test_the_ellipsoid_is_outlined_by_its_three_principal_ellipses_and_its_size_is_written(scene):
    renderer = SceneRenderer(scene, sigma=2.0)
    renderer.draw(view(variances=(0.25, 0.04, 0.01)))
    outline = scene.get_handle_by_name("/person/covariance_outline")
    centred = outline.points.reshape(-1, 3) - [0.5, 0.0, 0.9]
    # every outline point lies on the 2-sigma ellipsoid: x^2/1^2 + y^2/0.4^2 + z^2/0.2^2 = 1
    assert np.sum((centred / [1.0, 0.4, 0.2]) ** 2, axis=1) == pytest.approx(np.ones(len(centred)), abs=1e-6)
    assert renderer.ellipsoid_axes_m is not None
    assert sorted(renderer.ellipsoid_axes_m) == pytest.approx([0.4, 0.8, 2.0])
    assert scene.get_handle_by_name("/person/covariance_label").text == "2\u03c3: 2.00 x 0.80 x 0.40 m"


def test_the_ellipsoid_is_transparent_and_the_person_markers_are_smaller_than_a_small_ellipsoid(scene):
    SceneRenderer(scene).draw(view(variances=(0.01, 0.01, 0.01)))  # 2 sigma = 0.2 m
    assert scene.get_handle_by_name("/person/covariance").opacity < 0.5
    assert scene.get_handle_by_name("/person/estimate").radius < 0.2
    assert scene.get_handle_by_name("/person/truth").radius < 0.2


def test_each_horizon_plan_marks_every_step_with_a_dot(scene):
    SceneRenderer(scene).draw(view())
    steps = scene.get_handle_by_name("/plan/1/steps")
    assert steps.points.shape == (16, 3)  # x(1)..x(16) of the 17-point plan; x(0) is the MAV itself
    assert steps.points == pytest.approx(vehicle(1).plan_positions_m[1:], abs=1e-3)


def test_a_north_arrow_points_along_plus_y_and_the_origin_is_labelled_when_known(scene):
    origin = GeodeticOrigin(lat_deg=47.397742, lon_deg=8.545594, alt_m=488.0)
    renderer = SceneRenderer(scene)
    renderer.draw(view())
    shaft = scene.get_handle_by_name("/arena/north").points[0]
    assert shaft[1, 1] - shaft[0, 1] > 2.0 and shaft[1, 0] == shaft[0, 0]
    assert scene.get_handle_by_name("/arena/north_label").text == "N"
    assert not scene.get_handle_by_name("/arena/origin_label").visible
    renderer.draw(view(origin=origin))
    label = scene.get_handle_by_name("/arena/origin_label")
    assert label.visible and label.text == "team origin 47.397742\u00b0N 8.545594\u00b0E, 488.0 m AMSL"


def test_sixteen_mavs_get_sixteen_distinct_colours_none_of_them_the_obstacles_or_the_person():
    colours = [vehicle_color(i) for i in range(1, 17)]
    assert len(set(colours)) == 16 == len(VEHICLE_COLORS)
    reserved = {
        TREE_COLOR,
        VIRTUAL_OBSTACLE_COLOR,
        PERSON_TRUTH_COLOR,
        PERSON_ESTIMATE_COLOR,
        COVARIANCE_COLOR,
    }
    assert not reserved & set(colours)


def test_the_readme_names_the_colours_the_scene_uses():
    text = README.read_text()
    legend = re.search(r"Colours in the 3-D view: (.*?)\.\n", text, re.S)
    assert legend is not None, "the README's colour legend sentence is missing"
    said = " ".join(legend.group(1).split())
    for phrase in (
        "trees brown",
        "virtual obstacles red",
        "desired circle green",
        "true position a light grey column",
        "fused estimate a black ball",
        "amber 2-sigma ellipsoid",
        "each MAV its own colour",
    ):
        assert phrase in said, phrase
    assert TREE_COLOR == (110, 80, 45) and VIRTUAL_OBSTACLE_COLOR[0] > 200 > VIRTUAL_OBSTACLE_COLOR[1] + 150
    assert CIRCLE_COLOR[1] > CIRCLE_COLOR[0] and CIRCLE_COLOR[1] > CIRCLE_COLOR[2]  # green
    assert len(set(PERSON_TRUTH_COLOR)) == 1 and PERSON_TRUTH_COLOR[0] > 150  # light grey
    assert max(PERSON_ESTIMATE_COLOR) < 50  # black
    assert COVARIANCE_COLOR[0] > 200 and COVARIANCE_COLOR[1] > 150 and COVARIANCE_COLOR[2] < 100  # amber


def test_ellipsoid_label_lists_the_axes_largest_first():
    assert ellipsoid_label(np.array([0.4, 1.2, 0.8]), 2.0) == "2\u03c3: 1.20 x 0.80 x 0.40 m"

"""The 3-D scene and the panel text drawn from a view, against a real viser server (no browser)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import viser

from controller.messages import Obstacle, PersonEstimate
from controller.params import FormationParams
from webui.panels import vehicle_card
from webui.scene import SceneRenderer, vehicle_label
from webui.view import Range, SceneView, VehicleView


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


def view(*, obstacles=(), variances=(0.25, 0.04, 0.01)) -> SceneView:
    full = np.eye(6)
    full[:3, :3] = np.diag(variances)
    estimate = PersonEstimate(
        stamp_s=1.0, position_m=np.array([0.5, 0.0, 0.9]), velocity_mps=np.array([0.0, 0.0, 0.0]), cov=full
    )
    return SceneView(
        time_s=1.0,
        vehicles=(vehicle(1), vehicle(2, phase="landing")),
        obstacles=tuple(obstacles),
        formation=FormationParams(),
        formation_enabled=True,
        arena_min_m=np.array([-20, -20, 3]),
        arena_max_m=np.array([20, 20, 10]),
        d_des_range_m=Range(1.8, 18.5),
        h_des_range_m=Range(2.1, 9.1),
        person_truth_m=np.array([0.0, 0.0, 0.9]),
        person_estimate=estimate,
        estimate_source_id=1,
        tracking_error_m=0.5,
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


def test_vehicle_card_shows_mode_solver_battery_and_a_stale_link():
    card = vehicle_card(vehicle(3, stale=True))
    assert "autopilot offboard, armed, in air" in card
    assert "link 2.5 s **STALE**" in card and "solver 0.25 ms (solved)" in card and "battery 80 %" in card
    assert "STALE" not in vehicle_card(vehicle(3))


def test_vehicle_card_shows_the_autopilots_own_mode_and_its_failsafe_with_its_reason():
    v = dataclasses.replace(
        vehicle(2),
        autopilot_mode="LAND",
        failsafe=True,
        failsafe_reason="Failsafe activated: switching to Land",
    )
    card = vehicle_card(v)
    assert "autopilot LAND" in card
    assert "**FAILSAFE**: Failsafe activated: switching to Land" in card
    assert "FAILSAFE" not in vehicle_card(vehicle(2))


def test_vehicle_card_shows_why_the_autopilot_refused_to_arm_and_why_it_may_not_take_off_here():
    v = dataclasses.replace(
        vehicle(1, phase="takeoff"),
        arming_refusal="Arming denied: Resolve system health failures first (Vehicle is in safety "
        "configuration)",
        takeoff_check="stands 3.0 m from the person, inside the 7.0 m keep-out (0.875 d_des)",
    )
    card = vehicle_card(v)
    assert "**ARMING REFUSED**: Arming denied: Resolve system health failures first" in card
    assert "safety configuration" in card
    assert "**CANNOT TAKE OFF HERE**: stands 3.0 m from the person" in card

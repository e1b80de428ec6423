"""The operator's 3-D scene: MAVs with camera frustums and horizon plans, the person and the fused covariance
ellipsoid, trees and virtual obstacles, and the desired circle, drawn in viser from a `SceneView`.

Node names (stable, so tests and later code can look them up with `scene.get_handle_by_name`):
/mav/<id> (body frame), /mav/<id>/body, /mav/<id>/camera, /mav/<id>/label, /plan/<id>, /person/truth,
/person/estimate, /person/covariance, /obstacle/<id>, /formation/circle, /arena/grid, /arena/bounds.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import viser

from controller.messages import Obstacle
from webui.geometry import (
    box_segments,
    camera_wxyz,
    circle_segments,
    ellipsoid_pose,
    polyline_segments,
    vehicle_color,
    yaw_wxyz,
)
from webui.view import SceneView, VehicleView

PERSON_TRUTH_COLOR = (230, 60, 60)
PERSON_ESTIMATE_COLOR = (20, 20, 20)
COVARIANCE_COLOR = (250, 200, 30)
TREE_COLOR = (110, 80, 45)
VIRTUAL_OBSTACLE_COLOR = (200, 30, 160)
CIRCLE_COLOR = (60, 170, 90)
PERSON_HEIGHT_M = 1.75


def vehicle_label(vehicle: VehicleView) -> str:
    """The text floating above a MAV: its number and, when it is not flying formation, its phase."""
    text = f"MAV {vehicle.vehicle_id}"
    return text if vehicle.in_formation else f"{text} ({vehicle.phase})"


class SceneRenderer:
    """Keeps one viser node per drawn thing and moves it on every `draw`; adds and removes obstacle and
    vehicle nodes as they appear and disappear. `sigma` is the ellipsoid's size in standard deviations (2:
    about 74 % of a 3-D Gaussian's mass lies inside)."""

    def __init__(self, scene: viser.SceneApi, *, sigma: float = 2.0) -> None:
        self._scene = scene
        self.sigma = sigma
        self._vehicles: dict[int, dict[str, Any]] = {}
        self._plans: dict[int, Any] = {}
        self._obstacles: dict[str, tuple[Obstacle, Any]] = {}
        self._arena_key: tuple[float, ...] | None = None
        self._person_truth = scene.add_cylinder(
            "/person/truth", radius=0.25, height=PERSON_HEIGHT_M, color=PERSON_TRUTH_COLOR, visible=False
        )
        self._person_estimate = scene.add_icosphere(
            "/person/estimate", radius=0.2, color=PERSON_ESTIMATE_COLOR, visible=False
        )
        self._covariance = scene.add_icosphere(
            "/person/covariance",
            radius=1.0,
            color=COVARIANCE_COLOR,
            opacity=0.35,
            visible=False,
            cast_shadow=False,
        )
        self._circle = scene.add_line_segments(
            "/formation/circle",
            points=np.zeros((1, 2, 3)),
            colors=CIRCLE_COLOR,
            thickness=2.0,
            thickness_units="screen",
            visible=False,
        )

    def draw(self, view: SceneView) -> None:
        """Bring the scene up to date with `view` (call inside `server.atomic()` to apply it as one frame)."""
        self._draw_arena(view)
        for vehicle in view.vehicles:
            self._draw_vehicle(vehicle, view)
        self._drop_missing_vehicles({v.vehicle_id for v in view.vehicles})
        self._draw_person(view)
        self._draw_obstacles(view.obstacles)
        self._draw_circle(view)

    def _draw_arena(self, view: SceneView) -> None:
        key = tuple(view.arena_min_m) + tuple(view.arena_max_m)
        if key == self._arena_key:
            return
        self._arena_key = key
        size = view.arena_max_m - view.arena_min_m
        center = 0.5 * (view.arena_max_m + view.arena_min_m)
        self._scene.add_grid(
            "/arena/grid",
            width=float(size[0]),
            height=float(size[1]),
            cell_size=1.0,
            section_size=5.0,
            position=(float(center[0]), float(center[1]), 0.0),
        )
        outline = box_segments(view.arena_min_m, view.arena_max_m)
        self._scene.add_line_segments(
            "/arena/bounds", points=outline, colors=(90, 90, 90), thickness=2.0, thickness_units="screen"
        )

    def _draw_vehicle(self, vehicle: VehicleView, view: SceneView) -> None:
        nodes = self._vehicles.get(vehicle.vehicle_id)
        color = vehicle_color(vehicle.vehicle_id)
        if nodes is None:
            root = f"/mav/{vehicle.vehicle_id}"
            cam = view.camera
            nodes = {
                "frame": self._scene.add_frame(root, show_axes=False),
                "body": self._scene.add_box(f"{root}/body", color=color, dimensions=(0.8, 0.8, 0.2)),
                "camera": self._scene.add_camera_frustum(
                    f"{root}/camera",
                    fov=cam.vertical_fov_rad,
                    aspect=cam.aspect,
                    scale=2.0,
                    color=color,
                    position=(cam.forward_offset_m, 0.0, 0.0),
                    wxyz=camera_wxyz(cam.pitch_down_rad),
                ),
                "label": self._scene.add_label(
                    f"{root}/label", vehicle_label(vehicle), position=(0.0, 0.0, 0.7)
                ),
            }
            self._vehicles[vehicle.vehicle_id] = nodes
            self._plans[vehicle.vehicle_id] = self._scene.add_line_segments(
                f"/plan/{vehicle.vehicle_id}",
                points=np.zeros((1, 2, 3)),
                colors=color,
                thickness=3.0,
                thickness_units="screen",
                visible=False,
            )
        nodes["frame"].position = vehicle.position_m
        nodes["frame"].wxyz = yaw_wxyz(vehicle.yaw_rad)
        label = vehicle_label(vehicle)
        if nodes["label"].text != label:
            nodes["label"].text = label
        plan = self._plans[vehicle.vehicle_id]
        segments = polyline_segments(vehicle.plan_positions_m)
        if len(segments) and vehicle.in_air:
            plan.points = segments
            plan.visible = True
        else:
            plan.visible = False

    def _drop_missing_vehicles(self, present: set[int]) -> None:
        for vehicle_id in [v for v in self._vehicles if v not in present]:
            self._vehicles.pop(vehicle_id)["frame"].remove()
            self._plans.pop(vehicle_id).remove()

    def _draw_person(self, view: SceneView) -> None:
        if view.person_truth_m is not None:
            self._person_truth.position = view.person_truth_m
            self._person_truth.visible = True
        else:
            self._person_truth.visible = False
        estimate = view.person_estimate
        if estimate is None or not np.all(np.isfinite(estimate.position_m)):
            self._person_estimate.visible = False
            self._covariance.visible = False
            return
        self._person_estimate.position = estimate.position_m
        self._person_estimate.visible = True
        try:
            semi_axes, wxyz = ellipsoid_pose(estimate.position_cov_m2, sigma=self.sigma)
        except ValueError:
            self._covariance.visible = False
            return
        self._covariance.position = estimate.position_m
        self._covariance.wxyz = wxyz
        sx, sy, sz = (float(a) for a in np.maximum(semi_axes, 1e-3))
        self._covariance.scale = (sx, sy, sz)
        self._covariance.visible = True

    def _draw_obstacles(self, obstacles: tuple[Obstacle, ...]) -> None:
        wanted = {o.obstacle_id: o for o in obstacles}
        for obstacle_id in list(self._obstacles):
            old, handle = self._obstacles[obstacle_id]
            new = wanted.get(obstacle_id)
            if new is None or not _same_obstacle(old, new):
                handle.remove()
                del self._obstacles[obstacle_id]
        for obstacle_id, obstacle in wanted.items():
            if obstacle_id in self._obstacles:
                continue
            virtual = obstacle.kind == "virtual"
            handle = self._scene.add_cylinder(
                f"/obstacle/{obstacle_id}",
                radius=obstacle.radius_m,
                height=obstacle.height_m,
                color=VIRTUAL_OBSTACLE_COLOR if virtual else TREE_COLOR,
                opacity=0.55 if virtual else None,
                position=(float(obstacle.center_m[0]), float(obstacle.center_m[1]), obstacle.height_m / 2.0),
            )
            self._obstacles[obstacle_id] = (obstacle, handle)

    def _draw_circle(self, view: SceneView) -> None:
        if view.person_estimate is not None and np.all(np.isfinite(view.person_estimate.position_m)):
            center = np.array(view.person_estimate.position_m)
        elif view.person_truth_m is not None:
            center = np.array(view.person_truth_m)
        else:
            self._circle.visible = False
            return
        center[2] += view.formation.h_des_m
        self._circle.points = circle_segments(center, view.formation.d_des_m)
        self._circle.visible = True


def _same_obstacle(a: Obstacle, b: Obstacle) -> bool:
    return (
        a.kind == b.kind
        and a.radius_m == b.radius_m
        and a.height_m == b.height_m
        and bool(np.array_equal(a.center_m, b.center_m))
    )

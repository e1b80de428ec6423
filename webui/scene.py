"""The operator's 3-D scene: MAVs with camera frustums and horizon plans, the person and the fused covariance
ellipsoid, trees and virtual obstacles, the desired circle, a north arrow and the team origin, drawn in viser
from a `SceneView`.

Colours (the README's legend says the same; `LEGEND` feeds the page's): each MAV its own colour
(`geometry.VEHICLE_COLORS`) for its body, frustum, label and horizon plan (a line with a dot per MPC step);
the person's true position (simulation) a light grey column, the fused estimate a black ball inside an amber
2-sigma ellipsoid (transparent, with its three principal ellipses outlined and its size written beside it);
trees brown, virtual obstacles red; the desired circle green; the arena's outline grey; north a dark arrow
marked N.

Node names (stable, so tests and later code can look them up with `scene.get_handle_by_name`):
/mav/<id> (body frame), /mav/<id>/body, /mav/<id>/camera, /mav/<id>/label, /plan/<id>, /plan/<id>/steps,
/person/truth, /person/estimate, /person/covariance, /person/covariance_outline, /person/covariance_label,
/obstacle/<id>, /formation/circle, /arena/grid, /arena/bounds, /arena/north, /arena/north_label,
/arena/origin_label.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
import viser

from webui.geometry import (
    box_segments,
    camera_wxyz,
    circle_segments,
    ellipse_outline_segments,
    ellipsoid_pose,
    north_arrow_segments,
    polyline_segments,
    vehicle_color,
    yaw_wxyz,
)
from webui.view import ObstacleView, SceneView, VehicleView

PERSON_TRUTH_COLOR = (170, 170, 170)
PERSON_ESTIMATE_COLOR = (20, 20, 20)
COVARIANCE_COLOR = (250, 200, 30)
COVARIANCE_OUTLINE_COLOR = (200, 130, 0)
TREE_COLOR = (110, 80, 45)
VIRTUAL_OBSTACLE_COLOR = (220, 40, 40)
CIRCLE_COLOR = (60, 170, 90)
ARENA_COLOR = (90, 90, 90)
NORTH_COLOR = (40, 40, 40)
PERSON_HEIGHT_M = 1.75
PLAN_STEP_SIZE_M = 0.22  # the dots marking each MPC step of a horizon plan
LEGEND: tuple[tuple[str, tuple[int, int, int]], ...] = (
    ("person (true, simulation)", PERSON_TRUTH_COLOR),
    ("fused estimate", PERSON_ESTIMATE_COLOR),
    ("2-sigma ellipsoid", COVARIANCE_COLOR),
    ("tree", TREE_COLOR),
    ("virtual obstacle", VIRTUAL_OBSTACLE_COLOR),
    ("desired circle", CIRCLE_COLOR),
    ("arena outline", ARENA_COLOR),
)


def vehicle_label(vehicle: VehicleView) -> str:
    """The text floating above a MAV: its number and, when it is not flying formation, its phase."""
    text = f"MAV {vehicle.vehicle_id}"
    return text if vehicle.in_formation else f"{text} ({vehicle.phase})"


class SceneRenderer:
    """Keeps one viser node per drawn thing and moves it on every `draw`; adds and removes obstacle and
    vehicle nodes as they appear and disappear. `sigma` is the ellipsoid's size in standard deviations (2:
    about 74 % of a 3-D Gaussian's mass lies inside)."""

    def __init__(
        self,
        scene: viser.SceneApi,
        *,
        sigma: float = 2.0,
        on_vehicle_click: Callable[[int, viser.ClientHandle | None], None] | None = None,
    ) -> None:
        self._scene = scene
        self.sigma = sigma
        self._on_vehicle_click = on_vehicle_click
        self.ellipsoid_axes_m: np.ndarray | None = None  # full lengths (3,) of the drawn ellipsoid's axes
        self._vehicles: dict[int, dict[str, Any]] = {}
        self._plans: dict[int, tuple[Any, Any]] = {}
        self._obstacles: dict[str, tuple[ObstacleView, Any]] = {}
        self._arena_key: tuple[float, ...] | None = None
        self._origin_text: str | None = None
        self._person_truth = scene.add_cylinder(
            "/person/truth",
            radius=0.12,
            height=PERSON_HEIGHT_M,
            color=PERSON_TRUTH_COLOR,
            opacity=0.45,
            visible=False,
            cast_shadow=False,
        )
        self._person_estimate = scene.add_icosphere(
            "/person/estimate", radius=0.1, color=PERSON_ESTIMATE_COLOR, visible=False
        )
        self._covariance = scene.add_icosphere(
            "/person/covariance",
            radius=1.0,
            color=COVARIANCE_COLOR,
            opacity=0.3,
            visible=False,
            cast_shadow=False,
        )
        self._covariance_outline = scene.add_line_segments(
            "/person/covariance_outline",
            points=np.zeros((1, 2, 3)),
            colors=COVARIANCE_OUTLINE_COLOR,
            thickness=2.0,
            thickness_units="screen",
            visible=False,
        )
        self._covariance_label = scene.add_label(
            "/person/covariance_label", "", anchor="bottom-left", visible=False, font_screen_scale=0.8
        )
        self._origin_label = scene.add_label(
            "/arena/origin_label", "", position=(0.0, 0.0, 0.1), anchor="top-left", visible=False
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
        self._draw_origin(view)
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
            "/arena/bounds", points=outline, colors=ARENA_COLOR, thickness=2.0, thickness_units="screen"
        )
        base = np.array([view.arena_min_m[0] + 2.0, view.arena_min_m[1] + 2.0, 0.05])
        length = max(2.0, 0.1 * float(size[1]))
        self._scene.add_line_segments(
            "/arena/north",
            points=north_arrow_segments(base, length),
            colors=NORTH_COLOR,
            thickness=4.0,
            thickness_units="screen",
        )
        self._scene.add_label(
            "/arena/north_label",
            "N",
            position=tuple(base + np.array([0.0, length + 0.5, 0.0])),
            anchor="bottom-center",
            font_screen_scale=1.4,
        )

    def _draw_origin(self, view: SceneView) -> None:
        o = view.origin
        text = (
            None
            if o is None
            else f"team origin {abs(o.lat_deg):.6f}\u00b0{'N' if o.lat_deg >= 0 else 'S'} "
            f"{abs(o.lon_deg):.6f}\u00b0{'E' if o.lon_deg >= 0 else 'W'}, {o.alt_m:.1f} m AMSL"
        )
        if text == self._origin_text:
            return
        self._origin_text = text
        if text is None:
            self._origin_label.visible = False
        else:
            self._origin_label.text = text
            self._origin_label.visible = True

    def _draw_vehicle(self, vehicle: VehicleView, view: SceneView) -> None:
        nodes = self._vehicles.get(vehicle.vehicle_id)
        color = vehicle_color(vehicle.vehicle_id)
        if nodes is None:
            root = f"/mav/{vehicle.vehicle_id}"
            cam = view.camera
            nodes = {
                "frame": self._scene.add_frame(root, show_axes=False),
                "body": self._scene.add_box(f"{root}/body", color=color, dimensions=(0.8, 0.8, 0.25)),
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
            if self._on_vehicle_click is not None:
                vid = vehicle.vehicle_id
                click = self._on_vehicle_click
                nodes["body"].on_click(lambda event, vid=vid, click=click: click(vid, event.client))
            line = self._scene.add_line_segments(
                f"/plan/{vehicle.vehicle_id}",
                points=np.zeros((1, 2, 3)),
                colors=color,
                thickness=4.0,
                thickness_units="screen",
                visible=False,
            )
            steps = self._scene.add_point_cloud(
                f"/plan/{vehicle.vehicle_id}/steps",
                points=np.zeros((1, 3)),
                colors=color,
                point_size=PLAN_STEP_SIZE_M,
                point_shape="circle",
                precision="float32",
            )
            self._plans[vehicle.vehicle_id] = (line, steps)
        nodes["frame"].position = vehicle.position_m
        nodes["frame"].wxyz = yaw_wxyz(vehicle.yaw_rad)
        label = vehicle_label(vehicle)
        if nodes["label"].text != label:
            nodes["label"].text = label
        line, steps = self._plans[vehicle.vehicle_id]
        segments = polyline_segments(vehicle.plan_positions_m)
        if len(segments) and vehicle.in_air:
            line.points = segments
            steps.points = np.asarray(vehicle.plan_positions_m[1:], dtype=np.float32)
            line.visible = True
        else:
            line.visible = False

    def _drop_missing_vehicles(self, present: set[int]) -> None:
        for vehicle_id in [v for v in self._vehicles if v not in present]:
            self._vehicles.pop(vehicle_id)["frame"].remove()
            self._plans.pop(vehicle_id)[0].remove()

    def _draw_person(self, view: SceneView) -> None:
        if view.person_truth_m is not None:
            self._person_truth.position = view.person_truth_m
            self._person_truth.visible = True
        else:
            self._person_truth.visible = False
        estimate = view.person_estimate
        if estimate is None or not np.all(np.isfinite(estimate.position_m)):
            self._person_estimate.visible = False
            self._hide_covariance()
            return
        self._person_estimate.position = estimate.position_m
        self._person_estimate.visible = True
        try:
            semi_axes, wxyz = ellipsoid_pose(estimate.position_cov_m2, sigma=self.sigma)
        except ValueError:
            self._hide_covariance()
            return
        semi_axes = np.maximum(semi_axes, 1e-3)
        center = np.asarray(estimate.position_m, dtype=float)
        self._covariance.position = center
        self._covariance.wxyz = wxyz
        self._covariance.scale = (float(semi_axes[0]), float(semi_axes[1]), float(semi_axes[2]))
        self._covariance.visible = True
        self._covariance_outline.points = ellipse_outline_segments(center, semi_axes, wxyz)
        self._covariance_outline.visible = True
        self.ellipsoid_axes_m = 2.0 * semi_axes
        self._covariance_label.text = ellipsoid_label(self.ellipsoid_axes_m, self.sigma)
        self._covariance_label.position = center + np.array([0.3, 0.0, float(np.max(semi_axes)) + 0.3])
        self._covariance_label.visible = True

    def _hide_covariance(self) -> None:
        self.ellipsoid_axes_m = None
        self._covariance.visible = False
        self._covariance_outline.visible = False
        self._covariance_label.visible = False

    def _draw_obstacles(self, obstacles: tuple[ObstacleView, ...]) -> None:
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


def ellipsoid_label(axes_m: np.ndarray, sigma: float) -> str:
    """The size written beside the ellipsoid: its full axis lengths, largest first."""
    a = sorted((float(x) for x in axes_m), reverse=True)
    return f"{sigma:g}\u03c3: {a[0]:.2f} x {a[1]:.2f} x {a[2]:.2f} m"


def _same_obstacle(a: ObstacleView, b: ObstacleView) -> bool:
    return (
        a.kind == b.kind
        and a.radius_m == b.radius_m
        and a.height_m == b.height_m
        and bool(np.array_equal(a.center_m, b.center_m))
    )

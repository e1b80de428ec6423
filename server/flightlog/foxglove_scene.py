"""The operator's 3-D scene as a Foxglove `SceneUpdate` in the `world` frame (local ENU, metres), so a flight
log or a live Foxglove client shows what the operator's page showed: each MAV's body, camera frustum, label
and horizon plan; the person (truth as a cylinder, estimate as a sphere) and the fused position covariance
as its 2-sigma ellipsoid; trees and virtual obstacles as cylinders; the desired circle at d_des / h_des.

Every update replaces the whole scene (a delete-all, then every entity), so removed obstacles and vehicles
vanish; entity ids are stable (`mav/<id>`, `plan/<id>`, `person/...`, `obstacle/<id>`, `formation/circle`).
"""

from __future__ import annotations

import math

import numpy as np
from foxglove.messages import (
    Color,
    CubePrimitive,
    CylinderPrimitive,
    LinePrimitive,
    LinePrimitiveLineType,
    Point3,
    Pose,
    Quaternion,
    SceneEntity,
    SceneEntityDeletion,
    SceneEntityDeletionType,
    SceneUpdate,
    SpherePrimitive,
    TextPrimitive,
    Timestamp,
    Vector3,
)

from webui.geometry import circle_segments, ellipsoid_pose, vehicle_color
from webui.view import ObstacleView, SceneView, VehicleView

FRAME = "world"
SIGMA = 2.0  # the ellipsoid's size in standard deviations, as on the page
PERSON_HEIGHT_M = 1.75
TREE = (110, 80, 45)
VIRTUAL = (200, 30, 160)
TRUTH = (230, 60, 60)
ESTIMATE = (20, 20, 20)
COVARIANCE = (250, 200, 30)
CIRCLE = (60, 170, 90)


def _color(rgb: tuple[int, int, int], alpha: float = 1.0) -> Color:
    return Color(r=rgb[0] / 255.0, g=rgb[1] / 255.0, b=rgb[2] / 255.0, a=alpha)


def _pose(position, wxyz=(1.0, 0.0, 0.0, 0.0)) -> Pose:
    p = [float(v) if math.isfinite(v) else 0.0 for v in position]
    w, x, y, z = (float(v) for v in wxyz)
    return Pose(position=Vector3(x=p[0], y=p[1], z=p[2]), orientation=Quaternion(x=x, y=y, z=z, w=w))


def _points(points: np.ndarray) -> list[Point3]:
    return [Point3(x=float(p[0]), y=float(p[1]), z=float(p[2])) for p in points if np.all(np.isfinite(p))]


def _stamp(time_s: float) -> Timestamp:
    t = max(0.0, time_s) if math.isfinite(time_s) else 0.0
    sec = int(t)
    return Timestamp(sec=sec, nsec=int(round((t - sec) * 1e9)) % 1_000_000_000)


def _entity(entity_id: str, stamp: Timestamp, **primitives) -> SceneEntity:
    return SceneEntity(timestamp=stamp, frame_id=FRAME, id=entity_id, **primitives)


def _frustum(vehicle: VehicleView, view: SceneView, scale_m: float = 2.0) -> LinePrimitive:
    """The camera frustum as line pairs in the world frame: apex at the camera, four edges and the far
    rectangle, pitched down and turned with the MAV's yaw."""
    cam = view.camera
    half_v = scale_m * math.tan(cam.vertical_fov_rad / 2.0)
    half_h = half_v * cam.aspect
    # camera frame: x forward, y left, z up; the image corners at distance scale_m along x
    corners = np.array([[scale_m, s * half_h, t * half_v] for s, t in ((1, 1), (-1, 1), (-1, -1), (1, -1))])
    pitch, yaw = cam.pitch_down_rad, float(vehicle.yaw_rad) if math.isfinite(vehicle.yaw_rad) else 0.0
    down = np.array(
        [[math.cos(pitch), 0.0, math.sin(pitch)], [0.0, 1.0, 0.0], [-math.sin(pitch), 0.0, math.cos(pitch)]]
    )
    turn = np.array(
        [[math.cos(yaw), -math.sin(yaw), 0.0], [math.sin(yaw), math.cos(yaw), 0.0], [0.0, 0.0, 1.0]]
    )
    apex = np.asarray(vehicle.position_m) + turn @ np.array([cam.forward_offset_m, 0.0, 0.0])
    world = apex + (turn @ down @ corners.T).T
    pairs = [apex, world[0], apex, world[1], apex, world[2], apex, world[3]]
    for i in range(4):
        pairs += [world[i], world[(i + 1) % 4]]
    return LinePrimitive(
        type=LinePrimitiveLineType.LineList,
        points=_points(np.array(pairs)),
        thickness=2.0,
        scale_invariant=True,
        color=_color(vehicle_color(vehicle.vehicle_id)),
    )


def _vehicle(vehicle: VehicleView, view: SceneView, stamp: Timestamp) -> list[SceneEntity]:
    color = _color(vehicle_color(vehicle.vehicle_id))
    yaw = float(vehicle.yaw_rad) if math.isfinite(vehicle.yaw_rad) else 0.0
    wxyz = (math.cos(yaw / 2.0), 0.0, 0.0, math.sin(yaw / 2.0))
    label = f"MAV {vehicle.vehicle_id}" + ("" if vehicle.in_formation else f" ({vehicle.phase})")
    body = _entity(
        f"mav/{vehicle.vehicle_id}",
        stamp,
        cubes=[
            CubePrimitive(
                pose=_pose(vehicle.position_m, wxyz), size=Vector3(x=0.8, y=0.8, z=0.2), color=color
            )
        ],
        lines=[_frustum(vehicle, view)],
        texts=[
            TextPrimitive(
                pose=_pose(np.asarray(vehicle.position_m) + [0.0, 0.0, 0.7]),
                billboard=True,
                font_size=14.0,
                scale_invariant=True,
                color=_color((20, 20, 20)),
                text=label,
            )
        ],
    )
    entities = [body]
    if vehicle.in_air and len(vehicle.plan_positions_m) >= 2:
        entities.append(
            _entity(
                f"plan/{vehicle.vehicle_id}",
                stamp,
                lines=[
                    LinePrimitive(
                        type=LinePrimitiveLineType.LineStrip,
                        points=_points(vehicle.plan_positions_m),
                        thickness=3.0,
                        scale_invariant=True,
                        color=color,
                    )
                ],
            )
        )
    return entities


def _obstacle(obstacle: ObstacleView, stamp: Timestamp) -> SceneEntity:
    virtual = obstacle.kind == "virtual"
    x, y = (float(v) for v in obstacle.center_m)
    d = 2.0 * obstacle.radius_m
    return _entity(
        f"obstacle/{obstacle.obstacle_id}",
        stamp,
        cylinders=[
            CylinderPrimitive(
                pose=_pose((x, y, obstacle.height_m / 2.0)),
                size=Vector3(x=d, y=d, z=obstacle.height_m),
                bottom_scale=1.0,
                top_scale=1.0,
                color=_color(VIRTUAL, 0.55) if virtual else _color(TREE),
            )
        ],
    )


def _person(view: SceneView, stamp: Timestamp) -> list[SceneEntity]:
    entities = []
    if view.person_truth_m is not None:
        x, y, _ = (float(v) for v in view.person_truth_m)
        entities.append(
            _entity(
                "person/truth",
                stamp,
                cylinders=[
                    CylinderPrimitive(
                        pose=_pose((x, y, PERSON_HEIGHT_M / 2.0)),
                        size=Vector3(x=0.5, y=0.5, z=PERSON_HEIGHT_M),
                        bottom_scale=1.0,
                        top_scale=1.0,
                        color=_color(TRUTH),
                    )
                ],
            )
        )
    estimate = view.person_estimate
    if estimate is None or not np.all(np.isfinite(estimate.position_m)):
        return entities
    entities.append(
        _entity(
            "person/estimate",
            stamp,
            spheres=[
                SpherePrimitive(
                    pose=_pose(estimate.position_m), size=Vector3(x=0.4, y=0.4, z=0.4), color=_color(ESTIMATE)
                )
            ],
        )
    )
    try:
        semi_axes, wxyz = ellipsoid_pose(estimate.position_cov_m2, sigma=SIGMA)
    except ValueError:
        return entities
    size = 2.0 * np.maximum(semi_axes, 1e-3)
    entities.append(
        _entity(
            "person/covariance",
            stamp,
            spheres=[
                SpherePrimitive(
                    pose=_pose(estimate.position_m, wxyz),
                    size=Vector3(x=float(size[0]), y=float(size[1]), z=float(size[2])),
                    color=_color(COVARIANCE, 0.35),
                )
            ],
        )
    )
    return entities


def _circle(view: SceneView, stamp: Timestamp) -> list[SceneEntity]:
    if view.person_estimate is not None and np.all(np.isfinite(view.person_estimate.position_m)):
        center = np.array(view.person_estimate.position_m)
    elif view.person_truth_m is not None:
        center = np.array(view.person_truth_m)
    else:
        return []
    center[2] += view.formation.h_des_m
    segments = circle_segments(center, view.formation.d_des_m)
    return [
        _entity(
            "formation/circle",
            stamp,
            lines=[
                LinePrimitive(
                    type=LinePrimitiveLineType.LineList,
                    points=_points(segments.reshape(-1, 3)),
                    thickness=2.0,
                    scale_invariant=True,
                    color=_color(CIRCLE),
                )
            ],
        )
    ]


def scene_update(view: SceneView) -> SceneUpdate:
    """The whole scene of `view`, replacing whatever was drawn before."""
    stamp = _stamp(view.time_s)
    entities: list[SceneEntity] = []
    for vehicle in view.vehicles:
        entities += _vehicle(vehicle, view, stamp)
    entities += [_obstacle(o, stamp) for o in view.obstacles]
    entities += _person(view, stamp)
    entities += _circle(view, stamp)
    return SceneUpdate(
        deletions=[SceneEntityDeletion(timestamp=stamp, type=SceneEntityDeletionType.All)],
        entities=entities,
    )

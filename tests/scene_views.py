"""Operator views for the tests of the operator page and of the alert rules: a MAV in formation flight and a
scene around a team, each changed by keyword where a test needs something else."""

from __future__ import annotations

import dataclasses
from collections.abc import Iterable

import numpy as np

from controller.params import FormationParams
from webui.view import Range, SceneView, VehicleView


def flying_mav(vehicle_id: int = 1, **changes) -> VehicleView:
    """MAV `vehicle_id` in formation flight, offboard and armed, 9 m above the origin, its link fresh."""
    base = VehicleView(
        vehicle_id=vehicle_id,
        phase="formation",
        mode="offboard",
        armed=True,
        in_air=True,
        in_formation=True,
        position_m=np.array([0.0, 0.0, 9.0]),
        yaw_rad=0.0,
        link_age_s=0.0,
        link_stale=False,
    )
    return dataclasses.replace(base, **changes)


def scene_view(vehicles: Iterable[VehicleView], **changes) -> SceneView:
    """The scene of `vehicles` at mission second 1: no obstacles, the default formation (enabled), the arena
    40 m x 40 m and 3-10 m up, the operator's ranges d_des 3-18.5 m and h_des 2.1-9.1 m."""
    base = SceneView(
        time_s=1.0,
        vehicles=tuple(vehicles),
        obstacles=(),
        formation=FormationParams(),
        formation_enabled=True,
        arena_min_m=np.array([-20.0, -20.0, 3.0]),
        arena_max_m=np.array([20.0, 20.0, 10.0]),
        d_des_range_m=Range(3.0, 18.5),
        h_des_range_m=Range(2.1, 9.1),
    )
    return dataclasses.replace(base, **changes)

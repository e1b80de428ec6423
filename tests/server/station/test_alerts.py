"""The alerts of the operator's view: what needs attention now, derived from the vehicles, critical first,
and shown at the top of the panel."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from controller.params import FormationParams
from server.station.ground_station import alerts_of
from webui.panels import status_line
from webui.view import Alert, Range, SceneView, VehicleView


def vehicle(vehicle_id: int, **changes: object) -> VehicleView:
    base = VehicleView(
        vehicle_id=vehicle_id,
        phase="formation",
        mode="offboard",
        armed=True,
        in_air=True,
        in_formation=True,
        position_m=np.zeros(3),
        yaw_rad=0.0,
        link_age_s=0.1,
        link_stale=False,
        solve_status="solved",
        battery_fraction=0.9,
    )
    return replace(base, **changes)


def test_a_healthy_team_tracking_the_person_has_no_alerts():
    assert alerts_of((vehicle(1), vehicle(2)), tracking=True) == ()


def test_a_flying_mav_without_telemetry_or_nearly_empty_is_critical_and_listed_first():
    alerts = alerts_of(
        (
            vehicle(1, battery_fraction=0.25),
            vehicle(2, link_stale=True, link_age_s=3.46),
            vehicle(3, battery_fraction=0.1),
        ),
        tracking=True,
    )
    assert alerts == (
        Alert("critical", "MAV 2: no telemetry for 3.5 s", 2),
        Alert("critical", "MAV 3: battery 10%", 3),
        Alert("warning", "MAV 1: battery 25%", 1),
    )


def test_a_braking_mav_and_a_team_without_a_person_estimate_are_warnings():
    alerts = alerts_of((vehicle(1, solve_status="braking"),), tracking=False)
    assert alerts == (
        Alert("warning", "MAV 1: no MPC plan, braking", 1),
        Alert("warning", "no person estimate: the team holds position"),
    )


def test_a_landed_mav_with_an_old_link_is_not_an_alert():
    landed = vehicle(
        1, phase="landed", in_air=False, in_formation=False, link_stale=True, link_age_s=math.inf
    )
    assert alerts_of((landed,), tracking=True) == ()


def test_the_panel_status_shows_the_alerts_with_critical_ones_in_bold():
    view = SceneView(
        time_s=1.0,
        vehicles=(vehicle(1),),
        obstacles=(),
        formation=FormationParams(),
        formation_enabled=True,
        arena_min_m=np.array([-20.0, -20.0, 3.0]),
        arena_max_m=np.array([20.0, 20.0, 10.0]),
        d_des_range_m=Range(1.8, 18.5),
        h_des_range_m=Range(2.1, 9.1),
        alerts=(
            Alert("critical", "MAV 2: no telemetry for 3.5 s", 2),
            Alert("warning", "MAV 1: battery 25%", 1),
        ),
    )
    text = status_line(view)
    assert "**CRITICAL**: MAV 2: no telemetry for 3.5 s" in text and "warning: MAV 1: battery 25%" in text

"""The alert rules read off the operator's view: each rule raised at its threshold and silent below it."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scene_views import flying_mav, scene_view

from controller.messages import Obstacle
from server.station.alert_rules import AlertParams, conditions
from webui.view import AgentView, PaceView, SceneView, Severity, VehicleView

PARAMS = AlertParams()  # d_min 1.5 m, margin 0.5 m, battery 25 % / 15 %


def mav(vehicle_id: int, position=(0.0, 0.0, 9.0), **changes) -> VehicleView:
    """A MAV in formation flight at `position` (m), its solver and battery healthy."""
    healthy = {"solve_status": "solved", "solver_time_s": 2e-4, "battery_fraction": 0.9, "plan_age_s": 0.0}
    return flying_mav(vehicle_id, **(healthy | {"position_m": np.array(position, dtype=float)} | changes))


def scene(*vehicles: VehicleView, obstacles=(), pace: PaceView | None = None) -> SceneView:
    return scene_view(vehicles, time_s=10.0, obstacles=tuple(obstacles), pace=pace)


def kinds(view: SceneView) -> dict[str, Severity]:
    return {c.kind: c.severity for c in conditions(view, PARAMS)}


def test_a_healthy_team_in_formation_raises_nothing():
    view = scene(mav(1, (8.0, 0.0, 9.0)), mav(2, (-4.0, 6.9, 9.0)), mav(3, (-4.0, -6.9, 9.0)))
    assert conditions(view, PARAMS) == []


@pytest.mark.parametrize(
    ("fraction", "expected"), [(0.26, None), (0.20, Severity.WARNING), (0.14, Severity.CRITICAL)]
)
def test_battery_is_low_below_25_percent_and_critical_below_15(fraction, expected):
    found = kinds(scene(mav(1, battery_fraction=fraction))).get("battery")
    assert found == expected


def test_an_unknown_battery_raises_nothing():
    assert "battery" not in kinds(scene(mav(1, battery_fraction=None)))


@pytest.mark.parametrize(
    ("distance", "expected"), [(2.1, None), (1.8, Severity.WARNING), (1.4, Severity.CRITICAL)]
)
def test_two_airborne_mavs_closer_than_d_min_plus_margin_warn_and_closer_than_d_min_are_critical(
    distance, expected
):
    view = scene(mav(1, (0.0, 0.0, 9.0)), mav(2, (distance, 0.0, 9.0)), mav(3, (8.0, 8.0, 9.0)))
    found = [c for c in conditions(view, PARAMS) if c.kind == "separation"]
    if expected is None:
        assert found == []
    else:
        (c,) = found
        assert (c.vehicle_id, c.subject, c.severity) == (1, "MAV 2", expected)
        assert f"{distance:.2f} m apart" in c.message


def test_mavs_on_the_ground_side_by_side_are_not_a_separation_alert():
    view = scene(
        mav(1, (0.0, 0.0, 0.0), in_air=False, phase="idle"),
        mav(2, (1.0, 0.0, 0.0), in_air=False, phase="idle"),
    )
    assert "separation" not in kinds(view)


@pytest.mark.parametrize(
    ("clearance", "expected"), [(1.2, None), (0.8, Severity.WARNING), (0.3, Severity.CRITICAL)]
)
def test_trunk_clearance_below_1_m_warns_and_below_half_a_metre_is_critical(clearance, expected):
    tree = Obstacle(obstacle_id="t3", center_m=np.array([0.0, 0.0]), radius_m=0.5, height_m=12.0, kind="tree")
    view = scene(mav(1, (0.5 + clearance, 0.0, 9.0)), obstacles=[tree])
    found = [c for c in conditions(view, PARAMS) if c.kind == "trunk_clearance"]
    assert [c.severity for c in found] == ([] if expected is None else [expected])
    if found:
        assert found[0].subject == "trunk t3"


def test_a_mav_above_an_obstacle_top_is_clear_of_it():
    low = Obstacle(
        obstacle_id="v1", center_m=np.array([0.0, 0.0]), radius_m=1.0, height_m=5.0, kind="virtual"
    )
    assert "trunk_clearance" not in kinds(scene(mav(1, (0.5, 0.0, 9.0)), obstacles=[low]))


@pytest.mark.parametrize(
    ("position", "expected"),
    [((19.5, 0.0, 9.0), None), ((21.0, 0.0, 9.0), Severity.WARNING), ((0.0, -23.0, 9.0), Severity.CRITICAL)],
)
def test_leaving_the_arena_warns_and_more_than_2_m_out_is_critical(position, expected):
    assert kinds(scene(mav(1, position))).get("arena") == expected


def test_flying_above_the_arena_ceiling_is_leaving_the_arena():
    (c,) = [c for c in conditions(scene(mav(1, (0.0, 0.0, 11.0))), PARAMS) if c.kind == "arena"]
    assert "above the arena's ceiling" in c.message


def test_a_stale_link_is_critical_in_the_air_and_a_warning_on_the_ground():
    flying = mav(1, link_stale=True, link_age_s=2.5)
    grounded = mav(2, (5.0, 5.0, 0.0), link_stale=True, link_age_s=math.inf, in_air=False, phase="landed")
    found = {c.vehicle_id: c for c in conditions(scene(flying, grounded), PARAMS) if c.kind == "link"}
    assert found[1].severity == Severity.CRITICAL and "no telemetry for 2.5 s" in found[1].message
    assert found[2].severity == Severity.WARNING and "never heard from" in found[2].message


def test_an_airborne_mav_whose_controller_published_no_plan_for_a_second_is_an_agent_lost():
    assert kinds(scene(mav(1, plan_age_s=1.5)))["agent"] == Severity.CRITICAL
    assert "agent" not in kinds(scene(mav(1, plan_age_s=0.5)))


def test_an_onboard_agent_not_heard_is_an_agent_lost():
    lost = mav(1, agent=AgentView(lost=True, age_s=0.8), link_stale=True, link_age_s=0.8)
    found = [c for c in conditions(scene(lost), PARAMS) if c.kind == "agent"]
    assert [c.severity for c in found] == [Severity.CRITICAL] and "0.8 s" in found[0].message
    assert "agent" not in kinds(scene(mav(1, agent=AgentView(lost=False, age_s=0.1))))


def test_agent_lost_is_not_raised_when_the_link_is_what_is_lost():
    assert "agent" not in kinds(scene(mav(1, plan_age_s=3.0, link_stale=True, link_age_s=3.0)))


@pytest.mark.parametrize(("achieved", "raised"), [(3.5, False), (3.1, True), (None, False)])
def test_the_loop_is_behind_real_time_below_80_percent_of_the_speed_asked(achieved, raised):
    view = scene(mav(1), pace=PaceView(requested_speed=4.0, realtime_factor=achieved))
    assert ("realtime" in kinds(view)) == raised


def test_ticks_slower_than_their_period_are_behind_real_time_before_the_achieved_factor_drops():
    view = scene(mav(1), pace=PaceView(requested_speed=1.0, realtime_factor=0.98, capacity=0.5))
    (c,) = conditions(view, PARAMS)
    assert c.kind == "realtime" and "its ticks allow 0.50x at most, 1x asked" in c.message
    assert "realtime" not in kinds(scene(mav(1), pace=PaceView(requested_speed=1.0, capacity=3.0)))


def test_autopilot_failsafe_is_critical_and_arming_refused_a_warning():
    view = scene(
        mav(1, failsafe=True, failsafe_reason="battery 14 % at or below 15 %: landing"),
        mav(2, (8, 8, 9), arming_refusal="x"),
    )
    found = kinds(view)
    assert found["failsafe"] == Severity.CRITICAL and found["arming"] == Severity.WARNING


def test_a_failsafe_alert_names_the_autopilots_mode_and_its_words_or_says_it_has_none():
    landing = mav(1, autopilot_mode="LAND", failsafe=True, failsafe_reason="Low battery")
    (c,) = conditions(scene(landing), PARAMS)
    assert c.message == "MAV 1 autopilot failsafe (LAND): Low battery"
    (c,) = conditions(scene(mav(1, failsafe=True)), PARAMS)
    assert c.message == "MAV 1 autopilot failsafe (offboard): the autopilot runs its own failsafe"


def test_a_braking_solver_is_a_warning_with_its_fault():
    (c,) = conditions(scene(mav(1, solve_status="braking", fault="OSQP: max iterations")), PARAMS)
    assert c.kind == "solver" and c.severity == Severity.WARNING and "OSQP: max iterations" in c.message


def test_a_link_loss_hold_is_a_warning_naming_the_unheard_teammates():
    fault = "hold: teammate 3, 5 unheard for more than 1.5 s"
    (c,) = conditions(scene(mav(1, solve_status="hold", fault=fault)), PARAMS)
    assert c.kind == "hold" and c.severity == Severity.WARNING
    assert c.message == "MAV 1 holds, not hearing its team: teammate 3, 5 unheard for more than 1.5 s"


def test_inconsistent_thresholds_are_refused():
    with pytest.raises(ValueError, match="battery"):
        AlertParams(battery_low_fraction=0.1, battery_critical_fraction=0.2)

"""What the panels say: the header, the team table (16 MAVs), a MAV's detail, the alert list and summary."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from scene_views import flying_mav, scene_view

from webui.cards import (
    STATUS_CRITICAL,
    STATUS_GROUND,
    STATUS_MOVING,
    STATUS_OK,
    STATUS_WARNING,
    alert_summary_html,
    alert_table_html,
    header_html,
    team_table_html,
    utc_text,
    vehicle_detail_markdown,
    vehicle_status,
)
from webui.geometry import vehicle_color
from webui.view import Alert, PaceView, SceneView, Severity, VehicleView


def mav(vehicle_id: int, **changes) -> VehicleView:
    """A MAV in formation flight with what the cards show of it: speed, solver, battery, distance."""
    shown = {
        "position_m": np.array([1.0, 2.0, 9.25]),
        "velocity_mps": np.array([0.3, 0.4, 0.0]),
        "link_age_s": 0.04,
        "solve_status": "solved",
        "solver_time_s": 1.5e-4,
        "battery_fraction": 0.87,
        "distance_to_person_m": 8.04,
        "plan_age_s": 0.0,
    }
    return flying_mav(vehicle_id, **(shown | changes))


def alert(alert_id: str, vehicle_id: int | None, severity: Severity, **changes) -> Alert:
    base = Alert(
        alert_id=alert_id,
        kind="battery",
        vehicle_id=vehicle_id,
        subject="",
        severity=severity,
        message=f"MAV {vehicle_id} battery low: 20 % (below 25 %)",
        first_s=12.3,
        last_s=15.0,
        active=True,
        acknowledged=False,
        first_utc_s=1_700_000_000.0,
    )
    return dataclasses.replace(base, **changes)


def scene(vehicles, alerts=(), **changes) -> SceneView:
    fields = {"time_s": 123.45, "alerts": tuple(alerts), "utc_s": 1_700_000_000.0}
    return scene_view(vehicles, **(fields | changes))


def test_header_shows_mission_time_utc_the_recording_with_its_path_and_the_real_time_factor():
    view = scene(
        [mav(1)],
        recording_path="runs/flight-20250601T120000Z.jsonl",
        pace=PaceView(requested_speed=4.0, realtime_factor=3.92),
    )
    text = header_html(view)
    assert "T+ 123.5 s" in text and "22:13:20 UTC" in text
    assert "REC" in text and "runs/flight-20250601T120000Z.jsonl" in text
    assert "3.92x real time (asked 4x)" in text


def test_header_says_when_nothing_is_recorded():
    assert "not recording" in header_html(scene([mav(1)]))


def test_utc_text_of_an_unknown_time_is_a_dash():
    assert utc_text(None) == "-" and utc_text(0.0) == "00:00:00 UTC"


def test_the_team_table_has_one_row_per_mav_with_every_column_for_16_mavs():
    view = scene([mav(i) for i in range(1, 17)])
    html = team_table_html(view, {i: vehicle_color(i) for i in range(1, 17)})
    assert html.count("<tr data-vehicle=") == 16
    for header in ("phase", "mode", "alt m", "v m/s", "d m", "link s", "batt", "solver"):
        assert f">{header}</th>" in html
    row = html.split('<tr data-vehicle="7">')[1].split("</tr>")[0]
    for cell in ("formation", "offboard", ">9.2<", ">0.5<", ">8.0<", ">0.0<", "87%", ">0.1<"):
        assert cell in row, cell


def test_a_stale_link_shows_stale_in_red_and_a_failed_solve_shows_its_status():
    html = team_table_html(scene([mav(1, link_stale=True, solve_status="braking")]), {1: (0, 0, 0)})
    assert ">STALE</span>" in html and "color:#e03131" in html and ">braking<" in html


def test_status_colour_follows_the_worst_active_alert_then_the_phase():
    assert vehicle_status(mav(1), []) == STATUS_OK
    assert vehicle_status(mav(1), [alert("a1", 1, Severity.WARNING)]) == STATUS_WARNING
    assert vehicle_status(mav(1), [alert("a1", 1, Severity.CRITICAL)]) == STATUS_CRITICAL
    assert vehicle_status(mav(1), [alert("a1", 2, Severity.CRITICAL)]) == STATUS_OK  # another MAV's
    assert vehicle_status(mav(1), [alert("a1", 1, Severity.CRITICAL, active=False)]) == STATUS_OK
    assert vehicle_status(mav(1, phase="landed", in_air=False, in_formation=False), []) == STATUS_GROUND
    assert vehicle_status(mav(1, phase="holding", in_formation=False), []) == STATUS_MOVING
    assert vehicle_status(mav(1, link_stale=True), []) == STATUS_CRITICAL


def test_the_detail_lists_position_velocity_battery_link_solver_failsafe_and_alerts():
    text = vehicle_detail_markdown(
        mav(3, failsafe=True, failsafe_reason="battery 14 % at or below 15 %: landing"),
        [alert("a4", 3, Severity.CRITICAL)],
    )
    assert "**MAV 3**: formation · in formation, autopilot offboard, armed, in air" in text
    assert "position (1.0, 2.0, 9.2) m" in text and "velocity (0.3, 0.4, 0.0) m/s" in text
    assert "battery 87 %" in text and "distance to person 8.0 m" in text
    assert "**FAILSAFE**: battery 14 % at or below 15 %: landing" in text
    assert "- critical: MAV 3 battery low" in text


def test_the_detail_shows_the_separation_to_the_nearest_teammate_and_tree():
    v = mav(3, nearest_teammate_m=3.21, nearest_teammate_id=2, nearest_obstacle_m=4.06)
    assert "sep 3.2 m (MAV 2) / tree 4.1 m" in vehicle_detail_markdown(v, [])
    assert "sep - / tree -" in vehicle_detail_markdown(mav(3, in_air=False), [])


def test_the_detail_and_the_table_show_the_autopilots_own_mode_and_its_failsafe_with_its_reason():
    v = mav(2, autopilot_mode="LAND", failsafe=True, failsafe_reason="Failsafe activated: switching to Land")
    text = vehicle_detail_markdown(v, [])
    assert "autopilot LAND" in text
    assert "**FAILSAFE**: Failsafe activated: switching to Land" in text
    assert "FAILSAFE" not in vehicle_detail_markdown(mav(2), [])
    row = team_table_html(scene([v]), {2: (0, 0, 0)}).split('<tr data-vehicle="2">')[1]
    assert ">LAND<" in row


def test_the_detail_shows_why_the_autopilot_refused_to_arm_and_why_it_may_not_take_off_here():
    v = mav(
        1,
        phase="takeoff",
        arming_refusal="Arming denied: Resolve system health failures first (Vehicle is in safety "
        "configuration)",
        takeoff_check="stands 3.0 m from the person, inside the 7.0 m keep-out (0.875 d_des)",
    )
    text = vehicle_detail_markdown(v, [])
    assert "**ARMING REFUSED**: Arming denied: Resolve system health failures first" in text
    assert "safety configuration" in text
    assert "**CANNOT TAKE OFF HERE**: stands 3.0 m from the person" in text


def test_the_alert_table_shows_each_alert_with_time_state_and_severity():
    alerts = [
        alert("a2", 2, Severity.CRITICAL),
        alert("a1", 1, Severity.WARNING, active=False, acknowledged=True, count=3),
    ]
    html = alert_table_html(alerts)
    assert html.index('data-alert="a2"') < html.index('data-alert="a1"')
    assert "12.3 s (22:13:20 UTC)" in html
    assert ">ACTIVE</td>" in html and ">cleared, ack, x3</td>" in html


def test_the_alert_table_escapes_messages():
    html = alert_table_html([alert("a1", 1, Severity.WARNING, message="<script>x</script>")])
    assert "<script>" not in html and "&lt;script&gt;" in html


def test_the_summary_counts_active_and_unacknowledged_alerts_and_shows_the_most_urgent():
    alerts = [
        alert("a1", 1, Severity.WARNING, message="warning one"),
        alert("a2", 2, Severity.CRITICAL, message="critical two"),
        alert("a3", 3, Severity.CRITICAL, acknowledged=True, message="seen"),
        alert("a4", 4, Severity.CRITICAL, active=False),
    ]
    text = alert_summary_html(alerts)
    assert "3 active alerts (2 critical), 2 not acknowledged" in text and "critical two" in text


def test_the_summary_says_so_when_nothing_is_active():
    assert "no active alerts" in alert_summary_html([alert("a1", 1, Severity.WARNING, active=False)])


@pytest.mark.parametrize("count", [1, 2])
def test_the_summary_speaks_in_the_singular_for_one_alert(count):
    text = alert_summary_html([alert(f"a{i}", i, Severity.WARNING) for i in range(count)])
    assert (f"{count} active alert," if count == 1 else f"{count} active alerts,") in text

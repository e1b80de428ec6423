"""PX4's messages turned into the operator's reasons: arming refusals and failsafes (vehicles/px4/notices.py).
The texts are PX4 v1.16's own, as seen on SITL (docs/px4.md)."""

from __future__ import annotations

from vehicles.px4.notices import Px4Message, Px4Notices, clean_text, statustext_severity

DENIED = "Arming denied: Resolve system health failures first\t"


def test_clean_text_drops_pxs_tab_and_joins_list_lines():
    assert clean_text(DENIED) == "Arming denied: Resolve system health failures first"
    event = "Failsafe activated: switching to Land\n- No offboard signal\n- No manual control input\n"
    assert (
        clean_text(event)
        == "Failsafe activated: switching to Land; No offboard signal; No manual control input"
    )


def test_mavsdk_statustext_types_map_to_mav_severity():
    assert statustext_severity(7) == 0  # EMERGENCY
    assert statustext_severity(5) == 2  # CRITICAL
    assert statustext_severity(1) == 6  # INFO


def test_arming_refusal_is_pxs_line_with_the_failing_checks_of_its_mode():
    notices = Px4Notices()
    notices.add(Px4Message(10.0, "Armed by external command", 6))  # not a refusal
    notices.add(Px4Message(20.1, DENIED, 2))
    notices.set_arming_problems(19.0, ("Vehicle is in safety configuration",))
    text = notices.arming_refusal(refused_at_s=20.0, fallback="no reason")
    assert text == "Arming denied: Resolve system health failures first (Vehicle is in safety configuration)"


def test_arming_refusal_falls_back_when_px4_said_nothing_near_it():
    notices = Px4Notices()
    notices.add(Px4Message(1.0, DENIED, 2))  # an old refusal, not this one
    assert notices.arming_refusal(refused_at_s=30.0, fallback="PX4 refused arm (COMMAND_DENIED)") == (
        "PX4 refused arm (COMMAND_DENIED)"
    )


def test_repeated_refusal_lines_are_said_once():
    notices = Px4Notices()
    notices.add(Px4Message(5.0, DENIED, 2, source="statustext"))
    notices.add(Px4Message(5.0, DENIED, 2, source="event", name="commander_arm_denied_resolve_failures"))
    assert notices.arming_refusal(refused_at_s=5.0, fallback="-") == (
        "Arming denied: Resolve system health failures first"
    )


def test_failsafe_reason_prefers_pxs_event_that_names_cause_and_action():
    notices = Px4Notices()
    notices.add(Px4Message(50.0, "Failsafe activated\t", 2))
    notices.add(
        Px4Message(
            50.0,
            "Failsafe activated: switching to Land\n- No offboard signal",
            2,
            source="event",
            name="commander_failsafe_enter_generic",
        )
    )
    assert (
        notices.failsafe_reason(since_s=50.0) == "Failsafe activated: switching to Land; No offboard signal"
    )


def test_failsafe_reason_without_events_joins_the_critical_lines_sent_beside_it():
    notices = Px4Notices()
    notices.add(Px4Message(96.0, "Critical battery\t", 0))
    notices.add(Px4Message(96.0, "Failsafe activated: entering Hold for 5 seconds\t", 2))
    assert notices.failsafe_reason(since_s=96.0) == (
        "Critical battery; Failsafe activated: entering Hold for 5 seconds"
    )


def test_a_warning_only_failsafe_event_is_not_the_reason_for_a_failsafe_that_acts():
    notices = Px4Notices()
    notices.add(
        Px4Message(
            95.5,
            "Low battery level, return advised",
            4,
            source="event",
            name="commander_failsafe_enter_low_bat",
        )
    )
    notices.add(Px4Message(96.0, "Failsafe activated\t", 2))
    assert notices.failsafe_reason(since_s=96.0) == "Failsafe activated"


def test_failsafe_reason_says_so_when_px4_gave_none():
    assert Px4Notices().failsafe_reason(since_s=0.0) == "PX4 failsafe (PX4 gave no reason)"

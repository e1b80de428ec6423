"""The alert list as a specification: conditions in, persistent time-stamped alerts out."""

from __future__ import annotations

import pytest

from server.station.alerts import AlertBook, AlertBookParams, Condition, UnknownAlertError
from webui.view import Severity


def battery(severity: Severity = Severity.WARNING, vehicle: int = 2, text: str = "battery 20 %") -> Condition:
    return Condition(kind="battery", vehicle_id=vehicle, severity=severity, message=text)


def test_a_new_condition_raises_an_active_unacknowledged_alert_stamped_with_its_time():
    book = AlertBook()
    book.update(12.5, [battery()], utc_s=1_700_000_000.0)
    (alert,) = book.alerts
    assert (alert.alert_id, alert.kind, alert.vehicle_id, alert.severity) == ("a1", "battery", 2, "warning")
    assert alert.active and not alert.acknowledged
    assert alert.first_s == alert.last_s == 12.5
    assert alert.first_utc_s == 1_700_000_000.0
    assert alert.message == "battery 20 %"


def test_while_the_condition_holds_the_alert_follows_its_message_and_last_time():
    book = AlertBook()
    book.update(1.0, [battery(text="battery 20 %")])
    book.update(2.0, [battery(text="battery 19 %")])
    (alert,) = book.alerts
    assert (alert.first_s, alert.last_s, alert.message, alert.count) == (1.0, 2.0, "battery 19 %", 1)


def test_an_alert_stays_active_until_its_condition_is_gone_for_the_clear_delay_then_stays_listed():
    book = AlertBook(AlertBookParams(clear_after_s=1.0))
    book.update(1.0, [battery()])
    book.update(1.5, [])
    assert book.alerts[0].active  # a flicker shorter than the delay does not clear it
    book.update(2.0, [])
    (alert,) = book.alerts
    assert not alert.active and alert.last_s == 1.0


def test_acknowledging_keeps_the_alert_in_the_list_marked_as_seen():
    book = AlertBook()
    book.update(1.0, [battery()])
    book.acknowledge("a1")
    book.update(1.1, [battery()])
    (alert,) = book.alerts
    assert alert.acknowledged and alert.active


def test_a_condition_that_gets_worse_is_unacknowledged_and_escalated():
    book = AlertBook()
    book.update(1.0, [battery(Severity.WARNING)])
    book.acknowledge("a1")
    book.update(2.0, [battery(Severity.CRITICAL, text="battery 14 %")])
    (alert,) = book.alerts
    assert alert.severity == Severity.CRITICAL and not alert.acknowledged


def test_severity_stays_at_the_worst_seen_while_the_alert_is_active():
    book = AlertBook()
    book.update(1.0, [battery(Severity.CRITICAL)])
    book.update(2.0, [battery(Severity.WARNING)])
    assert book.alerts[0].severity == Severity.CRITICAL


def test_a_cleared_condition_that_returns_reraises_the_same_alert_unacknowledged_and_counted():
    book = AlertBook(AlertBookParams(clear_after_s=0.5))
    book.update(1.0, [battery()])
    book.acknowledge("a1")
    book.update(2.0, [])
    book.update(5.0, [battery()])
    (alert,) = book.alerts
    assert (alert.alert_id, alert.count, alert.active, alert.acknowledged) == ("a1", 2, True, False)
    assert (alert.first_s, alert.last_s) == (1.0, 5.0)


def test_conditions_are_told_apart_by_kind_vehicle_and_subject():
    book = AlertBook()
    a = Condition(kind="separation", vehicle_id=1, subject="MAV 2", severity=Severity.WARNING, message="")
    b = Condition(kind="separation", vehicle_id=1, subject="MAV 3", severity=Severity.WARNING, message="")
    c = Condition(kind="battery", vehicle_id=1, severity=Severity.WARNING, message="")
    book.update(1.0, [a, b, c, a])
    assert sorted(x.alert_id for x in book.alerts) == ["a1", "a2", "a3"]


def test_the_list_puts_pending_alerts_first_most_severe_then_newest():
    book = AlertBook(AlertBookParams(clear_after_s=0.0))
    gone = Condition(kind="link", vehicle_id=1, severity=Severity.CRITICAL, message="")
    book.update(0.0, [gone])
    book.update(1.0, [battery(Severity.WARNING, vehicle=2)])
    book.update(2.0, [battery(Severity.WARNING, vehicle=2), battery(Severity.CRITICAL, vehicle=3)])
    book.update(3.0, [battery(Severity.WARNING, vehicle=2), battery(Severity.CRITICAL, vehicle=3)])
    book.acknowledge("a3")
    assert [a.alert_id for a in book.alerts] == ["a2", "a3", "a1"]  # pending, acknowledged, cleared


def test_acknowledging_an_unknown_alert_is_refused_and_changes_nothing():
    book = AlertBook()
    book.update(1.0, [battery()])
    with pytest.raises(UnknownAlertError, match="no alert with id 'a9'"):
        book.acknowledge("a9")
    assert not book.alerts[0].acknowledged


def test_acknowledge_all_counts_only_the_alerts_not_seen_before():
    book = AlertBook()
    book.update(1.0, [battery(vehicle=1), battery(vehicle=2)])
    book.acknowledge("a1")
    assert book.acknowledge_all() == 1
    assert all(a.acknowledged for a in book.alerts)


def test_time_going_backwards_is_refused():
    book = AlertBook()
    book.update(2.0, [])
    with pytest.raises(ValueError, match="non-decreasing"):
        book.update(1.0, [])


def test_the_list_drops_the_oldest_inactive_alerts_beyond_its_size_and_never_an_active_one():
    book = AlertBook(AlertBookParams(clear_after_s=0.0, max_alerts=3))
    for t in range(5):  # five conditions that hold one instant each
        book.update(float(t), [battery(vehicle=t)])
    book.update(10.0, [battery(vehicle=9)])
    ids = [a.alert_id for a in book.alerts]
    assert len(ids) == 3 and "a6" in ids  # the active one is kept
    assert ids[1:] == ["a5", "a4"]  # the newest inactive ones

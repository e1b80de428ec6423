"""The operator's alert list: conditions in, persistent time-stamped alerts out.

Pure and synchronous (the caller passes mission time and, when it has one, the wall clock): `AlertBook.update`
takes the conditions that hold at one instant (`Condition`, produced by `server.station.alert_rules`) and
keeps one `webui.view.Alert` per condition key (kind, vehicle, subject):

- a new condition raises a new alert (active, not acknowledged);
- while it holds, the alert's last time and message follow it, and its severity is the worst seen; a
  condition that gets worse than what the operator acknowledged is un-acknowledged;
- a condition that is gone for `clear_after_s` makes its alert inactive; the alert stays in the list;
- a condition that comes back re-raises the same alert (active again, not acknowledged, count + 1), so a
  flapping condition does not flood the list;
- acknowledging marks an alert as seen and keeps it in the list.

The list keeps at most `max_alerts`: the oldest inactive alerts go first, active ones are never dropped.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass, replace

from webui.view import SEVERITY_RANK, Alert, Severity


class UnknownAlertError(KeyError):
    """An acknowledgement named an alert that does not exist."""

    def __str__(self) -> str:  # KeyError quotes its argument; the message is for a person
        return str(self.args[0]) if self.args else "unknown alert"


@dataclass(frozen=True)
class Condition:
    """Something wrong now: kind (battery, separation, ...), the MAV it concerns (None: the team), subject
    (the other party: "MAV 3", "tree t4"; "" when none), severity and a message for the operator."""

    kind: str
    vehicle_id: int | None
    severity: Severity
    message: str
    subject: str = ""

    @property
    def key(self) -> tuple[str, int | None, str]:
        return (self.kind, self.vehicle_id, self.subject)


@dataclass(frozen=True)
class AlertBookParams:
    """clear_after_s: mission seconds a condition must be gone before its alert turns inactive (a flicker
    of a few ticks does not clear and re-raise it); max_alerts: the most alerts kept (inactive ones beyond
    it are dropped, oldest first)."""

    clear_after_s: float = 1.0
    max_alerts: int = 500

    def __post_init__(self) -> None:
        if not (math.isfinite(self.clear_after_s) and self.clear_after_s >= 0.0):
            raise ValueError(f"clear_after_s must be a finite number >= 0, got {self.clear_after_s}")
        if self.max_alerts < 1:
            raise ValueError(f"max_alerts must be at least 1, got {self.max_alerts}")


class AlertBook:
    """Every alert of one run, updated from the conditions of each instant."""

    def __init__(self, params: AlertBookParams | None = None) -> None:
        self._params = params or AlertBookParams()
        self._by_key: dict[tuple[str, int | None, str], Alert] = {}
        self._next_id = 1
        self._now = -math.inf

    def update(self, now_s: float, conditions: Iterable[Condition], *, utc_s: float | None = None) -> None:
        """Apply the conditions holding at mission time now_s (non-decreasing; ValueError otherwise)."""
        if not math.isfinite(now_s) or now_s < self._now:
            raise ValueError(f"alert time must be finite and non-decreasing, got {now_s} after {self._now}")
        self._now = now_s
        seen: set[tuple[str, int | None, str]] = set()
        for condition in conditions:
            if condition.key in seen:  # two rules said the same thing: the first one wins
                continue
            seen.add(condition.key)
            old = self._by_key.get(condition.key)
            self._by_key[condition.key] = (
                self._raise(condition, now_s, utc_s) if old is None else _hold(old, condition, now_s)
            )
        for key, alert in self._by_key.items():
            if key not in seen and alert.active and now_s - alert.last_s >= self._params.clear_after_s:
                self._by_key[key] = replace(alert, active=False)
        self._trim()

    def acknowledge(self, alert_id: str) -> Alert:
        """Mark one alert as seen (it stays in the list); UnknownAlertError for an id not in the list."""
        for key, alert in self._by_key.items():
            if alert.alert_id == alert_id:
                self._by_key[key] = replace(alert, acknowledged=True)
                return self._by_key[key]
        known = ", ".join(a.alert_id for a in self.alerts[:10]) or "none"
        raise UnknownAlertError(f"no alert with id {alert_id!r}; the newest are: {known}")

    def acknowledge_all(self) -> int:
        """Mark every alert as seen; returns how many were not acknowledged before."""
        count = 0
        for key, alert in self._by_key.items():
            if not alert.acknowledged:
                self._by_key[key] = replace(alert, acknowledged=True)
                count += 1
        return count

    @property
    def alerts(self) -> tuple[Alert, ...]:
        """Every alert, most urgent first: active and unacknowledged, then active and acknowledged, then
        inactive; within each, the most severe, then the most recent."""
        return tuple(sorted(self._by_key.values(), key=_urgency))

    def _raise(self, condition: Condition, now_s: float, utc_s: float | None) -> Alert:
        alert = Alert(
            alert_id=f"a{self._next_id}",
            kind=condition.kind,
            vehicle_id=condition.vehicle_id,
            subject=condition.subject,
            severity=condition.severity,
            message=condition.message,
            first_s=now_s,
            last_s=now_s,
            active=True,
            acknowledged=False,
            first_utc_s=utc_s,
        )
        self._next_id += 1
        return alert

    def _trim(self) -> None:
        excess = len(self._by_key) - self._params.max_alerts
        if excess <= 0:
            return
        inactive = sorted((a.last_s, key) for key, a in self._by_key.items() if not a.active)
        for _, key in inactive[:excess]:
            del self._by_key[key]


def _hold(alert: Alert, condition: Condition, now_s: float) -> Alert:
    """The alert of a condition that holds at now_s: re-raised if it had cleared, escalated if worse."""
    worse = SEVERITY_RANK[condition.severity] > SEVERITY_RANK[alert.severity]
    if not alert.active:
        return replace(
            alert,
            severity=condition.severity,
            message=condition.message,
            last_s=now_s,
            active=True,
            acknowledged=False,
            count=alert.count + 1,
        )
    return replace(
        alert,
        severity=condition.severity if worse else alert.severity,
        message=condition.message,
        last_s=now_s,
        acknowledged=alert.acknowledged and not worse,
    )


def _urgency(alert: Alert) -> tuple[int, int, float, int]:
    group = 0 if alert.active and not alert.acknowledged else 1 if alert.active else 2
    return (group, -SEVERITY_RANK[alert.severity], -alert.last_s, -int(alert.alert_id[1:]))

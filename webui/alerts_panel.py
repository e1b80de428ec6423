"""The Alerts tab: every alert of the run in a table (most urgent first), a button to acknowledge each one
not yet acknowledged (active or already cleared: a brief critical condition still wants to be seen), and
one for all. A newly raised (or re-raised, or worsened) critical
alert is also announced to every open page as a notification (warnings only show in the list and the
Mission window's summary, so that toasts do not pile up over the 3-D view); the list is what persists.
"""

from __future__ import annotations

from collections.abc import Callable
from contextlib import AbstractContextManager
from typing import Any, Literal

import viser

from webui.cards import alert_table_html
from webui.view import SEVERITY_RANK, Alert, OperatorActions, Severity

Clicked = Callable[[Callable[[], object], str | None], Callable[[viser.GuiEvent], None]]
NotifyColor = Literal["red", "green", "blue", "orange"]
Announce = Callable[[str, str, NotifyColor], None]  # (title, body, colour) to every page

ACK_BUTTONS = 8  # at most this many per-alert buttons; "Acknowledge all" covers the rest
NOTIFY_PER_REFRESH = 3
NOTIFY_COLORS: dict[Severity, NotifyColor] = {
    Severity.INFO: "blue",
    Severity.WARNING: "orange",
    Severity.CRITICAL: "red",
}


def ack_label(alert: Alert) -> str:
    """The label of an alert's acknowledge button: its id, kind, MAV and subject. It does not change while
    the alert lasts (its message does): a button is created once and removed once, never relabelled, which
    viser's client can take for an update of a button it has just removed."""
    who = f" MAV {alert.vehicle_id}" if alert.vehicle_id is not None else ""
    also = f" / {alert.subject}" if alert.subject else ""
    return f"Acknowledge {alert.alert_id}: {alert.kind.replace('_', ' ')}{who}{also}"


class AlertsPanel:
    """Built inside `container` (a tab or folder handle, re-entered to add buttons later); `refresh` shows a
    new alert list."""

    def __init__(
        self,
        gui: viser.GuiApi,
        container: AbstractContextManager[Any],
        actions: OperatorActions,
        *,
        clicked: Clicked,
        announce: Announce | None = None,
    ) -> None:
        self._gui = gui
        self._container = container
        self._actions = actions
        self._clicked = clicked
        self._announce = announce
        self._seen: dict[str, tuple[int, int]] = {}  # alert id -> (count, severity rank) announced
        with container:
            self.ack_all = gui.add_button("Acknowledge all", icon=viser.Icon.CHECKS, order=1.0)
            self.table = gui.add_html(alert_table_html(()), order=100.0)
        self.ack_all.on_click(self._clicked(self._actions.acknowledge_all_alerts, "Every alert acknowledged"))
        self.buttons: dict[str, viser.GuiButtonHandle] = {}

    def refresh(self, alerts: tuple[Alert, ...]) -> None:
        table = alert_table_html(alerts)
        if self.table.content != table:
            self.table.content = table
        self._refresh_buttons(alerts)
        self._announce_new(alerts)

    def _refresh_buttons(self, alerts: tuple[Alert, ...]) -> None:
        pending = [a for a in alerts if not a.acknowledged][:ACK_BUTTONS]
        wanted = {a.alert_id: a for a in pending}
        for alert_id in [i for i in self.buttons if i not in wanted]:
            self.buttons.pop(alert_id).remove()
        for rank, alert in enumerate(pending):
            if alert.alert_id not in self.buttons:
                self.buttons[alert.alert_id] = self._add_button(
                    alert, ack_label(alert), order=2.0 + rank * 0.01
                )

    def _add_button(self, alert: Alert, label: str, *, order: float) -> viser.GuiButtonHandle:
        with self._container:
            button = self._gui.add_button(
                label, color="orange" if alert.severity != Severity.CRITICAL else "red", order=order
            )
        alert_id = alert.alert_id
        button.on_click(
            self._clicked(lambda: self._actions.acknowledge_alert(alert_id), f"Alert {alert_id} acknowledged")
        )
        return button

    def _announce_new(self, alerts: tuple[Alert, ...]) -> None:
        fresh = []
        for a in alerts:
            seen = self._seen.get(a.alert_id)
            now = (a.count, SEVERITY_RANK[a.severity])
            if a.active and (seen is None or now > seen) and a.severity == Severity.CRITICAL:
                fresh.append(a)
            self._seen[a.alert_id] = now
        if self._announce is None:
            return
        for a in fresh[:NOTIFY_PER_REFRESH]:
            self._announce(f"{a.severity.value.upper()} ({a.alert_id})", a.message, NOTIFY_COLORS[a.severity])

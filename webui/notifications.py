"""Notifications on one operator's page: how long each kind stays, and showing or removing one when the page
may already have gone away."""

from __future__ import annotations

import logging
from typing import Literal

import viser

log = logging.getLogger(__name__)

NotifyColor = Literal["red", "green", "blue", "orange"]
REFUSAL_SHOWN_S = 15.0
"""Seconds a red notification (a refusal or an error) stays on the page: to be read after a glance away."""
NOTE_SHOWN_S = 6.0
"""Seconds any other notification (done, view changes) stays on the page unless its caller says otherwise."""


def notify(
    client: viser.ClientHandle | None,
    title: str,
    body: str,
    *,
    color: NotifyColor,
    seconds: float | None = None,
) -> viser.NotificationHandle | None:
    """Show a notification on one page; its handle (None when there is no page or it has gone away).
    seconds: how long it stays; by default REFUSAL_SHOWN_S when red, NOTE_SHOWN_S otherwise."""
    if client is None:
        return None
    if seconds is None:
        seconds = REFUSAL_SHOWN_S if color == "red" else NOTE_SHOWN_S
    try:
        return client.add_notification(title, body, auto_close_seconds=seconds, color=color)
    except Exception:  # noqa: BLE001 - the client may have gone away
        log.debug("could not notify client", exc_info=True)
        return None


def remove_notification(handle: viser.NotificationHandle | None) -> None:
    """Take a notification off its page (already closed or page gone: nothing to do)."""
    if handle is None:
        return
    try:
        handle.remove()
    except Exception:  # noqa: BLE001 - the client may have gone away
        log.debug("could not remove a notification", exc_info=True)

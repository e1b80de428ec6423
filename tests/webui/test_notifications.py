"""How long notifications stay on an operator's page (webui/notifications.py)."""

from __future__ import annotations

from typing import cast

import pytest
import viser

from webui.notifications import NOTE_SHOWN_S, REFUSAL_SHOWN_S, notify, remove_notification


class RecordingClient:
    """Stands in for a viser client: records each notification asked for."""

    def __init__(self) -> None:
        self.shown: list[tuple[str, str, float, str]] = []

    def add_notification(self, title: str, body: str, *, auto_close_seconds: float, color: str) -> str:
        self.shown.append((title, body, auto_close_seconds, color))
        return f"handle {len(self.shown)}"


class GoneClient:
    """A client whose page has closed: viser raises on every call."""

    def add_notification(self, *args, **kwargs):
        raise RuntimeError("client disconnected")


def as_client(double: RecordingClient | GoneClient) -> viser.ClientHandle:
    """A test double, typed as the viser client it stands in for (it has the one method notify calls)."""
    return cast(viser.ClientHandle, double)


def test_a_red_notification_stays_as_long_as_a_refusal_whoever_shows_it():
    client = RecordingClient()
    notify(as_client(client), "Refused", "That click did not hit the ground", color="red")
    assert client.shown == [("Refused", "That click did not hit the ground", REFUSAL_SHOWN_S, "red")]
    assert REFUSAL_SHOWN_S == pytest.approx(15.0)


@pytest.mark.parametrize("color", ["green", "blue", "orange"])
def test_other_notifications_stay_as_long_as_a_note(color):
    client = RecordingClient()
    notify(as_client(client), "Done", "Obstacle added", color=color)
    assert client.shown[0][2] == pytest.approx(NOTE_SHOWN_S)
    assert NOTE_SHOWN_S < REFUSAL_SHOWN_S


def test_a_caller_may_keep_a_prompt_up_longer():
    client = RecordingClient()
    notify(as_client(client), "Place obstacle", "Click on the ground", color="blue", seconds=60.0)
    assert client.shown[0][2] == pytest.approx(60.0)


def test_a_page_that_has_gone_gets_no_notification_and_nothing_raises():
    assert notify(as_client(GoneClient()), "Refused", "x", color="red") is None
    assert notify(None, "Refused", "x", color="red") is None
    remove_notification(None)

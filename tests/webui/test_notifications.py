"""How long notifications stay on an operator's page (webui/notifications.py)."""

from __future__ import annotations

import pytest

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


def test_a_red_notification_stays_as_long_as_a_refusal_whoever_shows_it():
    client = RecordingClient()
    notify(client, "Refused", "That click did not hit the ground", color="red")
    assert client.shown == [("Refused", "That click did not hit the ground", REFUSAL_SHOWN_S, "red")]
    assert REFUSAL_SHOWN_S == pytest.approx(15.0)


@pytest.mark.parametrize("color", ["green", "blue", "orange"])
def test_other_notifications_stay_as_long_as_a_note(color):
    client = RecordingClient()
    notify(client, "Done", "Obstacle added", color=color)
    assert client.shown[0][2] == pytest.approx(NOTE_SHOWN_S)
    assert NOTE_SHOWN_S < REFUSAL_SHOWN_S


def test_a_caller_may_keep_a_prompt_up_longer():
    client = RecordingClient()
    notify(client, "Place obstacle", "Click on the ground", color="blue", seconds=60.0)
    assert client.shown[0][2] == pytest.approx(60.0)


def test_a_page_that_has_gone_gets_no_notification_and_nothing_raises():
    assert notify(GoneClient(), "Refused", "x", color="red") is None
    assert notify(None, "Refused", "x", color="red") is None
    remove_notification(None)

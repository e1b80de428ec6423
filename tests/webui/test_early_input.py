"""A page's LAND ALL (button or Shift+L) sent before the page's first camera report still brings the
confirmation (webui/early_input.py): viser alone dropped it without a trace, and the operator's stop was lost.

Driven over viser's own WebSocket protocol on a real `OperatorUi`, as the page speaks it: the click, then the
camera report, on one connection (viser handles a connection's messages in order, so the click is handled
first, every time)."""

from __future__ import annotations

import contextlib
import time
from collections.abc import Callable, Iterator

import msgspec.msgpack
import pytest
import viser
import zstandard
from scene_views import flying_mav, scene_view
from viser import _messages
from websockets.sync.client import connect
from websockets.sync.connection import Connection
from websockets.typing import Subprotocol

from webui.app import OperatorUi
from webui.view import OperatorActions

ANSWER_S = 10.0  # the page's answer comes within milliseconds; this bounds a loaded machine


class Actions(OperatorActions):
    """Records LAND ALL; every other command does nothing."""

    def __init__(self) -> None:
        self.calls: list[str] = []

    def land_all(self) -> None:
        self.calls.append("land_all")

    def add_obstacle(self, *, x_m: float, y_m: float, radius_m: float) -> str:
        return "v1"

    def acknowledge_all_alerts(self) -> int:
        return 0


@pytest.fixture
def ui_and_actions() -> Iterator[tuple[OperatorUi, Actions]]:
    actions = Actions()
    ui = OperatorUi(actions=actions, initial=scene_view([flying_mav()]), port=0)
    try:
        yield ui, actions
    finally:
        ui.stop()


class Page:
    """A page speaking viser's protocol over one connection, keeping every message viser sent it."""

    def __init__(self, connection: Connection) -> None:
        self.connection = connection
        self.seen: list[dict] = []

    def send(self, message: _messages.Message) -> None:
        self.connection.send(msgspec.msgpack.encode(message.as_serializable_dict()))

    def wait_for(self, wanted: Callable[[dict], bool], what: str) -> dict:
        """The first message viser sent that is `wanted`, waiting up to ANSWER_S for it."""
        deadline = time.monotonic() + ANSWER_S
        while True:
            found = next((m for m in self.seen if wanted(m)), None)
            if found is not None:
                return found
            left = deadline - time.monotonic()
            assert left > 0, f"{what}: not sent to the page within {ANSWER_S} s"
            with contextlib.suppress(TimeoutError):
                self.seen += received(self.connection.recv(timeout=left))


def received(frame: str | bytes) -> list[dict]:
    """The messages of one frame viser sent (its wire format: two lengths, zstd msgpack, binary buffers)."""
    assert isinstance(frame, bytes)
    size = int.from_bytes(frame[:8], "little")
    compressed = int.from_bytes(frame[8:16], "little")
    inner = zstandard.ZstdDecompressor().decompress(frame[16 : 16 + compressed], max_output_size=size)
    return list(msgspec.msgpack.decode(inner)["messages"])


def camera_report() -> _messages.ViewerCameraMessage:
    return _messages.ViewerCameraMessage(
        wxyz=(1.0, 0.0, 0.0, 0.0),
        position=(0.0, -30.0, 20.0),
        fov=1.0,
        near=0.01,
        far=1000.0,
        image_height=700,
        image_width=1100,
        look_at=(0.0, 0.0, 0.0),
        up_direction=(0.0, 0.0, 1.0),
    )


@contextlib.contextmanager
def open_page(ui: OperatorUi) -> Iterator[Page]:
    protocol = Subprotocol(f"viser-v{viser.__version__}")
    with connect(f"ws://127.0.0.1:{ui.port}", subprotocols=[protocol], max_size=None) as connection:
        yield Page(connection)


@pytest.mark.parametrize("how", ["button", "shift+l"])
def test_land_all_sent_before_the_pages_camera_report_brings_the_confirmation_and_lands_on_confirm(
    ui_and_actions, how
):
    ui, actions = ui_and_actions
    with open_page(ui) as page:
        if how == "button":
            land_all = ui.panel.land_all_button._impl.uuid  # noqa: SLF001
            page.send(_messages.GuiUpdateMessage(uuid=land_all, updates={"value": True}))
        else:
            page.send(_messages.CommandTriggerMessage(uuid=ui.panel.land_all_command._impl.uuid))  # noqa: SLF001
        page.send(camera_report())  # only now does viser know the page
        page.wait_for(lambda m: m["type"] == "GuiModalMessage" and m["title"] == "LAND ALL?", "the dialog")
        confirm = page.wait_for(
            lambda m: m["type"] == "GuiButtonMessage" and m["props"]["label"] == "Confirm LAND ALL",
            "its Confirm LAND ALL button",
        )
        assert actions.calls == []  # nothing lands before the operator confirms
        page.send(_messages.GuiUpdateMessage(uuid=confirm["uuid"], updates={"value": True}))
        page.wait_for(
            lambda m: m["type"] == "NotificationShowMessage" and "All MAVs landing" in str(m), "the done note"
        )
    assert actions.calls == ["land_all"]

"""Operator input that reaches viser before viser knows the page it came from.

viser makes a page a client (`ViserServer.get_clients`, `event.client`) only when it handles the page's first
camera report, which the page sends from a timer once its 3-D view's camera controls exist; until then viser
drops every click, command and input of that page without a trace (`GuiApi._resolve_client` returns None, in
`_handle_gui_updates` and `_handle_command_trigger`). The page shows its controls from its first frame, so a
LAND ALL click (or Shift+L) in between was lost: no confirmation, no refusal, no audit, no log line.
`EarlyInput` keeps what such a page sent and hands it to the controls' callbacks, in the order sent, the
moment viser makes the page a client (its camera report follows within a frame or so: the page draws its
controls from the 3-D view's own frame loop, beside the camera controls). So every control answers (LAND ALL
with its confirmation, a refused command with its refusal and audit record), a little later, never not at all.

Everything here runs on viser's event loop (its message handlers and connect/disconnect callbacks), in the
order viser handles the page's messages; the callbacks themselves run on viser's thread pool, as viser runs
them.
"""

from __future__ import annotations

import inspect
import logging
from concurrent.futures import Future
from typing import Any

import viser
import viser.infra
from viser import _messages

log = logging.getLogger(__name__)

MAX_HELD_PER_PAGE = 64
"""Inputs kept for one page that viser does not know yet; later ones are dropped (and logged). A person
clicks a few times before the page reports its camera; only a client that never reports it sends more."""

EarlyMessage = _messages.GuiUpdateMessage | _messages.CommandTriggerMessage


class EarlyInput:
    """Keeps the GUI input of pages viser has not made clients yet and delivers it once it has."""

    def __init__(self, server: viser.ViserServer) -> None:
        self._server = server
        self._held: dict[int, list[EarlyMessage]] = {}
        websock = server._websock_server  # noqa: SLF001
        # After viser's own handlers for the same messages (registered when the server was built), so by the
        # time `_keep` sees a message viser has either run its callbacks or dropped it for an unknown page.
        websock.register_handler(_messages.GuiUpdateMessage, self._keep)
        websock.register_handler(_messages.CommandTriggerMessage, self._keep)
        websock.on_client_disconnect(self._forget)
        server.on_client_connect(self._deliver)

    def _keep(self, client_id: int, message: EarlyMessage) -> None:
        """Keep a message viser dropped because it does not know the page yet."""
        if client_id in self._server.get_clients():
            return  # viser dispatched it itself
        held = self._held.setdefault(client_id, [])
        if len(held) >= MAX_HELD_PER_PAGE:
            log.warning("page %d: %s dropped, %d inputs already wait", client_id, _name(message), len(held))
            return
        held.append(message)
        log.info(
            "page %d: %s before its camera report, kept until viser knows the page", client_id, _name(message)
        )

    def _forget(self, connection: viser.infra.WebsockClientConnection) -> None:
        """The page went away before viser knew it: nothing it sent will be delivered."""
        self._held.pop(connection.client_id, None)

    async def _deliver(self, client: viser.ClientHandle) -> None:
        """viser made the page a client: run the callbacks of everything it sent before, in order."""
        for message in self._held.pop(client.client_id, []):
            found = self._callbacks(client, message)
            if found is None:
                continue
            callbacks, event = found
            for callback in callbacks:
                if inspect.iscoroutinefunction(callback):
                    await callback(event)
                else:
                    pool = self._server._thread_executor  # noqa: SLF001
                    pool.submit(callback, event).add_done_callback(_log_failure)

    def _callbacks(self, client: viser.ClientHandle, message: EarlyMessage) -> tuple[list[Any], Any] | None:
        """The callbacks viser would have run for `message` had it known the page, and their event (None: the
        control has gone, or the command is disabled, as viser itself checks)."""
        gui = self._server.gui
        if isinstance(message, _messages.CommandTriggerMessage):
            command = gui._command_handle_from_uuid.get(message.uuid)  # noqa: SLF001
            if command is None or command._impl.removed or command._impl.props.disabled:  # noqa: SLF001
                return None
            return list(command._impl.trigger_cb), viser.CommandEvent(client, client.client_id, command)  # noqa: SLF001
        handle = gui._gui_input_handle_from_uuid.get(message.uuid)  # noqa: SLF001
        if handle is None or handle._impl.removed:  # noqa: SLF001
            return None
        return list(handle._impl.update_cb), viser.GuiEvent(client, client.client_id, handle)  # noqa: SLF001


def _name(message: EarlyMessage) -> str:
    return f"{type(message).__name__} {message.uuid}"


def _log_failure(future: Future[Any]) -> None:
    if future.cancelled():
        return
    exc = future.exception()
    if exc is not None:
        log.error("a control's callback failed", exc_info=exc)

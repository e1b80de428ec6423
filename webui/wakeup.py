"""Waking viser's message senders from any thread without losing a wake-up.

viser keeps each connection's outgoing messages in a buffer; the sender (a coroutine on viser's event loop)
sleeps on the buffer's `asyncio.Event` and the code that pushes a message sets it. The station pushes from
other threads (the frame publisher on the web's loop, button callbacks in viser's thread pool), and viser
sets the event directly there. `asyncio.Event` is not thread-safe: if that `set()` runs while the sender is
inside `wait()`, after it found the flag clear and before it registered its future, the flag ends up set
with the sender asleep on a future nobody resolves. Every later `set()` sees the flag already set and does
nothing, and only the sender itself clears it: a page with the station to itself then never receives another
update (its controls still work: they travel the other way). Seen on CI (2026-12-07): the operator page kept
its panels but showed no plots or alerts for three minutes while /api/state showed every alert.

`ThreadSafeWakeup` hands a `set()` from any other thread to the event loop (`call_soon_threadsafe`), where
it cannot interleave with `wait()`; `wake_safely` puts one in viser's broadcast buffer and in each new
connection's own buffer.
"""

from __future__ import annotations

import asyncio

import viser
import viser.infra
from viser.infra._async_message_buffer import AsyncMessageBuffer


class ThreadSafeWakeup(asyncio.Event):
    """An `asyncio.Event` of `loop` whose `set()` may be called from any thread: off the loop's own thread
    the set runs on the loop instead (and is dropped once the loop has closed: nobody waits any more).

    A frame pushes dozens of messages (73 for 16 MAVs), each with a `set()`; while one handed-over set
    waits to run, further ones add nothing (it runs after them, and the sender then reads every message
    pushed so far), so they are not handed over again."""

    def __init__(self, loop: asyncio.AbstractEventLoop) -> None:
        super().__init__()
        self._home = loop
        self._handed_over = False  # a set is queued on the loop and has not started yet

    def set(self) -> None:
        try:
            running = asyncio.get_running_loop()
        except RuntimeError:
            running = None
        if running is self._home:
            super().set()
            return
        if self._handed_over:
            return
        self._handed_over = True
        try:
            self._home.call_soon_threadsafe(self._set_on_loop)
        except RuntimeError:  # the loop has closed
            self._handed_over = False

    def _set_on_loop(self) -> None:
        self._handed_over = False  # first: a set from another thread from now on is handed over again
        super().set()


def _make_safe(buffer: AsyncMessageBuffer) -> None:
    buffer.message_event = ThreadSafeWakeup(buffer.event_loop)


def wake_safely(server: viser.ViserServer) -> None:
    """Give `server`'s broadcast buffer a `ThreadSafeWakeup`, and each connection's own buffer one before its
    sender starts. Call it before any client connects (right after creating the server)."""
    websock = server._websock_server  # noqa: SLF001 - the buffers are viser's; nothing public reaches them
    _make_safe(websock.get_message_buffer())

    def on_connect(connection: viser.infra.WebsockClientConnection) -> None:
        _make_safe(connection.get_message_buffer())

    websock.on_client_connect(on_connect)

"""Specification of `webui.wakeup`: a wake-up set from another thread while viser's sender is entering its
wait is never lost, and a station's viser server uses such wake-ups in every buffer.

The race is forced, not waited for: the event loop below stops inside `Event.wait()` (in its `create_future`,
after the flag was found clear and before the future is registered) until another thread has called `set()`.
"""

from __future__ import annotations

import asyncio
import contextlib
import threading

import pytest
import viser
import websockets.sync.client
from websockets.typing import Subprotocol

from webui.wakeup import ThreadSafeWakeup, wake_safely


class PausingLoop(asyncio.SelectorEventLoop):
    """An event loop whose next `create_future` after `pause_next()` waits until `resume` is set: the moment
    inside `asyncio.Event.wait()` between reading the flag and registering the waiter."""

    def __init__(self) -> None:
        super().__init__()
        self.paused = threading.Event()
        self.resume = threading.Event()
        self._pause = False

    def pause_next(self) -> None:
        self._pause = True

    def create_future(self) -> asyncio.Future:
        if self._pause:
            self._pause = False
            self.paused.set()
            assert self.resume.wait(5.0), "the other thread never set the event"
        return super().create_future()


def woken_after_a_set_mid_wait(make_event) -> bool:
    """Wait on make_event(loop) while another thread sets it at the worst moment (then sets it once more, as
    viser does at the end of an atomic block); True if the waiter woke within a second."""
    loop = PausingLoop()
    event = make_event(loop)

    def other_thread() -> None:
        assert loop.paused.wait(5.0)
        event.set()
        loop.resume.set()
        event.set()

    async def waiter() -> None:
        loop.pause_next()
        await event.wait()

    async def main() -> bool:
        task = loop.create_task(waiter())
        done, _ = await asyncio.wait({task}, timeout=1.0)
        task.cancel()
        return task in done

    setter = threading.Thread(target=other_thread)
    setter.start()
    try:
        return loop.run_until_complete(main())
    finally:
        setter.join(5.0)
        loop.close()


def test_a_plain_asyncio_event_set_from_another_thread_mid_wait_loses_the_wakeup():
    """Why the module exists: with asyncio's own Event the waiter sleeps on although the flag is set."""
    assert woken_after_a_set_mid_wait(lambda loop: asyncio.Event()) is False


def test_a_set_from_another_thread_mid_wait_wakes_the_waiter():
    assert woken_after_a_set_mid_wait(ThreadSafeWakeup) is True


def test_a_set_from_another_thread_leaves_the_flag_to_the_loop():
    """Off the loop's thread the flag is not touched there and then: the loop sets it when it runs."""
    loop = asyncio.new_event_loop()
    try:
        event = ThreadSafeWakeup(loop)
        setter = threading.Thread(target=event.set)
        setter.start()
        setter.join(5.0)
        assert not event.is_set()
        loop.run_until_complete(asyncio.sleep(0))
        assert event.is_set()
    finally:
        loop.close()


def test_a_set_on_the_loops_own_thread_takes_effect_at_once():
    loop = asyncio.new_event_loop()
    try:
        event = ThreadSafeWakeup(loop)

        async def set_here() -> bool:
            event.set()
            return event.is_set()

        assert loop.run_until_complete(set_here()) is True
    finally:
        loop.close()


def test_a_set_after_the_loop_closed_is_dropped_without_error():
    loop = asyncio.new_event_loop()
    event = ThreadSafeWakeup(loop)
    loop.close()
    event.set()
    assert not event.is_set()


@pytest.fixture
def server():
    server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    yield server
    server.stop()


def test_the_broadcast_buffer_and_each_new_connections_buffer_wake_safely(server):
    wake_safely(server)
    websock = server._websock_server  # noqa: SLF001
    assert isinstance(websock.get_message_buffer().message_event, ThreadSafeWakeup)
    url = f"ws://127.0.0.1:{server.get_port()}"
    protocol = Subprotocol(f"viser-v{viser.__version__}")
    with websockets.sync.client.connect(url, subprotocols=[protocol]) as socket:
        socket.recv(timeout=10.0)  # the scene: the connection's buffer exists by now
        buffers = [state.message_buffer for state in websock._client_state_from_id.values()]  # noqa: SLF001
        assert len(buffers) == 1
        assert isinstance(buffers[0].message_event, ThreadSafeWakeup)
        assert buffers[0].message_event._home is buffers[0].event_loop  # noqa: SLF001
        with contextlib.suppress(TimeoutError):
            while True:  # the rest of the scene
                socket.recv(timeout=0.5)
        server.gui.add_markdown("pushed from the test's thread")  # reaches the sender through the new event
        assert socket.recv(timeout=5.0)


def test_sets_from_another_thread_while_one_is_queued_are_handed_over_once():
    loop = asyncio.new_event_loop()
    try:
        event = ThreadSafeWakeup(loop)
        handed: list[object] = []
        real = loop.call_soon_threadsafe

        def counting(callback, *args):
            handed.append(callback)
            return real(callback, *args)

        loop.call_soon_threadsafe = counting  # type: ignore[method-assign]

        def push(times: int) -> None:
            setter = threading.Thread(target=lambda: [event.set() for _ in range(times)])
            setter.start()
            setter.join(5.0)

        push(200)
        assert len(handed) == 1 and not event.is_set()
        loop.run_until_complete(asyncio.sleep(0))
        assert event.is_set()
        event.clear()
        push(3)  # the queued set has run: the next one is handed over again
        assert len(handed) == 2
        loop.run_until_complete(asyncio.sleep(0))
        assert event.is_set()
    finally:
        loop.close()

"""Whether this system grants SCHED_FIFO to a thread of the test process, for tests whose expectation
depends on it (root or an rtprio limit grants it; otherwise the code under test must run on under the
normal scheduler and say why)."""

from __future__ import annotations

import threading

from vehicles.net.realtime import raise_calling_thread


def fifo_allowed(priority: int) -> bool:
    """Try SCHED_FIFO at `priority` on a short-lived thread of ours: True when the system granted it."""
    result: list[str | None] = []
    probe = threading.Thread(target=lambda: result.append(raise_calling_thread(priority)))
    probe.start()
    probe.join()
    return result == [None]

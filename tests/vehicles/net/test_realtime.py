"""Real-time scheduling of an agent's control thread (vehicles/net/realtime.py)."""

from __future__ import annotations

import os
import sys
import threading
from pathlib import Path

import pytest

from vehicles.net.onboard import OnboardParams
from vehicles.net.realtime import (
    GIL_SWITCH_INTERVAL_S,
    name_calling_thread,
    policy,
    raise_calling_thread,
    shorten_gil_switch_interval,
)


def _in_a_thread(priority: int) -> tuple[str | None, int]:
    """raise_calling_thread(priority) on a fresh thread: (its answer, the thread's policy afterwards)."""
    out: list[tuple[str | None, int]] = []

    def body() -> None:
        answer = raise_calling_thread(priority)
        out.append((answer, policy()))

    thread = threading.Thread(target=body)
    thread.start()
    thread.join()
    return out[0]


@pytest.mark.parametrize("priority", [-1, 100, 2.5])
def test_a_priority_outside_0_to_99_is_refused_with_a_clear_error(priority):
    with pytest.raises(ValueError, match="real-time priority must be an integer from 0"):
        raise_calling_thread(priority)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="real-time priority"):
        OnboardParams(realtime_priority=priority)  # type: ignore[arg-type]


def test_priority_zero_leaves_the_thread_under_the_normal_scheduler():
    assert _in_a_thread(0) == (None, os.SCHED_OTHER)


def test_a_granted_priority_puts_only_the_calling_thread_under_sched_fifo_and_a_refusal_says_why():
    """Either the system grants SCHED_FIFO (root or an rtprio limit) and the thread runs under it, or it
    refuses, the thread stays under the normal scheduler and the answer names the refusal; the process's
    other threads are untouched either way."""
    answer, scheduled = _in_a_thread(10)
    if answer is None:
        assert scheduled == os.SCHED_FIFO
    else:
        assert scheduled == os.SCHED_OTHER and "SCHED_FIFO priority 10 refused" in answer
    assert policy() == os.SCHED_OTHER


def test_threads_started_by_a_real_time_thread_run_under_the_normal_scheduler():
    """Library threads a control loop happens to start (Zenoh's, on its first publication) must not
    inherit its priority."""
    seen: list[int] = []

    def body() -> None:
        raise_calling_thread(10)
        child = threading.Thread(target=lambda: seen.append(policy()))
        child.start()
        child.join()

    thread = threading.Thread(target=body)
    thread.start()
    thread.join()
    assert seen == [os.SCHED_OTHER]


def test_the_calling_thread_gets_a_name_the_system_shows():
    names: list[str] = []

    def body() -> None:
        name_calling_thread("skyring-ctl-12345")
        names.append(Path(f"/proc/self/task/{threading.get_native_id()}/comm").read_text().strip())

    thread = threading.Thread(target=body)
    thread.start()
    thread.join()
    assert names == ["skyring-ctl-123"]  # the kernel keeps 15 characters


def test_the_agent_process_hands_the_interpreter_lock_over_every_half_millisecond():
    kept = sys.getswitchinterval()
    try:
        shorten_gil_switch_interval()
        assert sys.getswitchinterval() == pytest.approx(GIL_SWITCH_INTERVAL_S) == pytest.approx(0.0005)
    finally:
        sys.setswitchinterval(kept)

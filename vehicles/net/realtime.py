"""Real-time scheduling for an agent's control thread.

On a companion computer the control loop shares the CPUs with the camera, the detector and logging; under
the normal scheduler it waits behind them and its tick period jitters by several milliseconds. Linux's
SCHED_FIFO runs the thread as soon as it wakes, ahead of every normal thread (the kernel still keeps 5 % of
each second for them, `sched_rt_runtime_us`). Only that thread: threads it starts later (Zenoh starts some
on the first publication) get the normal scheduler (SCHED_RESET_ON_FORK). It needs CAP_SYS_NICE (root, or
an `rtprio` limit in /etc/security/limits.conf); without it the loop runs under the normal scheduler and
says why.

The control thread is also named at the system level (`control_thread_name`), so `top -H` and `ps -L` show
which thread it is. A Python thread also waits for the interpreter lock: `GIL_SWITCH_INTERVAL_S` bounds how
long another thread of the agent (Zenoh callbacks, the vehicle link) holds it before the control thread
gets it; and the threads that run Zenoh's message handlers take SCHED_FIFO one priority below the control
loop (`handler_priority`), so that normal work cannot preempt one while it holds the lock the control
thread waits for.
"""

from __future__ import annotations

import ctypes
import os
import sys

MAX_PRIORITY = 99
GIL_SWITCH_INTERVAL_S = 0.0005
"""Seconds between forced interpreter-lock hand-overs in an agent process (Python's default is 5 ms)."""


def check_priority(priority: int) -> None:
    """ValueError unless priority is 0 (normal scheduler) or a SCHED_FIFO priority 1..99."""
    if not (isinstance(priority, int) and 0 <= priority <= MAX_PRIORITY):
        raise ValueError(
            f"real-time priority must be an integer from 0 (off) to {MAX_PRIORITY}, got {priority!r}"
        )


def raise_calling_thread(priority: int) -> str | None:
    """Run the calling thread under SCHED_FIFO at `priority` (0: leave it as it is). Returns None when done
    (or not asked), else why the system refused, for the agent to report; never raises for a refusal."""
    check_priority(priority)
    if priority == 0:
        return None
    if not hasattr(os, "sched_setscheduler"):
        return f"SCHED_FIFO is not available on {sys.platform}"
    try:
        # 0: the calling thread (Linux); threads it starts do not inherit the policy
        os.sched_setscheduler(0, os.SCHED_FIFO | os.SCHED_RESET_ON_FORK, os.sched_param(priority))
    except OSError as exc:
        return f"SCHED_FIFO priority {priority} refused: {exc.strerror or exc}"
    return None


def handler_priority(control_priority: int) -> int:
    """The SCHED_FIFO priority of the threads that run message handlers in a process whose control loop runs
    at control_priority: one below it (never below 1), so that a handler holding the interpreter lock runs
    ahead of normal work and hands the lock back, and the control loop still preempts it; 0 for 0."""
    check_priority(control_priority)
    return max(control_priority - 1, 1) if control_priority else 0


def describe(priority: int, refused: str | None = None) -> str:
    """What a control loop runs under, in words, for start-up lines, benchmarks and the operator: the
    priority asked (0: the normal scheduler) and, when the system refused it, why."""
    if priority == 0:
        return "normal scheduler"
    if refused is not None:
        return f"normal scheduler ({refused})"
    return f"SCHED_FIFO priority {priority}"


def policy(tid: int = 0) -> int:
    """The scheduling policy of thread `tid` (0: the calling thread), without the reset-on-fork flag."""
    return os.sched_getscheduler(tid) & ~getattr(os, "SCHED_RESET_ON_FORK", 0)


def control_thread_name(vehicle_id: int) -> str:
    """The system-level name of MAV vehicle_id's control thread (at most 15 characters)."""
    return f"skyring-ctl-{vehicle_id}"


def name_calling_thread(name: str) -> None:
    """Give the calling thread a name the system shows (Linux's PR_SET_NAME keeps 15 bytes); elsewhere,
    or if the C library cannot be loaded, nothing happens (the name only helps a person find the thread)."""
    if not sys.platform.startswith("linux"):
        return
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(15, ctypes.c_char_p(name.encode()[:15]), 0, 0, 0)  # 15: PR_SET_NAME
    except (OSError, AttributeError):
        return


def shorten_gil_switch_interval() -> None:
    """Hand the interpreter lock over every GIL_SWITCH_INTERVAL_S (process-wide: call once at start-up)."""
    sys.setswitchinterval(GIL_SWITCH_INTERVAL_S)

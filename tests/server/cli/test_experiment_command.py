"""`skyring experiment` stopped from outside: SIGTERM (a job scheduler's, `kill`'s, a container's) ends its
worker processes as Ctrl-C does, instead of leaving them to finish their runs unwatched."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

pytestmark = pytest.mark.e2e  # starts `skyring experiment` as a process with its worker pool

ROOT = Path(__file__).resolve().parents[3]


def descendants(pid: int) -> set[int]:
    """Every live process below `pid` (children, their children, ...), from /proc."""
    parents: dict[int, int] = {}
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            fields = (entry / "stat").read_text().rsplit(")", 1)[1].split()
        except OSError:  # gone meanwhile
            continue
        if fields[0] != "Z":
            parents[int(entry.name)] = int(fields[1])
    found, frontier = set(), {pid}
    while frontier:
        frontier = {child for child, parent in parents.items() if parent in frontier} - found
        found |= frontier
    return found


def alive(pids: set[int]) -> set[int]:
    return {pid for pid in pids if Path(f"/proc/{pid}").exists() and not _zombie(pid)}


def _zombie(pid: int) -> bool:
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] == "Z"
    except OSError:
        return False


def test_sigterm_stops_the_sweep_and_its_workers(tmp_path):
    command = [sys.executable, "-m", "server.cli", "experiment", "safety", "--runs", "4", "--jobs", "2"]
    command += ["--duration", "60", "--out", str(tmp_path)]
    proc = subprocess.Popen(command, cwd=ROOT, stderr=subprocess.PIPE, stdout=subprocess.DEVNULL, text=True)
    try:
        workers: set[int] = set()
        deadline = time.monotonic() + 120
        while len(workers) < 3 and time.monotonic() < deadline:  # the fork server and two runs
            time.sleep(0.2)
            workers = descendants(proc.pid)
        assert len(workers) >= 3, f"the sweep started {len(workers)} worker processes within 120 s"
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    assert proc.returncode == 143
    assert "terminated: the finished runs are kept" in err
    deadline = time.monotonic() + 20
    while alive(workers) and time.monotonic() < deadline:
        time.sleep(0.2)
    left = alive(workers)
    for pid in left:  # do not leave them to the rest of the suite
        os.kill(pid, signal.SIGKILL)
    assert not left, f"worker processes still running 20 s after the sweep ended: {sorted(left)}"

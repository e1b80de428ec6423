"""Start `skyring serve` as its own process, as a user would, on free ports of 127.0.0.1."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def start_serve(*args: str) -> tuple[subprocess.Popen, str]:
    """`skyring serve --port 0 --viser-port 0 --rate 20 ARGS...`, read until it is ready: the process and its
    API's URL (from the "operator view:" line; both ports free, so no "port is busy" line comes first)."""
    command = [
        sys.executable,
        "-m",
        "server.cli",
        "serve",
        "--port",
        "0",
        "--viser-port",
        "0",
        "--rate",
        "20",
    ]
    proc = subprocess.Popen(
        [*command, *args],
        cwd=ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        env={**os.environ, "PYTHONUNBUFFERED": "1"},
    )
    assert proc.stdout is not None
    api = None
    for line in proc.stdout:
        if line.startswith("operator view:"):
            api = line.split()[2]
        if line.startswith("Ctrl-C"):
            break
    assert api is not None, "skyring serve printed no operator view"
    return proc, api

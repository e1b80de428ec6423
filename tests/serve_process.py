"""Start `skyring serve` as its own process, as a user would, on free ports of 127.0.0.1."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
UNBUFFERED = {**os.environ, "PYTHONUNBUFFERED": "1"}  # serve's lines reach a pipe or file as printed


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
        env=UNBUFFERED,
    )
    assert proc.stdout is not None
    api = None
    for line in proc.stdout:
        api = api or api_url_on(line)
        if line.startswith("Ctrl-C"):
            break
    assert api is not None, "skyring serve printed no operator view"
    return proc, api


def api_url_on(line: str) -> str | None:
    """The API's URL if `line` is serve's "operator view:" line, else None."""
    return line.split()[2] if line.startswith("operator view:") else None


def printed_api_url(output: Path) -> str | None:
    """The API URL (without the trailing slash) a `skyring serve` printed into the file `output`, or None
    while it has not. A station told to use a busy port takes another one and says so, so a test follows
    what was printed rather than the port it asked for (another test's station may answer on that one)."""
    try:
        text = output.read_text(errors="replace")
    except FileNotFoundError:
        return None
    for line in text.splitlines():
        if (url := api_url_on(line)) is not None:
            return url.rstrip("/")
    return None

"""Free ports to hand to another process (a spawned agent's Zenoh listener, a test's station or peer).

The usual trick, bind to port 0 and read the number back, picks from the kernel's ephemeral range: the port is
free when we close it, but the kernel may give it to anybody's next outgoing connection or bind(0) before the
process we told about it binds it ("Address already in use" a moment later, seen in the test suite when many
processes start at once). `free_port` therefore picks at random below the ephemeral range, where the kernel
never hands ports out by itself, checks that it binds now, and never hands the same port out twice in one
process. Only another program choosing fixed ports there can still collide.
"""

from __future__ import annotations

import random
import socket
from pathlib import Path

EPHEMERAL_RANGE_FILE = Path("/proc/sys/net/ipv4/ip_local_port_range")
DEFAULT_EPHEMERAL_LOW = 32768  # Linux's default (32768-60999) where the file cannot be read
SPAN = 12_000  # how far below the ephemeral range ports are picked
LOWEST = 1024  # never a privileged port
ATTEMPTS = 200

_given: set[tuple[str, int]] = set()
_random = random.SystemRandom()  # not the simulations' seeded generators: ports must differ between runs


def ephemeral_low() -> int:
    """The lowest port of the kernel's ephemeral range."""
    try:
        return int(EPHEMERAL_RANGE_FILE.read_text().split()[0])
    except (OSError, ValueError, IndexError):
        return DEFAULT_EPHEMERAL_LOW


def _bound_port(kind: str, host: str, port: int) -> int | None:
    """The port a `kind` socket on host gets when it binds `port` (0: the kernel's choice), or None when it
    cannot bind it; the socket is closed again."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM if kind == "tcp" else socket.SOCK_DGRAM) as s:
        try:
            s.bind((host, port))
        except OSError:
            return None
        return s.getsockname()[1]


def free_port(kind: str = "tcp", host: str = "127.0.0.1") -> int:
    """A `kind` ("tcp" or "udp") port on host that binds now, below the ephemeral range, not handed out before
    by this process. Falls back to the kernel's choice when the range below is too small or full."""
    if kind not in ("tcp", "udp"):
        raise ValueError(f"kind must be 'tcp' or 'udp', got {kind!r}")
    high = ephemeral_low() - 1
    low = max(LOWEST, high - SPAN)
    if high - low >= 100:
        for _ in range(ATTEMPTS):
            port = _random.randint(low, high)
            if (kind, port) not in _given and _bound_port(kind, host, port) is not None:
                _given.add((kind, port))
                return port
    port = _bound_port(kind, host, 0)
    if port is None:
        raise OSError(f"cannot bind a {kind} socket on {host}")
    _given.add((kind, port))
    return port

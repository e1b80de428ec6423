"""Who is asking: the operator behind a command, on which surface, from where.

Every surface that can change the mission (the 3-D page, the REST API, the WebSocket) runs the command
inside `acting_as(principal)`; the ground station reads `current_principal()` to refuse anyone who is not an
operator and to write the audit record. The page learns a viser client's principal from a `ClientAccess`
(the ground station's HTTP front signs browsers in and vouches for each viser connection it forwards).
"""

from __future__ import annotations

import contextlib
import secrets
from collections.abc import Iterator
from contextvars import ContextVar
from dataclasses import dataclass, replace
from enum import StrEnum
from typing import Protocol


class Role(StrEnum):
    """observer: watches (state, page, stream); operator: also commands."""

    OBSERVER = "observer"
    OPERATOR = "operator"


class Surface(StrEnum):
    """Where a command came from: the 3-D page, the REST API, the WebSocket, or the station itself (its own
    shutdown landing, or a caller in the same process such as a test)."""

    PAGE = "page"
    API = "api"
    WS = "ws"
    STATION = "station"


@dataclass(frozen=True)
class Principal:
    """One command's sender: operator name (empty: not signed in), role (None: not signed in), surface,
    remote address ("host:port", or "" in-process) and the command's id (unique per command)."""

    name: str
    role: Role | None
    surface: Surface
    remote: str = ""
    command_id: str = ""

    @property
    def may_command(self) -> bool:
        return self.role is Role.OPERATOR

    def for_command(self, command_id: str | None = None) -> Principal:
        """This principal with a command id (a fresh random one unless given)."""
        return replace(self, command_id=command_id or new_command_id())


STATION = Principal(name="station", role=Role.OPERATOR, surface=Surface.STATION)
"""Commands issued in-process with no surface (the station's own shutdown landing, tests)."""

_current: ContextVar[Principal | None] = ContextVar("skyring_principal", default=None)


def new_command_id() -> str:
    return secrets.token_hex(6)


@contextlib.contextmanager
def acting_as(principal: Principal) -> Iterator[Principal]:
    """Run the commands inside the block on behalf of `principal`."""
    token = _current.set(principal)
    try:
        yield principal
    finally:
        _current.reset(token)


def current_principal() -> Principal:
    """Who is commanding now (`STATION` outside any `acting_as`)."""
    return _current.get() or STATION


class ClientAccess(Protocol):
    """What the page needs to know about its viser clients."""

    def principal_of(self, client_id: int) -> Principal:
        """The principal of a connected viser client (not signed in: role None)."""
        ...

    def client_connected(self, client_id: int, ticket: str | None) -> bool:
        """A viser client connected carrying `ticket` (the value its forwarding front put on the
        connection; None when it connected directly). False: refuse the connection before viser sends it
        anything (it was not forwarded by the front that signs browsers in)."""
        ...

    def client_disconnected(self, client_id: int) -> None: ...


class OpenAccess:
    """Every viser client is an operator (a station on loopback without sign-in, and the replay)."""

    def __init__(self, name: str = "local") -> None:
        self._name = name

    def principal_of(self, client_id: int) -> Principal:
        return Principal(name=self._name, role=Role.OPERATOR, surface=Surface.PAGE)

    def client_connected(self, client_id: int, ticket: str | None) -> bool:
        return True

    def client_disconnected(self, client_id: int) -> None:
        pass

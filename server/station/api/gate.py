"""The one gate of the ground station's HTTP front: who a request is (session cookie or bearer token), and
whether it may come from where it comes from (Origin, Host).

- Sign-in: `POST /auth/login` checks the name and secret against `Users` and opens a session: a random token
  (only its SHA-256 is kept) sent back in the body (for API clients: `Authorization: Bearer <token>`) and as
  an HttpOnly, SameSite=Strict cookie (Secure under TLS) for browsers. Sessions end after `session_s` or on
  sign-out. Ten failed sign-ins from one address within a minute lock that address out for the minute.
- Open mode (no users: only allowed on loopback): every caller is the operator "local".
- Origin: a state-changing request or a WebSocket handshake that carries an Origin (every browser sends one)
  other than the station's own is refused, as is one a browser marks `Sec-Fetch-Site: cross-site`.
- Host: in open mode the Host header must name this machine (127.0.0.1, localhost, ::1), so a web page
  cannot reach the station through a DNS name rebound to 127.0.0.1.
"""

from __future__ import annotations

import hashlib
import secrets
import threading
import time
from collections import deque
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from urllib.parse import urlsplit

from server.station.api.users import User, Users
from webui.access import Principal, Role, Surface

SESSION_COOKIE = "skyring_session"
LOOPBACK_NAMES = {"127.0.0.1", "localhost", "::1", "[::1]"}
FAILURES_ALLOWED = 10
FAILURE_WINDOW_S = 60.0


@dataclass(frozen=True)
class Session:
    name: str
    role: Role
    expires_s: float


class Gate:
    """Sessions and origin rules for one ground station (thread-safe). users None: open mode."""

    def __init__(
        self,
        users: Users | None,
        *,
        session_s: float = 12 * 3600.0,
        secure: bool = False,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.users = users
        self.session_s = session_s
        self.secure = secure
        self._clock = clock
        self._lock = threading.Lock()
        self._sessions: dict[str, Session] = {}
        self._failures: dict[str, deque[float]] = {}

    @property
    def open(self) -> bool:
        """No sign-in: every caller is the local operator (a loopback station without users)."""
        return self.users is None

    # ---- sessions ------------------------------------------------------------------------------------------
    def locked_out(self, host: str) -> bool:
        with self._lock:
            failures = self._failures.get(host)
            now = self._clock()
            while failures and now - failures[0] > FAILURE_WINDOW_S:
                failures.popleft()
            return failures is not None and len(failures) >= FAILURES_ALLOWED

    def sign_in(self, name: str, secret: str, *, host: str) -> tuple[str, User] | None:
        """A new session token for a right name and secret, else None (and the failure counts for `host`)."""
        if self.users is None:
            return None
        user = self.users.check(name, secret)
        with self._lock:
            if user is None:
                self._failures.setdefault(host, deque()).append(self._clock())
                return None
            token = secrets.token_urlsafe(32)
            self._sessions[_digest(token)] = Session(
                name=user.name, role=user.role, expires_s=self._clock() + self.session_s
            )
            return token, user

    def sign_out(self, token: str | None) -> None:
        if token:
            with self._lock:
                self._sessions.pop(_digest(token), None)

    def session(self, token: str | None) -> Session | None:
        if not token:
            return None
        with self._lock:
            session = self._sessions.get(_digest(token))
            if session is not None and session.expires_s < self._clock():
                del self._sessions[_digest(token)]
                return None
            return session

    def principal(self, token: str | None, *, surface: Surface, remote: str) -> Principal:
        """Who holds `token` (open mode: the local operator; no valid session: not signed in)."""
        if self.open:
            return Principal(name="local", role=Role.OPERATOR, surface=surface, remote=remote)
        session = self.session(token)
        if session is None:
            return Principal(name="", role=None, surface=surface, remote=remote)
        return Principal(name=session.name, role=session.role, surface=surface, remote=remote)

    # ---- where a request comes from ------------------------------------------------------------------------
    def foreign_origin(self, headers: Mapping[str, str], *, scheme: str) -> str | None:
        """Why a state-changing request or WebSocket handshake with these headers comes from another site
        (None: it does not). scheme: "http" or "https" as the station serves."""
        if headers.get("sec-fetch-site") == "cross-site":
            return "a page of another site sent it"
        origin = headers.get("origin")
        if origin is None:
            return None  # not a browser (browsers send Origin on every such request)
        own = f"{scheme}://{headers.get('host', '')}".lower()
        ws_own = own.replace("http", "ws", 1)
        if origin.lower() not in (own, ws_own):
            return f"a page of another origin ({origin}) sent it"
        return None

    def bad_host(self, headers: Mapping[str, str]) -> str | None:
        """Why the Host header is refused in open mode (None: fine)."""
        if not self.open:
            return None
        host = headers.get("host", "")
        name = urlsplit(f"//{host}").hostname or ""
        if name in LOOPBACK_NAMES or f"[{name}]" in LOOPBACK_NAMES:
            return None
        return (
            f"host {host!r} is not this machine: without sign-in the station answers only on loopback names"
        )


def bearer_or_cookie(headers: Mapping[str, str], cookies: Mapping[str, str]) -> str | None:
    """The session token of a request: `Authorization: Bearer <token>`, else the session cookie."""
    auth = headers.get("authorization", "")
    if auth[:7].lower() == "bearer ":
        return auth[7:].strip() or None
    return cookies.get(SESSION_COOKIE)


def _digest(token: str) -> str:
    return hashlib.sha256(token.encode()).hexdigest()

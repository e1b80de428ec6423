"""Operators and their hashed secrets: who may sign in to the ground station, and with which role.

A users file has one operator per line: `name role hash`, where role is `operator` (may command) or
`observer` (may watch) and hash is `scrypt$N$r$p$<salt>$<key>` (base64, stdlib `hashlib.scrypt`, N = 2^14,
r = 8, p = 1: about 16 MB and 50 ms per check, so guessing is slow). Blank lines and `#` comments are
ignored. `skyring users add FILE NAME --role ROLE` writes such lines; the secret itself is never stored,
printed or logged. The same lines may come from the environment (`SKYRING_USERS`, lines separated by
newlines or `;`).
"""

from __future__ import annotations

import base64
import hashlib
import hmac
import re
import secrets
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path

from webui.access import Role

SCRYPT_N, SCRYPT_R, SCRYPT_P = 2**14, 8, 1
NAME = re.compile(r"^[A-Za-z0-9_.@-]{1,64}$")
MIN_SECRET_CHARS = 8


class UsersError(ValueError):
    """A users file or entry that cannot be used; the message says which line and why."""


def hash_secret(secret: str, *, salt: bytes | None = None) -> str:
    """The stored form of a secret: scrypt$N$r$p$salt$key (salt: 16 random bytes unless given)."""
    salt = salt if salt is not None else secrets.token_bytes(16)
    key = hashlib.scrypt(secret.encode(), salt=salt, n=SCRYPT_N, r=SCRYPT_R, p=SCRYPT_P, dklen=32)
    b64 = base64.b64encode
    return f"scrypt${SCRYPT_N}${SCRYPT_R}${SCRYPT_P}${b64(salt).decode()}${b64(key).decode()}"


def verify_secret(secret: str, stored: str) -> bool:
    """Whether `secret` matches the stored hash (constant-time compare)."""
    try:
        scheme, n, r, p, salt, key = stored.split("$")
        if scheme != "scrypt":
            return False
        expected = base64.b64decode(key)
        got = hashlib.scrypt(
            secret.encode(),
            salt=base64.b64decode(salt),
            n=int(n),
            r=int(r),
            p=int(p),
            dklen=len(expected),
            maxmem=256 * 1024 * 1024,
        )
    except (ValueError, TypeError):
        return False
    return hmac.compare_digest(got, expected)


@dataclass(frozen=True)
class User:
    """One operator: name, role and the stored hash of their secret (never the secret)."""

    name: str
    role: Role
    secret_hash: str

    def __repr__(self) -> str:  # the hash stays out of logs and tracebacks too
        return f"User(name={self.name!r}, role={self.role.value!r})"


def user_line(name: str, role: Role, secret: str) -> str:
    """The users-file line for a new operator (UsersError for a bad name or a short secret)."""
    if not NAME.match(name):
        raise UsersError(f"user name {name!r}: use 1-64 letters, digits and _.@-")
    if len(secret) < MIN_SECRET_CHARS:
        raise UsersError(f"the secret must have at least {MIN_SECRET_CHARS} characters")
    return f"{name} {role.value} {hash_secret(secret)}"


class Users:
    """The operators who may sign in, by name."""

    def __init__(self, users: Iterable[User]) -> None:
        self._by_name: dict[str, User] = {}
        for user in users:
            if user.name in self._by_name:
                raise UsersError(f"user {user.name!r} is listed twice")
            self._by_name[user.name] = user
        if not self._by_name:
            raise UsersError("no users: add one with `skyring users add FILE NAME --role operator`")
        # a fixed hash to check unknown names against, so a wrong name takes as long as a wrong secret
        self._dummy = hash_secret(secrets.token_hex(8))

    def __len__(self) -> int:
        return len(self._by_name)

    def check(self, name: str, secret: str) -> User | None:
        """The user if `secret` is theirs, else None (same work either way)."""
        user = self._by_name.get(name)
        ok = verify_secret(secret, user.secret_hash if user is not None else self._dummy)
        return user if ok and user is not None else None

    @classmethod
    def parse(cls, text: str, *, source: str) -> Users:
        """Users from the text of a users file (UsersError naming `source` and the line)."""
        users = []
        for number, raw in enumerate(re.split(r"[\n;]", text), start=1):
            line = raw.split("#", 1)[0].strip()
            if not line:
                continue
            parts = line.split()
            if len(parts) != 3:
                raise UsersError(
                    f"{source}, entry {number}: expected `name role hash`, got {len(parts)} fields"
                )
            name, role, stored = parts
            if not NAME.match(name):
                raise UsersError(f"{source}, entry {number}: bad user name {name!r}")
            try:
                role_ = Role(role)
            except ValueError:
                raise UsersError(
                    f"{source}, entry {number}: role must be operator or observer, got {role!r}"
                ) from None
            if not stored.startswith("scrypt$") or stored.count("$") != 5:
                raise UsersError(
                    f"{source}, entry {number}: the secret must be an scrypt hash, not plain text"
                )
            users.append(User(name=name, role=role_, secret_hash=stored))
        return cls(users)

    @classmethod
    def load(cls, path: Path | None, environ: Mapping[str, str]) -> Users | None:
        """Users from `path`, else from SKYRING_USERS_FILE or SKYRING_USERS in `environ`; None if none is
        given (UsersError if one is given but unusable)."""
        file = path or (Path(environ["SKYRING_USERS_FILE"]) if environ.get("SKYRING_USERS_FILE") else None)
        if file is not None:
            try:
                text = Path(file).read_text()
            except OSError as exc:
                raise UsersError(f"cannot read the users file {file}: {exc.strerror or exc}") from None
            return cls.parse(text, source=str(file))
        if environ.get("SKYRING_USERS"):
            return cls.parse(environ["SKYRING_USERS"], source="SKYRING_USERS")
        return None

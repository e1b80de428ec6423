"""Sign-in and TLS on the command line: `--users` (or SKYRING_USERS / SKYRING_USERS_FILE) and `--tls-cert` /
`--tls-key`, turned into the gate and TLS files every `skyring serve` mode hands `serve_station`. Listening
beyond loopback without users is refused here, before anything flies.
"""

from __future__ import annotations

import os
from pathlib import Path

import typer


def security_options(
    *, host: str, users: Path | None, tls_cert: Path | None, tls_key: Path | None
) -> dict[str, object]:
    """The gate and TLS files for `serve_station` from --users / SKYRING_USERS(_FILE) and --tls-*."""
    from server.station.api.gate import LOOPBACK_NAMES, Gate
    from server.station.api.users import Users, UsersError

    if (tls_cert is None) != (tls_key is None):
        raise typer.BadParameter("give both --tls-cert and --tls-key, or neither", param_hint="--tls-cert")
    try:
        loaded = Users.load(users, os.environ)
    except UsersError as exc:
        raise typer.BadParameter(str(exc), param_hint="--users") from None
    if loaded is None and host not in LOOPBACK_NAMES:
        raise typer.BadParameter(
            f"listening on {host} needs sign-in: give --users FILE (make one with `skyring users add FILE "
            "NAME --role operator`) or set SKYRING_USERS_FILE",
            param_hint="--host",
        )
    return {
        "gate": Gate(loaded, secure=tls_cert is not None),
        "ssl_certfile": None if tls_cert is None else str(tls_cert),
        "ssl_keyfile": None if tls_key is None else str(tls_key),
    }

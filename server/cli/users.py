"""`skyring users add FILE NAME --role ROLE`: add an operator to a users file (the secret is asked for,
hashed with scrypt and never stored or printed)."""

from __future__ import annotations

import getpass
import sys
from pathlib import Path
from typing import Annotated

import typer

from server.station.api.users import Users, UsersError, user_line
from webui.access import Role


def users(
    action: Annotated[str, typer.Argument(help="add")],
    file: Annotated[
        Path, typer.Argument(help="users file to append to (created if missing)", dir_okay=False)
    ],
    name: Annotated[str, typer.Argument(help="the operator's name")],
    role: Annotated[
        Role, typer.Option(help="operator (may command) or observer (may watch)")
    ] = Role.OPERATOR,
    secret_stdin: Annotated[bool, typer.Option("--secret-stdin", help="read the secret from stdin")] = False,
) -> None:
    """Add an operator with a hashed secret to a users file for `skyring serve --users FILE`."""
    if action != "add":
        raise typer.BadParameter("the only action is: add", param_hint="ACTION")
    secret = sys.stdin.readline().rstrip("\n") if secret_stdin else getpass.getpass(f"secret for {name}: ")
    try:
        line = user_line(name, role, secret)
        existing = file.read_text() if file.exists() else ""
        if existing.strip():
            Users.parse(existing + "\n" + line, source=str(file))  # a duplicate name is refused here
    except UsersError as exc:
        typer.echo(f"error: {exc}", err=True)
        raise typer.Exit(code=1) from None
    with file.open("a") as f:
        f.write(("" if not existing or existing.endswith("\n") else "\n") + line + "\n")
    file.chmod(0o600)
    typer.echo(f"added {name} ({role.value}) to {file}")

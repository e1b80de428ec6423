"""`skyring users add FILE NAME --role ROLE`: a users file the station signs operators in from, with the
secret hashed (never stored or printed), the file private to its owner, and bad entries refused."""

from __future__ import annotations

import stat
from pathlib import Path

from typer.testing import CliRunner, Result

from server.cli import COMMANDS, _register, app
from server.station.api.users import Users
from webui.access import Role

_register("users", COMMANDS["users"])


def add(file: Path, name: str, secret: str, *role: str) -> Result:
    return CliRunner().invoke(
        app, ["users", "add", str(file), name, *role, "--secret-stdin"], input=secret + "\n"
    )


def test_added_operators_sign_in_with_their_secret_which_is_stored_only_hashed(tmp_path):
    file = tmp_path / "users.txt"
    first = add(file, "alice", "alice-secret-1")
    second = add(file, "bob", "bob-secret-22", "--role", "observer")
    assert first.exit_code == 0 and second.exit_code == 0, first.output + second.output
    text = file.read_text()
    assert "alice-secret-1" not in text and "bob-secret-22" not in text
    assert "alice-secret-1" not in first.output
    users = Users.load(file, {})
    assert users is not None and len(users) == 2
    alice, bob = users.check("alice", "alice-secret-1"), users.check("bob", "bob-secret-22")
    assert alice is not None and alice.role is Role.OPERATOR
    assert bob is not None and bob.role is Role.OBSERVER
    assert users.check("alice", "bob-secret-22") is None
    assert stat.S_IMODE(file.stat().st_mode) == 0o600


def test_a_duplicate_name_or_a_short_secret_is_refused_and_the_file_left_as_it_was(tmp_path):
    file = tmp_path / "users.txt"
    assert add(file, "alice", "alice-secret-1").exit_code == 0
    before = file.read_text()
    twice = add(file, "alice", "another-secret")
    short = add(file, "carol", "short")
    assert twice.exit_code == 1 and "listed twice" in twice.stderr
    assert short.exit_code == 1 and "at least 8 characters" in short.stderr
    assert file.read_text() == before

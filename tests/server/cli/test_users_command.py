"""`skyring users add FILE NAME --role ROLE`: a users file the station signs operators in from, with the
secret hashed (never stored or printed), the file private to its owner, and bad entries refused."""

from __future__ import annotations

import stat
import subprocess
import sys
from pathlib import Path

from server.station.api.users import Users
from webui.access import Role

SKYRING = [sys.executable, "-c", "from server.cli import main; main()"]
ROOT = Path(__file__).resolve().parents[3]


def add(file: Path, name: str, secret: str, *role: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [*SKYRING, "users", "add", str(file), name, *role, "--secret-stdin"],
        input=secret + "\n",
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=120,
    )


def test_added_operators_sign_in_with_their_secret_which_is_stored_only_hashed(tmp_path):
    file = tmp_path / "users.txt"
    first = add(file, "alice", "alice-secret-1")
    second = add(file, "bob", "bob-secret-22", "--role", "observer")
    assert first.returncode == 0 and second.returncode == 0, first.stderr + second.stderr
    text = file.read_text()
    assert "alice-secret-1" not in text and "bob-secret-22" not in text
    assert "alice-secret-1" not in first.stdout + first.stderr
    users = Users.load(file, {})
    assert users is not None and len(users) == 2
    alice, bob = users.check("alice", "alice-secret-1"), users.check("bob", "bob-secret-22")
    assert alice is not None and alice.role is Role.OPERATOR
    assert bob is not None and bob.role is Role.OBSERVER
    assert users.check("alice", "bob-secret-22") is None
    assert stat.S_IMODE(file.stat().st_mode) == 0o600


def test_a_duplicate_name_or_a_short_secret_is_refused_and_the_file_left_as_it_was(tmp_path):
    file = tmp_path / "users.txt"
    assert add(file, "alice", "alice-secret-1").returncode == 0
    before = file.read_text()
    twice = add(file, "alice", "another-secret")
    short = add(file, "carol", "short")
    assert twice.returncode == 1 and "listed twice" in twice.stderr
    assert short.returncode == 1 and "at least 8 characters" in short.stderr
    assert file.read_text() == before

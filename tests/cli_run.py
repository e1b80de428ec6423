"""Run the `skyring` command line in this process, as a user's shell would, and capture what it prints."""

from __future__ import annotations

import sys
from dataclasses import dataclass
from unittest.mock import patch

import pytest

from server.cli import main


@dataclass(frozen=True)
class Done:
    returncode: int
    stdout: str
    stderr: str


def run_skyring(capsys: pytest.CaptureFixture[str], *args: str) -> Done:
    """`skyring ARGS...` through the real entry point (`main`, which always exits): exit status and output."""
    capsys.readouterr()
    with patch.object(sys, "argv", ["skyring", *args]):
        try:
            main()
        except SystemExit as exc:
            code = exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 1)
        else:
            code = 0
    out = capsys.readouterr()
    return Done(code, out.out, out.err)

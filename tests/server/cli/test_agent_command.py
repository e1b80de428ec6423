"""`skyring agent` and `skyring serve --agents`: bad command lines are refused with a message, before any
network or vehicle is touched."""

from __future__ import annotations

import pytest
from typer.testing import CliRunner

from server.cli import COMMANDS, _register, app

runner = CliRunner()


@pytest.fixture(scope="module", autouse=True)
def registered():
    for name in ("agent", "serve"):
        _register(name, COMMANDS[name])


@pytest.mark.parametrize(
    ("args", "says"),
    [
        (["agent", "--id", "1"], "exactly one of --px4 URL or --sim"),
        (["agent", "--id", "1", "--sim", "--px4", "udpin://0.0.0.0:14540"], "exactly one of"),
        (["agent", "--id", "0", "--sim"], "from 1 to 255"),
        (["agent", "--id", "4", "--sim", "--team-size", "3"], "--team-size"),
        (["agent", "--id", "1", "--sim", "--team", "a/b"], "team name"),
        (["agent", "--id", "1", "--sim", "--connect", "192.168.1.10:7447"], "not a Zenoh endpoint"),
        (["agent", "--id", "1", "--sim", "--rate", "0"], "from 1 to 200 Hz"),
        (["agent", "--id", "1", "--sim", "--station-timeout", "-1"], "station_timeout_s"),
        (["agent", "--id", "1", "--sim", "--realtime-priority", "100"], "from 0 (off) to 99"),
        (["agent", "--id", "1", "--px4", "udpin://0.0.0.0:1", "--emulate-camera", "dog"], "--emulate-camera"),
        (["serve", "--agents", "cloud"], "in-process, zenoh or spawn"),
        (["serve", "--agents", "spawn", "--px4", "udpin://0.0.0.0:14540", "--no-log"], "drop --px4"),
    ],
)
def test_a_bad_command_line_is_refused_with_a_message(args, says):
    result = runner.invoke(app, args)
    assert result.exit_code == 2
    assert says in result.output.replace("\n", " ") or says in str(result.output)

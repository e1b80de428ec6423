"""The Docker deployment of onboard agents, checked without a Docker engine (none on CI): the compose file
parses, pairs each agent with its own PX4 (its network namespace and API port), and every command line in it
is one the `skyring` CLI accepts."""

from __future__ import annotations

from pathlib import Path

import pytest
import typer
import yaml

DOCKER = Path(__file__).resolve().parents[2] / "docker"


@pytest.fixture(scope="module")
def compose() -> dict:
    return yaml.safe_load((DOCKER / "compose.agents.yaml").read_text())


def parse(command: list[str]):
    """Parse a `skyring ...` command line with the real CLI (nothing runs)."""
    from server.cli import COMMANDS, _register, app

    name = command[0]
    _register(name, COMMANDS[name])
    group = typer.main.get_command(app)
    sub = group.get_command(group.context_class(group), name)  # type: ignore[attr-defined]
    assert sub is not None
    return sub.make_context(name, list(command[1:]))


def option(command: list[str], name: str) -> str:
    return command[command.index(name) + 1]


def test_every_agent_sits_beside_its_own_px4_on_its_api_port(compose):
    services = compose["services"]
    agents = {k: v for k, v in services.items() if k.startswith("agent-")}
    base = yaml.safe_load((DOCKER / "compose.yaml").read_text())["services"]
    assert len(agents) == 3
    ids = []
    for agent in agents.values():
        px4_name = agent["network_mode"].removeprefix("service:")
        px4 = services[px4_name]
        assert px4["extends"]["file"] == "compose.yaml" and px4["extends"]["service"] in base
        instance = int(base[px4["extends"]["service"]]["environment"]["PX4_INSTANCE"])
        assert px4["environment"]["SKYRING_GCS_HOST"] == "127.0.0.1"  # PX4 talks to its own agent
        command = agent["command"]
        ids.append(int(option(command, "--id")))
        assert ids[-1] == instance + 1
        assert option(command, "--px4") == f"udpin://0.0.0.0:{14540 + instance}"
    assert sorted(ids) == [1, 2, 3]


def test_the_station_supervises_as_many_agents_as_there_are_and_they_reach_it(compose):
    services = compose["services"]
    station = services["groundstation"]["command"]
    assert option(station, "--agents") == "zenoh"
    agents = [v["command"] for k, v in services.items() if k.startswith("agent-")]
    assert int(option(station, "--vehicles")) == len(agents)
    port = option(station, "--listen").rsplit(":", 1)[1]
    for command in agents:
        assert option(command, "--connect") == f"tcp/groundstation:{port}"
        assert int(option(command, "--team-size")) == len(agents)
    assert "8000:8000" in services["groundstation"]["ports"]


@pytest.mark.parametrize("service", ["groundstation", "agent-1", "agent-2", "agent-3"])
def test_every_command_line_is_one_the_cli_accepts(compose, service):
    context = parse(compose["services"][service]["command"])
    assert context.params  # parsed into the command's parameters


@pytest.mark.parametrize("file", ["compose.yaml", "compose.agents.yaml"])
def test_the_station_publishes_only_its_front_and_takes_its_users_from_the_environment(file):
    station = yaml.safe_load((DOCKER / file).read_text())["services"]["groundstation"]
    assert option(station["command"], "--host") == "0.0.0.0"  # beyond loopback: sign-in is required
    assert "SKYRING_USERS" in station["environment"]  # passed through from the shell running compose
    assert [p.split(":")[-1] for p in station["ports"]] == ["8000"]  # viser's own port stays inside

"""Every Zenoh key expression skyring uses, in one place.

    skyring/<team>/agent/<id>/plan        PlanBody       agent <id> -> teammates, station       10 Hz
    skyring/<team>/agent/<id>/detection   DetectionBody  <id>'s detector -> its agent, teammates  4 Hz
                                          (or <id>'s agent, from its camera's pixels -> teammates)
    skyring/<team>/agent/<id>/camera      CameraBody     `skyring detect` on <id> -> its agent  per frame
    skyring/<team>/agent/<id>/camera_report  CameraReportBody  `skyring detect` -> station       1 Hz
    skyring/<team>/agent/<id>/state       StateBody      agent <id> -> station (its heartbeat)   10 Hz
    skyring/<team>/agent/<id>/ack         AckBody        agent <id> -> station                   per command
    skyring/<team>/station/heartbeat      HeartbeatBody  station -> agents                        2 Hz
    skyring/<team>/station/command        CommandBody    station -> agents (targets inside)      per command
    skyring/<team>/sim/<id>/telemetry     TelemetryBody  simulated vehicle <id> -> its agent      50 Hz
    skyring/<team>/sim/<id>/autopilot     AutopilotCommandBody  agent <id> -> simulated vehicle  per tick

A message's kind must match the last segment of its key, and the <id> in the key must be the header's sender
(0 on station keys); `vehicles.net.guard` rejects anything else. Team names are 1-32 characters of letters,
digits, '-' and '_' (no key-expression wildcards).
"""

from __future__ import annotations

import re
from dataclasses import dataclass

ROOT = "skyring"
AGENT_TOPICS = ("plan", "detection", "state", "ack", "camera", "camera_report")
STATION_TOPICS = ("heartbeat", "command")
SIM_TOPICS = ("telemetry", "autopilot")
_TEAM = re.compile(r"^[A-Za-z0-9_-]{1,32}$")


def check_team(team: str) -> str:
    """The team name, or ValueError saying what a team name may hold."""
    if not isinstance(team, str) or not _TEAM.match(team):
        raise ValueError(f"a team name is 1-32 letters, digits, '-' or '_', got {team!r}")
    return team


def agent_key(team: str, vehicle_id: int, topic: str) -> str:
    if topic not in AGENT_TOPICS:
        raise ValueError(f"unknown agent topic {topic!r}")
    return f"{ROOT}/{team}/agent/{int(vehicle_id)}/{topic}"


def all_agents_key(team: str, topic: str) -> str:
    """The subscription to `topic` of every agent of the team."""
    if topic not in AGENT_TOPICS:
        raise ValueError(f"unknown agent topic {topic!r}")
    return f"{ROOT}/{team}/agent/*/{topic}"


def station_key(team: str, topic: str) -> str:
    if topic not in STATION_TOPICS:
        raise ValueError(f"unknown station topic {topic!r}")
    return f"{ROOT}/{team}/station/{topic}"


def sim_key(team: str, vehicle_id: int, topic: str) -> str:
    if topic not in SIM_TOPICS:
        raise ValueError(f"unknown sim topic {topic!r}")
    return f"{ROOT}/{team}/sim/{int(vehicle_id)}/{topic}"


def all_sim_key(team: str, topic: str) -> str:
    if topic not in SIM_TOPICS:
        raise ValueError(f"unknown sim topic {topic!r}")
    return f"{ROOT}/{team}/sim/*/{topic}"


@dataclass(frozen=True)
class ParsedKey:
    """A key split into its parts: role "agent", "station" or "sim"; vehicle_id 0 for the station."""

    team: str
    role: str
    vehicle_id: int
    topic: str


def parse_key(key: str) -> ParsedKey | None:
    """The parts of a skyring key, or None when it is not one."""
    parts = str(key).split("/")
    if len(parts) == 4 and parts[0] == ROOT and parts[2] == "station" and parts[3] in STATION_TOPICS:
        return ParsedKey(team=parts[1], role="station", vehicle_id=0, topic=parts[3])
    if len(parts) == 5 and parts[0] == ROOT and parts[2] in ("agent", "sim") and parts[3].isdigit():
        topics = AGENT_TOPICS if parts[2] == "agent" else SIM_TOPICS
        if parts[4] in topics:
            return ParsedKey(team=parts[1], role=parts[2], vehicle_id=int(parts[3]), topic=parts[4])
    return None

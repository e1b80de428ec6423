"""`skyring serve --agents zenoh|spawn`: the ground station supervising onboard agents over Zenoh.

- `zenoh`: the agents run elsewhere (one `skyring agent` per companion computer); the station finds them on
  the team's Zenoh network, shows them and sends them the operator's commands. With `--px4 URL ...` it also
  keeps its own MAVLink link to each vehicle (a telemetry radio) and lands through it directly.
- `spawn` (the one-laptop rehearsal): the station process also serves the embedded world (simulated vehicles,
  the person, each MAV's camera/detector emulation publishing on that MAV's detection key) and starts one
  `skyring agent --sim` process per MAV, all on Zenoh over 127.0.0.1.

Either way the station computes no control, and `AgentFleet` stands where the in-process mission stands.
"""

from __future__ import annotations

import contextlib
import logging
import os
import subprocess
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

from controller.messages import Obstacle
from controller.params import ControllerParams, Method
from server.station.fleet import AgentFleet
from server.station.ground_station import GroundStation, camera_view
from vehicles.autopilot import Autopilot
from vehicles.net.ports import free_port
from vehicles.net.remote_sim import SimWorldServer
from vehicles.net.session import Bus, NetConfig
from vehicles.sim.scenario import Scenario, SeedStreams, build_sim, make_person, make_trees
from vehicles.sim.trees import TreeSpec

log = logging.getLogger(__name__)

STATION_RATE_HZ = 20.0  # the station's tick: snapshots for the page, the API and the log
# The station's time runs from 0 at one control period per tick, paced at real time by the live runner (as
# with PX4 vehicles); the agents' own stamps are UTC.


@dataclass
class AgentsStation:
    """A station over a fleet of agents, and what must be stopped with it (world, agent processes, bus)."""

    station: GroundStation
    fleet: AgentFleet
    bus: Bus
    world: SimWorldServer | None = None
    processes: list[subprocess.Popen] = field(default_factory=list)
    on_close: list[Callable[[], None]] = field(default_factory=list)

    def close(self) -> None:
        """Stop the fleet's service, the world, the agent processes (SIGTERM, then SIGKILL) and the bus."""
        self.fleet.close()
        for proc in self.processes:
            if proc.poll() is None:
                proc.terminate()
        deadline = time.monotonic() + 5.0
        for proc in self.processes:
            try:
                proc.wait(max(0.1, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait(2.0)
        if self.world is not None:
            self.world.stop()
        for hook in self.on_close:
            with contextlib.suppress(Exception):
                hook()
        self.bus.close()


def static_obstacles(*, trees: str, person: str, seed: int) -> tuple[Obstacle, ...]:
    """The map the station hands the agents: the paper's trees, none, or N random ones clear of the person."""
    streams = SeedStreams.from_seed(seed)
    return make_trees(TreeSpec.parse(trees), streams, person=make_person(person, streams), starts_xy_m=[])


def build_zenoh_station(
    *,
    config: NetConfig,
    vehicles: int,
    method: Method = Method.ACTIVE,
    trees: str = "none",
    person: str = "still",
    seed: int = 0,
    override: dict[int, Autopilot] | None = None,
    formation_enabled: bool = True,
) -> AgentsStation:
    """A station supervising agents 1..vehicles found on the Zenoh network of `config`."""
    bus = Bus(config, sender=0, is_member=lambda s: 1 <= s <= vehicles)
    try:
        fleet = AgentFleet(
            bus=bus,
            vehicle_ids=range(1, vehicles + 1),
            controller_params=ControllerParams(method=method),
            static_obstacles=static_obstacles(trees=trees, person=person, seed=seed),
            override=override,
            formation_enabled=formation_enabled,
        )
    except BaseException:
        bus.close()
        raise
    station = GroundStation(mission=fleet, control_period_s=1.0 / STATION_RATE_HZ)
    fleet.start()
    return AgentsStation(station=station, fleet=fleet, bus=bus)


def agent_command(
    *,
    vehicle_id: int,
    team: str,
    team_size: int,
    connect: Sequence[str],
    listen: str,
    rate_hz: float,
    method: Method,
    realtime_priority: int = 0,
) -> list[str]:
    """The command line of one rehearsal agent process."""
    return [
        sys.executable,
        "-m",
        "server.cli",
        "agent",
        "--id",
        str(vehicle_id),
        "--sim",
        "--team",
        team,
        "--team-size",
        str(team_size),
        "--no-multicast",
        "--rate",
        f"{rate_hz:g}",
        "--method",
        method.value,
        "--realtime-priority",
        str(realtime_priority),
        "--listen",
        listen,
        *[a for endpoint in connect for a in ("--connect", endpoint)],
    ]


def build_spawn_station(
    *,
    vehicles: int,
    seed: int = 0,
    method: Method = Method.ACTIVE,
    trees: str = "paper",
    person: str = "paper",
    agent_rate_hz: float = 20.0,
    agent_realtime_priority: int = 0,
    team: str = "rehearsal",
    listen_port: int | None = None,
    stderr=None,
) -> AgentsStation:
    """The one-laptop rehearsal: the world and the station in this process, one agent process per MAV, all on
    Zenoh over 127.0.0.1 (multicast scouting off; every agent connects to the station's endpoint and to the
    agents started before it). agent_realtime_priority: the agents' `--realtime-priority`."""
    setup = build_sim(Scenario(vehicles=vehicles, seed=seed, method=method, trees=trees, person=person))
    port = listen_port or free_port()
    station_endpoint = f"tcp/127.0.0.1:{port}"
    config = NetConfig(team=team, listen=(station_endpoint,), multicast_scouting=False)
    bus = Bus(config, sender=0, is_member=lambda s: 1 <= s <= vehicles)
    processes: list[subprocess.Popen] = []
    try:
        world = SimWorldServer(
            bus=bus, world=setup.world, autopilots={a.vehicle_id: a for a in setup.autopilots}
        )
        fleet = AgentFleet(
            bus=bus,
            vehicle_ids=[a.vehicle_id for a in setup.autopilots],
            controller_params=ControllerParams(method=method),
            static_obstacles=setup.world.obstacles,
            formation=setup.scenario.formation,
            person_truth=world.person_truth,
        )
        station = GroundStation(
            mission=fleet,
            control_period_s=1.0 / STATION_RATE_HZ,
            camera=camera_view(setup.world.camera),
        )
        world.start()
        fleet.start()
        endpoints = [station_endpoint]
        env = dict(os.environ, PYTHONUNBUFFERED="1")
        for a in setup.autopilots:
            own = f"tcp/127.0.0.1:{free_port()}"
            cmd = agent_command(
                vehicle_id=a.vehicle_id,
                team=team,
                team_size=vehicles,
                connect=endpoints,
                listen=own,
                rate_hz=agent_rate_hz,
                method=method,
                realtime_priority=agent_realtime_priority,
            )
            processes.append(subprocess.Popen(cmd, env=env, stdin=subprocess.DEVNULL, stderr=stderr))
            endpoints = [*endpoints, own]
    except BaseException:
        for proc in processes:
            proc.kill()
        bus.close()
        raise
    return AgentsStation(station=station, fleet=fleet, bus=bus, world=world, processes=processes)

"""`skyring serve`: the ground station over the embedded simulation (default) in real time.

Prints the operator URL and the API URL as soon as both listen. The station is built by
`build_station`; other back-ends (PX4 through MAVSDK) build their autopilots and hand the same ground station
a mission over them, then call `run`. Unless `--no-log`, the run is recorded in a flight log
(`server.flightlog.log`; `skyring replay` plays it back), opened before anything flies so a log that cannot be
written is refused up front rather than missed after the flight.
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from controller.params import ControllerParams, Method, ParameterError
from server.cli.log_options import (
    describe_log,
    log_header,
    log_line,
    log_path_option,
    open_log,
    start_foxglove,
)
from server.cli.options import OPTION_OF_FIELD, MethodOption, Person, PersonMode, Rate, Seed, Trees, Vehicles
from server.cli.security_options import security_options
from server.settings import RunSettings

if TYPE_CHECKING:
    from server.flightlog.log import FlightLog

log = logging.getLogger(__name__)


def build_station(settings: RunSettings):
    """A ground station over the embedded simulation of `settings`: its simulated MAVs, trees and person,
    ticking at settings.rate_hz."""
    from controller.warmup import warm_up
    from server.station.ground_station import GroundStation, camera_view
    from vehicles.sim.scenario import build_sim

    # the compiled kernels, before the first tick (compiles once on a fresh install)
    warm_up(ControllerParams(method=settings.method))
    setup = build_sim(settings.scenario(), clock=time.perf_counter)
    return GroundStation(
        mission=setup.mission, control_period_s=1.0 / settings.rate_hz, camera=camera_view(setup.world.camera)
    )


def run(
    station,
    *,
    host: str,
    port: int,
    viser_port: int,
    speed: float,
    flight_log: FlightLog | None = None,
    **serve_options,
) -> None:
    """Serve `station` until Ctrl-C / SIGTERM; the MAVs are told to land on the way out. `flight_log`, when
    given, records the whole run and is closed here. serve_options go to `serve_station` (gate, TLS)."""
    from server.station.live import Urls, serve_station

    def ready(urls: Urls, _ui: object) -> None:
        if urls.api_fell_back:
            typer.echo(f"port {port} is busy: the API uses {urls.api} instead")
        if urls.viser_fell_back:
            typer.echo(f"port {viser_port} is busy: the operator page uses {urls.operator} instead")
        typer.echo(f"operator view:  {urls.api}  (3-D page alone: {urls.operator})")
        typer.echo(
            f"API and docs:   {urls.api}docs  (state at {urls.api}api/state, stream at "
            f"{urls.api.replace('http', 'ws', 1)}ws)"
        )
        gate = serve_options.get("gate")
        typer.echo(
            "sign-in:        required (users file)"
            if gate is not None and not gate.open
            else "sign-in:        off (loopback only: anyone on this machine is the operator)"
        )
        typer.echo(log_line(flight_log))
        typer.echo("Ctrl-C to stop (every MAV is told to land).")

    if flight_log is not None:
        station.attach_log(flight_log)
    try:
        stats = asyncio.run(
            serve_station(
                station,
                host=host,
                port=port,
                viser_port=viser_port,
                speed=speed,
                on_ready=ready,
                **serve_options,
            )
        )
    finally:
        if flight_log is not None:
            flight_log.close()
    typer.echo(
        f"stopped after {stats.ticks} control ticks ({stats.achieved_speed:.2f}x real time"
        + (f", fell behind {stats.lagged} times" if stats.lagged else "")
        + ")"
    )
    if flight_log is not None and flight_log.recording:
        typer.echo(describe_log(flight_log))


Speed = Annotated[
    float, typer.Option(min=0.01, max=100.0, help="simulated seconds per wall second (PX4: 1, real time)")
]


def serve(
    host: Annotated[str, typer.Option(help="address to listen on (0.0.0.0: every interface)")] = "127.0.0.1",
    port: Annotated[int, typer.Option(min=0, max=65535, help="API port; a free one is used if busy")] = 8000,
    viser_port: Annotated[
        int,
        typer.Option(
            min=0, max=65535, help="viser's internal port on 127.0.0.1 (the page is served through --port)"
        ),
    ] = 8080,
    vehicles: Vehicles = 3,
    seed: Seed = 0,
    speed: Speed = 1.0,
    method: MethodOption = Method.ACTIVE,
    trees: Trees = "paper",
    person: Person = PersonMode.paper,
    rate: Rate = 100.0,
    px4: Annotated[
        list[str] | None,
        typer.Option(
            help="fly PX4 vehicles: a MAVSDK URL per vehicle (repeat, or comma-separate), e.g. "
            "udpin://0.0.0.0:14540"
        ),
    ] = None,
    px4_sitl: Annotated[
        int, typer.Option(min=0, help="fly N local PX4 SITL instances (udpin://0.0.0.0:14540+i)")
    ] = 0,
    origin: Annotated[
        str | None,
        typer.Option(help="team frame origin 'lat,lon,alt' for PX4 vehicles (default: vehicle 1's home)"),
    ] = None,
    log: Annotated[
        Path | None,
        typer.Option(
            "--log",
            help="flight log to write (MCAP) [default: runs/flight-<UTC time>.mcap]",
            dir_okay=False,
        ),
    ] = None,
    no_log: Annotated[bool, typer.Option("--no-log", help="do not write a flight log")] = False,
    users: Annotated[
        Path | None,
        typer.Option(
            help="users file (`skyring users add`): sign-in required; needed beyond loopback "
            "[env: SKYRING_USERS_FILE, or SKYRING_USERS with the lines]",
            dir_okay=False,
        ),
    ] = None,
    tls_cert: Annotated[Path | None, typer.Option(help="serve HTTPS: certificate chain (PEM)")] = None,
    tls_key: Annotated[Path | None, typer.Option(help="serve HTTPS: private key (PEM)")] = None,
    foxglove: Annotated[
        int | None,
        typer.Option(
            min=0,
            max=65535,
            help="also serve the log's channels live to Foxglove on 127.0.0.1:PORT (0: a free port)",
        ),
    ] = None,
    agents: Annotated[
        str,
        typer.Option(
            help="in-process: every agent in this process (default); zenoh: supervise `skyring agent` "
            "processes found on Zenoh (with --px4 URLs: a direct MAVLink link per vehicle for landing); "
            "spawn: the one-laptop rehearsal (world here, one agent process per MAV)"
        ),
    ] = "in-process",
    connect: Annotated[
        list[str] | None, typer.Option(help="Zenoh endpoint to connect to (repeatable)")
    ] = None,
    listen: Annotated[
        list[str] | None, typer.Option(help="Zenoh endpoint to listen on, e.g. tcp/0.0.0.0:7447 (repeatable)")
    ] = None,
    team: Annotated[str, typer.Option(help="team name: the Zenoh key prefix skyring/<team>/...")] = "skyring",
    zenoh_config: Annotated[
        Path | None,
        typer.Option(help="Zenoh JSON5 config (TLS/mTLS, access control)", exists=True, dir_okay=False),
    ] = None,
    multicast: Annotated[bool, typer.Option(help="find agents by multicast scouting")] = True,
) -> None:
    """Run the ground station over the embedded simulation: 3-D operator view, REST API and state stream."""
    log_path = log_path_option(log_path=log, no_log=no_log)
    try:
        settings = RunSettings(
            vehicles=vehicles, seed=seed, method=method, trees=trees, person=person.value, rate_hz=rate
        )
    except ParameterError as exc:
        raise typer.BadParameter(exc.reason, param_hint=OPTION_OF_FIELD.get(exc.field, exc.field)) from None
    secure = security_options(host=host, users=users, tls_cert=tls_cert, tls_key=tls_key)
    if agents not in ("in-process", "zenoh", "spawn"):
        raise typer.BadParameter(f"must be in-process, zenoh or spawn, got {agents!r}", param_hint="--agents")
    if agents != "in-process":
        from server.cli.agent import net_config
        from server.cli.serve_agents import run_agents
        from vehicles.px4.autopilot import sitl_urls

        if px4_sitl and px4:
            raise typer.BadParameter(
                "give either --px4 URL ... or --px4-sitl N, not both", param_hint="--px4"
            )
        if px4_sitl:
            px4 = sitl_urls(px4_sitl)

        run_agents(
            mode=agents,
            config=net_config(
                team=team, connect=connect, listen=listen, zenoh_config=zenoh_config, multicast=multicast
            ),
            vehicles=vehicles,
            px4=[u.strip() for item in px4 or [] for u in item.split(",") if u.strip()],
            origin=origin,
            seed=settings.seed,
            method=settings.method,
            trees=settings.trees,
            person=settings.person,
            host=host,
            port=port,
            viser_port=viser_port,
            log_path=log_path,
            foxglove_port=foxglove,
            **secure,
        )
        return
    if px4 or px4_sitl:
        run_px4(
            px4=px4 or [],
            sitl=px4_sitl,
            origin=origin,
            settings=settings,
            host=host,
            port=port,
            viser_port=viser_port,
            speed=speed,
            log_path=log_path,
            foxglove_port=foxglove,
            **secure,
        )
        return
    header = log_header(settings, command="serve", speed=speed)
    flight_log = None if log_path is None else open_log(log_path, header=header)
    fox, flight_log = start_foxglove(foxglove, flight_log=flight_log, header=header)
    try:
        station = build_station(settings)
    except BaseException:
        if flight_log is not None:
            flight_log.close()
        if fox is not None:
            fox.stop()
        raise
    logging.basicConfig(level=logging.WARNING, format="%(levelname)s %(name)s: %(message)s")
    try:
        run(
            station, host=host, port=port, viser_port=viser_port, speed=speed, flight_log=flight_log, **secure
        )
    finally:
        if fox is not None:
            fox.stop()


def run_px4(
    *,
    px4: Sequence[str],
    sitl: int,
    origin: str | None,
    settings: RunSettings,
    host: str,
    port: int,
    viser_port: int,
    speed: float,
    log_path: Path | None = None,
    foxglove_port: int | None = None,
    **serve_options,
) -> None:
    """`skyring serve --px4 URL ... | --px4-sitl N [--origin lat,lon,alt]`: validate, connect, serve until
    Ctrl-C / SIGTERM, land every MAV on the way out. `--px4` may be repeated or hold comma-separated URLs.
    settings: the person, trees, seed, method and rate (its vehicle count is that of the URLs); log_path: the
    flight log to write (None: none), opened before connecting."""
    import mavsdk

    from server.station.live import Urls
    from server.station.px4 import px4_urls, serve_px4
    from vehicles.px4.autopilot import Px4Error
    from vehicles.px4.geodesy import parse_geodetic

    try:
        urls = px4_urls(urls=[u.strip() for item in px4 for u in item.split(",") if u.strip()], sitl=sitl)
        reference = parse_geodetic(origin) if origin else None
    except ValueError as exc:
        raise typer.BadParameter(str(exc)) from None
    if speed != 1.0:
        raise typer.BadParameter("PX4 vehicles fly in real time: leave --speed at 1", param_hint="--speed")
    logging.basicConfig(level=logging.WARNING, format="%(levelname)s %(name)s: %(message)s")
    mavsdk.log_subscribe(lambda *args: True)  # MAVSDK's own chatter; skyring logs what matters

    def ready(urls_: Urls, _ui: object) -> None:
        typer.echo(f"PX4 vehicles:   {', '.join(urls)}")
        typer.echo(f"operator view:  {urls_.api}  (3-D page alone: {urls_.operator})")
        typer.echo(f"API and docs:   {urls_.api}docs")
        typer.echo(log_line(flight_log))
        typer.echo("Ctrl-C to stop (every MAV is told to land).")

    header = log_header(settings, command="serve --px4", speed=1.0, vehicle_urls=urls)
    flight_log = None if log_path is None else open_log(log_path, header=header)
    fox, flight_log = start_foxglove(foxglove_port, flight_log=flight_log, header=header)
    from controller.warmup import warm_up

    # the compiled kernels, before the first tick (compiles once on a fresh install)
    warm_up(ControllerParams(method=settings.method))
    typer.echo(f"connecting to {len(urls)} PX4 vehicle(s) ...")
    try:
        stats = asyncio.run(
            serve_px4(
                urls,
                origin=reference,
                seed=settings.seed,
                method=settings.method,
                person=settings.person,
                trees=settings.trees,
                rate_hz=settings.rate_hz,
                host=host,
                port=port,
                viser_port=viser_port,
                on_ready=ready,
                flight_log=flight_log,
                **serve_options,
            )
        )
    except Px4Error as exc:
        typer.echo(f"error: {exc}", err=True)
        raise typer.Exit(code=1) from None
    finally:
        if flight_log is not None:
            flight_log.close()
        if fox is not None:
            fox.stop()
    typer.echo(f"stopped after {stats.ticks} control ticks")
    if flight_log is not None and flight_log.recording:
        typer.echo(describe_log(flight_log))

"""`skyring serve`: the ground station over the embedded simulation (default) in real time.

Prints the operator URL (viser) and the API URL as soon as both listen. The station is built by
`build_station`; other back-ends (PX4 through MAVSDK) build their autopilots and hand the same ground station
a mission over them, then call `run`. Unless `--no-log`, the run is recorded in a flight log
(`server.flightlog.log`; `skyring replay` plays it back), opened before anything flies so a log that cannot be
written is refused up front rather than missed after the flight.
"""

from __future__ import annotations

import asyncio
import logging
import math
import time
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from controller.params import Method

if TYPE_CHECKING:
    from server.flightlog.log import FlightLog
    from server.flightlog.records import LogHeader

log = logging.getLogger(__name__)


def log_path_option(*, log_path: Path | None, no_log: bool) -> Path | None:
    """Where `--log PATH` / `--no-log` put the flight log (None: no log); default runs/flight-<UTC>.jsonl."""
    from server.flightlog.log import default_log_path

    if log_path is not None and no_log:
        raise typer.BadParameter("give either --log PATH or --no-log, not both", param_hint="--log")
    return None if no_log else (log_path or default_log_path())


def open_log(path: Path, *, header: LogHeader) -> FlightLog:
    """Create the flight log at `path` and write its header; a path that cannot be written is refused."""
    from server.flightlog.log import FlightLog

    try:
        return FlightLog.create(path, header=header)
    except OSError as exc:
        raise typer.BadParameter(
            f"cannot write the flight log {path}: {exc.strerror or exc} (choose another "
            "path with --log PATH, or --no-log)",
            param_hint="--log",
        ) from None


def describe_log(flight_log: FlightLog) -> str:
    """One line about a closed flight log: where, what it holds, and any records lost."""
    lost = f"; {flight_log.write_errors} records could not be written" if flight_log.write_errors else ""
    return (
        f"flight log:     {flight_log.name} ({flight_log.samples} samples, {flight_log.commands} "
        f"commands{lost}); replay with: skyring replay {flight_log.name}"
    )


def build_station(*, vehicles: int, seed: int, method: Method, trees: str, person: str, rate_hz: float):
    """A ground station over the embedded simulation: `vehicles` simulated MAVs, the paper's (or no, or N
    random) trees and the walking (random, still) person, ticking at rate_hz."""
    from server.station.ground_station import GroundStation, camera_view
    from vehicles.sim.scenario import Scenario, build_sim

    setup = build_sim(
        Scenario(vehicles=vehicles, seed=seed, method=method, trees=trees, person=person),
        clock=time.perf_counter,
    )
    return GroundStation(
        mission=setup.mission, control_period_s=1.0 / rate_hz, camera=camera_view(setup.world.camera)
    )


def run(
    station, *, host: str, port: int, viser_port: int, speed: float, flight_log: FlightLog | None = None
) -> None:
    """Serve `station` until Ctrl-C / SIGTERM; the MAVs are told to land on the way out. `flight_log`, when
    given, records the whole run and is closed here."""
    from server.station.live import Urls, serve_station

    def ready(urls: Urls, _ui: object) -> None:
        if urls.api_fell_back:
            typer.echo(f"port {port} is busy: the API uses {urls.api} instead")
        if urls.viser_fell_back:
            typer.echo(f"port {viser_port} is busy: the operator page uses {urls.operator} instead")
        typer.echo(f"operator view:  {urls.operator}")
        typer.echo(
            f"API and docs:   {urls.api}  ({urls.api}docs, state at {urls.api}api/state, stream at "
            f"{urls.api.replace('http', 'ws', 1)}ws)"
        )
        typer.echo(f"flight log:     {flight_log.name}" if flight_log is not None else "flight log:     off")
        typer.echo("Ctrl-C to stop (every MAV is told to land).")

    if flight_log is not None:
        station.attach_log(flight_log)
    try:
        stats = asyncio.run(
            serve_station(station, host=host, port=port, viser_port=viser_port, speed=speed, on_ready=ready)
        )
    finally:
        if flight_log is not None:
            flight_log.close()
    typer.echo(
        f"stopped after {stats.ticks} control ticks ({stats.achieved_speed:.2f}x real time"
        + (f", fell behind {stats.lagged} times" if stats.lagged else "")
        + ")"
    )
    if flight_log is not None:
        typer.echo(describe_log(flight_log))


def serve(
    host: Annotated[str, typer.Option(help="address to listen on (0.0.0.0: every interface)")] = "127.0.0.1",
    port: Annotated[int, typer.Option(help="API port; a free one is used if it is busy")] = 8000,
    viser_port: Annotated[
        int, typer.Option(help="operator page (viser) port; the next free one if busy")
    ] = 8080,
    vehicles: Annotated[int, typer.Option(help="number of simulated MAVs")] = 3,
    seed: Annotated[int, typer.Option(help="seed of the simulated world")] = 0,
    speed: Annotated[float, typer.Option(help="simulated seconds per wall second")] = 1.0,
    method: Annotated[Method, typer.Option(help="formation method")] = Method.ACTIVE,
    trees: Annotated[str, typer.Option(help="paper, none, or a number of random trees")] = "paper",
    person: Annotated[str, typer.Option(help="paper (scripted walk), random or still")] = "paper",
    rate: Annotated[float, typer.Option(help="control rate in Hz (the paper: 100)")] = 100.0,
    px4: Annotated[
        list[str] | None,
        typer.Option(
            help="fly PX4 vehicles: a MAVSDK URL per vehicle (repeat, or comma-separate), e.g. "
            "udpin://0.0.0.0:14540"
        ),
    ] = None,
    px4_sitl: Annotated[
        int, typer.Option(help="fly N local PX4 SITL instances (udpin://0.0.0.0:14540+i)")
    ] = 0,
    origin: Annotated[
        str | None,
        typer.Option(help="team frame origin 'lat,lon,alt' for PX4 vehicles (default: vehicle 1's home)"),
    ] = None,
    log: Annotated[
        Path | None,
        typer.Option(
            "--log",
            help="flight log to write (JSON Lines) [default: runs/flight-<UTC time>.jsonl]",
            dir_okay=False,
        ),
    ] = None,
    no_log: Annotated[bool, typer.Option("--no-log", help="do not write a flight log")] = False,
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
    if not 1 <= vehicles <= 16:
        raise typer.BadParameter(f"must be from 1 to 16, got {vehicles}", param_hint="--vehicles")
    if not (math.isfinite(speed) and 0.0 < speed <= 100.0):
        raise typer.BadParameter(f"must be in (0, 100], got {speed}", param_hint="--speed")
    if not (math.isfinite(rate) and 1.0 <= rate <= 1000.0):
        raise typer.BadParameter(f"must be from 1 to 1000 Hz, got {rate}", param_hint="--rate")
    if seed < 0:
        raise typer.BadParameter(f"must be >= 0, got {seed}", param_hint="--seed")
    for name, value in (("--port", port), ("--viser-port", viser_port)):
        if not 0 <= value <= 65535:
            raise typer.BadParameter(f"must be a TCP port (0-65535), got {value}", param_hint=name)
    log_path = log_path_option(log_path=log, no_log=no_log)
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
            seed=seed,
            method=method,
            trees=trees,
            person=person,
            host=host,
            port=port,
            viser_port=viser_port,
            log_path=log_path,
        )
        return
    if px4 or px4_sitl:
        run_px4(
            px4=px4 or [],
            sitl=px4_sitl,
            origin=origin,
            seed=seed,
            method=method,
            person=person,
            trees=trees,
            rate_hz=rate,
            host=host,
            port=port,
            viser_port=viser_port,
            speed=speed,
            log_path=log_path,
        )
        return
    from vehicles.sim.scenario import PERSON_MODES
    from vehicles.sim.trees import TreeSpec

    try:
        TreeSpec.parse(trees)
    except ValueError as exc:
        raise typer.BadParameter(str(exc), param_hint="--trees") from None
    if person not in PERSON_MODES:
        raise typer.BadParameter(
            f"must be one of {', '.join(PERSON_MODES)}, got {person!r}", param_hint="--person"
        )
    flight_log = None
    if log_path is not None:
        from server.flightlog.log import DEFAULT_SAMPLE_RATE_HZ, utc_now_iso
        from server.flightlog.records import LogHeader

        flight_log = open_log(
            log_path,
            header=LogHeader(
                command="serve",
                vehicles=vehicles,
                seed=seed,
                method=method.value,
                trees=trees,
                person=person,
                rate_hz=rate,
                speed=speed,
                sample_rate_hz=DEFAULT_SAMPLE_RATE_HZ,
                started_utc=utc_now_iso(),
            ),
        )
    try:
        station = build_station(
            vehicles=vehicles, seed=seed, method=method, trees=trees, person=person, rate_hz=rate
        )
    except BaseException:
        if flight_log is not None:
            flight_log.close()
        raise
    logging.basicConfig(level=logging.WARNING, format="%(levelname)s %(name)s: %(message)s")
    run(station, host=host, port=port, viser_port=viser_port, speed=speed, flight_log=flight_log)


def run_px4(
    *,
    px4: Sequence[str],
    sitl: int,
    origin: str | None,
    seed: int,
    method: Method,
    person: str,
    trees: str,
    rate_hz: float,
    host: str,
    port: int,
    viser_port: int,
    speed: float,
    log_path: Path | None = None,
) -> None:
    """`skyring serve --px4 URL ... | --px4-sitl N [--origin lat,lon,alt]`: validate, connect, serve until
    Ctrl-C / SIGTERM, land every MAV on the way out. `--px4` may be repeated or hold comma-separated URLs.
    log_path: the flight log to write (None: none), opened before connecting."""
    import mavsdk

    from server.flightlog.log import DEFAULT_SAMPLE_RATE_HZ, utc_now_iso
    from server.flightlog.records import LogHeader
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
        typer.echo(f"operator view:  {urls_.operator}")
        typer.echo(f"API and docs:   {urls_.api}  ({urls_.api}docs)")
        typer.echo(f"flight log:     {flight_log.name}" if flight_log is not None else "flight log:     off")
        typer.echo("Ctrl-C to stop (every MAV is told to land).")

    flight_log = (
        None
        if log_path is None
        else open_log(
            log_path,
            header=LogHeader(
                command="serve --px4",
                vehicles=len(urls),
                seed=seed,
                method=Method(method).value,
                trees=trees,
                person=person,
                rate_hz=rate_hz,
                speed=1.0,
                sample_rate_hz=DEFAULT_SAMPLE_RATE_HZ,
                started_utc=utc_now_iso(),
                vehicle_urls=tuple(urls),
            ),
        )
    )
    typer.echo(f"connecting to {len(urls)} PX4 vehicle(s) ...")
    try:
        stats = asyncio.run(
            serve_px4(
                urls,
                origin=reference,
                seed=seed,
                method=method,
                person=person,
                trees=trees,
                rate_hz=rate_hz,
                host=host,
                port=port,
                viser_port=viser_port,
                on_ready=ready,
                flight_log=flight_log,
            )
        )
    except Px4Error as exc:
        typer.echo(f"error: {exc}", err=True)
        raise typer.Exit(code=1) from None
    finally:
        if flight_log is not None:
            flight_log.close()
    typer.echo(f"stopped after {stats.ticks} control ticks")
    if flight_log is not None:
        typer.echo(describe_log(flight_log))

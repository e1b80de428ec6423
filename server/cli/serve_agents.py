"""`skyring serve --agents zenoh|spawn`: validate, build the supervising station, serve it until Ctrl-C.

The station lands every vehicle on the way out (a land command to every agent, and through the direct
MAVLink links when it has them), waits briefly for the acknowledgements, then closes.
"""

from __future__ import annotations

import asyncio
import logging
from pathlib import Path

import typer

from controller.params import Method
from server.cli.log_options import describe_log, log_line, open_log, start_foxglove
from vehicles.autopilot import Autopilot

log = logging.getLogger(__name__)


def run_agents(
    *,
    mode: str,
    config,
    vehicles: int,
    px4: list[str],
    origin: str | None,
    seed: int,
    method: Method,
    trees: str,
    person: str,
    host: str,
    port: int,
    viser_port: int,
    log_path: Path | None,
    foxglove_port: int | None = None,
    **serve_options,
) -> None:
    """Serve the station over agents on Zenoh (`mode` "zenoh") or the rehearsal (`mode` "spawn").
    foxglove_port: also publish the log's channels to Foxglove on 127.0.0.1; serve_options go to
    `serve_station` (gate, TLS)."""
    from server.flightlog.log import DEFAULT_SAMPLE_RATE_HZ, utc_now_iso
    from server.flightlog.records import LogHeader
    from server.station.agents_mode import STATION_RATE_HZ
    from vehicles.sim.scenario import PERSON_MODES

    if mode == "spawn" and px4:
        raise typer.BadParameter("--agents spawn flies simulated vehicles: drop --px4", param_hint="--px4")
    if person not in PERSON_MODES:
        raise typer.BadParameter(f"must be one of {', '.join(PERSON_MODES)}", param_hint="--person")
    if px4:
        vehicles = len(px4)
    logging.basicConfig(level=logging.WARNING, format="%(levelname)s %(name)s: %(message)s")
    header = LogHeader(
        command=f"serve --agents {mode}",
        vehicles=vehicles,
        seed=seed,
        method=Method(method).value,
        trees=trees,
        person=person,
        rate_hz=STATION_RATE_HZ,
        speed=1.0,
        sample_rate_hz=DEFAULT_SAMPLE_RATE_HZ,
        started_utc=utc_now_iso(),
        vehicle_urls=tuple(px4),
    )
    flight_log = None if log_path is None else open_log(log_path, header=header)
    fox, flight_log = start_foxglove(foxglove_port, flight_log=flight_log, header=header)
    try:
        asyncio.run(
            serve_agents(
                mode=mode,
                config=config,
                vehicles=vehicles,
                px4=px4,
                origin=origin,
                seed=seed,
                method=method,
                trees=trees,
                person=person,
                host=host,
                port=port,
                viser_port=viser_port,
                flight_log=flight_log,
                **serve_options,
            )
        )
    finally:
        if flight_log is not None:
            flight_log.close()
            if flight_log.recording:
                typer.echo(describe_log(flight_log))
        if fox is not None:
            fox.stop()


async def serve_agents(
    *,
    mode: str,
    config,
    vehicles: int,
    px4: list[str],
    origin: str | None,
    seed: int,
    method: Method,
    trees: str,
    person: str,
    host: str,
    port: int,
    viser_port: int,
    flight_log=None,
    stop: asyncio.Event | None = None,
    **serve_options,
) -> None:
    from server.station.agents_mode import build_spawn_station, build_zenoh_station
    from server.station.live import Urls, serve_station

    fleet_px4 = None
    override: dict[int, Autopilot] | None = None
    if px4:
        import mavsdk

        from vehicles.px4.autopilot import Px4Config, Px4Error, Px4Fleet
        from vehicles.px4.geodesy import parse_geodetic

        mavsdk.log_subscribe(lambda *args: True)
        typer.echo(f"opening the direct MAVLink link to {len(px4)} vehicle(s) (landing override) ...")
        try:
            fleet_px4 = await Px4Fleet.open(
                px4,
                origin=parse_geodetic(origin) if origin else None,
                config=Px4Config(require_armable=False),
            )
        except (Px4Error, ValueError) as exc:
            typer.echo(f"error: {exc}", err=True)
            raise typer.Exit(code=1) from None
        override = {a.vehicle_id: a for a in fleet_px4.autopilots}
    if mode == "spawn":
        agents = build_spawn_station(vehicles=vehicles, seed=seed, method=method, trees=trees, person=person)
    else:
        agents = build_zenoh_station(
            config=config,
            vehicles=vehicles,
            method=method,
            trees=trees,
            person=person,
            seed=seed,
            override=override,
        )
    if flight_log is not None:
        agents.station.attach_log(flight_log)

    def ready(urls: Urls, ui: object) -> None:
        from server.station.camera_reports import show_camera_reports

        show_camera_reports(agents.bus, ui.server)  # type: ignore[attr-defined] - a webui.app.OperatorUi
        where = "spawned on 127.0.0.1" if mode == "spawn" else f"team {config.team} on Zenoh"
        typer.echo(f"agents:         {vehicles} ({where})")
        typer.echo(f"operator view:  {urls.api}  (3-D page alone: {urls.operator})")
        typer.echo(f"API and docs:   {urls.api}docs")
        gate = serve_options.get("gate")
        typer.echo(
            "sign-in:        required (users file)"
            if gate is not None and not gate.open
            else "sign-in:        off (loopback only: anyone on this machine is the operator)"
        )
        typer.echo(log_line(flight_log))
        typer.echo("Ctrl-C to stop (every MAV is told to land).")

    try:
        await serve_station(
            agents.station,
            host=host,
            port=port,
            viser_port=viser_port,
            on_ready=ready,
            stop=stop,
            **serve_options,
        )
    finally:
        agents.close()
        if fleet_px4 is not None:
            await fleet_px4.settle(timeout_s=5.0)
            await fleet_px4.close()

"""The flight log on the command line: where `--log` / `--no-log` put it, opening it up front (a path that
cannot be written is refused before anything flies), its header, `--foxglove` (its channels live), and the
lines printed about it. Shared by every `skyring serve` mode.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import typer

from server.settings import RunSettings

if TYPE_CHECKING:
    from server.flightlog.log import FlightLog
    from server.flightlog.records import LogHeader


def log_path_option(*, log_path: Path | None, no_log: bool) -> Path | None:
    """Where `--log PATH` / `--no-log` put the flight log (None: no log); default runs/flight-<UTC>.mcap."""
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


def log_line(flight_log: FlightLog | None) -> str:
    """The printed line saying where the run is recorded."""
    if flight_log is None or not flight_log.recording:
        return "flight log:     off"
    return f"flight log:     {flight_log.name}"


def describe_log(flight_log: FlightLog) -> str:
    """One line about a closed flight log: where, what it holds, and any records lost."""
    lost = f"; {flight_log.write_errors} records could not be written" if flight_log.write_errors else ""
    return (
        f"flight log:     {flight_log.name} ({flight_log.samples} samples, {flight_log.audit_records} "
        f"audit records{lost}); replay with: skyring replay {flight_log.name}"
    )


def start_foxglove(port: int | None, *, flight_log: FlightLog | None, header: LogHeader):
    """`--foxglove PORT`: the flight log's channels live over Foxglove's WebSocket protocol on 127.0.0.1
    (its server has no sign-in, so it never listens beyond loopback). Returns (server, log to publish to)."""
    if port is None:
        return None, flight_log
    import foxglove

    from server.flightlog.log import FlightLog

    published = flight_log if flight_log is not None else FlightLog(header=header, name="foxglove")
    server = foxglove.start_server(name="skyring", host="127.0.0.1", port=port, context=published.context)
    typer.echo(f"foxglove:       ws://127.0.0.1:{server.port} (Foxglove WebSocket protocol, loopback only)")
    return server, published


def log_header(
    settings: RunSettings, *, command: str, speed: float, vehicle_urls: Sequence[str] = ()
) -> LogHeader:
    """The flight log's header: what this run flies."""
    from server.flightlog.log import DEFAULT_SAMPLE_RATE_HZ, utc_now_iso
    from server.flightlog.records import LogHeader

    return LogHeader(
        command=command,
        vehicles=len(vehicle_urls) or settings.vehicles,
        seed=settings.seed,
        method=settings.method.value,
        trees=settings.trees,
        person=settings.person,
        rate_hz=settings.rate_hz,
        speed=speed,
        sample_rate_hz=DEFAULT_SAMPLE_RATE_HZ,
        started_utc=utc_now_iso(),
        vehicle_urls=tuple(vehicle_urls),
    )

"""`skyring replay LOG`: a recorded flight (MCAP), summarised (`--summary`), its audit trail printed
(`--audit`), or played back in the operator's view.

The log records the `SceneView` the live station drew, so the playback hands each one to the same
`webui.app.OperatorUi` and a replay looks like the live page; its controls are there but every command is
refused (a replay flies nothing). Operator commands are printed as the playback passes them.
"""

from __future__ import annotations

import itertools
import math
import signal
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, NoReturn

import typer

from server.flightlog.reader import FlightLogError, FlightRecord, read_flight_log
from server.flightlog.records import AuditRecord
from webui.view import SceneView

if TYPE_CHECKING:
    from webui.app import OperatorUi


# ---- summary ----------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Closest:
    """The smallest distance seen between two airborne MAVs: distance_m between vehicle_ids at time_s."""

    distance_m: float
    vehicle_ids: tuple[int, int]
    time_s: float


@dataclass(frozen=True)
class Summary:
    """What a flight log holds: duration_s from the first to the last sample, the vehicle ids seen, commands
    accepted and refused, the closest approach of two airborne MAVs (None with fewer than two in the air),
    whether the file was cut short, messages that did not decode, and whether the run ended cleanly."""

    duration_s: float
    samples: int
    vehicle_ids: tuple[int, ...]
    accepted: int
    refused: int
    closest: Closest | None
    truncated: bool
    bad_messages: int
    clean_end: bool


def closest_approach(samples: Sequence[SceneView]) -> Closest | None:
    """The minimum distance between two MAVs that were both in the air, over every sample."""
    best: Closest | None = None
    for sample in samples:
        airborne = [v for v in sample.vehicles if v.in_air and all(math.isfinite(x) for x in v.position_m)]
        for a, b in itertools.combinations(airborne, 2):
            d = math.dist(a.position_m, b.position_m)
            if best is None or d < best.distance_m:
                best = Closest(distance_m=d, vehicle_ids=(a.vehicle_id, b.vehicle_id), time_s=sample.time_s)
    return best


def summarize(record: FlightRecord) -> Summary:
    samples = record.samples
    ids = sorted({v.vehicle_id for s in samples for v in s.vehicles})
    return Summary(
        duration_s=samples[-1].time_s - samples[0].time_s if samples else 0.0,
        samples=len(samples),
        vehicle_ids=tuple(ids),
        accepted=sum(c.accepted for c in record.audit),
        refused=sum(not c.accepted for c in record.audit),
        closest=closest_approach(samples),
        truncated=record.truncated,
        bad_messages=record.bad_messages,
        clean_end=record.end is not None,
    )


def summary_table(record: FlightRecord) -> str:
    """The `--summary` table: one fact per line."""
    h, s = record.header, summarize(record)
    c = s.closest
    closest = (
        "n/a (fewer than two MAVs in the air)"
        if c is None
        else f"{c.distance_m:.2f} m between airborne MAVs (MAV {c.vehicle_ids[0]} and {c.vehicle_ids[1]} "
        f"at {c.time_s:.1f} s)"
    )
    rows = [
        ("flight log", str(record.path)),
        (
            "recorded",
            f"{h.started_utc}: skyring {h.command}, {h.vehicles} MAVs, seed {h.seed}, {h.method}, "
            f"trees {h.trees}, person {h.person}, {h.rate_hz:g} Hz",
        ),
        ("duration", f"{s.duration_s:.1f} s ({s.samples} samples at {h.sample_rate_hz:g} Hz)"),
        ("vehicles", f"{len(s.vehicle_ids)} ({', '.join(map(str, s.vehicle_ids)) or 'none sampled'})"),
        ("commands", f"{s.accepted} accepted, {s.refused} refused"),
        ("min separation", closest),
        ("cut short", "yes (read up to the cut)" if s.truncated else "no"),
        ("bad messages", str(s.bad_messages)),
        (
            "ended",
            "cleanly" if s.clean_end else "without an end record (the ground station crashed or was killed)",
        ),
    ]
    return "\n".join(f"{name:<16} {value}" for name, value in rows)


def command_line(record: AuditRecord) -> str:
    """One audit record as printed by --audit and during a replay: time, command, who, from where, outcome."""
    args = ", ".join(f"{k}={v}" for k, v in record.arguments.items())
    who = f"{record.operator or '(not signed in)'} [{record.role or '-'}] via {record.surface}"
    where = f" from {record.remote}" if record.remote else ""
    outcome = "accepted" if record.accepted else f"REFUSED: {record.message}"
    head = f"{record.time_s:8.1f} s  {record.utc}  {record.command_id:<12} {who}{where}"
    return f"{head}  {record.command}({args}): {outcome}"


def audit_table(record: FlightRecord) -> str:
    """The `--audit` listing: every command, accepted or refused, in order."""
    lines = [command_line(r) for r in record.audit]
    return "\n".join(lines) if lines else "no operator commands recorded"


# ---- playback ---------------------------------------------------------------------------------------------


class ReplayActions:
    """The operator controls of a replay: each one says that a replay flies nothing (the UI shows it)."""

    def __init__(self, path: Path) -> None:
        self._path = path

    def _refuse(self, *_args: object, **_kwargs: object) -> NoReturn:
        raise ValueError(f"this is a replay of {self._path}: commands do not reach any vehicle")

    set_formation = add_obstacle = remove_obstacle = _refuse
    land = land_all = release = set_formation_enabled = hold = _refuse
    acknowledge_alert = acknowledge_all_alerts = _refuse


def play(
    record: FlightRecord,
    *,
    publish: Callable[[SceneView], None],
    speed: float,
    stop: threading.Event,
    on_command: Callable[[AuditRecord], None] | None = None,
    clock: Callable[[], float] = time.monotonic,
) -> int:
    """Publish the samples at `speed` times the mission-time spacing they were recorded at, and pass each
    command to on_command when the playback reaches its time. Returns the samples published (fewer when
    `stop` is set first)."""
    samples = record.samples
    if not samples:
        return 0
    commands = iter(record.audit)
    pending = next(commands, None)
    t0, wall0 = samples[0].time_s, clock()
    for published, sample in enumerate(samples):
        due = wall0 + (sample.time_s - t0) / speed
        if stop.wait(max(0.0, due - clock())):
            return published
        while pending is not None and not pending.time_s > sample.time_s:
            if on_command is not None:
                on_command(pending)
            pending = next(commands, None)
        publish(sample)
    while pending is not None:  # commands after the last sample (the shutdown, typically)
        if on_command is not None:
            on_command(pending)
        pending = next(commands, None)
    return len(samples)


def serve_replay(
    record: FlightRecord,
    *,
    host: str = "127.0.0.1",
    viser_port: int = 8080,
    speed: float = 1.0,
    stop: threading.Event,
    on_ready: Callable[[str, OperatorUi], None] | None = None,
    on_command: Callable[[AuditRecord], None] | None = None,
    on_end: Callable[[], None] | None = None,
) -> int:
    """Serve the operator page and play `record` on it, then hold the last frame until `stop` is set.
    on_ready(url, ui) runs once the page listens. Returns the samples published."""
    from webui.app import OperatorUi  # viser loads only for a playback

    ui = OperatorUi(actions=ReplayActions(record.path), initial=record.samples[0], host=host, port=viser_port)
    try:
        if on_ready is not None:
            on_ready(f"http://{host}:{ui.port}/", ui)
        published = play(record, publish=ui.publish, speed=speed, stop=stop, on_command=on_command)
        if on_end is not None and not stop.is_set():
            on_end()
        while not stop.wait(0.5):  # short waits: a signal handler setting `stop` is seen promptly
            pass
        return published
    finally:
        ui.stop()


# ---- the command ------------------------------------------------------------------------------------------


def replay(
    path: Annotated[Path, typer.Argument(help="flight log written by skyring serve (runs/flight-*.mcap)")],
    summary: Annotated[bool, typer.Option("--summary", help="print a short table and exit")] = False,
    audit: Annotated[
        bool, typer.Option("--audit", help="print every operator command (who, where, outcome) and exit")
    ] = False,
    speed: Annotated[float, typer.Option(help="recorded seconds per wall second")] = 1.0,
    viser_port: Annotated[
        int, typer.Option(help="operator page (viser) port; the next free one if busy")
    ] = 8080,
) -> None:
    """Summarise a flight log, or play it back in the operator's 3-D view on 127.0.0.1 until Ctrl-C."""
    if not (math.isfinite(speed) and 0.0 < speed <= 1000.0):
        raise typer.BadParameter(f"must be in (0, 1000], got {speed}", param_hint="--speed")
    if not 0 <= viser_port <= 65535:
        raise typer.BadParameter(f"must be a TCP port (0-65535), got {viser_port}", param_hint="--viser-port")
    try:
        record = read_flight_log(path)
    except FlightLogError as exc:
        typer.echo(f"error: {exc}", err=True)
        raise typer.Exit(code=1) from None
    if summary or audit:
        if summary:
            typer.echo(summary_table(record))
        if audit:
            typer.echo(audit_table(record))
        return
    if not record.samples:
        typer.echo(f"error: {path}: the flight log has no state samples to replay", err=True)
        raise typer.Exit(code=1)

    def ready(url: str, _ui: object) -> None:
        s = summarize(record)
        typer.echo(f"replaying {path}: {s.duration_s:.1f} s, {len(s.vehicle_ids)} MAVs, at {speed:g}x")
        typer.echo(f"operator view:  {url}")
        typer.echo("Ctrl-C to stop.")

    stop = threading.Event()
    # our own handlers: Python leaves SIGINT ignored when started in the background, and SIGTERM should stop
    # the page cleanly too
    previous = {sig: signal.signal(sig, lambda *_: stop.set()) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        published = serve_replay(
            record,
            viser_port=viser_port,
            speed=speed,
            stop=stop,
            on_ready=ready,
            on_command=lambda c: typer.echo(command_line(c)),
            on_end=lambda: typer.echo("end of the flight log; Ctrl-C to stop."),
        )
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
    typer.echo(f"stopped after {published} of {len(record.samples)} samples")

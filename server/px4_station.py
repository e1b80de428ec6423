"""`skyring serve --px4`: the ground station flying PX4 vehicles (SITL or real) through MAVSDK.

The same `GroundStation`, `Mission` and agents as the embedded simulation; only the autopilots differ. The
person and the camera/detector stay the embedded model, driven by the vehicles' telemetry poses and attitudes
(`TelemetryBody`), so the detections come from where the real vehicles are and how they are tilted. Mission
time runs from 0 at real time; telemetry is stamped on it so link ages in the operator's view are right,
while each vehicle's set-point watchdog runs on the wall clock in its back-end and so fires even when the
control loop stalls.
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

from controller.params import ControllerParams, Method
from server.flight_log import DEFAULT_SAMPLE_RATE_HZ, FlightLog, utc_now_iso
from server.ground_station import GroundStation
from server.live import PaceStats, Urls, serve_station
from server.log_records import LogHeader
from vehicles.geodesy import GeodeticPoint, parse_geodetic
from vehicles.links import SimLinks
from vehicles.mission import Mission
from vehicles.person import PERSON_MODES, PathPerson, PersonModel, RandomPerson, StillPerson, paper_path
from vehicles.px4 import Px4Config, Px4Error, Px4Fleet, sitl_urls
from vehicles.trees import TreeSpec, paper_trees, random_trees
from vehicles.world import SimWorld, TelemetryBody

log = logging.getLogger(__name__)

URL_SCHEMES = ("udpin://", "udpout://", "udp://", "tcpin://", "tcpout://", "tcp://", "serial://")


def px4_urls(*, urls: Sequence[str] = (), sitl: int = 0) -> list[str]:
    """The vehicle URLs from `--px4 URL ...` or `--px4-sitl N` (exactly one of them); ValueError says why."""
    if urls and sitl:
        raise ValueError("give either --px4 URL ... or --px4-sitl N, not both")
    if sitl:
        if not 1 <= sitl <= 10:
            raise ValueError(f"--px4-sitl takes 1 to 10 local SITL instances (ports 14540-14549), got {sitl}")
        return sitl_urls(sitl)
    if not urls:
        raise ValueError("no PX4 vehicle given: use --px4 URL ... or --px4-sitl N")
    for url in urls:
        if not url.startswith(URL_SCHEMES):
            raise ValueError(f"{url!r} is not a MAVSDK connection URL; expected e.g. udpin://0.0.0.0:14540, "
                             "tcpout://192.168.1.10:5760 or serial:///dev/ttyUSB0:57600")
    if len(set(urls)) != len(urls):
        raise ValueError(f"each vehicle needs its own URL, got {list(urls)}")
    return list(urls)


def _person(mode: str, rng: np.random.Generator) -> PersonModel:
    if mode not in PERSON_MODES:
        raise ValueError(f"person must be one of {', '.join(PERSON_MODES)}, got {mode!r}")
    if mode == "paper":
        return PathPerson(path_xy_m=paper_path())
    if mode == "random":
        return RandomPerson(rng)
    return StillPerson()


def build_px4_station(fleet: Px4Fleet, *, seed: int = 0, method: Method = Method.ACTIVE,
                      person: str = "paper", trees: str = "none", rate_hz: float = 20.0) -> GroundStation:
    """A ground station over connected PX4 vehicles; the embedded person and detector see them through their
    telemetry. The seed fixes the person's walk (random mode), the random trees and the detector noise.

    Mission time starts at 0 (the person's script runs from there) and the live runner paces it at real time;
    the vehicles' telemetry is stamped on it (its age carried over from the wall clock), so link ages are
    right even when the runner falls behind."""
    root = np.random.SeedSequence(seed)
    person_ss, trees_ss, links_ss, detectors_ss = root.spawn(4)
    model = _person(person, np.random.default_rng(person_ss))
    spec = TreeSpec.parse(trees)
    ids = [a.vehicle_id for a in fleet.autopilots]
    if spec.kind == "paper":
        obstacles = paper_trees()
    elif spec.kind == "random":
        starts = [(s.position_m[:2], 3.0) for a in fleet.autopilots if (s := a.state()) is not None]
        person_xy = np.asarray(model.truth(0.0).position_m[:2])
        obstacles = random_trees(np.random.default_rng(trees_ss), count=spec.count,
                                 keep_clear=[(person_xy, 3.0), *starts])
    else:
        obstacles = ()
    rngs = {vid: np.random.default_rng(ss) for vid, ss in zip(ids, detectors_ss.spawn(len(ids)), strict=True)}
    world = SimWorld(person=model, obstacles=obstacles, bodies=[TelemetryBody(a) for a in fleet.autopilots],
                     rngs=rngs)
    links = SimLinks(vehicle_ids=ids, rng=np.random.default_rng(links_ss))
    mission = Mission(autopilots=fleet.autopilots, world=world, links=links,
                      controller_params=ControllerParams(method=method), clock=time.perf_counter)
    station = GroundStation(mission=mission, control_period_s=1.0 / rate_hz)
    for a in fleet.autopilots:
        a.use_stamp_clock(lambda: station.time_s)
    return station


async def serve_px4(urls: Sequence[str], *, origin: GeodeticPoint | None = None,
                    config: Px4Config | None = None, seed: int = 0, method: Method = Method.ACTIVE,
                    person: str = "paper", trees: str = "none",
                    rate_hz: float = 20.0, host: str = "127.0.0.1", port: int = 8000, viser_port: int = 8080,
                    stop: asyncio.Event | None = None, on_ready: Callable[[Urls, object], None] | None = None,
                    on_station: Callable[[GroundStation, Px4Fleet], None] | None = None,
                    handle_signals: bool = True, flight_log: FlightLog | None = None) -> PaceStats:
    """Connect to every vehicle, serve the ground station until stopped, then land them and disconnect.

    on_station(station, fleet) is called once both exist (tests and tools use it). The landing asked for at
    shutdown is given time to reach PX4 before MAVSDK closes; from then on PX4's own failsafes
    (COM_OBL_RC_ACT, NAV_DLL_ACT) cover any vehicle still in the air. flight_log (closed by its owner)
    records the run from the moment the station exists.
    """
    fleet = await Px4Fleet.open(urls, origin=origin, config=config or Px4Config())
    try:
        station = build_px4_station(fleet, seed=seed, method=method, person=person, trees=trees,
                                    rate_hz=rate_hz)
        if flight_log is not None:
            station.attach_log(flight_log)
        if on_station is not None:
            on_station(station, fleet)
        return await serve_station(station, host=host, port=port, viser_port=viser_port, speed=1.0, stop=stop,
                                   on_ready=on_ready, handle_signals=handle_signals)
    finally:
        settled = await fleet.settle(timeout_s=5.0)
        for a, ok in zip(fleet.autopilots, settled, strict=True):
            if not ok:
                log.warning("vehicle %d: the landing command may not have reached PX4 (%s)", a.vehicle_id,
                            a.status().fault)
        await fleet.close()


def run_px4(*, px4: Sequence[str], sitl: int, origin: str | None, seed: int, method: Method, person: str,
            trees: str, rate_hz: float, host: str, port: int, viser_port: int, speed: float,
            log_path: Path | None = None) -> None:
    """`skyring serve --px4 URL ... | --px4-sitl N [--origin lat,lon,alt]`: validate, connect, serve until
    Ctrl-C / SIGTERM, land every MAV on the way out. `--px4` may be repeated or hold comma-separated URLs.
    log_path: the flight log to write (None: none), opened before connecting."""
    import typer

    from server.serve_command import describe_log, open_log

    try:
        urls = px4_urls(urls=[u.strip() for item in px4 for u in item.split(",") if u.strip()], sitl=sitl)
        reference = parse_geodetic(origin) if origin else None
    except ValueError as exc:
        raise typer.BadParameter(str(exc)) from None
    if speed != 1.0:
        raise typer.BadParameter("PX4 vehicles fly in real time: leave --speed at 1", param_hint="--speed")
    logging.basicConfig(level=logging.WARNING, format="%(levelname)s %(name)s: %(message)s")
    import mavsdk

    mavsdk.log_subscribe(lambda *args: True)  # MAVSDK's own chatter; skyring logs what matters

    def ready(urls_: Urls, _ui: object) -> None:
        typer.echo(f"PX4 vehicles:   {', '.join(urls)}")
        typer.echo(f"operator view:  {urls_.operator}")
        typer.echo(f"API and docs:   {urls_.api}  ({urls_.api}docs)")
        typer.echo(f"flight log:     {flight_log.name}" if flight_log is not None else "flight log:     off")
        typer.echo("Ctrl-C to stop (every MAV is told to land).")

    flight_log = None if log_path is None else open_log(log_path, header=LogHeader(
        command="serve --px4", vehicles=len(urls), seed=seed, method=Method(method).value, trees=trees,
        person=person, rate_hz=rate_hz, speed=1.0, sample_rate_hz=DEFAULT_SAMPLE_RATE_HZ,
        started_utc=utc_now_iso(), vehicle_urls=tuple(urls)))
    typer.echo(f"connecting to {len(urls)} PX4 vehicle(s) ...")
    try:
        stats = asyncio.run(serve_px4(urls, origin=reference, seed=seed, method=method, person=person,
                                      trees=trees, rate_hz=rate_hz, host=host, port=port,
                                      viser_port=viser_port, on_ready=ready, flight_log=flight_log))
    except Px4Error as exc:
        typer.echo(f"error: {exc}", err=True)
        raise typer.Exit(code=1) from None
    finally:
        if flight_log is not None:
            flight_log.close()
    typer.echo(f"stopped after {stats.ticks} control ticks")
    if flight_log is not None:
        typer.echo(describe_log(flight_log))

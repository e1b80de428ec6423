"""`skyring serve --px4`: the ground station flying PX4 vehicles (SITL or real) through MAVSDK.

The same `GroundStation`, `Mission` and agents as the embedded simulation; only the autopilots differ. The
person and the camera/detector stay the embedded model, driven by the vehicles' telemetry poses and attitudes
(`TelemetryBody`), so the detections come from where the real vehicles are and how they are tilted. Mission
time runs from 0 at real time; telemetry is stamped on it so link ages in the operator's view are right,
while each vehicle's set-point watchdog runs on the wall clock in its back-end and so fires even when the
control loop stalls.

The vehicles are taken as they are found: a fresh team on the ground takes off at once (formation running),
as before; but when a vehicle is already flying (an earlier ground station left it, or PX4 runs a failsafe),
or one stands where it may not take off (inside the person's keep-out, within d_min of a teammate), the
formation starts stopped, nothing is commanded, and the operator starts it (`start_hold_reasons`).
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections.abc import Callable, Sequence

import numpy as np

from controller.params import ControllerParams, FormationParams, Method
from server.flightlog.log import FlightLog
from server.station.commands import clearance_problems, limits_from_params
from server.station.ground_station import GroundStation
from server.station.live import PaceStats, Urls, serve_station
from vehicles.links import SimLinks
from vehicles.mission import Mission
from vehicles.px4.autopilot import Px4Config, Px4Fleet, sitl_urls
from vehicles.px4.geodesy import GeodeticPoint
from vehicles.sim.scenario import SeedStreams, make_person, make_trees
from vehicles.sim.trees import TreeSpec
from vehicles.sim.world import SimWorld, TelemetryBody
from webui.view import GeodeticOrigin

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
            raise ValueError(
                f"{url!r} is not a MAVSDK connection URL; expected e.g. udpin://0.0.0.0:14540, "
                "tcpout://192.168.1.10:5760 or serial:///dev/ttyUSB0:57600"
            )
    if len(set(urls)) != len(urls):
        raise ValueError(f"each vehicle needs its own URL, got {list(urls)}")
    return list(urls)


def start_hold_reasons(
    fleet: Px4Fleet, *, person_xyz_m: np.ndarray | None, controller_params: ControllerParams
) -> list[str]:
    """Why the formation must start stopped over these vehicles (empty: it may start at once): a vehicle
    already armed or flying (adopted as it is), or one the pre-take-off checks refuse where it stands."""
    reasons = []
    positions = {}
    for a in fleet.autopilots:
        s = a.state()
        if s is None:
            reasons.append(f"MAV {a.vehicle_id} has no position yet")
            continue
        positions[a.vehicle_id] = s.position_m
        if s.in_air or s.armed:
            fs = f", PX4 failsafe: {s.failsafe_reason}" if s.failsafe else ""
            where = "flying" if s.in_air else "armed on the ground"
            reasons.append(f"MAV {a.vehicle_id} is {where} in {s.autopilot_mode or s.mode.value}{fs}")
    problems = clearance_problems(
        vehicle_ids=sorted(positions),
        vehicles_m=positions,
        persons_m=[] if person_xyz_m is None else [person_xyz_m],
        limits=limits_from_params(controller_params),
        d_des_m=FormationParams().d_des_m,
    )
    reasons += [f"MAV {vid} {why}" for vid, why in sorted(problems.items())]
    return reasons


def build_px4_station(
    fleet: Px4Fleet,
    *,
    seed: int = 0,
    method: Method = Method.ACTIVE,
    person: str = "paper",
    trees: str = "none",
    rate_hz: float = 20.0,
) -> GroundStation:
    """A ground station over connected PX4 vehicles; the embedded person and detector see them through their
    telemetry. The seed fixes the person's walk (random mode), the random trees and the detector noise.

    Mission time starts at 0 (the person's script runs from there) and the live runner paces it at real time;
    the vehicles' telemetry is stamped on it (its age carried over from the wall clock), so link ages are
    right even when the runner falls behind. The formation starts running unless `start_hold_reasons` gives
    a reason (each is logged as a warning)."""
    streams = SeedStreams.from_seed(seed)
    model = make_person(person, streams)
    ids = [a.vehicle_id for a in fleet.autopilots]
    starts = [s.position_m for a in fleet.autopilots if (s := a.state()) is not None]
    obstacles = make_trees(TreeSpec.parse(trees), streams, person=model, starts_xy_m=starts)
    rngs = {vid: detector for vid, (_, detector) in zip(ids, streams.vehicle_rngs(len(ids)), strict=True)}
    world = SimWorld(
        person=model, obstacles=obstacles, bodies=[TelemetryBody(a) for a in fleet.autopilots], rngs=rngs
    )
    links = SimLinks(vehicle_ids=ids, rng=np.random.default_rng(streams.links))
    params = ControllerParams(method=method)
    holds = start_hold_reasons(fleet, person_xyz_m=world.person_truth().position_m, controller_params=params)
    for reason in holds:
        log.warning("formation starts stopped: %s; start it from the operator page when ready", reason)
    mission = Mission(
        autopilots=fleet.autopilots,
        world=world,
        links=links,
        controller_params=params,
        formation_enabled=not holds,
        clock=time.perf_counter,
    )
    ref = fleet.reference
    station = GroundStation(
        mission=mission,
        control_period_s=1.0 / rate_hz,
        origin=GeodeticOrigin(lat_deg=ref.latitude_deg, lon_deg=ref.longitude_deg, alt_m=ref.altitude_m),
    )
    for a in fleet.autopilots:
        a.use_stamp_clock(lambda: station.time_s)
    return station


async def serve_px4(
    urls: Sequence[str],
    *,
    origin: GeodeticPoint | None = None,
    config: Px4Config | None = None,
    seed: int = 0,
    method: Method = Method.ACTIVE,
    person: str = "paper",
    trees: str = "none",
    rate_hz: float = 20.0,
    host: str = "127.0.0.1",
    port: int = 8000,
    viser_port: int = 8080,
    stop: asyncio.Event | None = None,
    on_ready: Callable[[Urls, object], None] | None = None,
    on_station: Callable[[GroundStation, Px4Fleet], None] | None = None,
    handle_signals: bool = True,
    flight_log: FlightLog | None = None,
    **serve_options,
) -> PaceStats:
    """Connect to every vehicle, serve the ground station until stopped, then land them and disconnect.

    on_station(station, fleet) is called once both exist (tests and tools use it). The landing asked for at
    shutdown is given time to reach PX4 before MAVSDK closes; from then on PX4's own failsafes
    (COM_OBL_RC_ACT, NAV_DLL_ACT) cover any vehicle still in the air. flight_log (closed by its owner)
    records the run from the moment the station exists. serve_options go to `serve_station` (gate, TLS).
    """
    fleet = await Px4Fleet.open(urls, origin=origin, config=config or Px4Config())
    try:
        station = build_px4_station(
            fleet, seed=seed, method=method, person=person, trees=trees, rate_hz=rate_hz
        )
        if flight_log is not None:
            station.attach_log(flight_log)
        if on_station is not None:
            on_station(station, fleet)
        return await serve_station(
            station,
            host=host,
            port=port,
            viser_port=viser_port,
            speed=1.0,
            stop=stop,
            on_ready=on_ready,
            handle_signals=handle_signals,
            **serve_options,
        )
    finally:
        settled = await fleet.settle(timeout_s=5.0)
        for a, ok in zip(fleet.autopilots, settled, strict=True):
            if not ok:
                log.warning(
                    "vehicle %d: the landing command may not have reached PX4 (%s)",
                    a.vehicle_id,
                    a.status().fault,
                )
        await fleet.close()

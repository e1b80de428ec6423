"""`skyring agent`: one MAV's onboard agent as its own process (the companion computer's), over Zenoh.

    skyring agent --id N --px4 URL [--connect tcp/HOST:PORT ...] [--listen tcp/0.0.0.0:7447] [--team NAME]
    skyring agent --id N --sim ...   (a rehearsal vehicle, served by `skyring serve --agents spawn`)

It flies its own PX4 through MAVSDK 4 (the PX4 back-end and its supervisor: failsafe parameters, take-off,
offboard, the set-point watchdog, landing) and runs `vehicles.net.onboard.OnboardAgent` on its own thread.
SIGINT/SIGTERM land the vehicle before the process exits; a killed process leaves PX4 without set-points and
PX4's offboard-loss failsafe lands it. The protocol is in docs/agents.md.
"""

from __future__ import annotations

import asyncio
import dataclasses
import logging
import math
import signal
import threading
import time
from pathlib import Path
from typing import Annotated, Any

import typer

from controller.params import Method

log = logging.getLogger(__name__)


def net_config(
    *,
    team: str,
    connect: list[str] | None,
    listen: list[str] | None,
    zenoh_config: Path | None,
    multicast: bool,
):
    """The NetConfig of the command-line options; typer.BadParameter says what is wrong."""
    from vehicles.net.session import NetConfig

    try:
        return NetConfig(
            team=team,
            connect=tuple(e.strip() for item in connect or [] for e in item.split(",") if e.strip()),
            listen=tuple(e.strip() for item in listen or [] for e in item.split(",") if e.strip()),
            multicast_scouting=multicast,
            config_file=zenoh_config,
        )
    except ValueError as exc:
        raise typer.BadParameter(str(exc)) from None


def agent(
    vehicle_id: Annotated[int, typer.Option("--id", help="this MAV's id in the team (1..255)")],
    px4: Annotated[
        str | None, typer.Option(help="MAVSDK URL of this MAV's PX4, e.g. serial:///dev/ttyTHS1:921600")
    ] = None,
    sim: Annotated[
        bool, typer.Option("--sim", help="fly a vehicle of the rehearsal world instead of PX4")
    ] = False,
    connect: Annotated[
        list[str] | None, typer.Option(help="Zenoh endpoint to connect to (repeatable)")
    ] = None,
    listen: Annotated[list[str] | None, typer.Option(help="Zenoh endpoint to listen on (repeatable)")] = None,
    team: Annotated[
        str, typer.Option(help="team name (the Zenoh key prefix skyring/<team>/...)")
    ] = "skyring",
    team_size: Annotated[
        int, typer.Option(help="team ids are 1..K; messages from other ids are rejected")
    ] = 16,
    zenoh_config: Annotated[
        Path | None,
        typer.Option(help="Zenoh JSON5 config (TLS/mTLS, access control)", exists=True, dir_okay=False),
    ] = None,
    multicast: Annotated[bool, typer.Option(help="find peers by multicast scouting")] = True,
    rate: Annotated[float, typer.Option(help="control rate in Hz")] = 20.0,
    station_timeout: Annotated[
        float, typer.Option(help="land after this long without the station (s)")
    ] = 10.0,
    realtime_priority: Annotated[
        int,
        typer.Option(
            help="run the control loop under SCHED_FIFO at this priority (1-99; needs CAP_SYS_NICE), 0: off"
        ),
    ] = 0,
    method: Annotated[Method, typer.Option(help="formation method")] = Method.ACTIVE,
    origin: Annotated[
        str | None, typer.Option(help="team frame origin 'lat,lon,alt' (every agent must use the same)")
    ] = None,
    emulate_camera: Annotated[
        str,
        typer.Option(
            help="off, or emulate the camera/detector looking at a model person: still, paper, random"
        ),
    ] = "off",
    person_epoch: Annotated[
        float | None,
        typer.Option(help="UTC seconds at which the emulated person starts (shared by the team)"),
    ] = None,
    seed: Annotated[int, typer.Option(help="seed of the emulated detector's noise")] = 0,
    calibration: Annotated[
        Path | None,
        typer.Option(help="the camera's OpenCV YAML calibration, for `skyring detect` (docs/detection.md)"),
    ] = None,
) -> None:
    """Run one MAV's onboard agent: its controller beside its PX4, talking to teammates and the station over
    Zenoh."""
    from vehicles.net.onboard import OnboardParams
    from vehicles.sim.person import PERSON_MODES

    if not 1 <= vehicle_id <= 255:
        raise typer.BadParameter(f"must be from 1 to 255, got {vehicle_id}", param_hint="--id")
    if not 1 <= team_size <= 255 or vehicle_id > team_size:
        raise typer.BadParameter(
            f"must be from --id ({vehicle_id}) to 255, got {team_size}", param_hint="--team-size"
        )
    if (px4 is None) == (not sim):
        raise typer.BadParameter("give exactly one of --px4 URL or --sim", param_hint="--px4")
    if not (math.isfinite(rate) and 1.0 <= rate <= 200.0):
        raise typer.BadParameter(f"must be from 1 to 200 Hz, got {rate}", param_hint="--rate")
    if emulate_camera != "off" and emulate_camera not in PERSON_MODES:
        raise typer.BadParameter(
            f"must be off or one of {', '.join(PERSON_MODES)}, got {emulate_camera!r}",
            param_hint="--emulate-camera",
        )
    try:
        params = OnboardParams(rate_hz=rate, station_timeout_s=station_timeout)
    except ValueError as exc:
        raise typer.BadParameter(str(exc), param_hint="--station-timeout") from None
    try:
        params = dataclasses.replace(params, realtime_priority=realtime_priority)
    except ValueError as exc:
        raise typer.BadParameter(str(exc), param_hint="--realtime-priority") from None
    config = net_config(
        team=team, connect=connect, listen=listen, zenoh_config=zenoh_config, multicast=multicast
    )
    logging.basicConfig(
        level=logging.WARNING, format=f"%(levelname)s agent {vehicle_id} %(name)s: %(message)s"
    )
    from vehicles.detect.calibration import Calibration, CalibrationError

    try:
        camera = (
            Calibration.load(calibration) if calibration is not None else Calibration.from_camera_params()
        )
    except CalibrationError as exc:
        raise typer.BadParameter(str(exc), param_hint="--calibration") from None
    options: dict[str, Any] = dict(
        vehicle_id=vehicle_id,
        team_size=team_size,
        config=config,
        params=params,
        method=method,
        seed=seed,
        calibration=camera,
    )
    if sim:
        run_sim_agent(**options)
    else:
        assert px4 is not None
        asyncio.run(
            run_px4_agent(
                url=px4,
                origin=origin,
                emulate_camera=emulate_camera,
                person_epoch=person_epoch,
                **options,
            )
        )


def _make_agent(*, vehicle_id, team_size, config, params, method, autopilot_factory, calibration=None):
    from controller.params import ControllerParams
    from controller.warmup import warm_up
    from vehicles.net import realtime
    from vehicles.net.onboard import OnboardAgent
    from vehicles.net.session import Bus

    warm_up(ControllerParams(method=method))  # the compiled kernels, before the agent's first tick
    realtime.shorten_gil_switch_interval()

    bus = Bus(
        config,
        sender=vehicle_id,
        is_member=lambda s: 0 <= s <= team_size,
        handler_priority=realtime.handler_priority(params.realtime_priority),
    )
    try:
        autopilot = autopilot_factory(bus)
        onboard = OnboardAgent(
            vehicle_id=vehicle_id,
            autopilot=autopilot,
            bus=bus,
            controller_params=ControllerParams(method=method),
            params=params,
            calibration=calibration,
        )
    except BaseException:
        bus.close()
        raise
    return bus, autopilot, onboard


def run_sim_agent(
    *, vehicle_id: int, team_size: int, config, params, method: Method, seed: int, calibration=None
) -> None:
    """The agent of a rehearsal vehicle (served by the world process) until SIGINT/SIGTERM."""
    from vehicles.net import realtime
    from vehicles.net.remote_sim import RemoteAutopilot

    bus, autopilot, onboard = _make_agent(
        vehicle_id=vehicle_id,
        team_size=team_size,
        config=config,
        params=params,
        method=method,
        autopilot_factory=lambda b: RemoteAutopilot(b, vehicle_id=vehicle_id),
        calibration=calibration,
    )
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    onboard.start()
    typer.echo(
        f"agent {vehicle_id}: team {config.team}, simulated vehicle, {params.rate_hz:g} Hz, "
        f"control loop: {realtime.describe(params.realtime_priority)}",
        err=True,
    )
    try:
        while not stop.wait(0.5):
            pass
    finally:
        onboard.stop()
        if onboard.phase.value in ("takeoff", "formation"):
            autopilot.land()
            time.sleep(0.2)
        bus.close()


async def run_px4_agent(
    *,
    vehicle_id: int,
    team_size: int,
    config,
    params,
    method: Method,
    seed: int,
    url: str,
    origin: str | None,
    emulate_camera: str,
    person_epoch: float | None,
    calibration=None,
) -> None:
    """The agent of a PX4 vehicle: connect through MAVSDK, fly until SIGINT/SIGTERM, land, disconnect."""
    import mavsdk

    from server.station.px4 import URL_SCHEMES
    from vehicles.net import realtime
    from vehicles.net.camera_emulator import EmulatedCamera
    from vehicles.px4.autopilot import Px4Autopilot, Px4Config, Px4Error
    from vehicles.px4.geodesy import parse_geodetic

    if not url.startswith(URL_SCHEMES):
        raise typer.BadParameter(f"{url!r} is not a MAVSDK connection URL", param_hint="--px4")
    try:
        reference = parse_geodetic(origin) if origin else None
    except ValueError as exc:
        raise typer.BadParameter(str(exc), param_hint="--origin") from None
    mavsdk.log_subscribe(lambda *args: True)
    px4 = Px4Autopilot(vehicle_id=vehicle_id, url=url, config=Px4Config())
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, stop.set)
    try:
        await px4.connect()
        team_origin = reference if reference is not None else px4.home
        if team_origin is None:
            raise Px4Error("no home position to serve as the team origin; pass --origin lat,lon,alt")
        px4.set_reference(team_origin)
        px4.use_stamp_clock(time.time)
        px4.start()
    except Px4Error as exc:
        typer.echo(f"error: {exc}", err=True)
        await px4.close()
        raise typer.Exit(code=1) from None
    bus, _, onboard = _make_agent(
        vehicle_id=vehicle_id,
        team_size=team_size,
        config=config,
        params=params,
        method=method,
        autopilot_factory=lambda b: px4,
        calibration=calibration,
    )
    camera = None
    if emulate_camera != "off":
        camera = EmulatedCamera(
            bus=bus,
            autopilot=px4,
            person=emulate_camera,
            epoch_utc=person_epoch if person_epoch is not None else time.time(),
            seed=seed,
        )
        camera.start()
    onboard.start()
    typer.echo(
        f"agent {vehicle_id}: team {config.team}, PX4 at {url}, {params.rate_hz:g} Hz, "
        f"control loop: {realtime.describe(params.realtime_priority)}",
        err=True,
    )
    try:
        await stop.wait()
    finally:
        onboard.stop()
        if camera is not None:
            camera.stop()
        if onboard.phase.value in ("takeoff", "formation", "landing"):
            px4.land()
        await px4.settle(timeout_s=5.0)
        await px4.close()
        bus.close()

"""The wire format of every skyring message on the network: a fixed header and a typed body, in MessagePack.

Serializer: msgspec (MessagePack). Its `Struct` types are declared once, with field types that the decoder
enforces (a string where a number belongs, a missing field or a plan row of four numbers is a decode error,
not a surprise three calls later); decoding is strict and allocation-light (a few microseconds for a plan),
and MessagePack is a compact binary form that keeps floats exact. JSON would cost about twice the bytes on a
radio link and round-trips floats through text; pydantic validates as well but is several times slower on the
control path and brings no binary format of its own.

Every message is a `Header` whose `body` is the MessagePack encoding of one body type, named by `kind`:

    Header {v, team, sender, boot, seq, stamp, kind, body}

- `v`: WIRE_VERSION; a message of another version is rejected (the header layout never changes, bodies may);
- `team`: the team name; `sender`: the vehicle id (1..255) or 0 for the ground station;
- `boot`: the sender's incarnation (UTC nanoseconds when the sending process started) and `seq`: its message
  counter (per kind), so (boot, seq) grows strictly per sender and kind; anything else is a replay;
- `stamp`: UTC seconds when sent (see docs/agents.md#clocks for how clock offsets are measured).

Bodies carry SI units in the team's ENU frame, like the domain types they mirror (controller.messages,
vehicles.autopilot). `*_to_wire` / `*_from_wire` convert; a `*_from_wire` raises ValueError for values the
domain type refuses (wrong shapes, non-finite numbers), which `vehicles.net.guard` counts as invalid.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Annotated

import msgspec
import numpy as np

from controller.messages import Detection, HorizonPlan, Obstacle, PersonEstimate
from controller.params import FormationParams
from vehicles.autopilot import AutopilotState, FlightMode, Setpoint
from vehicles.detect.pixels import CameraDetection, PersonPixels
from vehicles.detect.runner import CameraReport

WIRE_VERSION = 1
MAX_MESSAGE_BYTES = 16 * 1024  # a state message is ~2.5 kB, a plan ~1 kB; anything larger is refused unread
MAX_PLAN_STATES = 64
MAX_OBSTACLES = 64
MAX_TEXT = 400
THUMBNAIL_BYTES = 12_000  # a camera report's JPEG (320 px wide); the whole message stays below the limit
STATION_ID = 0
MAX_VEHICLE_ID = 255

Vec3 = tuple[float, float, float]
Mat3 = Annotated[list[float], msgspec.Meta(min_length=9, max_length=9)]  # row-major (3, 3)
Rows = Annotated[list[Vec3], msgspec.Meta(min_length=1, max_length=MAX_PLAN_STATES)]
Text = Annotated[str, msgspec.Meta(max_length=MAX_TEXT)]
Counts = Annotated[dict[Annotated[str, msgspec.Meta(max_length=40)], int], msgspec.Meta(max_length=32)]


class Header(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    """The envelope of every message (see the module docstring)."""

    v: int
    team: Annotated[str, msgspec.Meta(min_length=1, max_length=64)]
    sender: Annotated[int, msgspec.Meta(ge=0, le=MAX_VEHICLE_ID)]
    boot: Annotated[int, msgspec.Meta(ge=0)]
    seq: Annotated[int, msgspec.Meta(ge=0)]
    stamp: float
    kind: Annotated[str, msgspec.Meta(max_length=32)]
    body: msgspec.Raw


class _Body(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    """Base of every body type."""


Body = _Body  # the base of every message body, for annotations outside this module


class PlanBody(_Body, frozen=True):
    """A horizon plan (controller.messages.HorizonPlan) and the sender's mission phase, which teammates use
    for the roster (phase "takeoff" or "formation" counts)."""

    stamp_s: float
    dt_s: float
    positions_m: Rows
    velocities_mps: Rows
    in_formation: bool
    position_cov_m2: Mat3
    phase: Annotated[str, msgspec.Meta(max_length=16)] = ""
    gps_offset_m: Vec3 = (0.0, 0.0, 0.0)


class DetectionBody(_Body, frozen=True):
    """A person detection (controller.messages.Detection) in world ENU; its source is the header's sender."""

    stamp_s: float
    position_m: Vec3
    cov_m2: Mat3


class TelemetryBody(_Body, frozen=True):
    """An autopilot reading (vehicles.autopilot.AutopilotState); stamp_s in UTC seconds."""

    stamp_s: float
    position_m: Vec3
    velocity_mps: Vec3
    yaw_rad: float
    armed: bool
    in_air: bool
    mode: Annotated[str, msgspec.Meta(max_length=16)]
    roll_rad: float = 0.0
    pitch_rad: float = 0.0
    battery_fraction: float | None = None
    healthy: bool = True
    position_cov_m2: Mat3 = msgspec.field(default_factory=lambda: [0.25, 0, 0, 0, 0.25, 0, 0, 0, 0.25])
    link_lost: bool = False
    released: bool = False


class AutopilotCommandBody(_Body, frozen=True):
    """A request to a remote (simulated) autopilot: action "setpoint", "takeoff", "hold" or "land"."""

    action: Annotated[str, msgspec.Meta(max_length=16)]
    position_m: Vec3 = (0.0, 0.0, 0.0)
    velocity_mps: Vec3 = (0.0, 0.0, 0.0)
    yaw_rad: float = 0.0
    height_m: float = 0.0
    acceleration_mps2: Vec3 = (0.0, 0.0, 0.0)


class ObstacleBody(_Body, frozen=True):
    """An obstacle (controller.messages.Obstacle): kind "tree" (the map) or "virtual" (the operator's)."""

    obstacle_id: Annotated[str, msgspec.Meta(min_length=1, max_length=40)]
    center_m: tuple[float, float]
    radius_m: float
    height_m: float
    kind: Annotated[str, msgspec.Meta(max_length=16)] = "virtual"


class SettingsBody(_Body, frozen=True):
    """What the operator set, as one value the agents follow: rev (UTC ns of the operator action that made
    it; 0 = never configured), d_des/h_des, formation on/off, and every obstacle (the map's trees and the
    operator's virtual ones), so an agent keeps all it needs when the station is gone."""

    rev: int = 0
    d_des_m: float = 8.0
    h_des_m: float = 8.0
    enabled: bool = False
    obstacles: Annotated[list[ObstacleBody], msgspec.Meta(max_length=MAX_OBSTACLES)] = msgspec.field(
        default_factory=list
    )


class PersonBody(_Body, frozen=True):
    """A fused person estimate (controller.messages.PersonEstimate); cov row-major (6, 6)."""

    stamp_s: float
    position_m: Vec3
    velocity_mps: Vec3
    cov: Annotated[list[float], msgspec.Meta(min_length=36, max_length=36)]


class StateBody(_Body, frozen=True):
    """An agent's state for the station, 10 times a second (also its heartbeat).

    tick_s: duration of the last control tick; tick_period_p99_error_s: 99th percentile of |period - nominal|
    over the last few seconds; tracker/counters: TrackerStats/AgentCounters fields; rejected: network
    messages this agent refused, by reason; hb_stamp / hb_received: the last station heartbeat's stamp and
    when it arrived (agent UTC), for the station's clock-offset measurement; station_lost: no heartbeat for
    longer than the station timeout; camera: the camera converter's counts (received, converted, pending,
    rejected_<reason>, latency_p50_ms and latency_max_ms from capture to conversion, -1 before the first);
    scheduler: what its control loop runs under (vehicles.net.realtime.describe), a refusal included;
    gps_offset_m: the agent's estimate of its GPS offset (AgentOutputs.gps_offset_m; None: not estimated).
    """

    phase: Annotated[str, msgspec.Meta(max_length=16)]
    settings: SettingsBody
    autopilot: TelemetryBody | None = None
    plan: PlanBody | None = None
    person: PersonBody | None = None
    setpoint: Vec3 | None = None
    setpoint_yaw_rad: float | None = None
    status: Annotated[str, msgspec.Meta(max_length=16)] | None = None
    solver_time_s: float = 0.0
    tick_s: float | None = None
    tick_period_p99_error_s: float | None = None
    control_rate_hz: float = 0.0
    teammates_known: int = 0
    used_slot: bool = False
    fault: Text | None = None
    tracker: Counts = msgspec.field(default_factory=dict)
    counters: Counts = msgspec.field(default_factory=dict)
    rejected: Counts = msgspec.field(default_factory=dict)
    camera: Counts = msgspec.field(default_factory=dict)
    hb_stamp: float | None = None
    hb_received: float | None = None
    station_lost: bool = False
    scheduler: Text = ""
    gps_offset_m: Vec3 | None = None


class HeartbeatBody(_Body, frozen=True):
    """The station's heartbeat (2 Hz): it is alive; the header stamp starts a clock-offset round trip."""

    rate_hz: float = 2.0


class CommandBody(_Body, frozen=True):
    """An operator command for the agents in `targets`: action "configure" (apply `settings`), "land",
    "hold" or "release". command_id is unique per station run (with the header's boot); agents acknowledge
    each once applied and acknowledge a re-sent one again without applying it twice."""

    command_id: Annotated[int, msgspec.Meta(ge=1)]
    action: Annotated[str, msgspec.Meta(max_length=16)]
    targets: Annotated[
        list[Annotated[int, msgspec.Meta(ge=1, le=MAX_VEHICLE_ID)]], msgspec.Meta(max_length=256)
    ]
    settings: SettingsBody | None = None


class AckBody(_Body, frozen=True):
    """An agent's answer to a command: accepted (applied, or already applied) or refused, with why."""

    command_boot: int
    command_id: int
    accepted: bool
    message: Text = ""


class CameraBody(_Body, frozen=True):
    """One person seen by the sender's camera (vehicles.detect.pixels.CameraDetection), for its own agent to
    place with its pose: stamp_s the capture time (UTC), pixels in the raw image of image_size_px."""

    stamp_s: float
    frame_seq: Annotated[int, msgspec.Meta(ge=0)]
    image_size_px: tuple[
        Annotated[int, msgspec.Meta(gt=0, le=20_000)], Annotated[int, msgspec.Meta(gt=0, le=20_000)]
    ]
    head_px: tuple[float, float]
    feet_px: tuple[float, float]
    head_conf: Annotated[float, msgspec.Meta(ge=0.0, le=1.0)]
    feet_conf: Annotated[float, msgspec.Meta(ge=0.0, le=1.0)]
    box_px: tuple[float, float, float, float]
    score: float = 1.0
    method: Annotated[str, msgspec.Meta(max_length=16)] = ""


class CameraReportBody(_Body, frozen=True):
    """How the sender's camera and detector are doing (vehicles.detect.runner.CameraReport), about once a
    second, with a small JPEG of the newest overlaid frame for the operator page."""

    stamp_s: float
    state: Annotated[str, msgspec.Meta(max_length=16)]
    frames: Annotated[int, msgspec.Meta(ge=0)]
    corrupt: Annotated[int, msgspec.Meta(ge=0)]
    reconnects: Annotated[int, msgspec.Meta(ge=0)]
    stalls: Annotated[int, msgspec.Meta(ge=0)]
    frame_age_s: float | None
    fps: float
    detections: Annotated[int, msgspec.Meta(ge=0)]
    detector_errors: Annotated[int, msgspec.Meta(ge=0)]
    backend: Annotated[str, msgspec.Meta(max_length=64)]
    message: Text = ""
    thumbnail_jpeg: Annotated[bytes, msgspec.Meta(max_length=THUMBNAIL_BYTES)] | None = None


BODIES: dict[str, type[_Body]] = {
    "plan": PlanBody,
    "detection": DetectionBody,
    "telemetry": TelemetryBody,
    "autopilot": AutopilotCommandBody,
    "state": StateBody,
    "heartbeat": HeartbeatBody,
    "command": CommandBody,
    "ack": AckBody,
    "camera": CameraBody,
    "camera_report": CameraReportBody,
}
KIND_OF = {t: k for k, t in BODIES.items()}

_ENCODER = msgspec.msgpack.Encoder()
HEADER_DECODER = msgspec.msgpack.Decoder(Header)
BODY_DECODERS = {kind: msgspec.msgpack.Decoder(t) for kind, t in BODIES.items()}


def encode(*, team: str, sender: int, boot: int, seq: int, stamp: float, body: _Body) -> bytes:
    """One message as bytes (the header around the body)."""
    return _ENCODER.encode(
        Header(
            v=WIRE_VERSION,
            team=team,
            sender=sender,
            boot=boot,
            seq=seq,
            stamp=stamp,
            kind=KIND_OF[type(body)],
            body=msgspec.Raw(_ENCODER.encode(body)),
        )
    )


# ---- conversions -------------------------------------------------------------------------------------------
def _mat(a: np.ndarray) -> list[float]:
    return [float(x) for x in np.asarray(a, dtype=float).reshape(-1)]


def _vec(a: Sequence[float] | np.ndarray) -> Vec3:
    x, y, z = (float(v) for v in a)
    return (x, y, z)


def _finite(*values: float) -> None:
    if not all(math.isfinite(v) for v in values):
        raise ValueError("a number in the message is not finite")


def plan_to_wire(plan: HorizonPlan, *, phase: str = "") -> PlanBody:
    return PlanBody(
        stamp_s=float(plan.stamp_s),
        dt_s=float(plan.dt_s),
        positions_m=[_vec(p) for p in plan.positions_m],
        velocities_mps=[_vec(v) for v in plan.velocities_mps],
        in_formation=bool(plan.in_formation),
        position_cov_m2=_mat(plan.position_cov_m2),
        phase=phase,
        gps_offset_m=_vec(plan.gps_offset_m),
    )


def plan_from_wire(body: PlanBody, *, vehicle_id: int) -> HorizonPlan:
    """The plan of `vehicle_id` (the header's sender); ValueError for non-finite values or a bad shape."""
    plan = HorizonPlan(
        vehicle_id=vehicle_id,
        stamp_s=body.stamp_s,
        dt_s=body.dt_s,
        positions_m=np.array(body.positions_m),
        velocities_mps=np.array(body.velocities_mps),
        in_formation=body.in_formation,
        position_cov_m2=np.array(body.position_cov_m2).reshape(3, 3),
        gps_offset_m=np.array(body.gps_offset_m),
    )
    _finite(plan.stamp_s, plan.dt_s)
    if plan.dt_s <= 0 or not (
        np.all(np.isfinite(plan.positions_m))
        and np.all(np.isfinite(plan.velocities_mps))
        and np.all(np.isfinite(plan.position_cov_m2))
        and np.all(np.isfinite(plan.gps_offset_m))
    ):
        raise ValueError("a plan needs dt_s > 0 and finite states")
    return plan


def detection_to_wire(detection: Detection) -> DetectionBody:
    return DetectionBody(
        stamp_s=float(detection.stamp_s), position_m=_vec(detection.position_m), cov_m2=_mat(detection.cov_m2)
    )


def detection_from_wire(body: DetectionBody, *, source_id: int) -> Detection:
    _finite(body.stamp_s, *body.position_m, *body.cov_m2)
    return Detection(
        source_id=source_id,
        stamp_s=body.stamp_s,
        position_m=np.array(body.position_m),
        cov_m2=np.array(body.cov_m2).reshape(3, 3),
    )


def camera_to_wire(det: CameraDetection) -> CameraBody:
    p = det.person
    return CameraBody(
        stamp_s=float(det.stamp_s),
        frame_seq=int(det.frame_seq),
        image_size_px=(int(det.image_size_px[0]), int(det.image_size_px[1])),
        head_px=(float(p.head_px[0]), float(p.head_px[1])),
        feet_px=(float(p.feet_px[0]), float(p.feet_px[1])),
        head_conf=float(p.head_conf),
        feet_conf=float(p.feet_conf),
        box_px=(float(p.box_px[0]), float(p.box_px[1]), float(p.box_px[2]), float(p.box_px[3])),
        score=float(p.score),
        method=p.method[:16],
    )


def camera_from_wire(body: CameraBody, *, vehicle_id: int) -> CameraDetection:
    _finite(body.stamp_s, *body.head_px, *body.feet_px, *body.box_px, body.score)
    person = PersonPixels(
        head_px=np.array(body.head_px),
        feet_px=np.array(body.feet_px),
        head_conf=body.head_conf,
        feet_conf=body.feet_conf,
        box_px=np.array(body.box_px),
        score=body.score,
        method=body.method,
    )
    return CameraDetection(
        vehicle_id=vehicle_id,
        stamp_s=body.stamp_s,
        frame_seq=body.frame_seq,
        image_size_px=body.image_size_px,
        person=person,
    )


def camera_report_to_wire(rep: CameraReport) -> CameraReportBody:
    c = rep.camera
    thumb = rep.thumbnail_jpeg if rep.thumbnail_jpeg and len(rep.thumbnail_jpeg) <= THUMBNAIL_BYTES else None
    return CameraReportBody(
        stamp_s=float(rep.stamp_s),
        state=str(c.state),
        frames=c.frames,
        corrupt=c.corrupt,
        reconnects=c.reconnects,
        stalls=c.stalls,
        frame_age_s=c.frame_age_s if math.isfinite(c.frame_age_s) else None,
        fps=float(rep.fps) if math.isfinite(rep.fps) else 0.0,
        detections=rep.detections,
        detector_errors=rep.detector_errors,
        backend=rep.backend[:64],
        message=(rep.message or c.message)[:MAX_TEXT],
        thumbnail_jpeg=thumb,
    )


def telemetry_to_wire(state: AutopilotState, *, stamp_s: float | None = None) -> TelemetryBody:
    return TelemetryBody(
        stamp_s=float(state.stamp_s if stamp_s is None else stamp_s),
        position_m=_vec(state.position_m),
        velocity_mps=_vec(state.velocity_mps),
        yaw_rad=float(state.yaw_rad),
        armed=bool(state.armed),
        in_air=bool(state.in_air),
        mode=state.mode.value,
        roll_rad=float(state.roll_rad),
        pitch_rad=float(state.pitch_rad),
        battery_fraction=None if state.battery_fraction is None else float(state.battery_fraction),
        healthy=bool(state.healthy),
        position_cov_m2=_mat(state.position_cov_m2),
        link_lost=bool(state.link_lost),
        released=bool(state.released),
    )


def telemetry_from_wire(body: TelemetryBody, *, vehicle_id: int) -> AutopilotState:
    _finite(body.stamp_s, *body.position_m, *body.velocity_mps, body.yaw_rad, body.roll_rad, body.pitch_rad)
    _finite(*body.position_cov_m2)
    try:
        mode = FlightMode(body.mode)
    except ValueError:
        mode = FlightMode.UNKNOWN
    return AutopilotState(
        vehicle_id=vehicle_id,
        stamp_s=body.stamp_s,
        position_m=np.array(body.position_m),
        velocity_mps=np.array(body.velocity_mps),
        yaw_rad=body.yaw_rad,
        armed=body.armed,
        in_air=body.in_air,
        mode=mode,
        roll_rad=body.roll_rad,
        pitch_rad=body.pitch_rad,
        battery_fraction=body.battery_fraction,
        healthy=body.healthy,
        position_cov_m2=np.array(body.position_cov_m2).reshape(3, 3),
        link_lost=body.link_lost,
        released=body.released,
    )


def setpoint_command(setpoint: Setpoint) -> AutopilotCommandBody:
    return AutopilotCommandBody(
        action="setpoint",
        position_m=_vec(setpoint.position_m),
        velocity_mps=_vec(setpoint.velocity_mps),
        yaw_rad=float(setpoint.yaw_rad),
        acceleration_mps2=_vec(setpoint.acceleration_mps2),
    )


def setpoint_from_wire(body: AutopilotCommandBody, *, stamp_s: float) -> Setpoint:
    """ValueError when not finite (Setpoint refuses it)."""
    return Setpoint(
        stamp_s=stamp_s,
        position_m=np.array(body.position_m),
        velocity_mps=np.array(body.velocity_mps),
        yaw_rad=body.yaw_rad,
        acceleration_mps2=np.array(body.acceleration_mps2),
    )


def person_to_wire(person: PersonEstimate) -> PersonBody:
    return PersonBody(
        stamp_s=float(person.stamp_s),
        position_m=_vec(person.position_m),
        velocity_mps=_vec(person.velocity_mps),
        cov=_mat(person.cov),
    )


def person_from_wire(body: PersonBody) -> PersonEstimate:
    return PersonEstimate(
        stamp_s=body.stamp_s,
        position_m=np.array(body.position_m),
        velocity_mps=np.array(body.velocity_mps),
        cov=np.array(body.cov).reshape(6, 6),
    )


def obstacle_to_wire(obstacle: Obstacle) -> ObstacleBody:
    return ObstacleBody(
        obstacle_id=obstacle.obstacle_id,
        center_m=(float(obstacle.center_m[0]), float(obstacle.center_m[1])),
        radius_m=float(obstacle.radius_m),
        height_m=float(obstacle.height_m),
        kind=obstacle.kind,
    )


def obstacle_from_wire(body: ObstacleBody) -> Obstacle:
    _finite(*body.center_m)
    return Obstacle(
        obstacle_id=body.obstacle_id,
        center_m=np.array(body.center_m),
        radius_m=body.radius_m,
        height_m=body.height_m,
        kind=body.kind if body.kind in ("tree", "virtual") else "virtual",
    )


def formation_of(settings: SettingsBody) -> FormationParams:
    return FormationParams(d_des_m=settings.d_des_m, h_des_m=settings.h_des_m)

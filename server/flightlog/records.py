"""The records of a flight log, one JSON object per line, and their explicit JSON form.

A log is a header (what was flown: the `skyring serve` settings), then in time order the operator's commands
with their outcome and periodic state samples, then an end record when the ground station stopped cleanly.
Every record is a frozen dataclass of plain typed values (tuples, not numpy arrays, so records compare by
value) with a hand-written `to_json` / `from_json`: the file format is what these functions say, nothing is
serialised by reflection. Non-finite numbers are written as null (strict JSON, readable by any tool) and read
back as NaN. Add fields with defaults; never rename one (old logs must stay readable).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from controller.messages import Obstacle, PersonEstimate
from controller.params import FormationParams
from vehicles.mission import MissionSnapshot
from webui.view import CameraView, Range, SceneView, VehicleView

FORMAT = "skyring-flight-log"
VERSION = 1
SIGNIFICANT_DIGITS = 6  # 0.1 mm at 100 m: ample for review, and it keeps a line of 3 MAVs near 2.5 kB

Vec2 = tuple[float, float]
Vec3 = tuple[float, float, float]
Scalar = bool | int | float | str


class RecordError(ValueError):
    """A line that is JSON but not a record this reader understands (a field missing or of the wrong type)."""


# ---- numbers ----------------------------------------------------------------------------------------------


def _q(x: float) -> float:
    """x kept to SIGNIFICANT_DIGITS (NaN and infinities unchanged)."""
    x = float(x)
    return float(f"{x:.{SIGNIFICANT_DIGITS}g}") if math.isfinite(x) else x


def _qv(values) -> tuple[float, ...]:
    return tuple(_q(v) for v in np.asarray(values, dtype=float).ravel())


def _qv2(values) -> Vec2:
    x, y = _qv(values)
    return x, y


def _qv3(values) -> Vec3:
    x, y, z = _qv(values)
    return x, y, z


def _qv4(values) -> tuple[float, float, float, float]:
    a, b, c, d = _qv(values)
    return a, b, c, d


def _out(x: float | None) -> float | None:
    """A number as JSON: null for None, NaN and infinities."""
    return x if x is not None and math.isfinite(x) else None


def _outv(values: tuple[float, ...]) -> list[float | None]:
    return [_out(v) for v in values]


def _in(x: Any) -> float:
    """A JSON number back (null: NaN). Refuses anything that is not a number."""
    if x is None:
        return math.nan
    if isinstance(x, bool) or not isinstance(x, int | float):
        raise RecordError(f"expected a number, got {x!r}")
    return float(x)


def _in_opt(x: Any) -> float | None:
    return None if x is None else _in(x)


def _inv(values: Any, n: int) -> tuple[float, ...]:
    if not isinstance(values, list) or len(values) != n:
        raise RecordError(f"expected a list of {n} numbers, got {values!r}")
    return tuple(_in(v) for v in values)


def _inv2(values: Any) -> Vec2:
    x, y = _inv(values, 2)
    return x, y


def _inv3(values: Any) -> Vec3:
    x, y, z = _inv(values, 3)
    return x, y, z


def _inv4(values: Any) -> tuple[float, float, float, float]:
    a, b, c, d = _inv(values, 4)
    return a, b, c, d


def _field(obj: Any, name: str, kind: type | tuple[type, ...]) -> Any:
    if not isinstance(obj, dict):
        raise RecordError(f"expected an object, got {obj!r}")
    if name not in obj:
        raise RecordError(f"field {name!r} is missing")
    value = obj[name]
    if not isinstance(value, kind) or (isinstance(value, bool) and bool not in _kinds(kind)):
        raise RecordError(f"field {name!r} has the wrong type: {value!r}")
    return value


def _kinds(kind: type | tuple[type, ...]) -> tuple[type, ...]:
    return kind if isinstance(kind, tuple) else (kind,)


# ---- header -----------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class LogHeader:
    """What was flown. command: "serve" (embedded simulation) or "serve --px4"; vehicles: number of MAVs;
    seed, method, trees, person: the world's settings; rate_hz: control rate; speed: simulated seconds per
    wall second; vehicle_urls: the MAVSDK URLs of PX4 vehicles (empty in simulation); sample_rate_hz: state
    samples per second of mission time; started_utc: wall time the log was opened, ISO 8601 UTC."""

    command: str
    vehicles: int
    seed: int
    method: str
    trees: str
    person: str
    rate_hz: float
    speed: float
    sample_rate_hz: float
    started_utc: str
    vehicle_urls: tuple[str, ...] = ()

    def to_json(self) -> dict[str, Any]:
        return {
            "kind": "header",
            "format": FORMAT,
            "version": VERSION,
            "command": self.command,
            "vehicles": self.vehicles,
            "seed": self.seed,
            "method": self.method,
            "trees": self.trees,
            "person": self.person,
            "rate_hz": self.rate_hz,
            "speed": self.speed,
            "sample_rate_hz": self.sample_rate_hz,
            "started_utc": self.started_utc,
            "vehicle_urls": list(self.vehicle_urls),
        }

    @classmethod
    def from_json(cls, obj: dict[str, Any]) -> LogHeader:
        """Read a header (check_format first: this assumes the format and version are known)."""
        urls = obj.get("vehicle_urls", [])
        if not isinstance(urls, list) or not all(isinstance(u, str) for u in urls):
            raise RecordError(f"field 'vehicle_urls' has the wrong type: {urls!r}")
        return cls(
            command=_field(obj, "command", str),
            vehicles=_field(obj, "vehicles", int),
            seed=_field(obj, "seed", int),
            method=_field(obj, "method", str),
            trees=_field(obj, "trees", str),
            person=_field(obj, "person", str),
            rate_hz=_in(_field(obj, "rate_hz", (int, float))),
            speed=_in(_field(obj, "speed", (int, float))),
            sample_rate_hz=_in(_field(obj, "sample_rate_hz", (int, float))),
            started_utc=_field(obj, "started_utc", str),
            vehicle_urls=tuple(urls),
        )


def check_format(obj: Any) -> None:
    """RecordError unless obj is the header of a flight log this reader can read (format and version)."""
    if not isinstance(obj, dict) or obj.get("kind") != "header" or obj.get("format") != FORMAT:
        raise RecordError(f"the first line is not a skyring flight-log header (expected format {FORMAT!r})")
    if obj.get("version") != VERSION:
        raise RecordError(
            f"flight-log version {obj.get('version')!r} is not supported (this skyring reads "
            f"version {VERSION})"
        )


# ---- operator commands ------------------------------------------------------------------------------------


@dataclass(frozen=True)
class LogCommand:
    """One operator command (from the GUI or the API) and its outcome, at mission time time_s.

    name: the ground-station method (set_formation, add_obstacle, ...); arguments: (name, value) pairs as
    the operator gave them; accepted: False when refused, and message then says why; result: what an
    accepted command returned, as text (an obstacle id, the MAVs told to land), else None.
    """

    time_s: float
    name: str
    arguments: tuple[tuple[str, Scalar], ...]
    accepted: bool
    message: str = ""
    result: str | None = None

    def to_json(self) -> dict[str, Any]:
        return {
            "kind": "command",
            "time_s": _out(self.time_s),
            "name": self.name,
            "arguments": {k: _scalar_out(v) for k, v in self.arguments},
            "accepted": self.accepted,
            "message": self.message,
            "result": self.result,
        }

    @classmethod
    def from_json(cls, obj: dict[str, Any]) -> LogCommand:
        arguments = _field(obj, "arguments", dict)
        result = obj.get("result")
        if result is not None and not isinstance(result, str):
            raise RecordError(f"field 'result' has the wrong type: {result!r}")
        return cls(
            time_s=_in(obj.get("time_s")),
            name=_field(obj, "name", str),
            arguments=tuple((str(k), _scalar_in(v)) for k, v in arguments.items()),
            accepted=_field(obj, "accepted", bool),
            message=_field(obj, "message", str),
            result=result,
        )


def scalar(value: Any) -> Scalar:
    """An operator's argument as a log scalar: bools, ints, floats and strings as they are, anything else as
    its repr (the log shows what was sent, even when it was nonsense)."""
    return value if isinstance(value, bool | int | float | str) else repr(value)


def _scalar_out(value: Scalar) -> Scalar:
    # a non-finite number is kept as its text ("nan", "inf"): the log must show what the operator sent
    return repr(value) if isinstance(value, float) and not math.isfinite(value) else value


def _scalar_in(value: Any) -> Scalar:
    if not isinstance(value, bool | int | float | str):
        raise RecordError(f"an argument must be a number, a string or a boolean, got {value!r}")
    return value


# ---- state samples ----------------------------------------------------------------------------------------


@dataclass(frozen=True)
class VehicleSample:
    """One MAV in a sample: as the operator saw it (`webui.view.VehicleView`) plus its velocity.

    position_m / velocity_mps: ENU from its autopilot; yaw_rad ENU; link_age_s: seconds since its last
    telemetry (inf: never heard from); plan_positions_m: its latest horizon plan (empty when none);
    autopilot_mode, failsafe, failsafe_reason, arming_refusal: what the autopilot said of itself (absent in
    logs written before they were recorded: read as unknown)."""

    vehicle_id: int
    phase: str
    mode: str
    armed: bool
    in_air: bool
    in_formation: bool
    position_m: Vec3
    velocity_mps: Vec3
    yaw_rad: float
    link_age_s: float
    link_stale: bool
    solve_status: str = ""
    solver_time_s: float | None = None
    battery_fraction: float | None = None
    plan_positions_m: tuple[Vec3, ...] = ()
    autopilot_mode: str = ""
    failsafe: bool = False
    failsafe_reason: str | None = None
    arming_refusal: str | None = None

    @property
    def landed(self) -> bool:
        return self.phase == "landed"

    def to_json(self) -> dict[str, Any]:
        return {
            "id": self.vehicle_id,
            "phase": self.phase,
            "mode": self.mode,
            "armed": self.armed,
            "in_air": self.in_air,
            "in_formation": self.in_formation,
            "position_m": _outv(self.position_m),
            "velocity_mps": _outv(self.velocity_mps),
            "yaw_rad": _out(self.yaw_rad),
            "link_age_s": _out(self.link_age_s),
            "link_stale": self.link_stale,
            "solve_status": self.solve_status,
            "solver_time_s": _out(self.solver_time_s),
            "battery_fraction": _out(self.battery_fraction),
            "plan_positions_m": [_outv(p) for p in self.plan_positions_m],
            "autopilot_mode": self.autopilot_mode,
            "failsafe": self.failsafe,
            "failsafe_reason": self.failsafe_reason,
            "arming_refusal": self.arming_refusal,
        }

    @classmethod
    def from_json(cls, obj: dict[str, Any]) -> VehicleSample:
        age = obj.get("link_age_s")
        return cls(
            vehicle_id=_field(obj, "id", int),
            phase=_field(obj, "phase", str),
            mode=_field(obj, "mode", str),
            armed=_field(obj, "armed", bool),
            in_air=_field(obj, "in_air", bool),
            in_formation=_field(obj, "in_formation", bool),
            position_m=_inv3(obj.get("position_m")),
            velocity_mps=_inv3(obj.get("velocity_mps")),
            yaw_rad=_in(obj.get("yaw_rad")),
            link_age_s=math.inf if age is None else _in(age),
            link_stale=_field(obj, "link_stale", bool),
            solve_status=_field(obj, "solve_status", str),
            solver_time_s=_in_opt(obj.get("solver_time_s")),
            battery_fraction=_in_opt(obj.get("battery_fraction")),
            plan_positions_m=tuple(_inv3(p) for p in _field(obj, "plan_positions_m", list)),
            autopilot_mode=_optional(obj, "autopilot_mode", str) or "",
            failsafe=bool(_optional(obj, "failsafe", bool)),
            failsafe_reason=_optional(obj, "failsafe_reason", str),
            arming_refusal=_optional(obj, "arming_refusal", str),
        )


def _optional(obj: dict[str, Any], name: str, kind: type) -> Any:
    """A field added in a later release: None when absent or null, else it must have the right type."""
    value = obj.get(name)
    if value is not None and (not isinstance(value, kind) or (isinstance(value, bool) and kind is not bool)):
        raise RecordError(f"field {name!r} has the wrong type: {value!r}")
    return value


@dataclass(frozen=True)
class EstimateSample:
    """The fused person estimate drawn at that instant: from MAV source_id's tracker replica, valid at
    stamp_s; cov: 6 x 6 covariance of [position, velocity] (m^2, m^2/s^2), row by row."""

    source_id: int
    stamp_s: float
    position_m: Vec3
    velocity_mps: Vec3
    cov: tuple[float, ...]

    def to_json(self) -> dict[str, Any]:
        return {
            "source_id": self.source_id,
            "stamp_s": _out(self.stamp_s),
            "position_m": _outv(self.position_m),
            "velocity_mps": _outv(self.velocity_mps),
            "cov": _outv(self.cov),
        }

    @classmethod
    def from_json(cls, obj: dict[str, Any]) -> EstimateSample:
        return cls(
            source_id=_field(obj, "source_id", int),
            stamp_s=_in(obj.get("stamp_s")),
            position_m=_inv3(obj.get("position_m")),
            velocity_mps=_inv3(obj.get("velocity_mps")),
            cov=_inv(obj.get("cov"), 36),
        )


@dataclass(frozen=True)
class ObstacleSample:
    """A vertical cylinder: axis at ENU center_m (x, y), radius_m, height_m; kind "tree" or "virtual"."""

    obstacle_id: str
    kind: str
    center_m: Vec2
    radius_m: float
    height_m: float

    def to_json(self) -> dict[str, Any]:
        return {
            "id": self.obstacle_id,
            "kind": self.kind,
            "center_m": _outv(self.center_m),
            "radius_m": _out(self.radius_m),
            "height_m": _out(self.height_m),
        }

    @classmethod
    def from_json(cls, obj: dict[str, Any]) -> ObstacleSample:
        return cls(
            obstacle_id=_field(obj, "id", str),
            kind=_field(obj, "kind", str),
            center_m=_inv2(obj.get("center_m")),
            radius_m=_in(obj.get("radius_m")),
            height_m=_in(obj.get("height_m")),
        )


@dataclass(frozen=True)
class LogSample:
    """The team at mission time time_s: everything the operator's 3-D view showed (so a replay draws the same
    scene) plus the vehicles' velocities.

    person_truth_m: the simulated person's true centre (None with real vehicles); estimate: the drawn fused
    estimate (None before the first detection); tracking_error_m: mean |estimate - truth| over MAVs
    (simulation only); d_des_m / h_des_m: the formation parameters, *_range_m: (low, high) the operator
    could set; arena_*_m: the box the MAVs fly in; camera: (vertical fov rad, aspect, pitch down rad, forward
    offset m) of the drawn frustums.
    """

    time_s: float
    vehicles: tuple[VehicleSample, ...]
    obstacles: tuple[ObstacleSample, ...]
    d_des_m: float
    h_des_m: float
    formation_enabled: bool
    person_truth_m: Vec3 | None = None
    estimate: EstimateSample | None = None
    tracking_error_m: float | None = None
    d_des_range_m: Vec2 = (math.nan, math.nan)
    h_des_range_m: Vec2 = (math.nan, math.nan)
    obstacle_radius_range_m: Vec2 = (0.1, 5.0)
    arena_min_m: Vec3 = (-20.0, -20.0, 3.0)
    arena_max_m: Vec3 = (20.0, 20.0, 10.0)
    camera: tuple[float, float, float, float] = (math.nan, math.nan, math.nan, math.nan)

    def to_json(self) -> dict[str, Any]:
        return {
            "kind": "sample",
            "time_s": _out(self.time_s),
            "vehicles": [v.to_json() for v in self.vehicles],
            "obstacles": [o.to_json() for o in self.obstacles],
            "d_des_m": _out(self.d_des_m),
            "h_des_m": _out(self.h_des_m),
            "formation_enabled": self.formation_enabled,
            "person_truth_m": None if self.person_truth_m is None else _outv(self.person_truth_m),
            "estimate": None if self.estimate is None else self.estimate.to_json(),
            "tracking_error_m": _out(self.tracking_error_m),
            "d_des_range_m": _outv(self.d_des_range_m),
            "h_des_range_m": _outv(self.h_des_range_m),
            "obstacle_radius_range_m": _outv(self.obstacle_radius_range_m),
            "arena_min_m": _outv(self.arena_min_m),
            "arena_max_m": _outv(self.arena_max_m),
            "camera": _outv(self.camera),
        }

    @classmethod
    def from_json(cls, obj: dict[str, Any]) -> LogSample:
        truth, estimate = obj.get("person_truth_m"), obj.get("estimate")
        return cls(
            time_s=_in(obj.get("time_s")),
            vehicles=tuple(VehicleSample.from_json(v) for v in _field(obj, "vehicles", list)),
            obstacles=tuple(ObstacleSample.from_json(o) for o in _field(obj, "obstacles", list)),
            d_des_m=_in(obj.get("d_des_m")),
            h_des_m=_in(obj.get("h_des_m")),
            formation_enabled=_field(obj, "formation_enabled", bool),
            person_truth_m=None if truth is None else _inv3(truth),
            estimate=None if estimate is None else EstimateSample.from_json(estimate),
            tracking_error_m=_in_opt(obj.get("tracking_error_m")),
            d_des_range_m=_inv2(obj.get("d_des_range_m")),
            h_des_range_m=_inv2(obj.get("h_des_range_m")),
            obstacle_radius_range_m=_inv2(obj.get("obstacle_radius_range_m")),
            arena_min_m=_inv3(obj.get("arena_min_m")),
            arena_max_m=_inv3(obj.get("arena_max_m")),
            camera=_inv4(obj.get("camera")),
        )


@dataclass(frozen=True)
class LogEnd:
    """Written when the log is closed cleanly (a log without it ended in a crash or a kill): the last mission
    time, and the records and write failures counted by the writer."""

    time_s: float
    samples: int
    commands: int
    write_errors: int

    def to_json(self) -> dict[str, Any]:
        return {
            "kind": "end",
            "time_s": _out(self.time_s),
            "samples": self.samples,
            "commands": self.commands,
            "write_errors": self.write_errors,
        }

    @classmethod
    def from_json(cls, obj: dict[str, Any]) -> LogEnd:
        return cls(
            time_s=_in(obj.get("time_s")),
            samples=_field(obj, "samples", int),
            commands=_field(obj, "commands", int),
            write_errors=_field(obj, "write_errors", int),
        )


# ---- from the ground station and back to the operator's view ----------------------------------------------


def sample_from(snapshot: MissionSnapshot, view: SceneView) -> LogSample:
    """The sample of one instant: `view` is the operator's view of `snapshot` (`GroundStation.scene_view()`);
    the snapshot adds the velocities the view does not carry. Numbers are kept to SIGNIFICANT_DIGITS."""
    velocities = {
        v.vehicle_id: v.autopilot.velocity_mps for v in snapshot.vehicles if v.autopilot is not None
    }

    def vehicle(v: VehicleView) -> VehicleSample:
        return VehicleSample(
            vehicle_id=v.vehicle_id,
            phase=v.phase,
            mode=v.mode,
            armed=v.armed,
            in_air=v.in_air,
            in_formation=v.in_formation,
            position_m=_qv3(v.position_m),
            velocity_mps=_qv3(velocities.get(v.vehicle_id, (math.nan,) * 3)),
            yaw_rad=_q(v.yaw_rad),
            link_age_s=_q(v.link_age_s),
            link_stale=v.link_stale,
            solve_status=v.solve_status,
            solver_time_s=None if v.solver_time_s is None else _q(v.solver_time_s),
            battery_fraction=None if v.battery_fraction is None else _q(v.battery_fraction),
            plan_positions_m=tuple(_qv3(p) for p in v.plan_positions_m),
            autopilot_mode=v.autopilot_mode,
            failsafe=v.failsafe,
            failsafe_reason=v.failsafe_reason,
            arming_refusal=v.arming_refusal,
        )

    e = view.person_estimate
    c = view.camera
    return LogSample(
        time_s=float(view.time_s),
        vehicles=tuple(vehicle(v) for v in view.vehicles),
        obstacles=tuple(
            ObstacleSample(
                obstacle_id=o.obstacle_id,
                kind=o.kind,
                center_m=_qv2(o.center_m),
                radius_m=_q(o.radius_m),
                height_m=_q(o.height_m),
            )
            for o in view.obstacles
        ),
        d_des_m=_q(view.formation.d_des_m),
        h_des_m=_q(view.formation.h_des_m),
        formation_enabled=bool(view.formation_enabled),
        person_truth_m=None if view.person_truth_m is None else _qv3(view.person_truth_m),
        estimate=None
        if e is None
        else EstimateSample(
            source_id=int(view.estimate_source_id if view.estimate_source_id is not None else -1),
            stamp_s=float(e.stamp_s),
            position_m=_qv3(e.position_m),
            velocity_mps=_qv3(e.velocity_mps),
            cov=_qv(e.cov),
        ),
        tracking_error_m=None if view.tracking_error_m is None else _q(view.tracking_error_m),
        d_des_range_m=_qv2((view.d_des_range_m.low, view.d_des_range_m.high)),
        h_des_range_m=_qv2((view.h_des_range_m.low, view.h_des_range_m.high)),
        obstacle_radius_range_m=_qv2((view.obstacle_radius_range_m.low, view.obstacle_radius_range_m.high)),
        arena_min_m=_qv3(view.arena_min_m),
        arena_max_m=_qv3(view.arena_max_m),
        camera=_qv4((c.vertical_fov_rad, c.aspect, c.pitch_down_rad, c.forward_offset_m)),
    )


def scene_from(sample: LogSample) -> SceneView:
    """The operator's view of a sample, for the same scene code that draws the live station."""
    vehicles = tuple(
        VehicleView(
            vehicle_id=v.vehicle_id,
            phase=v.phase,
            mode=v.mode,
            armed=v.armed,
            in_air=v.in_air,
            in_formation=v.in_formation,
            position_m=np.array(v.position_m),
            yaw_rad=v.yaw_rad,
            link_age_s=v.link_age_s,
            link_stale=v.link_stale,
            solve_status=v.solve_status,
            solver_time_s=v.solver_time_s,
            battery_fraction=v.battery_fraction,
            plan_positions_m=np.array(v.plan_positions_m).reshape(-1, 3),
            autopilot_mode=v.autopilot_mode,
            failsafe=v.failsafe,
            failsafe_reason=v.failsafe_reason,
            arming_refusal=v.arming_refusal,
        )
        for v in sample.vehicles
    )
    obstacles = tuple(
        Obstacle(
            obstacle_id=o.obstacle_id,
            center_m=np.array(o.center_m),
            radius_m=o.radius_m,
            height_m=o.height_m,
            kind=o.kind,
        )
        for o in sample.obstacles
    )
    e = sample.estimate
    estimate = (
        None
        if e is None
        else PersonEstimate(
            stamp_s=e.stamp_s,
            position_m=np.array(e.position_m),
            velocity_mps=np.array(e.velocity_mps),
            cov=np.array(e.cov).reshape(6, 6),
        )
    )
    fov, aspect, pitch, offset = sample.camera
    camera = (
        CameraView(vertical_fov_rad=fov, aspect=aspect, pitch_down_rad=pitch, forward_offset_m=offset)
        if all(math.isfinite(x) for x in sample.camera)
        else CameraView()
    )
    return SceneView(
        time_s=sample.time_s,
        vehicles=vehicles,
        obstacles=obstacles,
        formation=FormationParams(d_des_m=sample.d_des_m, h_des_m=sample.h_des_m),
        formation_enabled=sample.formation_enabled,
        arena_min_m=np.array(sample.arena_min_m),
        arena_max_m=np.array(sample.arena_max_m),
        d_des_range_m=Range(*sample.d_des_range_m),
        h_des_range_m=Range(*sample.h_des_range_m),
        obstacle_radius_range_m=Range(*sample.obstacle_radius_range_m),
        person_truth_m=None if sample.person_truth_m is None else np.array(sample.person_truth_m),
        person_estimate=estimate,
        estimate_source_id=None if e is None else e.source_id,
        tracking_error_m=sample.tracking_error_m,
        camera=camera,
    )

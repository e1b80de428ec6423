"""The embedded world: a person model, static obstacles, bodies with cameras, and the detector model.

Its bodies are either simulated vehicles (`SimAutopilot`, which integrate their own physics) or real ones
seen through telemetry (`TelemetryBody`, for PX4 SITL or real vehicles flying round an emulated person),
while the person and the camera/detector model stay the same.

The detector runs at 4 Hz per camera (staggered between vehicles). It sees the person when head and feet
project inside the image and no trunk blocks the line of sight, and then reports the noisy position from the
measurement model in the world frame *as the MAV believes it*: shifted by the MAV's own GPS drift.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from controller.measurement import NoiseParams, sample_detection
from controller.messages import Detection, Obstacle
from vehicles.autopilot import Autopilot
from vehicles.camera import CameraParams, FrameView, body_rotations, mounted_camera_pose, view_person
from vehicles.world import Body, BodyPose, PersonModel, PersonTruth


class TelemetryBody:
    """A real (or PX4-simulated) vehicle as a body: its pose is its latest telemetry, taken as the truth."""

    def __init__(self, autopilot: Autopilot) -> None:
        self.vehicle_id = autopilot.vehicle_id
        self._autopilot = autopilot

    def advance(self, now_s: float) -> None:
        return None

    def pose(self) -> BodyPose | None:
        s = self._autopilot.state()
        if s is None:
            return None
        return BodyPose(
            vehicle_id=s.vehicle_id,
            stamp_s=s.stamp_s,
            position_m=s.position_m,
            believed_offset_m=np.zeros(3),
            yaw_rad=s.yaw_rad,
            roll_rad=s.roll_rad,
            pitch_rad=s.pitch_rad,
            in_air=s.in_air,
            position_cov_m2=s.position_cov_m2,
        )


@dataclass(frozen=True)
class DetectorParams:
    """rate_hz: frames per second per camera; noise: the measurement model's spherical noise;
    add_pose_covariance: a world-frame detection's covariance includes the MAV's self-localisation
    covariance (its GPS drift is unknown to it, so without this, teammates' detections disagree beyond their
    covariance)."""

    rate_hz: float = 4.0
    noise: NoiseParams = field(default_factory=NoiseParams)
    add_pose_covariance: bool = True


@dataclass(frozen=True, eq=False)
class CameraFrame:
    """One camera frame of one airborne vehicle: what it showed and whether a detection came of it."""

    vehicle_id: int
    stamp_s: float
    view: FrameView
    detected: bool


@dataclass(frozen=True, eq=False)
class _Shot:
    """A frame an airborne camera takes: its vehicle, when, the body's pose and the person's truth then."""

    vehicle_id: int
    stamp_s: float
    pose: BodyPose
    truth: PersonTruth


class SimWorld:
    """The simulated world: a person model, static obstacles, bodies with cameras, and a detector.

    rngs: one generator per vehicle id for its detector noise. physics_step_s: bodies and cameras are stepped
    on this grid inside each `advance`, whatever the control rate. start_s: the world's time at creation
    (a camera emulator joining a running mission starts at its time, not at 0).
    """

    def __init__(
        self,
        *,
        person: PersonModel,
        obstacles: Sequence[Obstacle],
        bodies: Sequence[Body],
        rngs: Mapping[int, np.random.Generator],
        camera: CameraParams | None = None,
        detector: DetectorParams | None = None,
        physics_step_s: float = 0.01,
        start_s: float = 0.0,
    ) -> None:
        camera = camera or CameraParams()
        detector = detector or DetectorParams()
        if not (detector.rate_hz > 0 and physics_step_s > 0):
            raise ValueError("detector rate and physics step must be positive")
        self._person = person
        self._obstacles = tuple(obstacles)
        self._bodies = tuple(bodies)
        ids = [b.vehicle_id for b in self._bodies]
        if len(set(ids)) != len(ids) or set(ids) - set(rngs):
            raise ValueError("bodies need unique vehicle ids, each with a detector rng")
        self._rngs = dict(rngs)
        self._camera = camera
        self._detector = detector
        self._step = float(physics_step_s)
        period = 1.0 / detector.rate_hz
        self._period = period
        # Stagger the cameras over one frame period, as unsynchronised cameras are.
        self._next_frame = {
            b.vehicle_id: start_s + period * i / max(len(ids), 1) for i, b in enumerate(self._bodies)
        }
        self._pending: dict[int, list[Detection]] = {v: [] for v in ids}
        self._frames: deque[CameraFrame] = deque(maxlen=100_000)  # bounded if nobody drains it
        self._t = float(start_s)
        self._truth = person.truth(self._t)

    @property
    def obstacles(self) -> tuple[Obstacle, ...]:
        return self._obstacles

    @property
    def camera(self) -> CameraParams:
        return self._camera

    @property
    def time_s(self) -> float:
        return self._t

    @property
    def bodies(self) -> tuple[Body, ...]:
        return self._bodies

    def person_truth(self) -> PersonTruth:
        return self._truth

    def advance(self, now_s: float) -> None:
        """Step the bodies to now_s on the physics grid, taking each camera's frames when they are due.

        The frames are developed (projected, detected) after the last step, in the order they were taken,
        so that one call of scipy's makes all their rotations (`body_rotations`); what each frame sees was
        fixed when it was taken, and each camera's detector draws from its own generator.
        """
        if not math.isfinite(now_s):
            raise ValueError(f"time must be finite, got {now_s}")
        t0 = self._t
        if now_s <= t0:
            return
        n = max(1, math.ceil((now_s - t0) / self._step - 1e-9))
        shots: list[_Shot] = []
        for k in range(1, n + 1):
            t = now_s if k == n else t0 + (now_s - t0) * k / n
            for body in self._bodies:
                body.advance(t)
            self._t = t
            for body in self._bodies:
                if self._next_frame[body.vehicle_id] <= t + 1e-9:
                    if self._truth.stamp_s != t:
                        self._truth = self._person.truth(t)
                    shot = self._shoot(body, t)
                    if shot is not None:
                        shots.append(shot)
        self._develop(shots)
        if self._truth.stamp_s != now_s:
            self._truth = self._person.truth(now_s)

    def _shoot(self, body: Body, t: float) -> _Shot | None:
        """The frame body's camera takes at t (due now), or None while the body is not in the air."""
        vid = body.vehicle_id
        while self._next_frame[vid] <= t + 1e-9:
            self._next_frame[vid] += self._period
        pose = body.pose()
        if pose is None or not pose.in_air:
            return None
        return _Shot(vehicle_id=vid, stamp_s=t, pose=pose, truth=self._truth)

    def _develop(self, shots: list[_Shot]) -> None:
        """What each frame shows, its detection if it sees the person, and its record, in order."""
        if not shots:
            return
        rotations = body_rotations([(s.pose.yaw_rad, s.pose.pitch_rad, s.pose.roll_rad) for s in shots])
        for shot, r_wb in zip(shots, rotations, strict=True):
            vid, t, pose, truth = shot.vehicle_id, shot.stamp_s, shot.pose, shot.truth
            cam = mounted_camera_pose(
                body_position_m=pose.position_m, body_to_world=r_wb, params=self._camera
            )
            view = view_person(
                pose=cam,
                center_m=truth.position_m,
                feet_m=truth.feet_m,
                head_m=truth.head_m,
                obstacles=self._obstacles,
                params=self._camera,
            )
            if view.visible:
                pos, cov = sample_detection(
                    self._rngs[vid],
                    camera_position_m=cam.position_m,
                    target_position_m=truth.position_m,
                    noise=self._detector.noise,
                )
                # Placed in the world with the MAV's believed pose, so its covariance includes the MAV's own
                # self-localisation covariance (independent of the camera noise).
                self._pending[vid].append(
                    Detection(
                        source_id=vid,
                        stamp_s=t,
                        position_m=np.asarray(pos) + pose.believed_offset_m,
                        cov_m2=cov + pose.position_cov_m2 if self._detector.add_pose_covariance else cov,
                    )
                )
            self._frames.append(CameraFrame(vehicle_id=vid, stamp_s=t, view=view, detected=view.visible))

    def detections(self, vehicle_id: int) -> tuple[Detection, ...]:
        pending = self._pending.get(vehicle_id)
        if not pending:
            return ()
        out = tuple(pending)
        pending.clear()
        return out

    def drain_frames(self) -> tuple[CameraFrame, ...]:
        """Every camera frame taken since the last call (for metrics and displays)."""
        out = tuple(self._frames)
        self._frames.clear()
        return out

    def poses(self) -> dict[int, BodyPose | None]:
        """The true pose of every body, by vehicle id."""
        return {b.vehicle_id: b.pose() for b in self._bodies}

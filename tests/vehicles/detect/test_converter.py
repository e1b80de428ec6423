"""The agent's side: camera detections converted with the pose at capture time, fused, counted, never
waited for."""

from __future__ import annotations

import numpy as np

from vehicles.agent import Agent, AgentInputs, AgentRole
from vehicles.autopilot import AutopilotState, FlightMode
from vehicles.camera import camera_pose, project
from vehicles.detect.calibration import Calibration
from vehicles.detect.converter import ConverterParams, DetectionConverter
from vehicles.detect.pixels import CameraDetection, PersonPixels

CAL = Calibration.from_camera_params()
FEET = np.array([1.0, -0.5, 0.0])


def _state(t: float, vid: int = 1) -> AutopilotState:
    """A MAV 8 m west of the person, 8.9 m up, turning slowly (so the pose at capture time matters)."""
    return AutopilotState(
        vehicle_id=vid,
        stamp_s=t,
        position_m=np.array([-7.0 + 0.5 * t, -0.5, 8.9]),
        velocity_mps=np.array([0.5, 0.0, 0.0]),
        yaw_rad=0.02 * t,
        armed=True,
        in_air=True,
        mode=FlightMode.OFFBOARD,
    )


def _seen(t: float, vid: int = 1) -> CameraDetection:
    s = _state(t, vid)
    pose = camera_pose(body_position_m=s.position_m, yaw_rad=s.yaw_rad)
    px, _ = project(np.stack([FEET + [0, 0, 1.75], FEET]), pose)
    person = PersonPixels(
        head_px=px[0], feet_px=px[1], head_conf=0.9, feet_conf=0.8, box_px=np.array([0.0, 0.0, 1.0, 1.0])
    )
    return CameraDetection(
        vehicle_id=vid, stamp_s=t, frame_seq=int(t * 10), image_size_px=(2040, 1086), person=person
    )


def test_detections_are_placed_with_the_pose_at_their_capture_time():
    conv = DetectionConverter(vehicle_id=1, calibration=CAL)
    for k in range(20):
        conv.record_pose(_state(0.05 * k))
    out = conv.convert(1.0, [_seen(0.42), _seen(0.77)])
    assert len(out) == 2
    for det in out:
        np.testing.assert_allclose(det.position_m, FEET + [0, 0, 0.9], atol=1e-3)
    stats = conv.stats()
    assert stats.converted == 2 and stats.rejected_total == 0
    assert 0.2 < stats.latency_p50_s < 0.6


def test_a_detection_newer_than_the_pose_waits_without_blocking_then_converts():
    conv = DetectionConverter(vehicle_id=1, calibration=CAL)
    conv.record_pose(_state(0.0))
    assert conv.convert(0.05, [_seen(0.04)]) == ()
    assert conv.stats().pending == 1
    conv.record_pose(_state(0.1))
    out = conv.convert(0.1, [])
    assert len(out) == 1 and conv.stats().pending == 0


def test_a_detection_whose_pose_never_comes_is_dropped_and_counted():
    conv = DetectionConverter(vehicle_id=1, calibration=CAL, params=ConverterParams(max_wait_s=0.2))
    conv.record_pose(_state(0.0))
    conv.convert(0.05, [_seen(0.04)])
    assert conv.convert(0.5, []) == ()
    assert dict(conv.stats().rejected) == {"no_pose": 1}


def test_another_vehicles_and_stale_detections_are_rejected():
    conv = DetectionConverter(vehicle_id=1, calibration=CAL)
    for k in range(60):
        conv.record_pose(_state(0.05 * k))
    assert conv.convert(2.9, [_seen(1.0, vid=2), _seen(0.5)]) == ()
    assert dict(conv.stats().rejected) == {"foreign": 1, "too_old": 1}


def test_the_agent_fuses_its_cameras_pixel_detections_and_counts_them():
    agent = Agent(vehicle_id=1, converter=DetectionConverter(vehicle_id=1, calibration=CAL))
    out = None
    shared = 0
    for k in range(40):
        t = 0.05 * k
        camera = (_seen(t - 0.15),) if k >= 4 and k % 2 == 0 else ()
        out = agent.tick(t, AgentInputs(own=_state(t), camera=camera, role=AgentRole.GROUND))
        shared += sum(1 for m in out.outbox if getattr(m, "source_id", None) == 1)
    assert out is not None and out.camera is not None
    assert out.camera.converted == 18
    assert out.counters.own_detections_fused == 18
    assert out.person is not None
    np.testing.assert_allclose(out.person.position_m, FEET + [0, 0, 0.9], atol=0.05)
    assert shared == 18  # converted detections go to the teammates, as the simulated camera's do


def test_an_agent_without_a_converter_counts_camera_detections_as_rejected():
    agent = Agent(vehicle_id=1)
    out = agent.tick(0.0, AgentInputs(own=_state(0.0), camera=(_seen(0.0),), role=AgentRole.GROUND))
    assert out.counters.rejected_messages == 1 and out.camera is None

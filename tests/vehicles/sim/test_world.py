"""The simulated world: cameras at 4 Hz, occlusion by trunks, detections in the MAV's believed frame."""

import math

import numpy as np
import pytest

from controller.messages import Obstacle
from vehicles.sim.autopilot import SimAutopilot
from vehicles.sim.gps_drift import DriftParams, GpsDrift
from vehicles.sim.person import StillPerson
from vehicles.sim.world import SimWorld


def _world(obstacles=(), drift=False, n=1, seed=0, drift_params=None):
    """n MAVs on the 8 m circle about a person at the origin, facing it; returns (world, autopilots)."""
    drift_params = drift_params or DriftParams(enabled=drift)
    aps = []
    for k in range(n):
        b = 2 * math.pi * k / n
        aps.append(
            SimAutopilot(
                vehicle_id=k + 1,
                start_position_m=(8 * math.cos(b), 8 * math.sin(b), 0.0),
                start_yaw_rad=b + math.pi,
                drift=GpsDrift(np.random.default_rng(seed + k), drift_params),
            )
        )
    world = SimWorld(
        person=StillPerson(),
        obstacles=obstacles,
        bodies=aps,
        rngs={a.vehicle_id: np.random.default_rng(100 + a.vehicle_id) for a in aps},
    )
    return world, aps


def _fly(world, aps, t_end, t0=0.0, dt=0.1):
    t = t0
    while t < t_end - 1e-9:
        t = round(t + dt, 6)
        world.advance(t)
    return t


def _airborne(world, aps):
    for a in aps:
        a.takeoff(8.9)
    t = _fly(world, aps, 12.0)
    world.drain_frames()
    for a in aps:
        world.detections(a.vehicle_id)
    return t


def test_no_frames_or_detections_on_the_ground():
    world, aps = _world()
    _fly(world, aps, 5.0)
    assert world.drain_frames() == ()
    assert world.detections(1) == ()


def test_an_airborne_camera_detects_the_visible_person_at_4_hz():
    world, aps = _world()
    t = _airborne(world, aps)
    _fly(world, aps, t + 10.0, t0=t)
    frames = world.drain_frames()
    detections = world.detections(1)
    assert len(frames) == 40
    assert all(f.view.in_frame and f.view.visible for f in frames)
    assert len(detections) == 40
    np.testing.assert_allclose(np.diff([d.stamp_s for d in detections]), 0.25, atol=1e-9)


def test_cameras_of_a_team_are_staggered_within_a_frame_period():
    world, aps = _world(n=3)
    t = _airborne(world, aps)
    _fly(world, aps, t + 1.0, t0=t)
    firsts = sorted({f.vehicle_id: f.stamp_s for f in reversed(world.drain_frames())}.values())
    assert np.diff(firsts) == pytest.approx([0.25 / 3, 0.25 / 3], abs=0.011)


def test_detections_scatter_about_the_person_with_their_covariance():
    world, aps = _world()
    t = _airborne(world, aps)
    _fly(world, aps, t + 100.0, t0=t)
    dets = world.detections(1)
    err = np.array([d.position_m - [0.0, 0.0, 0.9] for d in dets])
    # normalised squared errors average the 3 dof when the reported covariance is right (the pose covariance
    # added for GPS drift makes it conservative when drift is off: the average is then below 3)
    nees = np.array([e @ np.linalg.solve(d.cov_m2, e) for e, d in zip(err, dets, strict=True)])
    assert 0.3 < nees.mean() < 3.0
    assert np.linalg.norm(err.mean(axis=0)) < 0.3


def test_detections_are_shifted_by_the_mavs_own_gps_drift():
    frozen = DriftParams(accel_noise=(0.0, 0.0, 0.0), leg_s=1e9)  # a constant offset
    world, aps = _world(seed=3, drift_params=frozen)
    t = _airborne(world, aps)
    _fly(world, aps, t + 100.0, t0=t)
    dets = world.detections(1)
    offset = aps[0].pose().believed_offset_m
    mean_err = np.mean([d.position_m for d in dets], axis=0) - [0.0, 0.0, 0.9]
    assert np.linalg.norm(offset) > 0.3
    np.testing.assert_allclose(mean_err, offset, atol=0.3)


def test_a_trunk_in_the_line_of_sight_hides_the_person_from_the_detector():
    trunk = Obstacle(obstacle_id="t", center_m=np.array((4.0, 0.0)), radius_m=0.3)
    world, aps = _world(obstacles=(trunk,))
    t = _airborne(world, aps)
    _fly(world, aps, t + 5.0, t0=t)
    frames = world.drain_frames()
    assert len(frames) == 20 and all(f.view.in_frame and not f.view.visible for f in frames)
    assert world.detections(1) == ()


def test_detection_streams_are_reproducible_from_the_seeds():
    def run():
        world, aps = _world(drift=True, n=2)
        t = _airborne(world, aps)
        _fly(world, aps, t + 5.0, t0=t)
        return [d.position_m for d in world.detections(1) + world.detections(2)]

    np.testing.assert_array_equal(run(), run())

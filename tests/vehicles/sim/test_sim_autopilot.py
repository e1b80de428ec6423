"""The simulated vehicle and autopilot: modes, limits, lag, failsafe, yaw, battery, GPS drift."""

import math

import numpy as np
import pytest

from vehicles.autopilot import FlightMode, Setpoint
from vehicles.sim.autopilot import AirframeParams, SimAutopilot
from vehicles.sim.gps_drift import DriftParams, GpsDrift

DT = 0.01


def _vehicle(drift=False, seed=0, start=(0.0, 0.0, 0.0)):
    return SimAutopilot(
        vehicle_id=1,
        start_position_m=start,
        drift=GpsDrift(np.random.default_rng(seed), DriftParams(enabled=drift)),
    )


def _run(ap, t0, duration, setpoint_fn=None, every=1):
    """Advance from t0 for duration in 10 ms steps, sending setpoint_fn(t) every `every` steps."""
    t = t0
    log = []
    for i in range(round(duration / DT)):
        t = round(t + DT, 6)
        if setpoint_fn is not None and i % every == 0:
            ap.send_setpoint(setpoint_fn(t))
        ap.advance(t)
        log.append((t, ap.true_position_m, ap.state()))
    return t, log


def _airborne(height=8.9):
    ap = _vehicle()
    ap.takeoff(height)
    t, _ = _run(ap, 0.0, 12.0)
    return ap, t


def test_starts_on_the_ground_disarmed_and_ready():
    s = _vehicle().state()
    assert (s.armed, s.in_air, s.mode) == (False, False, FlightMode.READY)
    assert s.battery_fraction == pytest.approx(1.0)


def test_takeoff_climbs_to_the_height_and_holds_there():
    ap = _vehicle()
    ap.takeoff(8.9)
    t, log = _run(ap, 0.0, 12.0)
    s = ap.state()
    assert (s.armed, s.in_air, s.mode) == (True, True, FlightMode.HOLD)
    assert s.position_m[2] == pytest.approx(8.9, abs=0.2)
    climb = np.diff([p[2] for _, p, _ in log]) / DT
    assert np.max(climb) <= 1.5 * 1.1  # the takeoff speed, with the attitude lag's small overshoot


def test_setpoints_on_the_ground_are_refused_and_counted():
    ap = _vehicle()
    _run(
        ap,
        0.0,
        1.0,
        lambda t: Setpoint(
            stamp_s=t, position_m=np.array((5, 0, 5)), velocity_mps=np.array((0, 0, 0)), yaw_rad=0
        ),
    )
    assert ap.state().position_m == pytest.approx(np.zeros(3))
    assert ap.refused_commands == 100


def test_offboard_step_settles_within_limits():
    ap, t = _airborne()
    start = ap.true_position_m
    goal = start + np.array([10.0, 0.0, 0.0])
    t, log = _run(
        ap,
        t,
        15.0,
        lambda t: Setpoint(stamp_s=t, position_m=goal, velocity_mps=np.array((0, 0, 0)), yaw_rad=0.0),
    )
    assert ap.state().mode == FlightMode.OFFBOARD
    np.testing.assert_allclose(ap.true_position_m, goal, atol=0.05)
    speeds = [np.linalg.norm(s.velocity_mps[:2]) for _, _, s in log]
    assert max(speeds) <= AirframeParams().max_speed_xy_mps + 1e-6
    v = np.array([s.velocity_mps[0] for _, _, s in log])
    assert np.max(np.abs(np.diff(v) / DT)) <= AirframeParams().max_accel_xy_mps2 + 1e-6


@pytest.mark.parametrize(("speed", "low", "high"), [(2.0, 0.2, 0.4), (4.0, 0.9, 1.4)])
def test_tracking_a_circle_lags_like_a_real_position_controller(speed, low, high):
    # Position + velocity feed-forward, no acceleration feed-forward: the cascade's steady lag is about
    # a / (K_pos K_vel) = (v^2 / r) / 1.71: 0.29 m at 2 m/s, 1.17 m at 4 m/s (2 m/s^2) on an 8 m circle.
    ap, t = _airborne()
    centre = ap.true_position_m - np.array([8.0, 0.0, 0.0])
    w = speed / 8.0
    t0 = t

    def sp(t):
        a = w * (t - t0)
        return Setpoint(
            stamp_s=t,
            position_m=centre + 8.0 * np.array([math.cos(a), math.sin(a), 0.0]),
            velocity_mps=speed * np.array([-math.sin(a), math.cos(a), 0.0]),
            yaw_rad=0.0,
        )

    t, log = _run(ap, t, 30.0, sp)
    errors = [np.linalg.norm(p - sp(tt).position_m) for tt, p, _ in log[1500:]]
    assert low < np.mean(errors) < high


def test_the_acceleration_feed_forward_takes_the_lag_out_of_tracking_a_circle():
    """With the centripetal acceleration fed forward (as skyring sends the plan's), the cascade no longer has
    to fall behind to build it up: at 4 m/s on the 8 m circle the lag drops from about 1.2 m (the test above)
    to what the attitude lag leaves, 0.12 m."""
    ap, t = _airborne()
    centre = ap.true_position_m - np.array([8.0, 0.0, 0.0])
    w = 4.0 / 8.0
    t0 = t

    def sp(t):
        a = w * (t - t0)
        radial = np.array([math.cos(a), math.sin(a), 0.0])
        return Setpoint(
            stamp_s=t,
            position_m=centre + 8.0 * radial,
            velocity_mps=4.0 * np.array([-math.sin(a), math.cos(a), 0.0]),
            yaw_rad=0.0,
            acceleration_mps2=-(4.0**2 / 8.0) * radial,
        )

    t, log = _run(ap, t, 30.0, sp)
    errors = [np.linalg.norm(p - sp(tt).position_m) for tt, p, _ in log[1500:]]
    assert np.mean(errors) < 0.2


def test_the_acceleration_feed_forward_only_counts_in_offboard():
    """Hold ignores the last offboard set-point's acceleration: the vehicle rests where it is."""
    ap, t = _airborne()
    here = ap.true_position_m
    push = Setpoint(
        stamp_s=t,
        position_m=here,
        velocity_mps=np.zeros(3),
        yaw_rad=0.0,
        acceleration_mps2=np.array([3.0, 0, 0]),
    )
    ap.send_setpoint(push)
    ap.hold()
    t, _ = _run(ap, t, 3.0)
    assert ap.state().mode == FlightMode.HOLD
    np.testing.assert_allclose(ap.true_position_m, here, atol=0.05)


def test_lost_setpoint_stream_falls_back_to_hold_after_half_a_second():
    ap, t = _airborne()
    goal = ap.true_position_m + np.array([1.0, 0.0, 0.0])
    t, _ = _run(
        ap,
        t,
        1.0,
        lambda t: Setpoint(stamp_s=t, position_m=goal, velocity_mps=np.array((0, 0, 0)), yaw_rad=0),
    )
    assert ap.state().mode == FlightMode.OFFBOARD
    t, log = _run(ap, t, 1.0)
    modes = [s.mode for _, _, s in log]
    assert modes[45] == FlightMode.OFFBOARD and modes[55] == FlightMode.HOLD
    assert ap.failsafe_holds == 1


def test_land_descends_at_land_speed_and_disarms_on_the_ground():
    ap, t = _airborne(5.0)
    ap.land()
    t, log = _run(ap, t, 12.0)
    s = ap.state()
    assert (s.armed, s.in_air, s.mode) == (False, False, FlightMode.READY)
    assert ap.true_position_m[2] == pytest.approx(0.0)
    descent = -np.diff([p[2] for _, p, _ in log[:300]]) / DT
    assert np.median(descent[150:]) == pytest.approx(0.7, abs=0.02)


def test_setpoints_during_landing_are_refused():
    ap, t = _airborne(5.0)
    ap.land()
    _run(
        ap,
        t,
        1.0,
        lambda t: Setpoint(
            stamp_s=t, position_m=np.array((0, 0, 8)), velocity_mps=np.array((0, 0, 0)), yaw_rad=0
        ),
    )
    assert ap.state().mode == FlightMode.LAND
    assert ap.refused_commands == 100


def test_yaw_follows_the_command_at_no_more_than_60_degrees_per_second():
    ap, t = _airborne()
    here = ap.state().position_m
    t, log = _run(
        ap,
        t,
        4.0,
        lambda t: Setpoint(
            stamp_s=t, position_m=here, velocity_mps=np.array((0, 0, 0)), yaw_rad=math.pi - 0.01
        ),
    )
    yaws = np.unwrap([s.yaw_rad for _, _, s in log])
    assert np.max(np.abs(np.diff(yaws))) / DT <= math.radians(60.0) + 1e-9
    assert yaws[99] == pytest.approx(math.radians(60.0), abs=math.radians(1.0))
    assert yaws[-1] == pytest.approx(math.pi - 0.01, abs=math.radians(0.5))


def test_battery_drains_by_one_twentieth_per_minute_in_the_air():
    ap, t = _airborne()
    before = ap.state().battery_fraction
    _run(ap, t, 60.0)
    after = ap.state().battery_fraction
    assert before is not None and after is not None
    assert before - after == pytest.approx(60.0 / 1200.0, rel=1e-6)


def test_reported_position_is_the_true_one_plus_the_gps_drift():
    drift = GpsDrift(np.random.default_rng(4))
    ap = SimAutopilot(vehicle_id=2, start_position_m=(3.0, 4.0, 0.0), drift=drift)
    ap.advance(0.5)
    np.testing.assert_allclose(ap.state().position_m, ap.true_position_m + drift.offset_m, atol=1e-12)
    assert np.linalg.norm(drift.offset_m) > 0.05
    np.testing.assert_allclose(ap.pose().believed_offset_m, drift.offset_m)


def test_hold_keeps_the_believed_position_so_the_true_one_drifts_with_the_gps():
    drift = GpsDrift(np.random.default_rng(8))
    ap = SimAutopilot(vehicle_id=1, start_position_m=(0.0, 0.0, 0.0), drift=drift)
    ap.takeoff(6.0)
    t, _ = _run(ap, 0.0, 10.0)
    believed0, true0 = ap.state().position_m, ap.true_position_m
    _run(ap, t, 120.0)
    np.testing.assert_allclose(ap.state().position_m, believed0, atol=0.05)
    assert np.linalg.norm(ap.true_position_m - true0) > 0.1


def test_accelerating_forward_pitches_the_body_nose_down():
    ap, t = _airborne()
    goal = ap.state().position_m + np.array([20.0, 0.0, 0.0])
    _run(
        ap,
        t,
        0.5,
        lambda t: Setpoint(stamp_s=t, position_m=goal, velocity_mps=np.array((0, 0, 0)), yaw_rad=0.0),
    )
    s = ap.state()
    assert s.pitch_rad < -math.radians(10.0)
    assert abs(s.roll_rad) < 1e-6


def test_bad_takeoff_height_is_refused():
    ap = _vehicle()
    ap.takeoff(float("nan"))
    ap.takeoff(-3.0)
    assert ap.refused_commands == 2
    assert not ap.state().armed


# ---- battery failsafe and fault injection -----------------------------------------------------------------


def test_at_the_failsafe_level_the_battery_failsafe_lands_the_vehicle_out_of_skyrings_control():
    ap, t = _airborne()
    ap.set_battery(0.151)  # draining in the air crosses 15 % within a couple of seconds
    t, log = _run(ap, t, 3.0)
    s = ap.state()
    assert s.mode == FlightMode.LAND and s.released
    assert s.failsafe and s.failsafe_reason == "battery 15 % at or below 15 %: landing"
    assert ap.failsafe_landings == 1
    ap.send_setpoint(
        Setpoint(stamp_s=t, position_m=np.array([0.0, 0.0, 9.0]), velocity_mps=np.zeros(3), yaw_rad=0.0)
    )
    assert ap.state().mode == FlightMode.LAND  # the failsafe has it: set-points are refused
    t, _ = _run(ap, t, 20.0)
    s = ap.state()
    assert (s.in_air, s.armed, s.failsafe, s.failsafe_reason) == (False, False, False, None)


def test_the_battery_failsafe_level_is_a_parameter():
    ap = SimAutopilot(
        vehicle_id=1,
        start_position_m=(0.0, 0.0, 0.0),
        drift=GpsDrift(np.random.default_rng(0), DriftParams(enabled=False)),
        params=AirframeParams(battery_land_fraction=0.30),
    )
    ap.takeoff(8.9)
    t, _ = _run(ap, 0.0, 12.0)
    ap.set_battery(0.31)
    _run(ap, t, 0.1)
    assert not ap.state().failsafe
    ap.set_battery(0.30)
    _run(ap, t + 0.1, 0.1)
    s = ap.state()
    assert s.mode == FlightMode.LAND and s.failsafe and "at or below 30 %" in (s.failsafe_reason or "")


def test_arming_on_a_battery_at_the_failsafe_level_is_refused_with_the_reason():
    ap = _vehicle()
    ap.set_battery(0.12)
    ap.takeoff(8.9)
    _run(ap, 0.0, 1.0)
    s = ap.state()
    assert not s.armed and not s.in_air
    assert s.arming_refusal == "battery 12 % at or below the failsafe level 15 %"
    ap.set_battery(0.9)  # a fresh battery
    ap.takeoff(8.9)
    _run(ap, 1.0, 1.0)
    assert ap.state().armed and ap.state().arming_refusal is None


def test_a_cut_link_freezes_telemetry_as_lost_and_drops_commands_until_restored():
    ap, t = _airborne()
    before = ap.state()
    ap.cut_link()
    t, _ = _run(ap, t, 0.5)
    assert not ap.state().link_lost and ap.state().stamp_s == before.stamp_s  # frozen, not yet flagged
    t, _ = _run(ap, t, 1.5)
    frozen = ap.state()
    assert frozen.link_lost and frozen.stamp_s == before.stamp_s  # flagged after 1 s, as PX4's back-end
    ap.land()  # does not arrive
    t, _ = _run(ap, t, 1.0)
    assert ap.in_air
    ap.restore_link()
    assert not ap.state().link_lost and ap.state().stamp_s == pytest.approx(t)


def test_place_at_moves_the_vehicle_at_rest_and_refuses_nonsense():
    ap, _ = _airborne()
    ap.place_at((3.0, -2.0, 7.0))
    assert np.allclose(ap.true_position_m, (3.0, -2.0, 7.0))
    with pytest.raises(ValueError):
        ap.place_at((0.0, 0.0, -1.0))
    with pytest.raises(ValueError):
        ap.set_battery(1.5)

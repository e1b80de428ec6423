"""The PX4 back-end's pure parts: set-point construction, mode reading, configuration
(vehicles/px4/autopilot.py)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from vehicles.autopilot import FlightMode, Setpoint
from vehicles.px4.autopilot import (
    Px4Autopilot,
    Px4Config,
    check_setpoint,
    frozen,
    ned_setpoint,
    sitl_urls,
    skyring_mode,
)
from vehicles.px4.geodesy import GeodeticPoint, LocalFrame, geodetic_to_enu

REF = GeodeticPoint(47.397742, 8.545594, 488.0)


def setpoint(position, velocity=(0.0, 0.0, 0.0), yaw=0.0, acceleration=(0.0, 0.0, 0.0)):
    return Setpoint(
        stamp_s=0.0, position_m=position, velocity_mps=velocity, yaw_rad=yaw, acceleration_mps2=acceleration
    )


def test_setpoint_at_the_reference_swaps_axes_and_flips_up():
    frame = LocalFrame.from_origin(local_origin=REF, reference=REF)
    ned = ned_setpoint(setpoint([10.0, 20.0, 8.0], [1.0, -2.0, 0.5], acceleration=[0.3, -0.4, 1.5]), frame)
    np.testing.assert_allclose(ned.position_ned_m, [20.0, 10.0, -8.0], atol=1e-9)
    np.testing.assert_allclose(ned.velocity_ned_mps, [-2.0, 1.0, -0.5], atol=1e-12)
    np.testing.assert_allclose(ned.acceleration_ned_mps2, [-0.4, 0.3, -1.5], atol=1e-12)


@pytest.mark.parametrize(
    ("yaw_enu", "yaw_ned_deg"), [(0.0, 90.0), (math.pi / 2, 0.0), (math.pi, -90.0), (-math.pi / 4, 135.0)]
)
def test_setpoint_yaw_is_converted_to_ned_degrees(yaw_enu, yaw_ned_deg):
    frame = LocalFrame.from_origin(local_origin=REF, reference=REF)
    assert ned_setpoint(setpoint([0, 0, 5], yaw=yaw_enu), frame).yaw_ned_deg == pytest.approx(yaw_ned_deg)


def test_setpoint_is_relative_to_the_vehicles_own_origin():
    # A vehicle that booted 30 m east and 2 m higher than the team origin.
    origin = GeodeticPoint(REF.latitude_deg, REF.longitude_deg + 30.0 / 75_000.0, 490.0)
    frame = LocalFrame.from_origin(local_origin=origin, reference=REF)
    offset = geodetic_to_enu(origin, reference=REF)
    ned = ned_setpoint(setpoint(offset + [0.0, 5.0, 6.0]), frame)
    np.testing.assert_allclose(ned.position_ned_m, [5.0, 0.0, -6.0], atol=1e-3)


def test_setpoint_round_trips_through_the_frame():
    origin = GeodeticPoint(REF.latitude_deg + 0.001, REF.longitude_deg - 0.002, 470.0)
    frame = LocalFrame.from_origin(local_origin=origin, reference=REF)
    rng = np.random.default_rng(7)
    for p in rng.uniform(-100, 100, size=(10, 3)):
        ned = ned_setpoint(setpoint(p), frame)
        np.testing.assert_allclose(frame.to_enu(ned.position_ned_m), p, atol=1e-9)


@pytest.mark.parametrize(
    ("name", "mode"),
    [
        ("OFFBOARD", FlightMode.OFFBOARD),
        ("HOLD", FlightMode.HOLD),
        ("LAND", FlightMode.LAND),
        ("TAKEOFF", FlightMode.TAKEOFF),
        ("RETURN_TO_LAUNCH", FlightMode.RETURN),
        ("POSCTL", FlightMode.MANUAL),
        ("ALTCTL", FlightMode.MANUAL),
        ("STABILIZED", FlightMode.MANUAL),
        ("MISSION", FlightMode.UNKNOWN),
    ],
)
def test_px4_modes_read_as_skyring_modes_when_armed(name, mode):
    assert skyring_mode(name, armed=True, in_air=True) is mode


def test_disarmed_on_the_ground_reads_ready_whatever_the_mode():
    assert skyring_mode("LAND", armed=False, in_air=False) is FlightMode.READY


def test_check_setpoint_accepts_a_setpoint_near_the_team():
    assert check_setpoint(setpoint([100.0, -50.0, 8.0]), max_range_m=2000.0) is None


def test_check_setpoint_refuses_a_far_setpoint_with_the_distance():
    assert "2500 m" in str(check_setpoint(setpoint([2500.0, 0.0, 0.0]), max_range_m=2000.0))


def test_check_setpoint_refuses_what_is_not_a_setpoint():
    assert "expected a Setpoint" in str(check_setpoint((1.0, 2.0, 3.0), max_range_m=2000.0))


def test_sitl_urls_follow_px4_instance_ports():
    assert sitl_urls(3) == ["udpin://0.0.0.0:14540", "udpin://0.0.0.0:14541", "udpin://0.0.0.0:14542"]
    assert sitl_urls(11)[-2:] == ["udpin://0.0.0.0:14549", "udpin://0.0.0.0:14549"]


def test_failsafe_params_are_typed_for_px4():
    params = Px4Config(offboard_loss_action=5, datalink_loss_action=1).failsafe_params()
    assert params == {"COM_OF_LOSS_T": 1.0, "COM_OBL_RC_ACT": 5, "NAV_DLL_ACT": 1, "COM_LOW_BAT_ACT": 2}
    assert isinstance(params["COM_OF_LOSS_T"], float) and isinstance(params["COM_OBL_RC_ACT"], int)


def test_battery_failsafe_is_left_alone_when_asked():
    assert "COM_LOW_BAT_ACT" not in Px4Config(low_battery_action=None).failsafe_params()


@pytest.mark.parametrize(
    "kw",
    [
        {"offboard_loss_action": 0},
        {"datalink_loss_action": 4},
        {"low_battery_action": 1},
        {"link_lost_after_s": 0.0},
        {"connect_timeout_s": math.nan},
    ],
)
def test_config_rejects_unsafe_or_meaningless_values(kw):
    with pytest.raises(ValueError):
        Px4Config(**kw)


def test_unconnected_autopilot_has_no_state_and_refuses_commands_without_raising():
    a = Px4Autopilot(vehicle_id=1, url="udpin://127.0.0.1:1")
    assert a.state() is None
    a.send_setpoint(setpoint([0.0, 0.0, 5.0]))
    a.takeoff(5.0)
    status = a.status()
    assert status.rejected_setpoints == 1
    assert status.failed_commands == 1
    assert status.fault is not None
    assert "not connected" in status.fault


def test_takeoff_height_out_of_range_is_refused_and_counted():
    a = Px4Autopilot(vehicle_id=1, url="udpin://127.0.0.1:1")
    a.takeoff(float("nan"))
    a.takeoff(500.0)
    assert a.status().failed_commands == 2
    assert "[0.5, 120]" in str(a.status().fault)


def test_a_stopped_process_stood_frozen_a_busy_or_starved_one_did_not():
    assert frozen(6.0, 0.0)  # SIGSTOP: no thread ran
    assert frozen(2.5, 0.03)  # (the instants before and after the stop)
    assert not frozen(2.5, 2.5)  # the event loop was busy: the process ran flat out
    assert not frozen(2.5, 0.2)  # starved on a loaded machine, but MAVSDK's threads got some CPU
    assert not frozen(0.0, 0.0)

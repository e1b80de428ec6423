"""ENU <-> NED, yaw conventions and geodetic <-> team ENU (vehicles/px4/geodesy.py)."""

from __future__ import annotations

import math

import numpy as np
import pymap3d
import pytest

from controller.angles import wrap_angle
from vehicles.px4.geodesy import (
    GeodeticPoint,
    LocalFrame,
    enu_to_geodetic,
    enu_to_ned,
    geodetic_to_enu,
    ned_to_enu,
    parse_geodetic,
    yaw_enu_to_ned,
    yaw_ned_to_enu,
)

ZURICH = GeodeticPoint(47.397742, 8.545594, 488.0)


def test_enu_to_ned_swaps_east_north_and_flips_up():
    np.testing.assert_allclose(enu_to_ned([1.0, 2.0, 3.0]), [2.0, 1.0, -3.0])


def test_ned_to_enu_inverts_enu_to_ned_for_a_batch():
    rng = np.random.default_rng(1)
    v = rng.normal(size=(50, 3))
    np.testing.assert_allclose(ned_to_enu(enu_to_ned(v)), v, atol=1e-12)


@pytest.mark.parametrize(
    ("yaw_enu", "yaw_ned"),
    [
        (0.0, math.pi / 2),  # facing east
        (math.pi / 2, 0.0),  # facing north
        (math.pi, -math.pi / 2),  # facing west
        (-math.pi / 2, -math.pi),  # facing south (wrapped into [-pi, pi))
    ],
)
def test_yaw_enu_to_ned_maps_compass_directions(yaw_enu, yaw_ned):
    assert yaw_enu_to_ned(yaw_enu) == pytest.approx(yaw_ned, abs=1e-12)


def test_yaw_ned_to_enu_inverts_yaw_enu_to_ned():
    rng = np.random.default_rng(2)
    for yaw in rng.uniform(-math.pi, math.pi, size=100):
        assert yaw_ned_to_enu(yaw_enu_to_ned(yaw)) == pytest.approx(wrap_angle(yaw), abs=1e-12)


def test_geodetic_to_enu_of_a_point_111_m_north_is_111_m_north():
    north = GeodeticPoint(ZURICH.latitude_deg + 0.001, ZURICH.longitude_deg, ZURICH.altitude_m)
    enu = geodetic_to_enu(north, reference=ZURICH)
    assert enu[0] == pytest.approx(0.0, abs=1e-6)
    assert enu[1] == pytest.approx(111.2, abs=0.2)  # one milli-degree of latitude at 47 deg N
    assert enu[2] == pytest.approx(0.0, abs=1e-2)


def test_enu_to_geodetic_round_trips_within_a_millimetre():
    rng = np.random.default_rng(3)
    for enu in rng.uniform(-500, 500, size=(20, 3)):
        back = geodetic_to_enu(enu_to_geodetic(enu, reference=ZURICH), reference=ZURICH)
        np.testing.assert_allclose(back, enu, atol=1e-3)


def test_parse_geodetic_reads_lat_lon_alt():
    assert parse_geodetic(" 47.5, 8.5 ,400") == GeodeticPoint(47.5, 8.5, 400.0)


@pytest.mark.parametrize("text", ["47.5,8.5", "a,b,c", "95,8,0", "47,8,nan"])
def test_parse_geodetic_rejects_malformed_text_with_a_reason(text):
    with pytest.raises(ValueError, match="lat|latitude|finite"):
        parse_geodetic(text)


def test_local_frame_places_vehicle_origin_at_its_geodetic_offset():
    origin = GeodeticPoint(ZURICH.latitude_deg + 0.0002, ZURICH.longitude_deg - 0.0003, 490.0)
    frame = LocalFrame.from_origin(local_origin=origin, reference=ZURICH)
    np.testing.assert_allclose(frame.to_enu([0, 0, 0]), geodetic_to_enu(origin, reference=ZURICH), atol=1e-9)


def test_local_frame_agrees_with_pymap3d_ned_to_geodetic_to_enu():
    # Independent path: local NED -> geodetic about the vehicle origin -> ENU about the team reference.
    origin = GeodeticPoint(ZURICH.latitude_deg + 0.004, ZURICH.longitude_deg + 0.006, 470.0)  # ~600 m away
    frame = LocalFrame.from_origin(local_origin=origin, reference=ZURICH)
    rng = np.random.default_rng(4)
    for ned in rng.uniform(-200, 200, size=(20, 3)):
        lat, lon, alt = pymap3d.ned2geodetic(
            ned[0], ned[1], ned[2], origin.latitude_deg, origin.longitude_deg, origin.altitude_m
        )
        truth = geodetic_to_enu(GeodeticPoint(lat, lon, alt), reference=ZURICH)
        np.testing.assert_allclose(frame.to_enu(ned), truth, atol=1e-4)


def test_local_frame_to_ned_inverts_to_enu():
    origin = GeodeticPoint(ZURICH.latitude_deg - 0.001, ZURICH.longitude_deg + 0.002, 480.0)
    frame = LocalFrame.from_origin(local_origin=origin, reference=ZURICH)
    p = np.array([12.0, -30.0, 8.0])
    np.testing.assert_allclose(frame.to_enu(frame.to_ned(p)), p, atol=1e-9)


def test_local_frame_at_the_reference_is_the_plain_swap():
    frame = LocalFrame.from_origin(local_origin=ZURICH, reference=ZURICH)
    np.testing.assert_allclose(frame.to_enu([3.0, 4.0, -5.0]), [4.0, 3.0, 5.0], atol=1e-9)
    np.testing.assert_allclose(frame.vector_to_ned([1.0, 0.0, 0.0]), [0.0, 1.0, 0.0], atol=1e-12)
    assert frame.yaw_to_enu(0.0) == pytest.approx(math.pi / 2, abs=1e-12)


def test_local_frame_yaw_round_trips_and_tilts_with_distance():
    far = GeodeticPoint(ZURICH.latitude_deg, ZURICH.longitude_deg + 0.1, 488.0)  # ~7.5 km east
    frame = LocalFrame.from_origin(local_origin=far, reference=ZURICH)
    # not exact: the heading leaves the other tangent plane by the tilt, second order (~1e-7 rad here)
    assert frame.yaw_to_ned(frame.yaw_to_enu(0.3)) == pytest.approx(0.3, abs=1e-6)
    # meridians converge: north there is turned by dlon * sin(lat) ~ 1.3 mrad against north here
    tilt = frame.yaw_to_enu(0.0) - math.pi / 2
    assert tilt == pytest.approx(math.radians(0.1) * math.sin(math.radians(ZURICH.latitude_deg)), rel=0.01)


def test_local_frame_from_fix_recovers_the_origin_within_a_millimetre():
    origin = GeodeticPoint(ZURICH.latitude_deg + 0.0005, ZURICH.longitude_deg + 0.0005, 495.0)
    ned = np.array([40.0, -25.0, -12.0])
    lat, lon, alt = pymap3d.ned2geodetic(
        ned[0], ned[1], ned[2], origin.latitude_deg, origin.longitude_deg, origin.altitude_m
    )
    frame = LocalFrame.from_fix(position=GeodeticPoint(lat, lon, alt), local_ned_m=ned, reference=ZURICH)
    exact = LocalFrame.from_origin(local_origin=origin, reference=ZURICH)
    np.testing.assert_allclose(frame.offset_m, exact.offset_m, atol=1e-3)

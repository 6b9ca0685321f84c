"""Unit and frame conversions at the MAVLink boundary (property tests)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from remarl_fc.frames import (
    GeoPoint,
    cdeg_to_yaw,
    course_and_speed,
    from_deg_e7,
    geodetic_to_ned,
    heading_to_yaw,
    ne_to_sim,
    ned_to_geodetic,
    sim_to_ne,
    to_deg_e7,
    yaw_to_cdeg,
    yaw_to_heading,
)

lat = st.floats(-80.0, 80.0)
lon = st.floats(-179.0, 179.0)
metres = st.floats(-5000.0, 5000.0)
angle = st.floats(-10.0, 10.0)


@given(lat, lon, metres, metres, st.floats(-500.0, 500.0))
def test_ned_geodetic_round_trip(la, lo, n, e, d):
    home = GeoPoint(la, lo, 400.0)
    back = geodetic_to_ned(*ned_to_geodetic(n, e, d, home), home)
    np.testing.assert_allclose([float(v) for v in back], [n, e, d], atol=1e-6)


@given(lat, lon, st.floats(1.0, 2000.0))
def test_north_and_east_are_metres_on_the_ground(la, lo, dist):
    """Moving `dist` m north changes latitude by dist / M; east by dist / (N cos φ)."""
    home = GeoPoint(la, lo, 0.0)
    lat1, lon1, _ = ned_to_geodetic(dist, 0.0, 0.0, home)
    assert float(lon1) == pytest.approx(lo)
    assert float(lat1) > la
    # against a sphere of the mean radius: within the ellipsoid's flattening (< 1 %)
    r = 6_371_000.0
    dphi = math.radians(float(lat1) - la)
    assert r * dphi == pytest.approx(dist, rel=1e-2)


def test_one_degree_of_latitude_at_the_equator_is_110574_m():
    """WGS-84: the meridian arc from 0° to 1° is 110,574 m (± the flat-plane error)."""
    lat1, _, _ = ned_to_geodetic(110_574.0, 0.0, 0.0, GeoPoint(0.0, 0.0, 0.0))
    assert float(lat1) == pytest.approx(1.0, abs=2e-4)


@given(angle)
def test_heading_yaw_is_self_inverse(h):
    back = yaw_to_heading(heading_to_yaw(h))
    assert math.isclose(math.cos(back), math.cos(h), abs_tol=1e-9)
    assert math.isclose(math.sin(back), math.sin(h), abs_tol=1e-9)


@given(angle)
def test_heading_and_yaw_point_the_same_way(h):
    """A unit step along the simulator heading equals the step along the NED yaw."""
    step_sim = np.array([math.cos(h), math.sin(h)])  # (east, north)
    yaw = float(heading_to_yaw(h))
    step_ne = np.array([math.cos(yaw), math.sin(yaw)])  # (north, east)
    np.testing.assert_allclose(sim_to_ne(step_sim), step_ne, atol=1e-9)
    np.testing.assert_allclose(ne_to_sim(step_ne), step_sim, atol=1e-9)


@given(st.floats(-89.0, 89.0))
def test_deg_e7_round_trip_is_within_a_centimetre(deg):
    assert abs(float(from_deg_e7(to_deg_e7(deg))) - deg) <= 0.5e-7


@given(angle)
def test_cdeg_is_0_to_35999_and_round_trips(yaw):
    c = int(yaw_to_cdeg(yaw))
    assert 0 <= c <= 35999
    back = float(cdeg_to_yaw(c))
    assert math.isclose(math.cos(back), math.cos(yaw), abs_tol=1e-3)


def test_course_of_east_is_90_degrees():
    course, speed = course_and_speed(0.0, 3.0)
    assert math.degrees(float(course)) == pytest.approx(90.0) and float(speed) == 3.0


@pytest.mark.parametrize("text", ["1,2", "a,b,c", "95,0,0", "0,200,0"])
def test_bad_home_is_a_clear_error(text):
    with pytest.raises(ValueError, match=r"LAT|latitude|longitude"):
        GeoPoint.parse(text)

"""The ADS-B traffic picture: tracks in the mission frame, bad reports out."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from mavwire import ADSB_ALL, ORIGIN, QUANTUM_M, adsb

from remarl_fc.flight.traffic import TrafficPicture
from remarl_fc.mavlink.consts import AdsbFlag

# -- ADS-B ----------------------------------------------------------------------------------


def test_adsb_position_and_velocity():
    pic = TrafficPicture(ORIGIN)
    pic.update(adsb(0xABC123, 300.0, -200.0, 30.0, heading_cdeg=9000, speed_cm_s=1500), 4.0)
    (intr,) = pic.current(4.0, 30.0, 10.0)
    assert pic.tracks[0xABC123] is intr
    np.testing.assert_allclose(intr.ne_m, [300.0, -200.0], atol=QUANTUM_M)
    assert intr.height_m == pytest.approx(30.0, abs=1e-3)
    np.testing.assert_allclose(intr.vel_ne_m_s, [0.0, 15.0], atol=1e-9)  # heading 90°: east
    assert intr.t == 4.0
    np.testing.assert_allclose(intr.predicted_ne_m(6.0), [300.0, -170.0], atol=QUANTUM_M)
    np.testing.assert_allclose(intr.predicted_ne_m(3.0), intr.ne_m)


@pytest.mark.parametrize(
    ("heading_cdeg", "vel"),
    [
        (0, (2.5, 0.0)),  # north
        (9000, (0.0, 2.5)),  # east: clockwise from north
        (18000, (-2.5, 0.0)),  # south
        (27000, (0.0, -2.5)),  # west
        (4500, (2.5 / math.sqrt(2), 2.5 / math.sqrt(2))),  # north-east
    ],
)
def test_adsb_heading_is_clockwise_from_north(heading_cdeg, vel):
    pic = TrafficPicture(ORIGIN)
    pic.update(adsb(1, 0.0, 0.0, 20.0, heading_cdeg=heading_cdeg, speed_cm_s=250), 0.0)
    np.testing.assert_allclose(pic.tracks[1].vel_ne_m_s, vel, atol=1e-9)


@given(st.integers(0, 35999), st.integers(1, 30000))
def test_adsb_velocity_direction_and_magnitude(heading_cdeg, speed_cm_s):
    pic = TrafficPicture(ORIGIN)
    pic.update(adsb(7, 0.0, 0.0, 20.0, heading_cdeg=heading_cdeg, speed_cm_s=speed_cm_s), 0.0)
    vn, ve = pic.tracks[7].vel_ne_m_s
    assert math.hypot(vn, ve) == pytest.approx(speed_cm_s / 100.0)
    course = math.degrees(math.atan2(ve, vn)) % 360.0
    diff = (course - heading_cdeg / 100.0 + 180.0) % 360.0 - 180.0
    assert abs(diff) < 1e-6


def test_adsb_without_heading_or_velocity_flags():
    pic = TrafficPicture(ORIGIN)
    no_velocity = ADSB_ALL & ~AdsbFlag.VALID_VELOCITY
    pic.update(adsb(1, 0.0, 0.0, 20.0, heading_cdeg=9000, speed_cm_s=900, flags=no_velocity), 0.0)
    np.testing.assert_array_equal(pic.tracks[1].vel_ne_m_s, [0.0, 0.0])
    no_heading = ADSB_ALL & ~AdsbFlag.VALID_HEADING
    pic.update(adsb(2, 0.0, 0.0, 20.0, heading_cdeg=9000, speed_cm_s=900, flags=no_heading), 0.0)
    np.testing.assert_allclose(pic.tracks[2].vel_ne_m_s, [9.0, 0.0])  # course taken as north


def test_adsb_time_since_last_contact_ages_the_track():
    pic = TrafficPicture(ORIGIN, max_age_s=5.0)
    pic.update(adsb(1, 0.0, 0.0, 20.0, tslc=3), 10.0)
    assert pic.tracks[1].t == 7.0
    assert len(pic.current(12.0, 20.0, 5.0)) == 1
    assert pic.current(12.5, 20.0, 5.0) == []


def test_adsb_height_band():
    pic = TrafficPicture(ORIGIN)
    for icao, height in ((1, 20.0), (2, 29.0), (3, 31.0), (4, 5.0), (5, 400.0)):
        pic.update(adsb(icao, 50.0 * icao, 0.0, height), 1.0)
    close = pic.current(1.0, 20.0, 10.0)
    assert sorted(round(i.height_m) for i in close) == [20, 29]
    assert len(pic.current(1.0, 20.0, 1000.0)) == 5
    assert len(pic.tracks) == 5  # filtered, not forgotten


def test_adsb_expiry():
    pic = TrafficPicture(ORIGIN, max_age_s=5.0)
    pic.update(adsb(1, 0.0, 0.0, 20.0), 0.0)
    pic.update(adsb(2, 100.0, 0.0, 20.0), 3.0)
    assert len(pic.current(5.0, 20.0, 10.0)) == 2  # exactly max_age_s old: kept
    (left,) = pic.current(5.1, 20.0, 10.0)
    assert set(pic.tracks) == {2} and left is pic.tracks[2]
    pic.update(adsb(2, 110.0, 0.0, 20.0), 7.0)  # a fresh report renews the track
    (renewed,) = pic.current(11.0, 20.0, 10.0)
    np.testing.assert_allclose(renewed.ne_m, [110.0, 0.0], atol=QUANTUM_M)
    assert pic.current(12.5, 20.0, 10.0) == [] and not pic.tracks


def test_adsb_without_valid_coordinates_is_rejected():
    pic = TrafficPicture(ORIGIN)
    pic.update(adsb(1, 10.0, 10.0, 20.0, flags=ADSB_ALL & ~AdsbFlag.VALID_COORDS), 0.0)
    pic.update(adsb(2, 10.0, 10.0, 20.0, flags=0), 0.0)
    assert not pic.tracks
    assert pic.rejected == {"no valid coordinates": 2}


def test_adsb_impossible_speed_is_rejected():
    pic = TrafficPicture(ORIGIN)
    pic.update(adsb(1, 0.0, 0.0, 20.0, heading_cdeg=0, speed_cm_s=60000), 0.0)  # 600 m/s
    assert not pic.tracks and pic.rejected == {"impossible speed": 1}
    pic.update(adsb(1, 0.0, 0.0, 20.0, heading_cdeg=0, speed_cm_s=25000), 0.0)  # an airliner
    assert 1 in pic.tracks

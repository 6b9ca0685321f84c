"""The ADS-B traffic picture: tracks in the mission frame, bad reports out, hostile links capped."""

from __future__ import annotations

import math
import random
import tracemalloc
from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from mavwire import ADSB_ALL, ORIGIN, QUANTUM_M, adsb, adsb_raw

from remarl_fc.bus.core import Received
from remarl_fc.bus.schema import Detection, Detections, VehicleState
from remarl_fc.flight.config import Member
from remarl_fc.flight.peers import Peers
from remarl_fc.flight.tracking import VehicleTrack
from remarl_fc.flight.traffic import (
    CONFLICT_BASE_M,
    MAX_ADSB_SPEED_M_S,
    MAX_ALTITUDE_M,
    MAX_RANGE_M,
    MAX_TRACKS_STORED,
    MAX_TRACKS_USED,
    MIN_ALTITUDE_M,
    Intruder,
    TrafficPicture,
)
from remarl_fc.frames import to_deg_e7
from remarl_fc.mavlink.consts import AdsbFlag
from sim.config import SensorConfig
from sim.sensors import TrackNoise, fuse

SRC = (1, 1)  # the bound autopilot
OTHER = (7, 156)  # an ADS-B receiver the mission names (MAV_COMP_ID_ADSB)


def track(pic: TrafficPicture, icao: int, source: tuple[int, int] = SRC):
    return pic.tracks[(source, icao)]


def check_stored(pic: TrafficPicture, now: float) -> None:
    """Every kept track is a plausible aircraft, and the caps hold."""
    assert len(pic.tracks) <= pic.max_stored
    assert len(pic._far) == len(pic.tracks)
    assert sum(len(k) for k in pic._by_icao.values()) == len(pic.tracks)
    for v in pic.tracks.values():
        assert np.all(np.isfinite(v.ne_m)) and np.all(np.isfinite(v.vel_ne_m_s))
        assert math.hypot(*v.ne_m) <= MAX_RANGE_M
        assert math.hypot(*v.vel_ne_m_s) <= pic.max_speed_m_s + 1e-9
        assert math.isnan(v.height_m) or (
            MIN_ALTITUDE_M - 1e-6 <= ORIGIN.alt_m + v.height_m <= MAX_ALTITUDE_M + 1e-6
        )
        assert math.isfinite(v.t) and v.t <= now + 1.0


# -- ADS-B ----------------------------------------------------------------------------------


def test_adsb_position_and_velocity():
    pic = TrafficPicture(ORIGIN)
    msg = adsb(0xABC123, 300.0, -200.0, 30.0, heading_cdeg=9000, speed_cm_s=1500)
    assert pic.update(msg, 4.0, source=SRC)
    (intr,) = pic.current(4.0, 30.0, 10.0)
    assert track(pic, 0xABC123) is intr
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
    pic.update(adsb(1, 0.0, 0.0, 20.0, heading_cdeg=heading_cdeg, speed_cm_s=250), 0.0, source=SRC)
    np.testing.assert_allclose(track(pic, 1).vel_ne_m_s, vel, atol=1e-9)


@given(st.integers(0, 35999), st.integers(1, 30000))
def test_adsb_velocity_direction_and_magnitude(heading_cdeg, speed_cm_s):
    pic = TrafficPicture(ORIGIN)
    msg = adsb(7, 0.0, 0.0, 20.0, heading_cdeg=heading_cdeg, speed_cm_s=speed_cm_s)
    pic.update(msg, 0.0, source=SRC)
    vn, ve = track(pic, 7).vel_ne_m_s
    assert math.hypot(vn, ve) == pytest.approx(speed_cm_s / 100.0)
    course = math.degrees(math.atan2(ve, vn)) % 360.0
    diff = (course - heading_cdeg / 100.0 + 180.0) % 360.0 - 180.0
    assert abs(diff) < 1e-6


def test_adsb_without_heading_or_velocity_flags():
    pic = TrafficPicture(ORIGIN)
    no_velocity = ADSB_ALL & ~AdsbFlag.VALID_VELOCITY
    msg = adsb(1, 0.0, 0.0, 20.0, heading_cdeg=9000, speed_cm_s=900, flags=no_velocity)
    pic.update(msg, 0.0, source=SRC)
    np.testing.assert_array_equal(track(pic, 1).vel_ne_m_s, [0.0, 0.0])
    no_heading = ADSB_ALL & ~AdsbFlag.VALID_HEADING
    msg = adsb(2, 0.0, 0.0, 20.0, heading_cdeg=9000, speed_cm_s=900, flags=no_heading)
    pic.update(msg, 0.0, source=SRC)
    np.testing.assert_allclose(track(pic, 2).vel_ne_m_s, [9.0, 0.0])  # course taken as north


def test_adsb_time_since_last_contact_ages_the_track():
    pic = TrafficPicture(ORIGIN, max_age_s=5.0)
    pic.update(adsb(1, 0.0, 0.0, 20.0, tslc=3), 10.0, source=SRC)
    assert track(pic, 1).t == 7.0
    assert len(pic.current(12.0, 20.0, 5.0)) == 1
    assert pic.current(12.5, 20.0, 5.0) == []


def test_adsb_height_band():
    pic = TrafficPicture(ORIGIN)
    for icao, height in ((1, 20.0), (2, 29.0), (3, 31.0), (4, 5.0), (5, 400.0)):
        pic.update(adsb(icao, 50.0 * icao, 0.0, height), 1.0, source=SRC)
    close = pic.current(1.0, 20.0, 10.0)
    assert sorted(round(i.height_m) for i in close) == [20, 29]
    assert len(pic.current(1.0, 20.0, 1000.0)) == 5
    assert len(pic.tracks) == 5  # filtered, not forgotten


def test_adsb_expiry():
    pic = TrafficPicture(ORIGIN, max_age_s=5.0)
    pic.update(adsb(1, 0.0, 0.0, 20.0), 0.0, source=SRC)
    pic.update(adsb(2, 100.0, 0.0, 20.0), 3.0, source=SRC)
    assert len(pic.current(5.0, 20.0, 10.0)) == 2  # exactly max_age_s old: kept
    (left,) = pic.current(5.1, 20.0, 10.0)
    assert set(pic.tracks) == {(SRC, 2)} and left is track(pic, 2)
    pic.update(adsb(2, 110.0, 0.0, 20.0), 7.0, source=SRC)  # a fresh report renews the track
    (renewed,) = pic.current(11.0, 20.0, 10.0)
    np.testing.assert_allclose(renewed.ne_m, [110.0, 0.0], atol=QUANTUM_M)
    assert pic.current(12.5, 20.0, 10.0) == [] and not pic.tracks


def test_adsb_without_valid_coordinates_is_rejected():
    pic = TrafficPicture(ORIGIN)
    pic.update(adsb(1, 10.0, 10.0, 20.0, flags=ADSB_ALL & ~AdsbFlag.VALID_COORDS), 0.0, source=SRC)
    pic.update(adsb(2, 10.0, 10.0, 20.0, flags=0), 0.0, source=SRC)
    assert not pic.tracks
    assert pic.rejected == {"no valid coordinates": 2}


def test_adsb_impossible_speed_is_rejected():
    pic = TrafficPicture(ORIGIN)
    pic.update(adsb(1, 0.0, 0.0, 20.0, heading_cdeg=0, speed_cm_s=60000), 0.0, source=SRC)
    assert not pic.tracks and pic.rejected == {"impossible speed": 1}  # 600 m/s
    pic.update(adsb(1, 0.0, 0.0, 20.0, heading_cdeg=0, speed_cm_s=50000), 0.0, source=SRC)
    assert not pic.tracks and pic.rejected == {"impossible speed": 2}  # 500 m/s: the attack
    pic.update(adsb(1, 0.0, 0.0, 20.0, heading_cdeg=0, speed_cm_s=25000), 0.0, source=SRC)
    assert (SRC, 1) in pic.tracks  # an airliner
    limit_cm_s = round(MAX_ADSB_SPEED_M_S * 100)
    assert pic.update(adsb(2, 0.0, 0.0, 20.0, speed_cm_s=limit_cm_s), 0.0, source=SRC)
    assert not pic.update(adsb(3, 0.0, 0.0, 20.0, speed_cm_s=limit_cm_s + 1), 0.0, source=SRC)


def test_a_mission_may_tighten_the_speed_limit():
    pic = TrafficPicture(ORIGIN, max_speed_m_s=130.0)  # 250 kt, 14 CFR 91.117(a)
    assert not pic.update(adsb(1, 0.0, 0.0, 20.0, speed_cm_s=13001), 0.0, source=SRC)
    assert pic.update(adsb(1, 0.0, 0.0, 20.0, speed_cm_s=13000), 0.0, source=SRC)


# -- range checks ---------------------------------------------------------------------------

LAT0, LON0 = int(to_deg_e7(ORIGIN.lat_deg)), int(to_deg_e7(ORIGIN.lon_deg))
ALT0_MM = round(ORIGIN.alt_m * 1000)


@pytest.mark.parametrize(
    ("lat", "lon", "reason"),
    [
        (950_000_000, LON0, "latitude out of range"),  # 95°N
        (-900_000_001, LON0, "latitude out of range"),
        (LAT0, 1_800_000_001, "longitude out of range"),
        (LAT0, -2_000_000_000, "longitude out of range"),
        (LAT0 + 20_000_000, LON0, "out of range"),  # 2° (≈ 220 km) north: a real place, far
    ],
)
def test_positions_that_are_not_places_or_too_far_are_rejected(lat, lon, reason):
    pic = TrafficPicture(ORIGIN)
    assert not pic.update(adsb_raw(1, lat, lon, ALT0_MM), 0.0, source=SRC)
    assert not pic.tracks and pic.rejected == {reason: 1}


def test_the_poles_and_antimeridian_themselves_are_places():
    pic = TrafficPicture(ORIGIN)
    for lat, lon in ((900_000_000, LON0), (-900_000_000, LON0), (LAT0, 1_800_000_000)):
        pic.update(adsb_raw(1, lat, lon, ALT0_MM), 0.0, source=SRC)
    assert pic.rejected == {"out of range": 3}  # range-checked, then simply far


@pytest.mark.parametrize("alt_m", [MIN_ALTITUDE_M - 1.0, MAX_ALTITUDE_M + 1.0, -2.0e6, 2.0e6])
def test_implausible_altitude_is_rejected(alt_m):
    pic = TrafficPicture(ORIGIN)
    assert not pic.update(adsb_raw(1, LAT0, LON0, round(alt_m * 1000)), 0.0, source=SRC)
    assert pic.rejected == {"altitude out of range": 1}


def test_altitude_without_its_flag_is_not_checked_and_counts_at_every_height():
    pic = TrafficPicture(ORIGIN)
    flags = ADSB_ALL & ~AdsbFlag.VALID_ALTITUDE
    assert pic.update(adsb_raw(1, LAT0, LON0, -2_000_000_000, flags=flags), 0.0, source=SRC)
    assert math.isnan(track(pic, 1).height_m)
    assert pic.current(0.0, 5000.0, 1.0) == [track(pic, 1)]


def test_stale_report_is_rejected():
    pic = TrafficPicture(ORIGIN, max_age_s=5.0)
    assert not pic.update(adsb(1, 0.0, 0.0, 20.0, tslc=6), 10.0, source=SRC)
    assert pic.update(adsb(2, 0.0, 0.0, 20.0, tslc=5), 10.0, source=SRC)  # exactly max_age_s
    assert pic.rejected == {"stale": 1} and set(pic.tracks) == {(SRC, 2)}


def test_heading_beyond_a_circle_is_rejected_only_when_flagged_valid():
    pic = TrafficPicture(ORIGIN)
    assert not pic.update(adsb(1, 0.0, 0.0, 20.0, heading_cdeg=36000), 0.0, source=SRC)
    no_heading = ADSB_ALL & ~AdsbFlag.VALID_HEADING
    assert pic.update(adsb(2, 0.0, 0.0, 20.0, heading_cdeg=65535, flags=no_heading), 0, source=SRC)
    assert pic.rejected == {"heading out of range": 1}


# -- sources --------------------------------------------------------------------------------


def test_two_sources_of_one_icao_do_not_overwrite_each_other_and_conflict():
    pic = TrafficPicture(ORIGIN)
    pic.update(adsb(0xABC, 100.0, 0.0, 20.0), 1.0, source=SRC)
    pic.update(adsb(0xABC, 100.0, 1000.0, 20.0), 1.0, source=OTHER)  # a kilometre away
    np.testing.assert_allclose(track(pic, 0xABC, SRC).ne_m, [100.0, 0.0], atol=QUANTUM_M)
    np.testing.assert_allclose(track(pic, 0xABC, OTHER).ne_m, [100.0, 1000.0], atol=QUANTUM_M)
    assert pic.conflicts == 1
    kept = pic.current(1.0, 20.0, 10.0)  # we cannot tell which is true: both are obstacles
    assert {id(v) for v in kept} == {id(track(pic, 0xABC, SRC)), id(track(pic, 0xABC, OTHER))}
    pic.update(adsb(0xABC, 110.0, 0.0, 20.0), 2.0, source=SRC)  # one source's own update
    np.testing.assert_allclose(track(pic, 0xABC, OTHER).ne_m, [100.0, 1000.0], atol=QUANTUM_M)
    assert pic.conflicts == 2 and pic.stats()["conflicts"] == 2


def test_sources_that_agree_are_one_obstacle_the_freshest():
    pic = TrafficPicture(ORIGIN)
    pic.update(adsb(0xABC, 100.0, 0.0, 20.0, speed_cm_s=2000), 1.0, source=SRC)
    pic.update(adsb(0xABC, 150.0, 10.0, 20.0, speed_cm_s=2000), 2.0, source=OTHER)
    assert pic.conflicts == 0 and len(pic.tracks) == 2
    (one,) = pic.current(2.0, 20.0, 10.0)
    assert one is track(pic, 0xABC, OTHER)


def test_conflict_is_judged_at_one_time_not_at_the_report_times():
    pic = TrafficPicture(ORIGIN)
    pic.update(adsb(5, 0.0, 0.0, 20.0, speed_cm_s=10000), 0.0, source=SRC)  # north, 100 m/s
    pic.update(adsb(5, 400.0, 0.0, 20.0, speed_cm_s=10000), 4.0, source=OTHER)  # where it is now
    assert pic.conflicts == 0
    pic.update(adsb(6, 0.0, 0.0, 20.0), 0.0, source=SRC)
    pic.update(adsb(6, CONFLICT_BASE_M + 1.0, 0.0, 20.0), 0.0, source=OTHER)
    assert pic.conflicts == 1


# -- caps -----------------------------------------------------------------------------------


def test_nearest_first_cap_returns_the_nearest():
    pic = TrafficPicture(ORIGIN)
    rng = random.Random(3)
    spots = {icao: (rng.uniform(-3000, 3000), rng.uniform(-3000, 3000)) for icao in range(40)}
    for icao, (n, e) in spots.items():
        pic.update(adsb(icao, n, e, 20.0), 1.0, source=SRC)
    centre = np.array([800.0, -400.0])
    got = pic.current(1.0, 20.0, 10.0, near_ne_m=centre)
    assert len(got) == MAX_TRACKS_USED
    want = sorted(spots, key=lambda i: math.dist(spots[i], centre))[:MAX_TRACKS_USED]
    assert got == [track(pic, i) for i in want]
    assert len(pic.tracks) == 40  # capped on the way out, not forgotten
    np.testing.assert_array_equal(pic.reference_ne_m, centre)
    (first, *_) = pic.current(1.0, 20.0, 10.0)  # no centre given: the last one holds
    assert first is track(pic, want[0])


def random_reports(n: int, seed: int, radius_m: float = 5000.0) -> list:
    rng = random.Random(seed)
    return [
        adsb(
            rng.getrandbits(24),
            rng.uniform(-radius_m, radius_m),
            rng.uniform(-radius_m, radius_m),
            rng.uniform(0.0, 200.0),
            speed_cm_s=rng.randrange(0, 20000),
            heading_cdeg=rng.randrange(36000),
        )
        for _ in range(n)
    ]


def test_a_flood_of_random_icaos_keeps_memory_flat():
    pic = TrafficPicture(ORIGIN)
    first, rest = random_reports(1000, 1), random_reports(4000, 2)
    tracemalloc.start()
    try:
        for msg in first:
            pic.update(msg, 1.0, source=SRC)
        after_first, _ = tracemalloc.get_traced_memory()
        for msg in rest:
            pic.update(msg, 1.0, source=SRC)
        after_rest, _ = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert len(pic.tracks) == MAX_TRACKS_STORED
    check_stored(pic, 1.0)
    assert after_rest - after_first < 16 * 1024  # 4,000 more reports: no more memory
    s = pic.stats()
    assert s["tracks"] == MAX_TRACKS_STORED
    assert s["evicted"] + s["rejected"]["track cap (farther than all kept)"] == 5000 - 256


def test_a_flood_cannot_push_out_the_near_intruder():
    pic = TrafficPicture(ORIGIN)
    pic.current(0.0, 20.0, 10.0, near_ne_m=[1000.0, 1000.0])  # the swarm is here
    pic.update(adsb(0x5EA1, 1050.0, 1000.0, 20.0), 1.0, source=SRC)
    for msg in random_reports(1000, 4, radius_m=20_000.0):
        pic.update(msg, 1.0, source=SRC)
    assert len(pic.tracks) == MAX_TRACKS_STORED and pic.evicted > 0
    assert pic.current(1.0, 20.0, 10.0)[0] is track(pic, 0x5EA1)


def test_a_full_picture_drops_stale_tracks_before_near_ones():
    pic = TrafficPicture(ORIGIN, max_stored=4)
    for icao in range(4):
        pic.update(adsb(icao, 10.0 * icao, 0.0, 20.0), float(icao), source=SRC)
    assert pic.update(adsb(99, 3000.0, 0.0, 20.0), 5.5, source=SRC)  # 0 is stale by now
    assert set(pic.tracks) == {(SRC, 1), (SRC, 2), (SRC, 3), (SRC, 99)} and pic.evicted == 0
    assert not pic.update(adsb(100, 4000.0, 0.0, 20.0), 5.5, source=SRC)  # farther than all
    assert pic.update(adsb(101, 5.0, 0.0, 20.0), 5.5, source=SRC)  # nearer: the farthest goes
    assert (SRC, 99) not in pic.tracks and pic.evicted == 1


# -- hostile reports (property tests) -------------------------------------------------------

u8, u16, u32 = st.integers(0, 2**8 - 1), st.integers(0, 2**16 - 1), st.integers(0, 2**32 - 1)
i16, i32 = st.integers(-(2**15), 2**15 - 1), st.integers(-(2**31), 2**31 - 1)
near_lat = st.integers(LAT0 - 2_000_000, LAT0 + 2_000_000)  # ±0.2°: mostly within range
near_lon = st.integers(LON0 - 2_000_000, LON0 + 2_000_000)


def raw_report(icao, lat, lon, alt, hdg, spd, vv, flags, tslc):
    return adsb_raw(
        icao,
        lat,
        lon,
        alt,
        heading_cdeg=hdg,
        speed_cm_s=spd,
        ver_velocity_cm_s=vv,
        flags=flags,
        tslc=tslc,
    )


hostile_report = st.builds(
    raw_report,
    st.one_of(st.integers(0, 12), u32),  # few ICAOs (collisions between sources) or any
    st.one_of(near_lat, i32),
    st.one_of(near_lon, i32),
    st.one_of(st.integers(ALT0_MM - 100_000, ALT0_MM + 500_000), i32),
    u16,
    st.one_of(st.integers(0, 40_000), u16),
    i16,
    st.one_of(st.just(int(ADSB_ALL)), u16),
    st.one_of(st.integers(0, 8), u8),
)
sources = st.sampled_from([SRC, OTHER, (2, 1), (255, 190)])


@given(
    st.lists(st.tuples(hostile_report, sources, st.floats(0.0, 2.0)), max_size=40),
    st.floats(-1e5, 1e5),
    st.floats(-1e5, 1e5),
)
def test_hostile_reports_never_crash_nor_exceed_the_caps(reports, cn, ce):
    pic = TrafficPicture(ORIGIN, max_stored=8, max_used=3)
    now = 0.0
    for msg, source, dt in reports:
        now += dt
        pic.update(msg, now, source=source)
        assert len(pic.tracks) <= 8
        check_stored(pic, now)
    got = pic.current(now, 20.0, 50.0, near_ne_m=(cn, ce))
    assert len(got) <= 3
    assert all(now - v.t <= pic.max_age_s for v in pic.tracks.values())
    s = pic.stats()
    assert s["tracks"] == len(pic.tracks) and sum(s["rejected"].values()) <= len(reports)


wild = st.floats(allow_nan=True, allow_infinity=True, width=64)
metres = st.one_of(st.floats(-3000.0, 3000.0), wild)


@given(
    st.lists(
        st.tuples(
            st.integers(1, 4),
            st.integers(0, 6),
            st.tuples(metres, metres),
            st.one_of(st.none(), st.floats(-100.0, 500.0), wild),
            st.tuples(st.one_of(st.floats(-300.0, 300.0), wild), st.floats(-300.0, 300.0)),
            st.one_of(st.floats(-2.0, 0.5), wild),
        ),
        max_size=40,
    )
)
def test_hostile_shared_detections_never_crash_nor_exceed_the_caps(detections):
    pic = TrafficPicture(ORIGIN, max_stored=6, max_used=2)
    pic.update(adsb(3, 0.0, 0.0, 20.0), 0.0, source=SRC)
    now = 0.0
    for peer, icao, ne, h, vel, dt in detections:
        now += 0.1
        pic.merge_shared(peer, icao, ne, h, vel, now + dt, now)
        check_stored(pic, now)
    assert len(pic.current(now, 20.0, 50.0)) <= 2


# -- the swarm bus --------------------------------------------------------------------------


def test_shared_detections_are_checked_keyed_by_peer_and_give_way_to_ours():
    pic = TrafficPicture(ORIGIN)
    assert pic.merge_shared(2, 0xA, (100.0, 0.0), 20.0, (0.0, 5.0), 1.0, 1.0)
    assert pic.merge_shared(3, 0xA, (100.0, 2.0), None, (0.0, 5.0), 1.0, 1.0)
    assert pic.tracks[(("peer", 2), 0xA)].shared and pic.tracks[(("peer", 3), 0xA)].shared
    assert not pic.merge_shared(2, 0xA, (0.0, 0.0), 20.0, (0.0, 0.0), 0.5, 1.0)  # older: ignored
    assert len(pic.current(1.0, 20.0, 10.0)) == 1  # two peers, one aircraft
    for bad in [
        ((0.0, 0.0), 20.0, (500.0, 0.0), "shared: impossible speed"),
        ((math.nan, 0.0), 20.0, (0.0, 0.0), "shared: not finite"),
        ((0.0, 2e5), 20.0, (0.0, 0.0), "shared: out of range"),
        ((0.0, 0.0), 30_000.0, (0.0, 0.0), "shared: altitude out of range"),
        ((1.3e308, 1.3e308), 20.0, (0.0, 0.0), "shared: out of range"),  # no overflow warning
        ((0.0, 0.0), 20.0, (1.3e308, 1.3e308), "shared: impossible speed"),
    ]:
        assert not pic.merge_shared(4, 0xB, *bad[:3], 1.0, 1.0)
        assert pic.rejected[bad[3]] >= 1
    assert not pic.merge_shared(4, 0xB, (0.0, 0.0), 20.0, (0.0, 0.0), 1.0, 7.0)
    assert pic.rejected["shared: stale"] == 1
    pic.update(adsb(0xA, 500.0, 0.0, 20.0), 1.5, source=SRC)  # our own ADS-B sees it
    (ours,) = pic.current(1.5, 20.0, 10.0)
    assert ours is track(pic, 0xA)
    assert not pic.merge_shared(5, 0xA, (100.0, 0.0), 20.0, (0.0, 5.0), 2.0, 2.0)
    assert (("peer", 5), 0xA) not in pic.tracks  # ours is fresh: keep ours
    pic.current(7.0, 20.0, 10.0)  # ours ages out
    assert pic.merge_shared(5, 0xA, (100.0, 0.0), 20.0, (0.0, 5.0), 7.0, 7.0)
    assert pic.stats() == {
        "tracks": 1,
        "filtered": False,
        "own": 0,
        "shared": 1,
        "rejected": {
            "shared: altitude out of range": 1,
            "shared: impossible speed": 2,
            "shared: not finite": 1,
            "shared: out of range": 2,
            "shared: stale": 1,
        },
        "conflicts": 1,  # our report of 0xA lay 400 m from the peers'
        "evicted": 0,
    }


class FakeClock:
    speedup = 1.0

    def now(self) -> float:
        return 0.0

    def at(self, t_mono: float) -> float:
        return t_mono

    async def sleep(self, seconds: float) -> None:
        return None


def test_peers_merge_each_batch_once_and_publish_only_our_own_tracks():
    pic = TrafficPicture(ORIGIN)
    core = SimpleNamespace(states={}, detections={})
    peers = Peers(SimpleNamespace(core=core), [], pic, FakeClock(), 3.0, lambda m: "flying")
    batch = Detections(
        2,
        10,
        0.0,
        (
            Detection(0xA, (100.0, 0.0), 20.0, (0.0, 5.0)),
            Detection(0xB, (0.0, 0.0), 20.0, (600.0, 0.0)),  # impossible
        ),
    )
    core.detections[2] = Received(batch, 1.0)
    peers.sync(1.0)
    peers.sync(1.1)  # the same batch again: not merged (nor counted) twice
    assert set(pic.tracks) == {(("peer", 2), 0xA)}
    assert pic.rejected == {"shared: impossible speed": 1}
    pic.update(adsb(0xC, 50.0, 0.0, 20.0), 1.0, source=SRC)
    pic.update(adsb(0xD, 10.0, 0.0, 20.0), 1.0, source=OTHER)
    sent = peers._detections(SimpleNamespace(system_id=1), 1.2)
    assert [d.icao for d in sent.items] == [0xD, 0xC]  # ours only, nearest first
    assert sent.id == 1


def test_a_silent_peer_is_lost_and_its_last_word_is_kept():
    """A peer silent past the peer timeout is ``lost``; what its process last said (here: its
    vehicle reached its target and holds) stays known, for `whereabouts`."""
    core = SimpleNamespace(states={}, detections={})
    peer = Member(0, 2, VehicleTrack(2, ORIGIN), local=False)
    peers = Peers(SimpleNamespace(core=core), [peer], TrafficPicture(ORIGIN), FakeClock(), 1.5, str)
    state = VehicleState(2, 7, 0.0, (10.0, 0.0), 20.0, (5.0, 0.0, 0.0), 0.0, "reached")
    core.states[2] = Received(state, 1.0)
    peers.sync(2.0)
    assert (peer.remote_status, peer.remote_said) == ("reached", "reached")
    peers.sync(3.0)  # 2 s since its last state
    assert (peer.remote_status, peer.remote_said) == ("lost", "reached")


def test_a_peers_arc_is_taken_in_this_controllers_terms_while_it_flies_it():
    """The bus's arc (course and turn clockwise from north, seconds since its start) becomes
    the simulator's heading (counter-clockwise from east), turn and a start on this clock; a
    peer not under control, or silent, flies none."""
    core = SimpleNamespace(states={}, detections={})
    peer = Member(0, 2, VehicleTrack(2, ORIGIN), local=False)
    peers = Peers(SimpleNamespace(core=core), [peer], TrafficPicture(ORIGIN), FakeClock(), 1.5, str)
    arc = (0.0, 0.25, 8.0, 0.5)  # north, turning right, 0.5 s ago
    state = VehicleState(2, 7, 0.0, (10.0, 0.0), 20.0, (8.0, 0.0, 0.0), 0.0, "controlled", arc=arc)
    core.states[2] = Received(state, 4.0)
    peers.sync(4.1)
    assert peer.remote_arc is not None
    heading, turn, speed, start = peer.remote_arc
    assert math.isclose(heading, math.pi / 2) and (turn, speed, start) == (-0.25, 8.0, 3.5)
    core.states[2] = Received(replace(state, status="held"), 4.2)
    peers.sync(4.3)
    assert peer.remote_arc is None
    core.states[2] = Received(state, 5.0)
    peers.sync(7.0)  # silent past the peer timeout
    assert peer.remote_status == "lost" and peer.remote_arc is None


# -- the track filter ------------------------------------------------------------------------

FILTER_NOISE = TrackNoise.of(SensorConfig())


def test_runtime_fuses_with_the_same_filter():
    """`TrafficPicture` with the filter holds what `fuse` gives for the same reports."""
    pic = TrafficPicture(ORIGIN, noise=FILTER_NOISE)
    first = Intruder(np.array([100.0, 0.0]), 30.0, np.array([0.0, 15.0]), 1.0)
    second = Intruder(np.array([104.0, 16.0]), 30.0, np.array([1.0, 14.0]), 2.0)
    key = ((1, 1), 0xABC)
    pic._store(key, pic._filtered(key, first), 1.0, "")
    got = pic._filtered(key, second)
    start = np.array([FILTER_NOISE.pos_var_m2, 0.0, FILTER_NOISE.vel_var_m2_s2])
    pos, vel, cov, t = fuse(first.ne_m, first.vel_ne_m_s, start, 1.0, second.ne_m,
                            second.vel_ne_m_s, 2.0, FILTER_NOISE)  # fmt: skip
    np.testing.assert_array_equal(got.ne_m, pos)
    np.testing.assert_array_equal(got.vel_ne_m_s, vel)
    np.testing.assert_array_equal(got.cov, cov)
    assert got.t == t == 2.0 and got.height_m == 30.0
    assert TrafficPicture(ORIGIN)._filtered(key, second) is second  # no filter


def test_filtered_tracks_from_the_link_fuse_and_a_jump_restarts():
    pic = TrafficPicture(ORIGIN, noise=FILTER_NOISE)
    for k, north in enumerate([300.0, 318.0, 330.0]):  # reports of 15 m/s north, 1 s apart
        assert pic.update(adsb(0xABC123, north, 0.0, 30.0, heading_cdeg=0, speed_cm_s=1500),
                          10.0 + k, source=SRC)  # fmt: skip
    fused = track(pic, 0xABC123)
    assert fused.cov is not None and fused.cov[0] < FILTER_NOISE.pos_var_m2
    assert 0.1 < abs(fused.ne_m[0] - 330.0) < 5.0  # not the last report alone, but near it
    assert fused.t == 12.0
    assert pic.update(adsb(0xABC123, 900.0, 0.0, 30.0, heading_cdeg=0, speed_cm_s=1500),
                      13.0, source=SRC)  # fmt: skip
    restarted = track(pic, 0xABC123)
    np.testing.assert_allclose(restarted.ne_m, [900.0, 0.0], atol=QUANTUM_M)
    np.testing.assert_allclose(restarted.cov, [FILTER_NOISE.pos_var_m2, 0.0,
                                               FILTER_NOISE.vel_var_m2_s2])  # fmt: skip
    other = TrafficPicture(ORIGIN)  # no filter: the newest report
    other.update(adsb(0xABC123, 318.0, 0.0, 30.0, heading_cdeg=0, speed_cm_s=1500), 11.0,
                 source=SRC)  # fmt: skip
    assert track(other, 0xABC123).cov is None

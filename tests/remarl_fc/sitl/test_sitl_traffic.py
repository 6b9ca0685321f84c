"""The mock's ADS-B traffic: exact reports, or the simulator's report errors (``--adsb-noise``)."""

from __future__ import annotations

import numpy as np
import pytest

from remarl_fc.flight.traffic import TrafficPicture
from remarl_fc.frames import GeoPoint
from remarl_fc.mavlink.codec import Codec
from remarl_fc.sitl.config import SitlConfig
from remarl_fc.sitl.fleet import SitlFleet
from remarl_fc.sitl.traffic import ReportErrors, Traffic
from sim.config import SensorConfig
from sim.scenarios import load_scenario
from sim.sensors import POSITION_95_TO_SIGMA, TrackNoise

ORIGIN = GeoPoint(47.397742, 8.545594, 488.0)
VEHICLE, GCS = Codec(1, 1), Codec(255, 190)
SPAWN_M = np.array([[0.0, 100.0], [50.0, -80.0]])  # simulator frame (x east, y north)
VEL_M_S = np.array([[5.0, 0.0], [0.0, -3.0]])
NOISE = TrackNoise.of(SensorConfig())


def picture_of(traffic: Traffic, now_s: float, pic: TrafficPicture | None = None):
    """The runtime's tracks (north, east) of the mock's reports at ``now_s``, through the wire."""
    pic = pic or TrafficPicture(ORIGIN)
    for report in traffic.reports(VEHICLE.factory, ORIGIN, now_s):
        (msg,) = GCS.decode(VEHICLE.encode(report), "vehicle")
        assert pic.update(msg, now_s, source=(1, 1))
    return np.array([pic.tracks[key].ne_m for key in sorted(pic.tracks, key=lambda k: k[1])])


def test_reports_are_exact_by_default():
    traffic = Traffic(SPAWN_M, VEL_M_S, 20.0, start_s=0.0)
    truth = traffic.positions_ned(7.0)[:, :2]
    np.testing.assert_allclose(picture_of(traffic, 7.0), truth, atol=0.02)


def test_noisy_reports_have_the_simulators_sigma_and_every_receiver_hears_the_same():
    count, broadcasts = 2, 4000
    errors = ReportErrors(np.array([4.0, 12.0]), 1.5, rate_hz=2.0, seed=5)
    traffic = Traffic(SPAWN_M, VEL_M_S, 20.0, start_s=0.0, errors=errors)
    times = np.arange(broadcasts) / 2.0 + 0.1  # one per broadcast
    err = np.stack([picture_of(traffic, t) - traffic.positions_ned(t)[:, :2] for t in times])
    assert err.shape == (broadcasts, count, 2)
    np.testing.assert_allclose(err.std(axis=0), [[4.0, 4.0], [12.0, 12.0]], rtol=0.05)
    np.testing.assert_allclose(err.mean(axis=0), 0.0, atol=0.6)
    lag1 = np.mean(err[1:, 1] * err[:-1, 1]) / np.mean(err[:, 1] ** 2)
    assert abs(lag1) < 0.05  # drawn afresh for every broadcast
    # within one broadcast every vehicle's receiver hears the same report
    a = traffic.reports(VEHICLE.factory, ORIGIN, 10.1)
    b = traffic.reports(Codec(2, 1).factory, ORIGIN, 10.1)
    assert [(m.lat, m.lon, m.hor_velocity) for m in a] == [
        (m.lat, m.lon, m.hor_velocity) for m in b
    ]
    for x, y in zip(errors.at(10.1), errors.at(10.4), strict=True):  # one broadcast: 10.0-10.5 s
        np.testing.assert_array_equal(x, y)
    assert not np.array_equal(errors.at(10.4)[0], errors.at(10.6)[0])  # the next one


def test_the_fleet_draws_each_intruders_epu_from_the_simulators_range():
    fleet = SitlFleet(SitlConfig(adsb_noise=True, seed=3), scenario=load_scenario("3u2o"))
    assert fleet.traffic is not None and fleet.traffic.errors is not None
    lo, hi = SensorConfig().adsb_epu_m
    sigma = fleet.traffic.errors.pos_sigma_m * POSITION_95_TO_SIGMA
    assert sigma.shape == (2,) and np.all((lo <= sigma) & (sigma <= hi))
    plain = SitlFleet(SitlConfig(seed=3), scenario=load_scenario("3u2o"))
    assert plain.traffic is not None and plain.traffic.errors is None


def test_the_track_filter_averages_the_mocks_noisy_reports():
    """End to end below the socket: noisy mock reports, the runtime's picture with and without
    the filter, every report a vehicle's receiver forwards at 2 Hz for a minute."""
    errors = ReportErrors(np.array([8.0, 8.0]), 3.0 / POSITION_95_TO_SIGMA, rate_hz=2.0, seed=1)
    traffic = Traffic(SPAWN_M, VEL_M_S, 20.0, start_s=0.0, errors=errors)
    raw, filtered = TrafficPicture(ORIGIN), TrafficPicture(ORIGIN, noise=NOISE)
    raw_err, filtered_err = [], []
    for t in np.arange(0.1, 60.0, 0.5):
        truth = traffic.positions_ned(t)[:, :2]
        raw_err.append(picture_of(traffic, t, raw) - truth)
        filtered_err.append(picture_of(traffic, t, filtered) - truth)
    rms = [float(np.sqrt(np.mean(np.square(e[20:])))) for e in (raw_err, filtered_err)]
    assert rms[0] == pytest.approx(8.0, rel=0.15)
    assert rms[1] < 0.6 * rms[0]

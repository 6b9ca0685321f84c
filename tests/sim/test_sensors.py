"""The ADS-B sensor model: reports only from the past, newest first, with the stated errors, and
the extrapolation and age rule the runtime's tracker shares."""

import dataclasses
import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from remarl_fc.flight.traffic import Intruder, TrafficPicture, _at
from sim.config import SensorConfig
from sim.sensors import (
    ADSB_TSLC_S,
    FILTER_GATE,
    POSITION_95_TO_SIGMA,
    TRACK_MAX_AGE_S,
    AdsbTracks,
    TrackNoise,
    extrapolate,
    fuse,
    gps_error,
    is_fresh,
    picture,
    report_time,
    update,
)

EXACT = SensorConfig(
    model="adsb",
    adsb_latency_s=(0.0, 0.0),
    adsb_epu_m=(0.0, 0.0),
    adsb_nacv_m_s=0.0,
    adsb_drop_probability=0.0,
)
"""Reports without error, delay or loss."""


def straight(b, m, rng):
    """A random straight constant-velocity track per intruder: position at time t."""
    p0 = rng.uniform(-500.0, 500.0, (b, m, 2))
    vel = rng.uniform(-40.0, 40.0, (b, m, 2))
    return (lambda t: p0 + vel * t), vel


def arrived_indices(tracks, visible_since, now, b, m):
    """Reference: the report indices k of intruder (b, m) transmitted and arrived by ``now``."""
    period, phase = tracks.period_s[b, m], tracks.phase_s[b, m]
    latency, since = tracks.latency_s[b, m], visible_since[b, m]
    if since == math.inf:
        return []
    hi = math.floor((now - latency - phase) / period) + 1
    lo = hi - 200 if since == -math.inf else math.floor((since - phase) / period) - 1
    return [
        k
        for k in range(lo, hi + 1)
        if phase + k * period >= since and phase + k * period + latency <= now
    ]


settings_cfg = st.builds(
    lambda lo, span, lat, lat_span, p: SensorConfig(
        model="adsb",
        adsb_rate_hz=(lo, lo + span),
        adsb_latency_s=(lat, lat + lat_span),
        adsb_drop_probability=p,
    ),
    st.floats(0.2, 5.0),
    st.floats(0.0, 3.0),
    st.floats(0.0, 2.0),
    st.floats(0.0, 1.0),
    st.sampled_from([0.0, 0.1, 0.5, 0.9]),
)


@given(
    cfg=settings_cfg,
    seed=st.integers(0, 2**32 - 1),
    steps=st.lists(st.floats(0.0, 4.0), min_size=1, max_size=8),
    since_kind=st.sampled_from(["zero", "random", "never", "always"]),
)
def test_reports_come_only_from_the_past_and_never_go_back(cfg, seed, steps, since_kind):
    rng = np.random.default_rng(seed)
    b, m = 3, 4
    true_at, vel = straight(b, m, rng)
    since = {
        "zero": np.zeros((b, m)),
        "random": rng.uniform(0.0, 6.0, (b, m)),
        "never": np.full((b, m), math.inf),
        "always": np.full((b, m), -math.inf),
    }[since_kind]
    tracks = AdsbTracks.fresh(b, m, cfg, rng)
    now = 0.0
    for dt in steps:
        now += dt
        before = tracks
        tracks = update(tracks, true_at(now), vel, now, since, cfg, rng)
        held = np.isfinite(tracks.t_valid_s)
        # never from the future, never before the intruder transmits, never an older report
        assert np.all(tracks.t_valid_s[held] + tracks.latency_s[held] <= now)
        assert np.all(tracks.t_valid_s[held] >= since[held])
        assert np.all(tracks.t_valid_s >= before.t_valid_s)
        assert np.all(tracks.last_index >= before.last_index)
        assert np.array_equal(held, np.isfinite(tracks.pos_m).all(axis=-1))
        np.testing.assert_array_equal(
            tracks.t_report_s[held],
            report_time(tracks.t_valid_s[held] + tracks.latency_s[held], ADSB_TSLC_S),
        )
        for i in range(b):
            for j in range(m):
                arrived = arrived_indices(tracks, since, now, i, j)
                if not held[i, j]:
                    assert cfg.adsb_drop_probability > 0.0 or not arrived
                    continue
                k = (tracks.t_valid_s[i, j] - tracks.phase_s[i, j]) / tracks.period_s[i, j]
                assert k == pytest.approx(round(k), abs=1e-6)  # a transmitted report
                assert round(k) in arrived
                lost = max(arrived) - round(k)  # the newer reports that were lost
                age = now - tracks.t_valid_s[i, j]
                assert age <= tracks.latency_s[i, j] + tracks.period_s[i, j] * (1 + lost) + 1e-9
                if cfg.adsb_drop_probability == 0.0:
                    assert lost == 0


@given(seed=st.integers(0, 2**32 - 1), latency=st.floats(0.0, 2.0), now=st.floats(3.0, 60.0))
def test_without_losses_the_age_is_the_latency_within_a_period(seed, latency, now):
    rate_hz = 20.0
    cfg = SensorConfig(
        model="adsb",
        adsb_rate_hz=(rate_hz, rate_hz),
        adsb_latency_s=(latency, latency),
        adsb_drop_probability=0.0,
    )
    rng = np.random.default_rng(seed)
    true_at, vel = straight(2, 3, rng)
    tracks = AdsbTracks.fresh(2, 3, cfg, rng)
    tracks = update(tracks, true_at(now), vel, now, np.zeros((2, 3)), cfg, rng)
    age = now - tracks.t_valid_s
    assert np.all(age >= latency - 1e-9)
    assert np.all(age <= latency + 1.0 / rate_hz + 1e-9)
    _, _, valid = picture(tracks, now)
    assert valid.all()


@given(seed=st.integers(0, 2**32 - 1), times=st.lists(st.floats(1.0, 30.0), max_size=6))
def test_exact_config_reproduces_the_true_track(seed, times):
    rng = np.random.default_rng(seed)
    b, m = 2, 5
    true_at, vel = straight(b, m, rng)
    tracks = AdsbTracks.fresh(b, m, EXACT, rng)
    for now in sorted({1.0, *times}):
        tracks = update(tracks, true_at(now), vel, now, np.zeros((b, m)), EXACT, rng)
        pos, v, valid = picture(tracks, now)
        assert valid.all()  # report 0 went out before 1 s (period ≤ 1 s) and arrived at once
        np.testing.assert_allclose(pos, true_at(now), rtol=0, atol=1e-9)
        np.testing.assert_array_equal(v, vel)


def test_exact_config_at_the_start_sees_only_what_was_sent():
    rng = np.random.default_rng(0)
    true_at, vel = straight(4, 8, rng)
    tracks = AdsbTracks.fresh(4, 8, EXACT, rng)
    tracks = update(tracks, true_at(0.0), vel, 0.0, np.zeros((4, 8)), EXACT, rng)
    _, _, valid = picture(tracks, 0.0)
    np.testing.assert_array_equal(valid, tracks.phase_s == 0.0)  # report 0 only if sent at 0


def test_errors_have_the_stated_95_percent_radius():
    epu_m, nacv_m_s, count = 25.0, 3.0, 40_000
    cfg = SensorConfig(
        model="adsb",
        adsb_latency_s=(0.0, 0.0),
        adsb_epu_m=(epu_m, epu_m),
        adsb_nacv_m_s=nacv_m_s,
        adsb_drop_probability=0.0,
    )
    rng = np.random.default_rng(1)
    true_at, vel = straight(count, 1, rng)
    tracks = AdsbTracks.fresh(count, 1, cfg, rng)
    now = 1.0  # every intruder has sent a report by then (period ≤ 1 s)
    tracks = update(tracks, true_at(now), vel, now, np.zeros((count, 1)), cfg, rng)
    truth_then = true_at(tracks.t_valid_s[..., None])
    pos_err = (tracks.pos_m - truth_then).reshape(-1, 2)
    vel_err = (tracks.vel_m_s - vel).reshape(-1, 2)
    for err, radius in ((pos_err, epu_m), (vel_err, nacv_m_s)):
        np.testing.assert_allclose(err.mean(axis=0), 0.0, atol=0.03 * radius)
        np.testing.assert_allclose(err.std(axis=0), radius / POSITION_95_TO_SIGMA, rtol=0.02)
        within = np.mean(np.hypot(*err.T) <= radius)
        assert within == pytest.approx(0.95, abs=0.005)


@pytest.mark.parametrize("tau_s", [0.0, 8.0, 60.0])
def test_report_errors_correlate_over_their_stated_time_and_keep_their_sigma(tau_s):
    epu_m, nacv_m_s, count, period_s = 20.0, 3.0, 20_000, 1.0
    cfg = SensorConfig(
        model="adsb",
        adsb_rate_hz=(1.0 / period_s, 1.0 / period_s),
        adsb_latency_s=(0.0, 0.0),
        adsb_epu_m=(epu_m, epu_m),
        adsb_nacv_m_s=nacv_m_s,
        adsb_drop_probability=0.0,
        adsb_error_tau_s=(tau_s, tau_s),
    )
    rng = np.random.default_rng(3)
    true_at, vel = straight(count, 1, rng)
    tracks = AdsbTracks.fresh(count, 1, cfg, rng)
    errors = []  # (report, count, 2): one report per update, a period apart
    for now in np.arange(1.0, 12.0, period_s):
        tracks = update(tracks, true_at(now), vel, now, np.zeros((count, 1)), cfg, rng)
        truth_then = true_at(tracks.t_valid_s[..., None])
        pos_err = (tracks.pos_m - truth_then)[:, 0]
        np.testing.assert_allclose(pos_err, tracks.pos_err_m[:, 0], atol=1e-9)  # as held
        np.testing.assert_allclose(tracks.vel_m_s - vel, tracks.vel_err_m_s, atol=1e-12)
        errors.append(pos_err)
    series = np.stack(errors)
    sigma = epu_m / POSITION_95_TO_SIGMA
    np.testing.assert_allclose(series.std(axis=1), sigma, rtol=0.03)  # stationary, each report
    lag1 = np.mean(series[1:] * series[:-1]) / np.mean(series[1:] ** 2)
    expected = math.exp(-period_s / tau_s) if tau_s else 0.0
    assert lag1 == pytest.approx(expected, abs=0.01)


@pytest.mark.parametrize("p", [0.1, 0.5])
def test_losses_have_the_stated_probability(p):
    """One update per report: a fraction p is lost; three at once: all lost with p³."""
    count, rate_hz = 20_000, 1.0
    cfg = SensorConfig(
        model="adsb",
        adsb_rate_hz=(rate_hz, rate_hz),
        adsb_latency_s=(0.5, 0.5),
        adsb_drop_probability=p,
    )
    rng = np.random.default_rng(2)
    true_at, vel = straight(count, 1, rng)
    tracks = AdsbTracks.fresh(count, 1, cfg, rng)
    since = np.zeros((count, 1))
    now = 1.5  # report 0 (sent before 1 s) has arrived everywhere, report 1 (after) nowhere
    one = update(tracks, true_at(now), vel, now, since, cfg, rng)
    assert np.all(one.last_index[tracks.phase_s > 0] == 0.0)
    assert np.mean(np.isfinite(one.t_valid_s)) == pytest.approx(1 - p, abs=0.015)
    three = update(tracks, true_at(now + 2.0), vel, now + 2.0, since, cfg, rng)
    assert np.all(three.last_index[tracks.phase_s > 0] == 2.0)
    assert np.mean(np.isnan(three.pos_m[..., 0])) == pytest.approx(p**3, abs=0.01)
    newest = np.isclose(three.t_valid_s, three.phase_s + 2.0 * three.period_s)
    assert np.mean(newest) == pytest.approx(1 - p, abs=0.015)


def test_a_lost_report_stays_lost():
    """A report's loss is drawn once: until a newer one arrives, updates change nothing."""
    cfg = SensorConfig(model="adsb", adsb_drop_probability=0.5)
    rng = np.random.default_rng(3)
    true_at, vel = straight(500, 2, rng)
    since = np.zeros((500, 2))
    tracks = AdsbTracks.fresh(500, 2, cfg, rng)
    changed = np.zeros((500, 2), dtype=bool)
    for now in np.arange(0.0, 6.0, 0.05):
        new = update(tracks, true_at(now), vel, now, since, cfg, rng)
        same = new.last_index == tracks.last_index  # nothing arrived since the last update
        np.testing.assert_array_equal(new.t_valid_s[same], tracks.t_valid_s[same])
        np.testing.assert_array_equal(new.pos_m[same], tracks.pos_m[same])
        changed |= new.t_valid_s != tracks.t_valid_s
        tracks = new
    assert changed.mean() > 0.9  # most tracks got reports (all lost over 6 s: p⁶ ≈ 2%)


def test_picture_ages_by_report_time_and_extrapolates():
    cfg = dataclasses.replace(EXACT, adsb_latency_s=(1.2, 1.2))
    rng = np.random.default_rng(4)
    true_at, vel = straight(3, 2, rng)
    since = np.zeros((3, 2))
    tracks = AdsbTracks.fresh(3, 2, cfg, rng)
    tracks = update(tracks, true_at(3.0), vel, 3.0, since, cfg, rng)
    t = tracks.t_report_s
    assert np.all(t == tracks.t_valid_s + 1.2 - ADSB_TSLC_S)
    for now in (3.0, 5.0):
        pos, v, valid = picture(tracks, now)
        assert valid.all()
        np.testing.assert_array_equal(pos, extrapolate(tracks.pos_m, tracks.vel_m_s, t, now))
        np.testing.assert_array_equal(v, tracks.vel_m_s)
    # the latency is not corrected: the picture lags the truth by v · latency (minus tslc)
    lag = true_at(5.0) - picture(tracks, 5.0)[0]
    np.testing.assert_allclose(lag, vel * (1.2 - ADSB_TSLC_S), rtol=0, atol=1e-9)
    # exactly TRACK_MAX_AGE_S after the report time it is still used, after that not
    last = float(t.max())
    assert picture(tracks, last + TRACK_MAX_AGE_S)[2][t == last].all()
    pos, v, valid = picture(tracks, float(t.max()) + TRACK_MAX_AGE_S + 1e-6)
    assert not valid.any()
    assert np.isnan(pos).all() and np.isnan(v).all()


def test_never_visible_intruders_are_never_seen():
    cfg = SensorConfig(model="adsb", adsb_drop_probability=0.0)
    rng = np.random.default_rng(5)
    true_at, vel = straight(2, 3, rng)
    since = np.array([[0.0, math.inf, 10.0], [math.inf, 0.0, 0.0]])
    tracks = AdsbTracks.fresh(2, 3, cfg, rng)
    for now in (4.0, 8.0, 13.0):
        tracks = update(tracks, true_at(now), vel, now, since, cfg, rng)
        _, _, valid = picture(tracks, now)
        np.testing.assert_array_equal(valid[np.isinf(since)], False)
        assert valid[0, 2] == (now > 10.0)  # the pop-up: its first report arrived by 12.5 s
        held = np.isfinite(tracks.t_valid_s)
        assert np.all(tracks.t_valid_s[held] >= since[held])


def test_fresh_draws_within_the_configured_ranges():
    cfg = SensorConfig(model="adsb")
    tracks = AdsbTracks.fresh(50, 6, cfg, np.random.default_rng(6))
    rate = 1.0 / tracks.period_s
    assert np.all((rate >= cfg.adsb_rate_hz[0]) & (rate <= cfg.adsb_rate_hz[1]))
    assert np.all((tracks.phase_s >= 0.0) & (tracks.phase_s < tracks.period_s))
    lat = tracks.latency_s
    assert np.all((lat >= cfg.adsb_latency_s[0]) & (lat <= cfg.adsb_latency_s[1]))
    epu = tracks.pos_sigma_m * POSITION_95_TO_SIGMA
    assert np.all((epu >= cfg.adsb_epu_m[0] - 1e-9) & (epu <= cfg.adsb_epu_m[1] + 1e-9))
    np.testing.assert_allclose(tracks.vel_sigma_m_s, cfg.adsb_nacv_m_s / 2.448)
    assert math.sqrt(-2 * math.log(0.05)) == pytest.approx(POSITION_95_TO_SIGMA, abs=1e-3)
    assert not tracks.error_tau_s.any()  # errors drawn afresh by default
    ranged = dataclasses.replace(cfg, adsb_error_tau_s=(10.0, 60.0))
    mixed = AdsbTracks.fresh(50, 6, ranged, np.random.default_rng(6))
    assert np.all((mixed.error_tau_s >= 10.0) & (mixed.error_tau_s <= 60.0))
    assert mixed.error_tau_s.std() > 5.0  # drawn per intruder
    # drawn after the others: the rest of the tracks is the default's, draw for draw
    np.testing.assert_array_equal(mixed.pos_sigma_m, tracks.pos_sigma_m)


def merge(old, new, mask):
    """A local `merge_where`: every field an ndarray with B first, replaced where ``mask``."""
    fields = {}
    for f in dataclasses.fields(old):
        a, b_ = getattr(old, f.name), getattr(new, f.name)
        assert isinstance(a, np.ndarray) and a.shape[0] == mask.shape[0], f.name
        out = a.copy()
        out[mask] = b_[mask]
        fields[f.name] = out
    return dataclasses.replace(old, **fields)


def test_tracks_merge_per_environment():
    cfg = SensorConfig(model="adsb", adsb_drop_probability=0.0)
    rng = np.random.default_rng(7)
    b, m = 4, 3
    true_at, vel = straight(b, m, rng)
    tracks = AdsbTracks.fresh(b, m, cfg, rng)
    tracks = update(tracks, true_at(5.0), vel, 5.0, np.zeros((b, m)), cfg, rng)
    restart = AdsbTracks.fresh(b, m, cfg, rng)
    mask = np.array([True, False, True, False])
    merged = merge(tracks, restart, mask)
    _, _, valid = picture(merged, 5.0)
    np.testing.assert_array_equal(valid.any(axis=1), ~mask)
    np.testing.assert_array_equal(merged.period_s[mask], restart.period_s[mask])
    assert AdsbTracks.fresh(2, 0, cfg, rng).pos_m.shape == (2, 0, 2)


def test_draws_do_not_depend_on_the_data():
    cfg = SensorConfig(model="adsb")
    rng = np.random.default_rng(8)
    true_at, vel = straight(2, 2, rng)
    tracks = AdsbTracks.fresh(2, 2, cfg, rng)
    after = []
    for since in (np.zeros((2, 2)), np.full((2, 2), math.inf)):
        r = np.random.default_rng(9)
        update(tracks, true_at(3.0), vel, 3.0, since, cfg, r)
        after.append(r.random())
    assert after[0] == after[1]


def test_gps_error():
    rng = np.random.default_rng(10)
    state = rng.bit_generator.state
    assert not gps_error((1000, 3, 2), 0.0, rng).any()
    assert rng.bit_generator.state == state  # no draw
    error = gps_error((1000, 3, 2), 1.5, rng)
    assert error.shape == (1000, 3, 2)
    assert error.std() == pytest.approx(1.5, rel=0.05)
    assert abs(error.mean()) < 0.05


# -- shared with the runtime -----------------------------------------------------------------


@given(
    ne=st.tuples(st.floats(-1e5, 1e5), st.floats(-1e5, 1e5)),
    vel=st.tuples(st.floats(-400, 400), st.floats(-400, 400)),
    t=st.floats(0.0, 1e6),
    ahead=st.floats(-10.0, 10.0),
)
def test_runtime_extrapolates_with_the_same_code(ne, vel, t, ahead):
    intr = Intruder(np.array(ne), 20.0, np.array(vel), t)
    now = t + ahead
    expected = extrapolate(np.array(ne), np.array(vel), t, now)
    np.testing.assert_array_equal(intr.predicted_ne_m(now), expected)
    assert _at(intr, now) == tuple(expected.tolist())  # the float path: the same bits


def test_extrapolate_is_batched_and_never_goes_back():
    pos = np.zeros((2, 3, 2))
    vel = np.ones((2, 3, 2))
    t = np.arange(6.0).reshape(2, 3)
    out = extrapolate(pos, vel, t, 2.0)
    assert out.shape == (2, 3, 2)
    np.testing.assert_array_equal(out[..., 0], np.maximum(0.0, 2.0 - t))


def test_runtime_ages_tracks_with_the_shared_rule():
    assert TrafficPicture.__dataclass_fields__["max_age_s"].default == TRACK_MAX_AGE_S
    assert report_time(10.0, 3.0) == 7.0
    assert is_fresh(0.0, TRACK_MAX_AGE_S) and not is_fresh(0.0, TRACK_MAX_AGE_S + 1e-9)
    ages = np.array([0.0, 5.0, 5.5, -math.inf])
    np.testing.assert_array_equal(is_fresh(ages, 5.0), [True, True, True, False])


# -- the track filter ------------------------------------------------------------------------

NOISE = TrackNoise.of(SensorConfig())


def filtered_errors(cfg, seed=0, count=4000, steps=30):
    """RMS position and velocity error of the tracks' picture at every decision after the 5th,
    intruders flying straight at 15 m/s, decisions 2 s apart."""
    rng = np.random.default_rng(seed)
    vel = np.zeros((count, 1, 2))
    vel[..., 0] = 15.0
    tracks = AdsbTracks.fresh(count, 1, cfg, rng)
    pos_err, vel_err = [], []
    for k in range(steps):
        now = 2.0 * k
        tracks = update(tracks, vel * now, vel, now, np.full((count, 1), -np.inf), cfg, rng)
        pos, v, ok = picture(tracks, now)
        if k >= 5:
            pos_err.append(np.hypot(*(pos - vel * now)[ok].T))
            vel_err.append(np.hypot(*(v - vel)[ok].T))
    rms = [float(np.sqrt(np.mean(np.concatenate(e) ** 2))) for e in (pos_err, vel_err)]
    return rms[0], rms[1]


def test_the_filter_halves_the_error_of_independent_reports():
    """Without latency the picture's error is the reports' own: the filter takes most of it away
    (fused reports 2 s apart; the runtime, which fuses every report, takes more)."""
    cfg = SensorConfig(model="adsb", adsb_latency_s=(0.0, 0.0))
    raw_pos, raw_vel = filtered_errors(cfg)
    pos, vel = filtered_errors(dataclasses.replace(cfg, adsb_filter=True))
    mean_epu2 = (10.0**2 + 10.0 * 30.0 + 30.0**2) / 3.0  # EPU uniform in 10–30 m
    assert raw_pos == pytest.approx(math.sqrt(2.0 * mean_epu2) / POSITION_95_TO_SIGMA, rel=0.05)
    assert pos < 0.6 * raw_pos
    assert vel < 0.95 * raw_vel


def test_the_filter_is_off_by_default_and_changes_nothing_then():
    cfg = SensorConfig(model="adsb")
    assert not cfg.adsb_filter
    on = dataclasses.replace(cfg, adsb_filter=True)
    a, b = (
        update(AdsbTracks.fresh(8, 3, c, np.random.default_rng(2)), np.zeros((8, 3, 2)),
               np.ones((8, 3, 2)), 3.0, np.zeros((8, 3)), c, np.random.default_rng(4))
        for c in (cfg, on)
    )  # fmt: skip
    np.testing.assert_array_equal(a.cov, 0.0)
    # a first report starts every track: the same picture, and the filter's covariance
    np.testing.assert_array_equal(a.pos_m, b.pos_m)
    took = np.isfinite(b.t_report_s)
    assert took.any()
    start = np.array([NOISE.pos_var_m2, 0.0, NOISE.vel_var_m2_s2])
    np.testing.assert_allclose(b.cov[took], np.broadcast_to(start, b.cov[took].shape))


def test_with_the_filter_off_every_track_is_its_newest_report():
    """Over a whole flight: off, the tracks carry no covariance and jump to each report; on, the
    same reports arrive at the same times (the filter draws nothing) and are fused, not copied."""
    cfg = SensorConfig(model="adsb")
    vel = np.broadcast_to([12.0, -5.0], (6, 3, 2))
    runs = {}
    for c in (cfg, dataclasses.replace(cfg, adsb_filter=True)):
        rng, seen = np.random.default_rng(7), []
        tracks = AdsbTracks.fresh(6, 3, c, rng)
        for k in range(1, 21):
            t = 0.5 * k
            tracks = update(tracks, vel * t, vel, t, np.zeros((6, 3)), c, rng)
            seen.append(tracks)
        runs[c.adsb_filter] = seen
    moved = 0
    for off, on in zip(runs[False], runs[True], strict=True):
        np.testing.assert_array_equal(off.cov, 0.0)
        np.testing.assert_array_equal(off.t_report_s, on.t_report_s)
        np.testing.assert_array_equal(off.pos_err_m, on.pos_err_m)  # the same draws
        moved += int((np.abs(off.pos_m - on.pos_m) > 1e-9).any(axis=-1).sum())
    assert moved > 100  # the filter smooths what the raw tracks copy
    last = runs[False][-1]
    valid = last.t_report_s - last.latency_s  # when its newest report was true (tslc 0)
    truth = vel * valid[..., np.newaxis]  # the intruders flew from the origin at t = 0
    np.testing.assert_allclose(last.pos_m, truth + last.pos_err_m, atol=1e-9)


@given(
    var=st.tuples(st.floats(0.01, 1e4), st.floats(-0.9, 0.9), st.floats(0.01, 1e3)),
    dt=st.floats(0.0, 4.9),
    z=st.lists(st.floats(-50.0, 50.0), min_size=4, max_size=4),
)
def test_a_fused_track_is_surer_than_its_prediction_and_its_report(var, dt, z):
    """The posterior covariance stays symmetric positive definite, below the report's variance
    and below the prediction's, whatever the prior (property of the Kalman update)."""
    ppp, rho, pvv = var
    cov = np.array([ppp, rho * math.sqrt(ppp * pvv), pvv])
    pos, _, out, t = fuse(np.zeros(2), np.zeros(2), cov, 0.0, np.array(z[:2]),
                            np.array(z[2:]), dt, NOISE)  # fmt: skip
    if np.array_equal(out, [NOISE.pos_var_m2, 0.0, NOISE.vel_var_m2_s2]):  # the gate restarted
        np.testing.assert_array_equal(pos, z[:2])
        return
    assert out[0] > 0 and out[2] > 0 and out[0] * out[2] > out[1] ** 2
    assert out[0] <= NOISE.pos_var_m2 + 1e-9 and out[2] <= NOISE.vel_var_m2_s2 + 1e-9
    predicted_pp = ppp + 2 * dt * cov[1] + dt * dt * pvv + NOISE.accel_var_m2_s4 * dt**4 / 4
    assert out[0] <= predicted_pp + 1e-9
    assert t == dt


def test_the_gate_restarts_a_track_on_a_report_it_did_not_expect():
    cov = np.array([NOISE.pos_var_m2, 0.0, NOISE.vel_var_m2_s2])
    prior = (np.zeros(2), np.array([10.0, 0.0]), cov, 0.0)
    near = fuse(*prior, np.array([12.0, 3.0]), np.array([10.5, 0.0]), 1.0, NOISE)
    assert 0.0 < near[0][0] < 12.0 and near[1][0] == pytest.approx(10.2, abs=0.3)  # fused
    jump = np.array([10.0 + 100.0, 0.0])  # 100 m off the prediction: χ² far beyond the gate
    far = fuse(*prior, jump, np.array([10.0, 0.0]), 1.0, NOISE)
    assert ((jump - [10.0, 0.0]) ** 2).sum() / (cov[0] + NOISE.pos_var_m2) > FILTER_GATE
    np.testing.assert_array_equal(far[0], jump)
    np.testing.assert_array_equal(far[2], cov)
    stale = fuse(*prior, np.array([60.0, 0.0]), np.array([10.0, 0.0]), TRACK_MAX_AGE_S + 1, NOISE)
    np.testing.assert_array_equal(stale[0], [60.0, 0.0])  # too old to fuse: starts afresh


def turning_track_errors(rate_deg_s, epu_m, seed=0, tracks=40, speed_m_s=50.0):
    """RMS error of the raw report and of the filtered track, 0.4 s after each 2 Hz report of
    an aircraft in a steady turn (reports with independent errors of ``epu_m``)."""
    rng = np.random.default_rng(seed)
    w = math.radians(rate_deg_s)
    sigma_p, sigma_v = epu_m / POSITION_95_TO_SIGMA, 3.0 / POSITION_95_TO_SIGMA

    def truth(th0, t):
        pos = (speed_m_s / w) * np.array([math.sin(th0 + w * t) - math.sin(th0),
                                          math.cos(th0) - math.cos(th0 + w * t)])  # fmt: skip
        return pos, speed_m_s * np.array([math.cos(th0 + w * t), math.sin(th0 + w * t)])

    raw, filtered = [], []
    for _ in range(tracks):
        th0 = rng.uniform(0.0, 2.0 * math.pi)
        p, v, c, t0 = np.full(2, np.nan), np.full(2, np.nan), np.zeros(3), -math.inf
        for t in np.arange(0.0, 60.0, 0.5):
            true_p, true_v = truth(th0, t)
            zp = true_p + sigma_p * rng.standard_normal(2)
            zv = true_v + sigma_v * rng.standard_normal(2)
            p, v, c, t0 = fuse(p, v, c, t0, zp, zv, t, NOISE)
            if t > 10.0:
                then = truth(th0, t + 0.4)[0]
                raw.append(np.hypot(*(extrapolate(zp, zv, t, t + 0.4) - then)))
                filtered.append(np.hypot(*(extrapolate(p, v, float(t0), t + 0.4) - then)))
    return [float(np.sqrt(np.mean(np.square(e)))) for e in (raw, filtered)]


def test_the_filter_follows_a_turning_aircraft_and_lags_where_reports_beat_its_assumption():
    """MODEL §18: with reports as noisy as the filter assumes (EPU 20 m) it beats the raw report
    even in a 5 m/s² turn; with reports four times better than it assumes (EPU 5 m) it lags a
    turning aircraft by more than the reports' own error: why it stays a setting."""
    raw, filtered = turning_track_errors(6.0, 20.0)  # 50 m/s at 6°/s: 5.2 m/s²
    assert filtered < 0.8 * raw
    raw, filtered = turning_track_errors(6.0, 5.0)
    assert filtered > 1.5 * raw
    raw, filtered = turning_track_errors(0.001, 5.0)  # straight: it still averages
    assert filtered < 0.7 * raw

"""The vehicle model (sim.vehicle): its arithmetic, its profiles, and its fit to real SITL."""

import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sim.errors import ConfigError
from sim.vehicle import (
    VehicleProfile,
    load_profile,
    profile_names,
    read_trace,
    respond,
    track_velocity,
    track_yaw,
)

TRACES = Path(__file__).resolve().parents[1] / "data" / "sitl"


def read(name):
    trace = read_trace(TRACES / f"{name}.csv")
    return trace.times_s, trace.command_m_s, trace.velocity_m_s


def test_shipped_profiles():
    assert {"ideal", "arducopter", "px4", "px4-sluggish"} <= set(profile_names())
    ardu = load_profile("arducopter")
    # The fit agrees with the figures read off the traces by hand (README of the traces):
    # first order τ ≈ 0.5 s, acceleration cap ≈ WPNAV_ACCEL 2.5 m/s², delay ≈ 0.3 s, and a yaw
    # rate capped near ATC_SLEW_YAW (60°/s).
    assert 0.4 <= ardu.velocity_tau_s <= 0.7 and 2.0 <= ardu.max_accel_m_s2 <= 3.0
    assert 0.2 <= ardu.delay_s <= 0.45
    assert 50 <= math.degrees(ardu.max_yaw_rate_rad_s) <= 75
    assert load_profile("ideal").ideal


@pytest.mark.parametrize(
    ("profile", "traces", "bound_m_s"),
    [
        ("arducopter", ("ardupilot-a", "ardupilot-b", "ardupilot-c"), 0.3),
        (
            "px4",
            ("px4-a-fast", "px4-b-fast", "px4-c-fast", "px4-a-gain", "px4-b-gain", "px4-c-gain"),
            0.3,
        ),
        ("px4-sluggish", ("px4-a", "px4-b", "px4-c"), 0.8),
    ],
)
def test_the_model_replays_the_real_traces(profile, traces, bound_m_s):
    """The recorded commands into the fitted model: RMS velocity error against the firmware."""
    model = load_profile(profile)
    squares, count = 0.0, 0
    for name in traces:
        t, cmd, vel = read(name)
        flown = respond(model, t, cmd, vel[0], dt_s=0.02)
        squares += float(((flown - vel) ** 2).sum())
        count += 2 * len(t)
    rms = math.sqrt(squares / count)
    assert rms <= bound_m_s
    assert rms == pytest.approx(model.fit_rms_m_s, abs=0.01)  # the recorded fit is this one


def test_the_ideal_model_flies_the_command():
    t, cmd, _ = read("ardupilot-c")
    assert np.array_equal(respond(load_profile("ideal"), t, cmd, cmd[0]), cmd)
    step = track_velocity(np.zeros(2), np.array([10.0, 0.0]), load_profile("ideal"), 0.1)
    assert step.tolist() == [10.0, 0.0]


@settings(max_examples=60, deadline=None)
@given(
    v=st.tuples(st.floats(-20, 20), st.floats(-20, 20)),
    c=st.tuples(st.floats(-20, 20), st.floats(-20, 20)),
    tau=st.floats(0.05, 3.0),
    cap=st.floats(0.2, 10.0),
    dt=st.floats(0.005, 0.2),
)
def test_tracking_moves_toward_the_command_within_the_cap(v, c, tau, cap, dt):
    profile = VehicleProfile(name="p", velocity_tau_s=tau, max_accel_m_s2=cap)
    v, c = np.array(v), np.array(c)
    new = track_velocity(v, c, profile, dt)
    assert np.linalg.norm(new - v) <= cap * dt * (1 + 1e-9) + 1e-12
    assert np.linalg.norm(c - new) <= np.linalg.norm(c - v) + 1e-9
    uncapped = c - (c - v) * math.exp(-dt / tau)  # the exact first-order response
    if np.linalg.norm(uncapped - v) <= cap * dt:
        assert np.allclose(new, uncapped, atol=1e-9)


def test_yaw_turns_at_most_at_its_rate_the_short_way():
    profile = VehicleProfile(name="p", yaw_tau_s=0.05, max_yaw_rate_rad_s=math.radians(60))
    yaw = track_yaw(np.array(math.radians(170)), np.array(math.radians(-170)), profile, 0.1)
    assert math.degrees(float(yaw)) == pytest.approx(176.0)  # 6° toward −170 across ±180


def test_bad_profiles_say_what_is_wrong(tmp_path):
    with pytest.raises(ConfigError, match="shipped: arducopter"):
        load_profile("dji")
    bad = tmp_path / "mine.toml"
    bad.write_text("velocity_tau_s = 0.5\nmax_jerk = 3\n")
    with pytest.raises(ConfigError, match="unknown key 'max_jerk'"):
        load_profile(bad)
    bad.write_text("velocity_tau_s = -1\n")
    with pytest.raises(ConfigError, match="velocity_tau_s must be > 0"):
        load_profile(bad)

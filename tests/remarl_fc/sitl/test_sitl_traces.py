"""The mock's airframes against real firmware: each recorded SITL trace's commands, replayed.

The traces (``tests/data/sitl``: real ArduCopter V4.7.0-dev and PX4 v1.16.0 SIH in SITL,
recorded 2026-11-23, how they were flown in the README there) carry the velocity command in
force at every telemetry sample (``cmd_vn_m_s``, ``cmd_ve_m_s``) and the velocity the vehicle
flew (``vn_m_s``, ``ve_m_s``). Here the commands go into the mock's own physics
(`remarl_fc.sitl.vehicle.step` at the mock's 50 Hz, with the fleet's `DelayLine`) flying the
vehicle profile fitted to those traces, as ``remarl-fc sitl --vehicle PROFILE`` would, and the
flown velocity is compared with the firmware's: the RMS of the 2-D error over every sample.

`tools/fit_vehicle.py` fits the profiles with `sim.vehicle.respond`; this checks that the mock,
which steps the same model in its own loop, flies what the fit promises.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from numpy.typing import NDArray

from remarl_fc.sitl.config import VehicleModelConfig
from remarl_fc.sitl.vehicle import Airframes, Guidance, step
from sim.vehicle import DelayLine, load_profile, read_trace

FloatArray = NDArray[np.float64]

TRACES = Path(__file__).resolve().parents[2] / "data" / "sitl"
"""The recorded traces, kept in the repository (the same files `tools/fit_vehicle.py` reads)."""

PHYSICS_DT_S = 1.0 / 50.0
"""The mock's physics step (`SitlConfig.physics_hz` 50 Hz), s."""

CRUISE_DOWN_M = -20.0
"""Height of the replays (the traces were flown at 20 m), NED down, m."""

TRACE_BOUNDS: tuple[tuple[str, str, float, float], ...] = (
    # (profile, trace, RMS measured on the mock when this test was written, bound), m/s;
    # the bound leaves ≈ 10 % for a refit of the profile
    ("arducopter", "ardupilot-a", 0.106, 0.12),
    ("arducopter", "ardupilot-b", 0.163, 0.18),
    ("arducopter", "ardupilot-c", 0.290, 0.32),
    ("px4", "px4-a-fast", 0.111, 0.13),
    ("px4", "px4-b-fast", 0.173, 0.19),
    ("px4", "px4-c-fast", 0.088, 0.10),
    ("px4", "px4-a-gain", 0.254, 0.28),
    ("px4", "px4-b-gain", 0.376, 0.42),
    ("px4", "px4-c-gain", 0.184, 0.21),
    ("px4-sluggish", "px4-a", 0.466, 0.52),
    ("px4-sluggish", "px4-b", 0.852, 0.94),
    ("px4-sluggish", "px4-c", 0.583, 0.65),
)
"""Each profile's traces (as `tools/fit_vehicle.py` assigns them) with their RMS bounds."""

BOUNDS_M_S: dict[str, dict[str, tuple[float, float]]] = {
    profile: {t: (m, b) for p, t, m, b in TRACE_BOUNDS if p == profile}
    for profile in {row[0] for row in TRACE_BOUNDS}
}
"""The same, per profile: trace → (measured, bound)."""


def read(name: str) -> tuple[FloatArray, FloatArray, FloatArray]:
    """(times (T,), commands (T, 2), velocities (T, 2)) of a trace, north/east."""
    trace = read_trace(TRACES / f"{name}.csv")
    return trace.times_s, trace.command_m_s, trace.velocity_m_s


def replay(profile_name: str, names: list[str]) -> list[FloatArray]:
    """Every trace of one profile flown at once by the mock's airframes, one row each.

    Each row starts level at the trace's first sample, with its velocity, in velocity
    guidance, and gets the trace's command in force (zero-order hold) at every physics step;
    after its trace ends a row keeps its last command. Returns each trace's flown velocity at
    its sample times.
    """
    profile = load_profile(profile_name)
    traces = [(t - t[0], cmd, vel) for t, cmd, vel in (read(n) for n in names)]
    n = len(traces)
    frames = Airframes.on_ground(np.zeros((n, 3)), np.zeros(n))
    frames.pos_ned_m[:, 2] = CRUISE_DOWN_M
    frames.landed[:] = False
    frames.guidance[:] = Guidance.VELOCITY
    for i, (_, _, vel) in enumerate(traces):
        frames.vel_ned_m_s[i, :2] = vel[0]
    t_end = max(float(t[-1]) for t, _, _ in traces)
    steps = math.ceil(t_end / PHYSICS_DT_S)
    grid = PHYSICS_DT_S * np.arange(steps + 1)  # (S + 1,) every trace from its first sample
    held = [np.searchsorted(t, grid[:-1] + 1e-9, side="right") - 1 for t, _, _ in traces]
    flown = np.empty((steps + 1, n, 2))
    flown[0] = frames.vel_ned_m_s[:, :2]
    cfg, rng = VehicleModelConfig(), np.random.default_rng(0)
    delay = DelayLine(profile.delay_s, PHYSICS_DT_S)
    for k in range(steps):
        for i, (_, cmd, _) in enumerate(traces):
            frames.vel_target_m_s[i, :2] = cmd[min(held[i][k], len(cmd) - 1)]
        step(frames, cfg, PHYSICS_DT_S, rng, profile, delay)
        flown[k + 1] = frames.vel_ned_m_s[:, :2]
    return [
        np.stack([np.interp(t, grid, flown[:, i, axis]) for axis in range(2)], axis=-1)
        for i, (t, _, _) in enumerate(traces)
    ]


@pytest.mark.parametrize("profile", sorted(BOUNDS_M_S))
def test_the_mock_flies_each_trace_within_its_bound(profile: str) -> None:
    bounds = BOUNDS_M_S[profile]
    names = sorted(bounds)
    for name, flown in zip(names, replay(profile, names), strict=True):
        _, _, vel = read(name)
        rms = math.sqrt(float(((flown - vel) ** 2).sum()) / (2 * len(vel)))
        measured, bound = bounds[name]
        assert rms <= bound, f"{name}: RMS {rms:.3f} m/s over the bound {bound} m/s"
        assert rms == pytest.approx(measured, abs=0.05), f"{name}: RMS {rms:.3f} m/s"

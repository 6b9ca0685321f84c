"""Vehicle tracks: telemetry in the mission frame, bad values out."""

from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import assume, given
from hypothesis import strategies as st
from mavwire import (
    ORIGIN,
    QUANTUM_M,
    F,
    attitude,
    ekf,
    heartbeat,
    position,
    statustext,
    wire,
)

from remarl_fc.flight.config import Member
from remarl_fc.flight.control import whereabouts
from remarl_fc.flight.status import Status
from remarl_fc.flight.tracking import (
    DISAGREEMENT_UNTRUSTED_M,
    MAX_SPEED_M_S,
    STATUSTEXT_KEPT,
    VehicleTrack,
)
from remarl_fc.frames import GeoPoint, ned_to_geodetic, to_deg_e7, yaw_to_cdeg
from remarl_fc.mavlink.consts import (
    EKF_GOOD,
    CopterMode,
    EkfFlag,
    LandedState,
    MavAutopilot,
    MavModeFlag,
    MavState,
    Px4AutoSubMode,
    Px4MainMode,
    px4_custom_mode,
)


def track() -> VehicleTrack:
    return VehicleTrack(1, ORIGIN)


# -- HEARTBEAT ------------------------------------------------------------------------------


def test_a_new_track_knows_nothing():
    t = track()
    assert t.autopilot is None and not t.armed and not t.is_px4
    assert np.isnan(t.ne_m).all() and math.isnan(t.height_m) and math.isnan(t.yaw_rad)
    assert not t.position_ok()
    assert t.position_age_s(5.0) == math.inf
    assert t.last_text(-math.inf) == ""
    assert not t.rejected and not t.seen


def test_heartbeat_sets_identity_mode_and_arming():
    t = track()
    base = MavModeFlag.SAFETY_ARMED | MavModeFlag.CUSTOM_MODE_ENABLED
    t.update(heartbeat(custom_mode=CopterMode.GUIDED, base=base), 3.0)
    assert t.autopilot == MavAutopilot.ARDUPILOTMEGA and not t.is_px4
    assert t.custom_mode == CopterMode.GUIDED and t.base_mode == base
    assert t.system_status == MavState.ACTIVE and t.t_heartbeat == 3.0
    assert t.armed
    t.update(heartbeat(custom_mode=CopterMode.LOITER, base=MavModeFlag.CUSTOM_MODE_ENABLED), 4.0)
    assert not t.armed and t.custom_mode == CopterMode.LOITER and t.t_heartbeat == 4.0
    assert t.seen["HEARTBEAT"] == 2


def test_heartbeat_of_a_gcs_or_companion_is_ignored():
    t = track()
    t.update(heartbeat(custom_mode=CopterMode.GUIDED, base=MavModeFlag.SAFETY_ARMED), 1.0)
    t.update(heartbeat(autopilot=MavAutopilot.INVALID, custom_mode=0, base=0), 2.0)
    assert t.autopilot == MavAutopilot.ARDUPILOTMEGA
    assert t.custom_mode == CopterMode.GUIDED and t.armed and t.t_heartbeat == 1.0
    assert t.seen["HEARTBEAT"] == 2  # counted, not used
    fresh = track()
    fresh.update(heartbeat(autopilot=MavAutopilot.INVALID), 1.0)
    assert fresh.autopilot is None and fresh.t_heartbeat == -math.inf


# -- external control mode ------------------------------------------------------------------


@pytest.mark.parametrize(
    ("autopilot", "custom_mode", "external"),
    [
        (MavAutopilot.ARDUPILOTMEGA, CopterMode.GUIDED, True),
        (MavAutopilot.ARDUPILOTMEGA, CopterMode.LOITER, False),
        (MavAutopilot.ARDUPILOTMEGA, CopterMode.GUIDED_NOGPS, False),
        (MavAutopilot.ARDUPILOTMEGA, px4_custom_mode(Px4MainMode.OFFBOARD), False),
        (MavAutopilot.PX4, px4_custom_mode(Px4MainMode.OFFBOARD), True),
        (MavAutopilot.PX4, 6 << 16, True),
        (MavAutopilot.PX4, CopterMode.GUIDED, False),  # 4 means nothing on PX4
        (MavAutopilot.PX4, px4_custom_mode(Px4MainMode.POSCTL), False),
        (MavAutopilot.PX4, px4_custom_mode(Px4MainMode.AUTO, Px4AutoSubMode.LOITER), False),
    ],
)
def test_in_external_control_mode(autopilot, custom_mode, external):
    t = track()
    t.update(heartbeat(autopilot=autopilot, custom_mode=custom_mode), 1.0)
    assert t.is_px4 == (autopilot == MavAutopilot.PX4)
    assert t.in_external_control_mode() is external


# -- GLOBAL_POSITION_INT --------------------------------------------------------------------


def test_position_in_the_mission_frame():
    t = track()
    t.update(position(120.0, -35.5, 20.0, (3.0, -4.0, -0.5)), 7.0)
    np.testing.assert_allclose(t.ne_m, [120.0, -35.5], atol=QUANTUM_M)
    assert t.height_m == pytest.approx(20.0, abs=1e-3)
    np.testing.assert_allclose(t.vel_ned_m_s, [3.0, -4.0, -0.5])
    assert t.t_position == 7.0 and t.position_age_s(7.5) == pytest.approx(0.5)
    assert t.seen["GLOBAL_POSITION_INT"] == 1 and not t.rejected


def test_position_against_an_exact_geodetic_point():
    """Lat/lon/alt on the wire built directly from `ned_to_geodetic` of a known offset."""
    lat, lon, alt = ned_to_geodetic(-250.0, 410.0, -45.0, ORIGIN)
    msg = wire(
        F.global_position_int_encode(
            0, int(to_deg_e7(lat)), int(to_deg_e7(lon)), round(float(alt) * 1000), 45000, 0, 0, 0, 0
        )
    )
    t = track()
    t.update(msg, 0.0)
    np.testing.assert_allclose(t.ne_m, [-250.0, 410.0], atol=QUANTUM_M)
    assert t.height_m == pytest.approx(45.0, abs=1e-3)
    assert t.yaw_rad == 0.0  # hdg 0: north


@given(
    st.floats(-60.0, 60.0),
    st.floats(-179.0, 179.0),
    st.floats(-3000.0, 3000.0),
    st.floats(-3000.0, 3000.0),
    st.floats(-50.0, 400.0),
)
def test_position_round_trip(lat0, lon0, north, east, height):
    origin = GeoPoint(lat0, lon0, 300.0)
    lat, lon, _ = ned_to_geodetic(north, east, 0.0, origin)
    # lat = lon = 0 on the wire is "no fix" by convention: a vehicle at null island is not flown
    assume(int(to_deg_e7(lat)) != 0 or int(to_deg_e7(lon)) != 0)
    t = VehicleTrack(1, origin)
    t.update(position(north, east, height, origin=origin), 1.0)
    assert not t.rejected
    np.testing.assert_allclose(t.ne_m, [north, east], atol=QUANTUM_M)
    assert t.height_m == pytest.approx(height, abs=1e-3)


def test_heading_from_position_until_attitude_arrives():
    t = track()
    t.update(position(0.0, 0.0, 10.0, hdg=9000), 1.0)
    assert t.yaw_rad == pytest.approx(math.pi / 2)
    t.update(position(0.0, 1.0, 10.0, hdg=27000), 1.1)
    assert t.yaw_rad == pytest.approx(-math.pi / 2)  # wrapped to [-π, π)
    t.update(position(0.0, 2.0, 10.0, hdg=65535), 1.2)  # unknown: kept
    assert t.yaw_rad == pytest.approx(-math.pi / 2)
    t.update(attitude(0.25), 1.3)
    assert t.yaw_rad == pytest.approx(0.25) and t.t_yaw == 1.3
    t.update(position(0.0, 3.0, 10.0, hdg=int(yaw_to_cdeg(2.0))), 1.4)
    assert t.yaw_rad == pytest.approx(0.25)  # ATTITUDE wins once heard


def test_no_fix_is_rejected():
    t = track()
    msg = wire(F.global_position_int_encode(0, 0, 0, 488000, 0, 0, 0, 0, 65535))
    t.update(msg, 1.0)
    assert t.rejected == {"no fix (lat = lon = 0)": 1}
    assert not math.isfinite(t.t_position) and np.isnan(t.ne_m).all()
    assert not t.position_ok()


@pytest.mark.parametrize(
    "vel",
    [
        (MAX_SPEED_M_S + 1.0, 0.0, 0.0),
        (0.0, -150.0, 0.0),
        (0.0, 0.0, 120.0),
        (80.0, 80.0, 0.0),  # 113 m/s in total
    ],
)
def test_absurd_velocity_is_rejected(vel):
    t = track()
    t.update(position(10.0, 10.0, 20.0), 1.0)
    t.update(position(11.0, 10.0, 20.0, vel), 1.1)
    assert t.rejected == {"impossible position or velocity": 1}
    np.testing.assert_allclose(t.ne_m, [10.0, 10.0], atol=QUANTUM_M)
    assert t.t_position == 1.0
    np.testing.assert_array_equal(t.vel_ned_m_s, [0.0, 0.0, 0.0])


def test_fast_but_possible_velocity_is_kept():
    t = track()
    t.update(position(10.0, 10.0, 20.0, (70.0, -70.0, 0.0)), 1.0)  # 99 m/s
    assert not t.rejected and t.t_position == 1.0


def test_latitude_outside_the_globe_is_rejected():
    t = track()
    t.update(wire(F.global_position_int_encode(0, 950_000_000, 85_000_000, 0, 0, 0, 0, 0, 0)), 1.0)
    assert t.rejected == {"impossible position or velocity": 1}
    assert not math.isfinite(t.t_position)


def test_position_jumps_are_rejected_then_caught_up_with():
    t = track()
    t.update(position(0.0, 0.0, 20.0), 10.0)
    # 0.1 s later: at most 100 m/s · 0.1 s + 5 m = 15 m away
    t.update(position(14.0, 0.0, 20.0), 10.1)
    assert not t.rejected and t.t_position == 10.1
    t.update(position(14.0, 40.0, 20.0), 10.2)
    assert t.rejected == {"position jump": 1}
    np.testing.assert_allclose(t.ne_m, [14.0, 0.0], atol=QUANTUM_M)
    assert t.t_position == 10.1
    t.update(position(14.0, 40.0, 20.0), 10.25)
    assert t.rejected["position jump"] == 2
    # the allowance grows with the time since the last accepted fix: 0.4 s → 45 m
    t.update(position(14.0, 40.0, 20.0), 10.5)
    assert t.rejected["position jump"] == 2
    np.testing.assert_allclose(t.ne_m, [14.0, 40.0], atol=QUANTUM_M)
    assert t.t_position == 10.5


def test_nan_attitude_is_rejected():
    t = track()
    t.update(attitude(0.5), 1.0)
    for bad in (math.nan, math.inf, -math.inf, 7.0):
        t.update(attitude(bad), 2.0)
    assert t.rejected == {"attitude not a number": 4}
    assert t.yaw_rad == pytest.approx(0.5) and t.t_yaw == 1.0
    assert t.seen["ATTITUDE"] == 5


def test_rejections_are_counted_by_reason():
    t = track()
    t.update(wire(F.global_position_int_encode(0, 0, 0, 0, 0, 0, 0, 0, 0)), 1.0)
    t.update(wire(F.global_position_int_encode(0, 0, 0, 0, 0, 0, 0, 0, 0)), 1.1)
    t.update(position(0.0, 0.0, 20.0, (150.0, 0.0, 0.0)), 1.2)
    t.update(attitude(math.nan), 1.3)
    t.update(position(0.0, 0.0, 20.0), 1.4)
    t.update(position(900.0, 0.0, 20.0), 1.5)
    assert t.rejected == {
        "no fix (lat = lon = 0)": 2,
        "impossible position or velocity": 1,
        "attitude not a number": 1,
        "position jump": 1,
    }


# -- position_ok ----------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("flags", "ok"),
    [
        (None, False),  # ArduPilot without an EKF report: not yet
        (EKF_GOOD, True),
        (EkfFlag.VELOCITY_HORIZ | EkfFlag.POS_HORIZ_ABS, True),
        (EKF_GOOD | EkfFlag.CONST_POS_MODE, False),
        (EKF_GOOD & ~EkfFlag.POS_HORIZ_ABS, False),
        (EKF_GOOD & ~EkfFlag.VELOCITY_HORIZ, False),
        (EkfFlag.ATTITUDE | EkfFlag.POS_HORIZ_REL, False),
        (0, False),
    ],
)
def test_position_ok_on_ardupilot(flags, ok):
    t = track()
    t.update(heartbeat(autopilot=MavAutopilot.ARDUPILOTMEGA), 0.0)
    t.update(position(1.0, 2.0, 3.0), 0.5)
    if flags is not None:
        t.update(ekf(int(flags)), 0.6)
        assert t.ekf_flags == int(flags)
    assert t.position_ok() is ok


def test_position_ok_on_ardupilot_needs_a_position_too():
    t = track()
    t.update(heartbeat(autopilot=MavAutopilot.ARDUPILOTMEGA), 0.0)
    t.update(ekf(int(EKF_GOOD)), 0.1)
    assert not t.position_ok()
    t.update(position(1.0, 2.0, 3.0), 0.5)
    assert t.position_ok()
    t.update(ekf(int(EKF_GOOD | EkfFlag.CONST_POS_MODE)), 0.6)  # lost GPS: dead reckoning
    assert not t.position_ok()


def test_position_ok_on_px4_needs_only_a_position():
    t = track()
    t.update(heartbeat(autopilot=MavAutopilot.PX4), 0.0)
    assert not t.position_ok()
    t.update(wire(F.global_position_int_encode(0, 0, 0, 0, 0, 0, 0, 0, 0)), 0.2)  # no fix
    assert not t.position_ok()
    t.update(position(1.0, 2.0, 3.0), 0.5)
    assert t.position_ok()


def test_other_telemetry_is_kept():
    t = track()
    t.update(wire(F.extended_sys_state_encode(0, LandedState.IN_AIR)), 1.0)
    assert t.landed_state == LandedState.IN_AIR
    t.update(wire(F.sys_status_encode(0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0)), 1.0)  # ignored
    assert t.seen == {"EXTENDED_SYS_STATE": 1, "SYS_STATUS": 1}


# -- STATUSTEXT -----------------------------------------------------------------------------


def test_last_text():
    t = track()
    t.update(statustext("PreArm: Need Position Estimate", severity=2), 1.0)
    t.update(statustext("Arming motors"), 2.0)
    t.update(statustext("Mode change failed"), 3.0)
    assert t.last_text(0.0) == "Mode change failed"
    assert t.last_text(3.0) == "Mode change failed"  # at `since` counts
    assert t.last_text(3.01) == ""
    assert t.texts[0] == (1.0, 2, "PreArm: Need Position Estimate")
    assert all(isinstance(text, str) for _, _, text in t.texts)


def test_only_recent_texts_are_kept():
    t = track()
    for k in range(STATUSTEXT_KEPT + 5):
        t.update(statustext(f"text {k}"), float(k))
    assert len(t.texts) == STATUSTEXT_KEPT
    assert t.texts[0][2] == "text 5"
    assert t.last_text(0.0) == f"text {STATUSTEXT_KEPT + 4}"


# -- prediction -----------------------------------------------------------------------------


def test_predicted_position_at_constant_velocity():
    """A flying vehicle's track, predicted by `remarl_fc.flight.control.whereabouts`."""

    def predicted(t: VehicleTrack, now: float) -> np.ndarray:
        rows = [(Member(0, t.system_id, t), Status.CONTROLLED)]
        return whereabouts(rows, np.array([[0.3, 0.5, 2.5]]), now).ne_m[0]

    t = track()
    t.update(position(100.0, -50.0, 20.0, (2.0, -1.0, 0.5)), 10.0)
    np.testing.assert_allclose(predicted(t, 10.0), [100.0, -50.0], atol=QUANTUM_M)
    np.testing.assert_allclose(predicted(t, 12.5), [105.0, -52.5], atol=QUANTUM_M)
    # never extrapolated backwards
    np.testing.assert_allclose(predicted(t, 9.0), t.ne_m)
    assert np.isnan(predicted(track(), 1.0)).all()  # nothing known, nothing predicted


# -- trust ----------------------------------------------------------------------------------


def test_a_takeover_is_believed_after_two_heartbeats_in_a_row():
    t = track()
    guided = heartbeat(custom_mode=CopterMode.GUIDED)
    loiter = heartbeat(custom_mode=CopterMode.LOITER)
    t.update(guided, 0.0)
    t.update(loiter, 1.0)  # one forged or corrupted heartbeat
    assert not t.in_external_control_mode() and not t.takeover_confirmed()
    t.update(guided, 2.0)
    t.update(loiter, 3.0)
    assert not t.takeover_confirmed()
    t.update(loiter, 4.0)
    assert t.takeover_confirmed()


def test_a_position_stream_drifting_from_its_own_velocity_makes_the_track_untrusted():
    t = track()
    for k in range(100):  # 10 s at 10 Hz, flying north at 10 m/s, all consistent
        t.update(position(10.0 * k / 10, 0.0, 20.0, (10.0, 0.0, 0.0), t_s=k / 10), k / 10)
    assert t.untrusted is None and t.disagreement_m < 1.0
    for k in range(100, 300):  # the position drifts east at 2 m/s; the velocity says north
        drift = 2.0 * (k - 100) / 10
        t.update(position(10.0 * k / 10, drift, 20.0, (10.0, 0.0, 0.0), t_s=k / 10), k / 10)
    assert t.untrusted is not None and "disagrees with its own velocity" in t.untrusted
    assert not t.rejected  # nothing rejected: every fix was plausible on its own


def test_two_interleaved_streams_make_the_track_untrusted_by_rejections():
    t = track()
    t.update(position(0.0, 0.0, 20.0), 0.0)
    for k in range(1, 30):
        north = 0.0 if k % 2 else 200.0  # every other fix 200 m away
        t.update(position(north, 0.0, 20.0), k * 0.05)
    assert t.rejected["position jump"] >= 10
    assert t.untrusted is not None and "positions rejected" in t.untrusted


def test_a_backlog_delivered_in_one_burst_is_not_distrusted():
    """A link that stalls and then delivers 3 s of fixes at once: arrival times say the
    vehicle jumped 30 m in no time, its own clock says it flew them; nothing is distrusted."""
    t = track()
    for k in range(50):
        arrival = k / 10 if k < 20 else 5.0  # fixes 20..49 all arrive at t = 5 s
        t.update(position(k * 1.0, 0.0, 20.0, (10.0, 0.0, 0.0), t_s=k / 10), arrival)
    beat = heartbeat(custom_mode=CopterMode.GUIDED)
    for _ in range(8):  # 8 s of heartbeats in the same burst
        t.update(beat, 5.0)
    assert t.untrusted is None and t.disagreement_m < 1.0


def test_a_short_glitch_is_rejected_but_not_distrusted():
    t = track()
    for k in range(20):
        north = 40.0 if 10 <= k < 13 else 0.0
        t.update(position(north, 0.0, 20.0), k / 10)
    assert t.rejected["position jump"] == 3
    assert t.untrusted is None


def test_statustext_is_made_printable():
    t = track()
    t.update(statustext("PreArm: \x1b[2J\x07bad"), 1.0)
    assert t.last_text(0.0) == "PreArm: ?[2J?bad"


def test_a_heartbeat_flood_on_the_vehicles_source_makes_it_untrusted():
    t = track()
    guided = heartbeat(custom_mode=CopterMode.GUIDED)
    for k in range(30):  # 1 Hz, as an autopilot sends them
        t.update(guided, float(k))
    assert t.untrusted is None
    loiter = heartbeat(custom_mode=CopterMode.LOITER)
    for k in range(20):  # a second sender at 10 Hz
        t.update(loiter, 30.0 + k / 10)
    assert t.untrusted is not None and "more than one sender" in t.untrusted


TRACES = sorted((Path(__file__).resolve().parents[2] / "data" / "sitl").glob("*.csv"))


@pytest.mark.parametrize("trace", TRACES, ids=lambda p: p.stem)
def test_real_firmware_telemetry_is_never_distrusted(trace):
    """ArduCopter and PX4 SITL, flying steps, turns and policy-like arcs: their position and
    velocity agree to a few metres, far under the 15 m that makes a track untrusted."""
    t = track()
    worst = 0.0
    with trace.open() as f:
        for row in csv.DictReader(f):
            now = float(row["t_s"])
            vel = (float(row["vn_m_s"]), float(row["ve_m_s"]), 0.0)
            fix = position(float(row["n_m"]), float(row["e_m"]), 20.0, vel, t_s=now + 100.0)
            t.update(fix, now)
            worst = max(worst, t.disagreement_m)
    assert t.untrusted is None and not t.rejected
    assert worst < DISAGREEMENT_UNTRUSTED_M / 3, worst  # measured: ≤ 0.3 m ArduCopter, ≤ 3.2 m PX4

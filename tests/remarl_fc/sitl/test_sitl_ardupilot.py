"""The ArduCopter flavour of the mock, walked with real MAVLink bytes over UDP."""

from __future__ import annotations

import math

import numpy as np
import pytest

from remarl_fc.frames import from_deg_e7, geodetic_to_ned
from remarl_fc.mavlink import consts

pytestmark = [pytest.mark.asyncio, pytest.mark.network, pytest.mark.timeout(120)]


async def arm_and_take_off(gcs, height_m: float = 20.0) -> None:
    await gcs.wait_ready()
    ack = await gcs.command(consts.MavCmd.DO_SET_MODE, 1, consts.CopterMode.GUIDED)
    assert ack.result == consts.MavResult.ACCEPTED
    ack = await gcs.command(consts.MavCmd.COMPONENT_ARM_DISARM, 1)
    assert ack.result == consts.MavResult.ACCEPTED
    ack = await gcs.command(consts.MavCmd.NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, height_m)
    assert ack.result == consts.MavResult.ACCEPTED
    await gcs.command(consts.MavCmd.SET_MESSAGE_INTERVAL, consts.MsgId.GLOBAL_POSITION_INT, 100_000)
    await gcs.wait_for("GLOBAL_POSITION_INT", lambda m: m.relative_alt > (height_m - 0.3) * 1000)


def velocity_yaw(gcs, vn: float, ve: float, yaw: float, mask: int = consts.TYPE_MASK_VELOCITY_YAW):
    return gcs.f.set_position_target_local_ned_encode(
        0, 1, 1, consts.MavFrame.LOCAL_NED, mask, 0, 0, 0, vn, ve, 0, 0, 0, 0, yaw, 0
    )


async def test_heartbeat_only_until_streams_are_requested(sitl):
    async with sitl() as (fleet, gcs):
        gcs.hello()
        hb = await gcs.wait_for("HEARTBEAT")
        assert (hb.type, hb.autopilot) == (2, 3)
        assert hb.base_mode & consts.MavModeFlag.CUSTOM_MODE_ENABLED
        await gcs.wait_sim(3.0)
        kinds = {m.get_type() for _, m in gcs.heard}
        assert kinds == {"HEARTBEAT"}, "ArduCopter sends nothing else until asked"
        ack = await gcs.command(consts.MavCmd.SET_MESSAGE_INTERVAL, consts.MsgId.ATTITUDE, 50_000)
        assert ack.result == consts.MavResult.ACCEPTED
        assert (ack.target_system, ack.target_component) == (255, 190)
        t0 = fleet.now_s()
        await gcs.sent_after("ATTITUDE", t0 + 2.0)  # the rate, counted on the vehicle's clock
        rate = len(gcs.sent_between("ATTITUDE", t0 + 0.2, t0 + 2.0)) / 1.8
        assert 17.0 <= rate <= 23.0
        # REQUEST_DATA_STREAM(POSITION, 5 Hz) turns on the position group
        gcs.send(gcs.f.request_data_stream_encode(1, 1, 6, 5, 1))
        await gcs.wait_for("GLOBAL_POSITION_INT")
        # −1 disables: nothing sent after the ACK
        ack = await gcs.command(consts.MavCmd.SET_MESSAGE_INTERVAL, consts.MsgId.ATTITUDE, -1)
        assert ack.result == consts.MavResult.ACCEPTED
        # after the tick that answered: a message of that same tick carries the same stamp
        # and may have been sent before the command was read
        t1 = fleet.now_s() + 0.001
        await gcs.wait_sim(1.0)
        assert gcs.sent_between("ATTITUDE", t1, math.inf) == []


async def test_boot_mode_is_overwritten_and_arming_waits_for_position(sitl):
    async with sitl() as (fleet, gcs):
        gcs.hello()
        hb = await gcs.wait_for("HEARTBEAT")
        assert hb.system_status == consts.MavState.BOOT
        ack = await gcs.command(consts.MavCmd.DO_SET_MODE, 1, consts.CopterMode.GUIDED)
        assert ack.result == consts.MavResult.ACCEPTED  # accepted during boot ...
        await gcs.wait_sim(fleet.cfg.ardupilot.boot_s)
        hb = await gcs.heartbeat_after(fleet.now_s())
        assert hb.custom_mode == consts.CopterMode.STABILIZE  # ... then overwritten
        ack = await gcs.command(consts.MavCmd.COMPONENT_ARM_DISARM, 1)
        assert ack.result == consts.MavResult.FAILED
        text = await gcs.wait_for("STATUSTEXT")
        assert "PreArm: Need Position Estimate" in text.text
        ack = await gcs.command(consts.MavCmd.DO_SET_MODE, 1, consts.CopterMode.GUIDED)
        assert ack.result == consts.MavResult.FAILED  # GUIDED needs a position
        await gcs.wait_ready()
        ack = await gcs.command(consts.MavCmd.DO_SET_MODE, 1, consts.CopterMode.LAND)
        assert ack.result == consts.MavResult.ACCEPTED
        ack = await gcs.command(consts.MavCmd.COMPONENT_ARM_DISARM, 1)
        assert ack.result == consts.MavResult.FAILED
        assert "Mode not armable" in (await gcs.wait_for("STATUSTEXT")).text
        ack = await gcs.command(consts.MavCmd.COMPONENT_ARM_DISARM, 1, 21196)  # forced
        assert ack.result == consts.MavResult.ACCEPTED


async def test_mode_change_shows_only_in_the_next_heartbeat(sitl):
    async with sitl() as (fleet, gcs):
        gcs.hello()
        await gcs.wait_ready()
        await gcs.wait_for("HEARTBEAT")
        ack = await gcs.command(consts.MavCmd.DO_SET_MODE, 1, consts.CopterMode.GUIDED)
        t_ack = fleet.now_s()
        assert ack.result == consts.MavResult.ACCEPTED
        beats = [t for t, m in gcs.heard if m.get_type() == "HEARTBEAT"]
        hb = await gcs.heartbeat_after(t_ack)
        assert hb.custom_mode == consts.CopterMode.GUIDED
        assert hb.base_mode & consts.MavModeFlag.GUIDED_ENABLED
        # no extra heartbeat was sent because of the change: the period stays 1 s
        later = [t for t, m in gcs.heard if m.get_type() == "HEARTBEAT"]
        gaps = np.diff(sorted(set(beats + later)))
        assert gaps.min() > 0.9


async def test_takeoff_refusals_and_command_int_frame(sitl):
    async with sitl() as (_fleet, gcs):
        gcs.hello()
        await gcs.wait_ready()
        await gcs.command(consts.MavCmd.DO_SET_MODE, 1, consts.CopterMode.GUIDED)
        ack = await gcs.command(consts.MavCmd.NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, 10)
        assert ack.result == consts.MavResult.FAILED  # not armed
        await gcs.command(consts.MavCmd.COMPONENT_ARM_DISARM, 1)
        cmd_int = gcs.f.command_int_encode(
            1, 1, consts.MavFrame.GLOBAL, consts.MavCmd.NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, 0, 0, 10.0
        )
        gcs.send(cmd_int)
        ack = await gcs.wait_for("COMMAND_ACK", lambda m: m.command == consts.MavCmd.NAV_TAKEOFF)
        assert ack.result == consts.MavResult.DENIED  # COMMAND_INT must use GLOBAL_RELATIVE_ALT
        ack = await gcs.command(64_000)  # not a command anyone knows
        assert ack.result == consts.MavResult.UNSUPPORTED
        # exactly one ACK per command
        await gcs.wait_sim(0.5)
        acks = [m.command for _, m in gcs.heard if m.get_type() == "COMMAND_ACK"]
        assert acks.count(consts.MavCmd.NAV_TAKEOFF) == 2 and acks.count(64_000) == 1


async def test_guided_velocity_and_yaw_2503_and_units(sitl):
    async with sitl() as (fleet, gcs):
        gcs.hello()
        await arm_and_take_off(gcs)
        yaw = math.radians(90)
        await gcs.stream(lambda: velocity_yaw(gcs, 3.0, 2.0, yaw), seconds=4.0)
        vel = fleet.frames.vel_ned_m_s[0].copy()
        assert vel[0] == pytest.approx(3.0, abs=0.1) and vel[1] == pytest.approx(2.0, abs=0.1)
        assert math.degrees(fleet.frames.yaw_rad[0]) == pytest.approx(90.0, abs=2.0)
        gcs.fresh()
        gpi = await gcs.wait_for("GLOBAL_POSITION_INT")
        assert gpi.vx == pytest.approx(300, abs=15) and gpi.vy == pytest.approx(200, abs=15)
        assert gpi.hdg == pytest.approx(9000, abs=300)
        home = fleet.homes[0]
        n, e, _d = geodetic_to_ned(from_deg_e7(gpi.lat), from_deg_e7(gpi.lon), gpi.alt / 1000, home)
        # the truth when it was sent: now, less the steady velocity since
        since_s = fleet.now_s() - gpi.time_boot_ms / 1000
        truth = fleet.frames.pos_ned_m[0] - fleet.frames.home_ned_m[0] - vel * since_s
        assert float(n) == pytest.approx(truth[0], abs=1.0)
        assert float(e) == pytest.approx(truth[1], abs=1.0)
        assert gpi.relative_alt == pytest.approx(-truth[2] * 1000, abs=1000)
        await gcs.command(
            consts.MavCmd.SET_MESSAGE_INTERVAL, consts.MsgId.POSITION_TARGET_LOCAL_NED, 200_000
        )
        echo = await gcs.wait_for("POSITION_TARGET_LOCAL_NED")
        assert echo.type_mask == consts.TYPE_MASK_VELOCITY_YAW and echo.vx == pytest.approx(3.0)
        await gcs.command(
            consts.MavCmd.SET_MESSAGE_INTERVAL, consts.MsgId.EKF_STATUS_REPORT, 500_000
        )
        ekf = await gcs.wait_for("EKF_STATUS_REPORT")
        assert ekf.flags & consts.EKF_GOOD == consts.EKF_GOOD


async def test_guid_timeout_stops_but_stays_guided(sitl):
    """GLOBAL_POSITION_INT's velocities, on the vehicle's clock from the last setpoint."""
    async with sitl() as (fleet, gcs):
        gcs.hello()
        await arm_and_take_off(gcs, 10.0)
        ap = fleet.vehicles[0]
        await gcs.stream(lambda: velocity_yaw(gcs, 0.0, 4.0, 0.0), seconds=3.0)
        assert fleet.frames.vel_ned_m_s[0, 1] == pytest.approx(4.0, abs=0.2)
        last = ap.last_setpoint_s
        await gcs.sent_after("GLOBAL_POSITION_INT", last + 5.5)
        flying = gcs.sent_between("GLOBAL_POSITION_INT", last, last + 2.5)
        assert len(flying) >= 20 and min(m.vy for m in flying) > 350  # < GUID_TIMEOUT (3 s)
        stopped = gcs.sent_between("GLOBAL_POSITION_INT", last + 5.5, math.inf)
        assert max(math.hypot(m.vx, m.vy) for m in stopped) < 30  # > 3 s + deceleration
        assert ap.custom_mode == consts.CopterMode.GUIDED
        gcs.send(velocity_yaw(gcs, 0.0, 4.0, 0.0))  # the next setpoint resumes
        await gcs.until("the setpoint", lambda: ap.last_setpoint_s > last)
        resumed = await gcs.sent_after("GLOBAL_POSITION_INT", ap.last_setpoint_s + 2.5)
        assert resumed.vy > 300


async def test_single_ignore_bit_makes_the_setpoint_invalid_and_stops(sitl):
    async with sitl() as (fleet, gcs):
        gcs.hello()
        await arm_and_take_off(gcs, 10.0)
        await gcs.stream(lambda: velocity_yaw(gcs, 4.0, 0.0, 0.0), seconds=2.0)
        assert fleet.frames.vel_ned_m_s[0, 0] > 3.0
        trap = consts.TYPE_MASK_VELOCITY_YAW | consts.TypeMask.VZ_IGNORE  # 2535
        await gcs.stream(lambda: velocity_yaw(gcs, 4.0, 0.0, 0.0, mask=trap), seconds=3.0)
        assert np.hypot(*fleet.frames.vel_ned_m_s[0, :2]) < 0.3
        counters = fleet.vehicles[0].counters
        invalid = "invalid: position, velocity and acceleration need all three axes"
        assert counters.ignored_reasons[invalid] == 30
        # outside GUIDED setpoints are silently ignored
        ack = await gcs.command(consts.MavCmd.DO_SET_MODE, 1, consts.CopterMode.BRAKE)
        assert ack.result == consts.MavResult.ACCEPTED
        before = counters.ignored_reasons["not in GUIDED"]
        gcs.send(velocity_yaw(gcs, 4.0, 0.0, 0.0))
        await gcs.wait_sim(0.3)
        assert counters.ignored_reasons["not in GUIDED"] == before + 1


async def test_auto_disarm_on_the_ground(sitl):
    async with sitl() as (fleet, gcs):
        gcs.hello()
        await gcs.wait_ready()
        await gcs.command(consts.MavCmd.DO_SET_MODE, 1, consts.CopterMode.GUIDED)
        await gcs.command(consts.MavCmd.COMPONENT_ARM_DISARM, 1)
        t_arm = fleet.now_s()
        hb = await gcs.heartbeat_after(t_arm)
        assert hb.base_mode & consts.MavModeFlag.SAFETY_ARMED
        await gcs.wait_sim(fleet.cfg.ardupilot.disarm_delay_s + 0.5)
        hb = await gcs.heartbeat_after(fleet.now_s())
        assert not hb.base_mode & consts.MavModeFlag.SAFETY_ARMED
        assert "Disarming motors" in gcs.texts()


async def test_land_disarms_at_touchdown(sitl):
    async with sitl() as (fleet, gcs):
        gcs.hello()
        await arm_and_take_off(gcs, 5.0)
        ack = await gcs.command(consts.MavCmd.NAV_LAND)
        assert ack.result == consts.MavResult.ACCEPTED
        await gcs.wait_sim(15.0)
        assert fleet.vehicles[0].landed and not fleet.vehicles[0].armed
        assert fleet.finished()


async def test_malformed_command_parameters_are_denied_not_fatal(sitl):
    """NaN or out-of-range parameters are refused like any malformed command (during boot
    too); the mock goes on serving."""
    nan = float("nan")
    async with sitl() as (_fleet, gcs):
        gcs.hello()
        ack = await gcs.command(consts.MavCmd.DO_SET_MODE, 1, -1)  # during boot
        assert ack.result == consts.MavResult.DENIED
        await gcs.wait_ready()
        for params in ((nan, consts.CopterMode.GUIDED), (1, nan), (1, 1e12)):
            ack = await gcs.command(consts.MavCmd.DO_SET_MODE, *params)
            assert ack.result == consts.MavResult.DENIED
            text = await gcs.wait_for("STATUSTEXT", lambda m: "invalid" in m.text)
            assert text.text.startswith("DO_SET_MODE: param")
        ack = await gcs.command(consts.MavCmd.SET_MESSAGE_INTERVAL, nan, 1e5)
        assert ack.result == consts.MavResult.DENIED
        ack = await gcs.command(consts.MavCmd.DO_SET_MODE, 1, consts.CopterMode.GUIDED)
        assert ack.result == consts.MavResult.ACCEPTED  # still serving
        hb = await gcs.wait_for("HEARTBEAT", lambda m: m.custom_mode == consts.CopterMode.GUIDED)
        assert hb.custom_mode == consts.CopterMode.GUIDED

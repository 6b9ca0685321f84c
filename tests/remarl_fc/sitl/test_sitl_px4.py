"""The PX4 flavour of the mock, walked with real MAVLink bytes over UDP."""

from __future__ import annotations

import math

import pytest

from remarl_fc.mavlink.consts import (
    TYPE_MASK_VELOCITY_YAW,
    LandedState,
    MavCmd,
    MavFrame,
    MavModeFlag,
    MavResult,
    MavState,
    Px4AutoSubMode,
    Px4MainMode,
    px4_custom_mode,
    px4_mode_parts,
)

pytestmark = [pytest.mark.asyncio, pytest.mark.network, pytest.mark.timeout(120)]

OFFBOARD = px4_custom_mode(Px4MainMode.OFFBOARD)
HOLD = px4_custom_mode(Px4MainMode.AUTO, Px4AutoSubMode.LOITER)


def velocity(gcs, vn: float, ve: float, vd: float = 0.0, yaw: float = 0.0, frame: int = 1):
    return gcs.f.set_position_target_local_ned_encode(
        0, 1, 1, frame, TYPE_MASK_VELOCITY_YAW, 0, 0, 0, vn, ve, vd, 0, 0, 0, yaw, 0
    )


async def stream(gcs, seconds: float, **kw) -> None:
    """Send velocity setpoints at 10 Hz for ``seconds`` simulated seconds."""
    await gcs.stream(lambda: velocity(gcs, **kw), seconds)


async def heartbeat_streaming(gcs, sim_s: float):
    """The first HEARTBEAT after ``sim_s``, streaming setpoints at 10 Hz meanwhile (so that
    OFFBOARD holds however long the heartbeat takes)."""
    while True:
        beats = [m for t, m in gcs.heard if t > sim_s and m.get_type() == "HEARTBEAT"]
        if beats:
            return beats[0]
        await stream(gcs, 0.1, vn=0.0, ve=0.0)


async def test_px4_streams_by_default_and_heartbeat_encoding(sitl):
    async with sitl(flavour="px4") as (fleet, gcs):
        gcs.hello()
        await gcs.wait_ready()
        await gcs.wait_sim(1.5)
        kinds = {m.get_type() for _, m in gcs.heard}
        assert {"HEARTBEAT", "GLOBAL_POSITION_INT", "ATTITUDE", "EXTENDED_SYS_STATE"} <= kinds
        hb = await gcs.heartbeat_after(fleet.now_s())
        assert hb.autopilot == 12 and hb.system_status == MavState.STANDBY
        assert px4_mode_parts(hb.custom_mode) == (Px4MainMode.POSCTL, 0)


async def test_offboard_needs_a_setpoint_stream(sitl):
    async with sitl(flavour="px4") as (fleet, gcs):
        gcs.hello()
        await gcs.wait_ready()
        ack = await gcs.command(MavCmd.DO_SET_MODE, 1, Px4MainMode.OFFBOARD)
        assert ack.result == MavResult.TEMPORARILY_REJECTED
        # the packed custom_mode in p2 truncates to 0: ACCEPTED, nothing changes
        ack = await gcs.command(MavCmd.DO_SET_MODE, 1, OFFBOARD)
        assert ack.result == MavResult.ACCEPTED
        hb = await gcs.heartbeat_after(fleet.now_s())
        assert px4_mode_parts(hb.custom_mode)[0] == Px4MainMode.POSCTL
        gcs.send(velocity(gcs, 0.0, 0.0))  # proof of life, then at once the mode change
        ack = await gcs.command(MavCmd.DO_SET_MODE, 1, Px4MainMode.OFFBOARD)
        assert ack.result == MavResult.ACCEPTED
        hb = await heartbeat_streaming(gcs, fleet.now_s())
        assert hb.custom_mode == OFFBOARD
        assert hb.base_mode & MavModeFlag.CUSTOM_MODE_ENABLED


async def test_offboard_flight_then_loss_goes_to_hold_then_the_action(sitl):
    async with sitl(flavour="px4") as (fleet, gcs):
        gcs.hello()
        await gcs.wait_ready()
        gcs.send(velocity(gcs, 0.0, 0.0, -2.0))  # proof of life, then at once the mode change
        ack = await gcs.command(MavCmd.DO_SET_MODE, 1, Px4MainMode.OFFBOARD)
        assert ack.result == MavResult.ACCEPTED
        gcs.send(velocity(gcs, 0.0, 0.0, -2.0))
        ack = await gcs.command(MavCmd.COMPONENT_ARM_DISARM, 1)
        assert ack.result == MavResult.ACCEPTED
        await stream(gcs, 4.0, vn=0.0, ve=0.0, vd=-2.0)  # climb in offboard
        assert fleet.frames.height_m()[0] > 4.0
        await stream(gcs, 4.0, vn=5.0, ve=0.0, vd=0.0, yaw=math.radians(45))
        assert fleet.frames.vel_ned_m_s[0, 0] == pytest.approx(5.0, abs=0.2)
        assert math.degrees(fleet.frames.yaw_rad[0]) == pytest.approx(45.0, abs=2.0)
        t_stop = fleet.now_s()
        await gcs.wait_sim(1.5)  # > COM_OF_LOSS_T = 1 s
        hb = await gcs.heartbeat_after(t_stop + 1.2)
        assert hb.custom_mode == HOLD
        assert hb.system_status == MavState.CRITICAL
        await gcs.wait_sim(fleet.cfg.px4.com_fail_act_t_s)  # then COM_OBL_RC_ACT (Position)
        hb = await gcs.heartbeat_after(fleet.now_s())
        assert px4_mode_parts(hb.custom_mode)[0] == Px4MainMode.POSCTL
        assert abs(fleet.frames.vel_ned_m_s[0, 0]) < 0.5


async def test_px4_frames_and_arming_rules(sitl):
    async with sitl(flavour="px4") as (fleet, gcs):
        gcs.hello()
        ack = await gcs.command(MavCmd.COMPONENT_ARM_DISARM, 1)  # at once: no position yet
        assert ack.result == MavResult.TEMPORARILY_REJECTED
        assert (await gcs.wait_for("STATUSTEXT")).text == "Arming denied: no global position"
        await gcs.wait_ready()
        # LOCAL_OFFSET_NED (7) is ArduPilot-only: PX4 drops it, so no proof of life
        gcs.send(velocity(gcs, 1.0, 0.0, frame=MavFrame.LOCAL_OFFSET_NED))
        await gcs.wait_sim(0.2)
        ack = await gcs.command(MavCmd.DO_SET_MODE, 1, Px4MainMode.OFFBOARD)
        assert ack.result == MavResult.TEMPORARILY_REJECTED
        assert fleet.vehicles[0].counters.ignored_reasons["invalid: frame 7 not accepted"] == 1
        # arm in POSCTL and sit: COM_DISARM_PRFLT disarms after 10 s
        ack = await gcs.command(MavCmd.COMPONENT_ARM_DISARM, 1)
        assert ack.result == MavResult.ACCEPTED
        await gcs.wait_sim(fleet.cfg.px4.com_disarm_prflt_s + 0.5)
        hb = await gcs.heartbeat_after(fleet.now_s())
        assert not hb.base_mode & MavModeFlag.SAFETY_ARMED


async def test_px4_takeoff_to_mis_takeoff_alt_then_hold_and_land(sitl):
    async with sitl(flavour="px4") as (fleet, gcs):
        gcs.hello()
        await gcs.wait_ready()
        ack = await gcs.command(MavCmd.COMPONENT_ARM_DISARM, 1)
        assert ack.result == MavResult.ACCEPTED
        ack = await gcs.command(MavCmd.NAV_TAKEOFF, 0, 0, 0, math.nan, math.nan, math.nan, math.nan)
        assert ack.result == MavResult.ACCEPTED
        await gcs.wait_sim(4.0)
        assert fleet.frames.height_m()[0] == pytest.approx(fleet.cfg.px4.mis_takeoff_alt_m, abs=0.2)
        hb = await gcs.heartbeat_after(fleet.now_s())
        assert hb.custom_mode == HOLD
        gcs.fresh()
        ext = await gcs.wait_for("EXTENDED_SYS_STATE")
        assert ext.landed_state == LandedState.IN_AIR
        assert (await gcs.command(MavCmd.NAV_LAND)).result == MavResult.ACCEPTED
        await gcs.wait_sim(8.0)
        assert fleet.vehicles[0].landed and not fleet.vehicles[0].armed  # COM_DISARM_LAND

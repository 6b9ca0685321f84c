"""What real ArduCopter SITL showed that the mock now does: the slow start, ADS-B on request.

Measured on ArduCopter SITL (V4.7.0-dev): arming is refused until the EKF uses GPS ("PreArm:
Need Position Estimate"; control began 52.8 s after start in a `fly --takeoff 20` flight), the
climb starts 4.5 s after NAV_TAKEOFF's ACK, and SET_MESSAGE_INTERVAL for ADSB_VEHICLE (246) is
ACCEPTED. The other tests start the mock quickly (`ARDUPILOT_QUICK_START`); these fly the
firmware's defaults, at a higher speed-up.
"""

from __future__ import annotations

from typing import Any

import pytest

from remarl_fc.mavlink.consts import (
    EKF_GOOD,
    CopterMode,
    EkfFlag,
    MavCmd,
    MavResult,
    MsgId,
)
from remarl_fc.sitl.config import (
    ARDUCOPTER_CLIMB_START_S,
    ARDUCOPTER_EKF_READY_S,
    ArduPilotParams,
)
from sim.scenarios import load_scenario

pytestmark = [pytest.mark.asyncio, pytest.mark.network, pytest.mark.timeout(120)]

FAST = 40.0
"""Speed-up of these mocks: the slow start is 39 simulated seconds."""


def ekf_ready(flags: int) -> bool:
    """What `fly` waits for: horizontal velocity and absolute position, not constant-position."""
    return bool(flags & EKF_GOOD == EKF_GOOD) and not flags & EkfFlag.CONST_POS_MODE


async def test_ardupilot_refuses_until_its_ekf_uses_gps_then_climbs_late(sitl):
    p = ArduPilotParams()  # the firmware's timing, not the tests' quick start
    assert (p.position_estimate_s, p.takeoff_delay_s) == (ARDUCOPTER_EKF_READY_S, 3.5)
    async with sitl(speedup=FAST, ardupilot=p) as (fleet, gcs):
        gcs.hello()
        await gcs.until_sim(p.boot_s + 0.5)
        ack = await gcs.command(MavCmd.SET_MESSAGE_INTERVAL, MsgId.EKF_STATUS_REPORT, 500_000)
        assert ack.result == MavResult.ACCEPTED
        assert not ekf_ready((await gcs.wait_for("EKF_STATUS_REPORT")).flags)
        for when_s in (p.boot_s + 1.0, p.position_estimate_s - 1.0):
            await gcs.until_sim(when_s)
            ack = await gcs.command(MavCmd.COMPONENT_ARM_DISARM, 1)
            assert ack.result == MavResult.FAILED
            assert (await gcs.wait_for("STATUSTEXT")).text == "PreArm: Need Position Estimate"
            ack = await gcs.command(MavCmd.DO_SET_MODE, 1, CopterMode.GUIDED)
            assert ack.result == MavResult.FAILED
            report = await gcs.wait_for("EKF_STATUS_REPORT")  # sent after the refusal
            assert not ekf_ready(report.flags) and report.flags & EkfFlag.CONST_POS_MODE
        await gcs.until_sim(p.position_estimate_s)
        gcs.fresh()
        t_ready, report = await gcs.wait_for_stamped("EKF_STATUS_REPORT")
        assert ekf_ready(report.flags) and t_ready >= p.position_estimate_s
        ack = await gcs.command(MavCmd.DO_SET_MODE, 1, CopterMode.GUIDED)
        assert ack.result == MavResult.ACCEPTED
        ack = await gcs.command(MavCmd.COMPONENT_ARM_DISARM, 1)
        assert ack.result == MavResult.ACCEPTED
        ack = await gcs.command(MavCmd.SET_MESSAGE_INTERVAL, MsgId.GLOBAL_POSITION_INT, 50_000)
        assert ack.result == MavResult.ACCEPTED
        ack = await gcs.command(MavCmd.NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, 20.0)
        assert ack.result == MavResult.ACCEPTED
        t_ack = max(t for t, m in gcs.heard if m.get_type() == "COMMAND_ACK")
        retry = await gcs.command(MavCmd.NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, 20.0)
        assert retry.result == MavResult.ACCEPTED  # a retry while spooling up changes nothing
        one_m = await gcs.wait_for("GLOBAL_POSITION_INT", lambda m: m.relative_alt >= 1000)
        # 1 m is reached 4.5 s after the ACK, as on ArduCopter SITL (within the 10 Hz timer
        # tick, the 20 Hz telemetry and the ACK's arrival stamp at 40× speed-up)
        climb_start_s = one_m.time_boot_ms / 1000 - t_ack
        assert climb_start_s == pytest.approx(ARDUCOPTER_CLIMB_START_S, abs=0.15)
        top = await gcs.wait_for("GLOBAL_POSITION_INT", lambda m: m.relative_alt >= 19_500)
        # ArduCopter SITL: 19.5 m 13.5 s after the ACK; the mock's climb is quicker at the top
        assert 11.5 <= top.time_boot_ms / 1000 - t_ack <= 13.5
        assert fleet.vehicles[0].armed


@pytest.mark.parametrize("flavour", ["ardupilot", "px4"])
async def test_adsb_vehicle_streams_at_the_interval_asked_for(sitl, flavour):
    async with sitl(flavour=flavour, scenario=load_scenario("3u2o")) as (fleet, gcs):
        gcs.hello()
        await gcs.wait_for("ADSB_VEHICLE")  # the receiver's own rate until asked
        # The rate is read off what the mock sends, stamped in its own simulated time: what the
        # ground station has received by the end of a window lags by however far its receive
        # loop is behind (under load, reports sent late in the window are still unread).
        sent: list[float] = []
        send = fleet.links.send

        def spy(i: int, msg: Any, *, component: int | None = None) -> None:
            if i == 0 and msg.get_type() == "ADSB_VEHICLE":
                sent.append(fleet.now_s())
            send(i, msg, component=component)

        fleet.links.send = spy  # type: ignore[method-assign]

        async def count_for(seconds: float) -> float:
            """ADSB_VEHICLE reports per intruder per second over the next ``seconds``."""
            start = fleet.now_s() + 0.05
            await gcs.wait_sim(seconds + 0.05)
            got = sum(1 for t in sent if start <= t < start + seconds)
            heard = gcs.count("ADSB_VEHICLE", since_s=start)
            assert heard > 0 or not got  # what was sent reaches the ground station
            return got / fleet.traffic.count / seconds

        assert await count_for(4.0) == pytest.approx(fleet.cfg.adsb_hz, abs=0.3)
        ack = await gcs.command(MavCmd.SET_MESSAGE_INTERVAL, MsgId.ADSB_VEHICLE, 100_000)
        assert ack.result == MavResult.ACCEPTED  # as on ArduCopter SITL (and PX4)
        assert await count_for(4.0) == pytest.approx(10.0, abs=0.5)
        ack = await gcs.command(MavCmd.SET_MESSAGE_INTERVAL, MsgId.ADSB_VEHICLE, -1)
        assert ack.result == MavResult.ACCEPTED
        assert await count_for(2.0) == 0.0
        ack = await gcs.command(MavCmd.SET_MESSAGE_INTERVAL, MsgId.ADSB_VEHICLE, 0)
        assert ack.result == MavResult.ACCEPTED  # back to the default
        assert await count_for(4.0) == pytest.approx(fleet.cfg.adsb_hz, abs=0.3)

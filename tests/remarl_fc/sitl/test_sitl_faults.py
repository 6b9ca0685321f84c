"""Faults, signing and ADS-B traffic of the mock, over real UDP."""

from __future__ import annotations

import math
import os

import pytest

from remarl_fc.frames import from_deg_e7, geodetic_to_ned
from remarl_fc.mavlink.consts import (
    CopterMode,
    EkfFlag,
    MavCmd,
    MavComponent,
    MavResult,
    MsgId,
)
from remarl_fc.sitl.faults import Faults
from sim.scenarios import load_scenario

pytestmark = [pytest.mark.asyncio, pytest.mark.network, pytest.mark.timeout(120)]


async def test_link_cut_and_heartbeat_dropout(sitl):
    faults = Faults()
    async with sitl(faults=faults) as (fleet, gcs):
        gcs.hello()
        await gcs.wait_for("HEARTBEAT")
        now = fleet.now_s()
        faults.cut_link(0, now + 1.0, 3.0)
        faults.drop_heartbeats(0, now + 6.0, 3.0)
        await gcs.wait_sim(11.0)
        beats = [t for t, m in gcs.heard if m.get_type() == "HEARTBEAT"]
        cut = [t for t in beats if now + 1.2 < t < now + 3.8]
        muted = [t for t in beats if now + 6.2 < t < now + 8.8]
        after = [t for t in beats if t > now + 9.2]
        assert cut == [] and muted == [] and after
        assert fleet.link_stats[0]["dropped_out"] > 0
        # commands during a cut get no answer at all
        faults.cut_link(0, fleet.now_s(), 2.0)
        gcs.send(gcs.f.command_long_encode(1, 1, MavCmd.REQUEST_MESSAGE, 0, 148, 0, 0, 0, 0, 0, 0))
        await gcs.wait_sim(1.0)
        assert fleet.vehicles[0].counters.commands["REQUEST_MESSAGE"] == 0


async def test_packet_loss_rate_is_close_to_asked(sitl):
    async with sitl(faults=Faults(loss=0.3)) as (fleet, gcs):
        for _ in range(20):
            gcs.hello()  # some greetings are lost too
        await gcs.wait_for("HEARTBEAT", limit_s=20.0)
        await gcs.command(MavCmd.SET_MESSAGE_INTERVAL, MsgId.ATTITUDE, 20_000)
        t0 = fleet.now_s()
        await gcs.until_sim(t0 + 10.0)
        await gcs.sent_after("ATTITUDE", t0 + 9.5)  # counted on the vehicle's clock
        got = len(gcs.sent_between("ATTITUDE", t0 + 0.5, t0 + 9.5))
        expected = 50 * 9.0
        assert 0.6 * expected < got < 0.8 * expected  # 70 % delivered


async def test_gps_glitch_moves_reported_position_and_flags_the_ekf(sitl):
    faults = Faults()
    async with sitl(faults=faults) as (fleet, gcs):
        gcs.hello()
        await gcs.wait_ready()
        await gcs.command(MavCmd.SET_MESSAGE_INTERVAL, MsgId.GLOBAL_POSITION_INT, 100_000)
        await gcs.command(MavCmd.SET_MESSAGE_INTERVAL, MsgId.EKF_STATUS_REPORT, 100_000)
        start = fleet.now_s() + 0.5
        faults.glitch_gps(0, start, 2.0, 50.0)
        gpi = await gcs.sent_after("GLOBAL_POSITION_INT", start + 0.5)  # within the glitch
        n, _, _ = geodetic_to_ned(from_deg_e7(gpi.lat), from_deg_e7(gpi.lon), 0.0, fleet.homes[0])
        assert float(n) == pytest.approx(50.0, abs=0.5)
        t, ekf = await gcs.wait_for_stamped("EKF_STATUS_REPORT")  # no time_boot_ms: arrival
        assert t < start + 2.0 and ekf.flags & EkfFlag.GPS_GLITCHING
        assert fleet.frames.pos_ned_m[0, 0] == pytest.approx(fleet.frames.home_ned_m[0, 0])
        gpi = await gcs.sent_after("GLOBAL_POSITION_INT", start + 2.1)  # after it
        n, _, _ = geodetic_to_ned(from_deg_e7(gpi.lat), from_deg_e7(gpi.lon), 0.0, fleet.homes[0])
        assert float(n) == pytest.approx(0.0, abs=0.5)


async def test_pilot_takes_the_mode_switch(sitl):
    faults = Faults()
    async with sitl(faults=faults) as (fleet, gcs):
        gcs.hello()
        await gcs.wait_ready()
        await gcs.command(MavCmd.DO_SET_MODE, 1, CopterMode.GUIDED)
        faults.switch_mode(0, fleet.now_s() + 1.0, "LOITER")
        await gcs.wait_sim(1.5)
        hb = await gcs.heartbeat_after(fleet.now_s())
        assert hb.custom_mode == CopterMode.LOITER


async def test_signing_rejects_unsigned_commands(sitl):
    key = os.urandom(32)
    async with sitl(flavour="px4", signing_key=key) as (fleet, gcs):
        gcs.hello()  # HEARTBEAT is on PX4's unsigned allow-list: the vehicle answers
        await gcs.wait_for("HEARTBEAT")
        gcs.send(gcs.f.command_long_encode(1, 1, MavCmd.REQUEST_MESSAGE, 0, 148, 0, 0, 0, 0, 0, 0))
        await gcs.wait_sim(1.0)
        assert fleet.vehicles[0].counters.commands["REQUEST_MESSAGE"] == 0
        assert fleet.codecs[0].stats.rejected_unsigned >= 1
    async with sitl(flavour="px4", signing_key=key, gcs_signing=key) as (fleet, gcs):
        gcs.hello()
        await gcs.wait_for("HEARTBEAT")
        ack = await gcs.command(MavCmd.REQUEST_MESSAGE, 148)
        assert ack.result == MavResult.ACCEPTED
        assert (await gcs.wait_for("AUTOPILOT_VERSION")).uid == 1


async def test_scenario_intruders_fly_as_adsb_traffic(sitl):
    scenario = load_scenario("3u2o")
    async with sitl(scenario=scenario) as (fleet, gcs):
        gcs.hello()
        await gcs.wait_sim(2.0)
        reports = [m for _, m in gcs.heard if m.get_type() == "ADSB_VEHICLE"]
        assert {m.callsign for m in reports} == {"OBST0000", "OBST0001"}
        assert all(m.get_srcComponent() == MavComponent.ADSB for m in reports)
        m = reports[-1]
        n, e, d = geodetic_to_ned(
            from_deg_e7(m.lat), from_deg_e7(m.lon), m.altitude / 1000, fleet.cfg.home
        )
        truth = fleet.traffic.positions_ned(fleet.now_s())
        k = int(m.callsign[-1])
        assert float(n) == pytest.approx(truth[k, 0], abs=1.0)
        assert float(e) == pytest.approx(truth[k, 1], abs=1.0)
        assert -float(d) == pytest.approx(fleet.cfg.cruise_alt_m, abs=0.01)
        assert m.hor_velocity == 0  # waiting for the swarm to start
        fleet.traffic.start_s = fleet.now_s()
        await gcs.wait_sim(1.0)
        gcs.fresh()
        m = await gcs.wait_for("ADSB_VEHICLE")
        assert m.hor_velocity == round(scenario.obstacles.speed_m_s * 100)
        vel = fleet.traffic.vel_ne_m_s[int(m.callsign[-1])]
        assert m.heading / 100 == pytest.approx(
            math.degrees(math.atan2(vel[1], vel[0])) % 360, abs=0.02
        )
        assert len(fleet.vehicles) == 3

"""The link is hostile: forged MAVLink against `fly` on the mock, judged by the ground truth.

An attacker on the same UDP network as `fly` (another address than the vehicles') replays the
whole attack table at once — a drifting position stream for vehicle 2, a HEARTBEAT saying
LOITER, forged ARM refusals with escape bytes, HEARTBEATs claiming vehicle 2, PARAM_VALUE
answers, phantom and flooding ADS-B. The flight must end exactly as a clean one: every vehicle
reached, no collision, exit 0, and the summary must count what was dropped. Where the forger
shares the vehicle's own address (a radio link), only signing can help; then `fly` must at least
never claim more than trusted telemetry shows.
"""

from __future__ import annotations

import asyncio
import os
from collections.abc import Coroutine
from typing import Any

import pytest

from remarl_fc.cli.common import EXIT_NOT_ALL_REACHED
from remarl_fc.cli.fly import fly_exit_status
from remarl_fc.demo import MockFlight, attacker_for
from remarl_fc.demo import fly_on_mock as demo_flight
from remarl_fc.errors import SpoofingDetected
from remarl_fc.flight.tracking import NO_FIX
from remarl_fc.frames import ned_to_geodetic, to_deg_e7
from remarl_fc.mavlink.codec import Codec
from remarl_fc.mavlink.consts import (
    MavAutopilot,
    MavState,
)
from remarl_fc.mavlink.udp import UdpEndpoint
from remarl_fc.sitl.config import DEFAULT_HOME


def fly_on_mock(*args: Any, **kwargs: Any) -> Coroutine[Any, Any, MockFlight]:
    """The demo's flight with ArduCopter's slow start skipped: these tests are about the flight
    (the start itself: tests/remarl_fc/sitl/test_sitl_start.py)."""
    return demo_flight(*args, quick_start=True, **kwargs)


pytestmark = [pytest.mark.asyncio, pytest.mark.network, pytest.mark.timeout(180)]

SPEEDUP = 2.0
"""Simulated seconds per wall second. The attacker, the mock fleet and `fly` share one process
and its event loop; the attacker's rounds run on the wall clock (80 a second), so under attack
the flight needs 0.60 of a core at 4× and 0.47 at 2×. At 4× with two other busy processes on
two cores, three flights in four went stale (`fly` saw no telemetry for 1 simulated second,
0.25 s of wall time) and held every vehicle; at 2×, four in four flew clean."""
VICTIM = 2


def assert_clean_outcome(flight) -> None:
    truth = flight.ground_truth
    assert truth["collisions_vehicle_intruder"] == 0
    assert truth["collisions_vehicle_vehicle"] == 0
    assert truth["min_vehicle_vehicle_m"] >= truth["d_col_m"]
    assert truth["reached_targets"] == len(truth["vehicles"])
    assert fly_exit_status(flight.runtime) == 0, flight.runtime["anomalies"]
    assert sorted(flight.runtime["reached"]) == [1, 2, 3]


def position_frame(forger: Codec, north: float, east: float, height: float, vel) -> bytes:
    lat, lon, alt = ned_to_geodetic(north, east, -height, DEFAULT_HOME)
    vx, vy = (round(v * 100) for v in vel)
    msg = forger.factory.global_position_int_encode(
        0, int(to_deg_e7(lat)), int(to_deg_e7(lon)), round(float(alt) * 1000),
        round(height * 1000), vx, vy, 0, 65535,
    )  # fmt: skip
    return forger.encode(msg)


async def attack_everything(fleet, runtime, box: dict[str, Any]) -> None:
    """The attack table from another address (`remarl_fc.sitl.attacker`), until the end."""
    attacker = box["attacker"] = attacker_for(runtime, victim=VICTIM)
    await attacker.run()


async def test_the_attack_table_from_another_address_changes_nothing():
    box: dict[str, Any] = {}
    flight = await fly_on_mock(
        "3u2o", speedup=SPEEDUP, during=lambda f, r: attack_everything(f, r, box)
    )
    assert_clean_outcome(flight)
    link = flight.runtime["link"]
    assert box["attacker"].sent > 1000
    assert link["foreign_frames"][str(VICTIM)] > 500  # counted, not believed
    assert link["dropped"]["sender not in the mission"] > 100
    assert [a["system_id"] for a in link["alarms"]] == [VICTIM]
    assert link["bound"][str(VICTIM)].startswith("link 0 127.0.0.1:")
    v2 = next(v for v in flight.runtime["vehicles"] if v["system_id"] == VICTIM)
    assert v2["status"] == "reached" and v2["trusted"]
    assert set(v2["telemetry_rejected"]) <= {NO_FIX}  # no real fix lost to the spoofed stream
    # the forged parameter was not read: the real one was
    assert any(e.startswith("parameters: GUID_TIMEOUT=3,") for _, e in v2["events"])
    # every command went to the vehicle, none to the forger: the mock saw them all
    truth_v2 = flight.ground_truth["vehicles"][VICTIM - 1]
    assert truth_v2["commands"]["COMPONENT_ARM_DISARM"] >= 1
    assert flight.runtime["traffic"]["tracks"] <= 16
    assert all(not a["affected"] for a in flight.runtime["anomalies"])
    assert any("spoofing alarm" in e for _, e in v2["events"])


async def test_signing_rejects_the_attack_before_it_is_parsed():
    box: dict[str, Any] = {}
    flight = await fly_on_mock(
        "3u2o",
        speedup=SPEEDUP,
        signing_key=os.urandom(32),
        during=lambda f, r: attack_everything(f, r, box),
    )
    assert_clean_outcome(flight)
    assert flight.runtime["link"]["signed"]
    assert flight.runtime["link"]["alarms"] == []  # unsigned forgeries never reach the gate
    assert flight.runtime["link"]["rejected_unsigned"] > 1000
    assert flight.runtime["link"]["foreign_frames"] == {}


async def test_a_forger_at_the_vehicles_own_address_never_yields_a_false_success():
    """Over a radio link the forger's frames arrive from the vehicle's own address: binding
    cannot tell them apart. The interleaved stream makes vehicle 2 untrusted: it is held, and
    the summary does not call it reached."""

    async def radio_forger(fleet, runtime) -> None:
        link = runtime.links[0]
        forger = Codec(VICTIM, 1)
        await runtime.commands.wait_until(
            "control",
            lambda: runtime.status(VICTIM).value == "controlled",
            120,
        )
        address = link.where[VICTIM]  # bound by now
        track = runtime.by_sysid[VICTIM].track
        while True:
            n, e = track.ne_m
            frame = position_frame(forger, n + 40.0, e, track.height_m, track.vel_ned_m_s[:2])
            link._received(frame, address)  # as if it came over the vehicle's radio
            await asyncio.sleep(0.05 / SPEEDUP)

    flight = await fly_on_mock("3u2o", speedup=SPEEDUP, during=radio_forger)
    truth = flight.ground_truth
    assert truth["collisions_vehicle_intruder"] == 0 == truth["collisions_vehicle_vehicle"]
    v2 = next(v for v in flight.runtime["vehicles"] if v["system_id"] == VICTIM)
    assert not v2["trusted"] and v2["status"] == "held"
    assert VICTIM not in flight.runtime["reached"]
    assert fly_exit_status(flight.runtime) == EXIT_NOT_ALL_REACHED
    kinds = {a["kind"] for a in flight.runtime["anomalies"] if a["affected"]}
    assert "untrusted telemetry" in kinds


async def test_a_second_source_claiming_a_vehicle_before_take_off_stops_the_flight():
    """Before take-off nothing tells which source is the vehicle: fly none, arm nothing."""

    async def claim(fleet, runtime) -> None:
        target = runtime.links[0].local_address
        forger = Codec(VICTIM, 1)
        async with UdpEndpoint(("127.0.0.1", 0), on_datagram=lambda *_: None) as udp:
            while True:
                hb = forger.factory.heartbeat_encode(
                    2, MavAutopilot.ARDUPILOTMEGA, 0, 0, MavState.STANDBY
                )
                udp.send(forger.encode(hb), target)
                await asyncio.sleep(0.2 / SPEEDUP)

    box: dict[str, Any] = {}

    async def claim_and_keep(fleet, runtime) -> None:
        box["fleet"] = fleet
        await claim(fleet, runtime)

    with pytest.raises(ExceptionGroup) as info:
        await fly_on_mock("3u2o", speedup=SPEEDUP, during=claim_and_keep)
    (error,) = info.value.subgroup(SpoofingDetected).exceptions
    assert error.system_id == VICTIM and len(error.sources) == 2
    assert "Nothing was armed" in str(error)
    truth = box["fleet"].summary()["vehicles"]
    assert all(not v["armed"] for v in truth)

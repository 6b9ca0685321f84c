"""MAVSDK, an independent MAVLink client, flies the mock fleet.

MAVSDK 4.x (the native binding, asyncio API) listens on one UDP port that every mock vehicle
sends to (PX4 style, ``out_step=0``), discovers them all, and then for every vehicle at once:
waits for its health, arms, takes off, streams VelocityNedYaw setpoints in offboard control
and stops offboard. The assertions read the mock's ground truth, not MAVSDK's telemetry: the
height reached, the velocity and heading flown, the mode after the stop.

MAVSDK's timeouts are wall-clock (heartbeat 3 s, commands 0.5 s × 3), so the mock runs at 1×,
and each flight takes some 16 s: marked slow. Skipped where the `mavsdk` package (the native
MAVSDK 4 binding) is not installed.
"""

from __future__ import annotations

import asyncio
import contextlib
import math
import socket
import time
from collections.abc import Callable, Iterator
from typing import Any

import numpy as np
import pytest

pytest.importorskip(
    "mavsdk.asyncio", reason="needs the mavsdk package (MAVSDK 4)", exc_type=ImportError
)

from mavsdk.asyncio import Autopilot, ComponentType, Configuration, Mavsdk, System
from mavsdk.asyncio.plugins.action import ActionAsync
from mavsdk.asyncio.plugins.offboard import OffboardAsync, VelocityNedYaw
from mavsdk.asyncio.plugins.telemetry import FlightMode, TelemetryAsync
from mavsdk.logging import LogLevel, log_subscribe, log_unsubscribe

from remarl_fc.mavlink.consts import CopterMode, Px4AutoSubMode, Px4MainMode, px4_custom_mode
from remarl_fc.sitl.config import ARDUPILOT_QUICK_START, Flavour, SitlConfig
from remarl_fc.sitl.fleet import SitlFleet
from remarl_fc.sitl.vehicle import Guidance

pytestmark = [
    pytest.mark.asyncio,
    pytest.mark.network,
    pytest.mark.slow,
    pytest.mark.timeout(120),
]

VEHICLES = 3
WAIT_S = 15.0
"""Wall-clock limit of one wait (generous: CI machines are slow)."""

COMMANDS = [(-2.0, 0.0, 90.0), (0.0, 1.5, -135.0), (1.0, -1.0, 45.0)]
"""Per vehicle: north m/s, east m/s, yaw deg — different for each, so that a setpoint flown by
the wrong vehicle shows; the yaw is not the direction of travel. The vehicles start on a
30 m grid (0, 0), (0, 30), (30, 0) and these take them apart."""

FLY_S = 4.0
"""Simulated seconds of offboard flight (5 velocity time constants)."""

TAKEOFF_M = {"px4": 4.0, "ardupilot": 5.0}
"""Take-off height MAVSDK is told: on PX4 it sets the parameter MIS_TAKEOFF_ALT (default 2.5 m),
on ArduPilot it sends the height in NAV_TAKEOFF's p7."""

OFFBOARD_MODE = {"px4": px4_custom_mode(Px4MainMode.OFFBOARD), "ardupilot": CopterMode.GUIDED}
HOLD_MODE = {
    "px4": px4_custom_mode(Px4MainMode.AUTO, Px4AutoSubMode.LOITER),
    "ardupilot": CopterMode.BRAKE,  # MAVSDK 4.1.0 maps Hold to BRAKE on ArduPilot
}
AUTOPILOT = {"px4": Autopilot.PX4, "ardupilot": Autopilot.ARDUPILOT}


def free_udp_port() -> int:
    """A UDP port nobody has bound on 127.0.0.1 (for MAVSDK's udpin)."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        port: int = s.getsockname()[1]
        return port


async def until(what: str, pred: Callable[[], bool], limit_s: float = WAIT_S) -> None:
    """Poll ``pred`` until it holds; fail with ``what`` after ``limit_s`` wall seconds."""
    end = time.monotonic() + limit_s
    while not pred():
        if time.monotonic() > end:
            raise AssertionError(f"timed out waiting for {what}")
        await asyncio.sleep(0.05)


async def sim_sleep(fleet: SitlFleet, seconds: float) -> None:
    """Sleep ``seconds`` of the mock's simulated clock."""
    target = fleet.now_s() + seconds
    await until("the mock's clock", lambda: fleet.now_s() >= target, WAIT_S + seconds)


async def discover(mavsdk: Mavsdk, flavour: str) -> dict[int, System]:
    """Every vehicle, by system id, once MAVSDK knows it is an autopilot of ``flavour``."""
    end = time.monotonic() + WAIT_S
    while True:
        found = {}
        for system in await mavsdk.get_systems():
            if await system.has_autopilot() and await system.autopilot_type() == AUTOPILOT[flavour]:
                found[await system.get_system_id()] = system
        if len(found) >= VEHICLES or time.monotonic() > end:
            return found
        await asyncio.sleep(0.1)


def heading_error_deg(fleet: SitlFleet, i: int, yaw_deg: float) -> float:
    """|true heading − commanded yaw|, degrees, wrapped."""
    diff = math.degrees(float(fleet.frames.yaw_rad[i])) - yaw_deg
    return abs((diff + 180.0) % 360.0 - 180.0)


async def fly(fleet: SitlFleet, system: System, flavour: Flavour) -> None:
    """Health → arm → take off → offboard velocity + yaw → stop, checked on the ground truth."""
    i = await system.get_system_id() - 1
    telemetry, action, offboard = TelemetryAsync(system), ActionAsync(system), OffboardAsync(system)
    try:
        await fly_with(fleet, i, telemetry, action, offboard, flavour)
    finally:
        # Release the plugins here, on the event loop's thread. Left to the garbage collector,
        # the last reference can die on an executor thread (MAVSDK's awaitables close over the
        # plugin) while Mavsdk.__aexit__ destroys the core on this one: a native abort.
        for plugin in (telemetry, action, offboard):
            plugin.destroy()


async def fly_with(
    fleet: SitlFleet,
    i: int,
    telemetry: TelemetryAsync,
    action: ActionAsync,
    offboard: OffboardAsync,
    flavour: Flavour,
) -> None:
    """The flight of vehicle ``i`` (0-based) through its three MAVSDK plugins."""
    ap, f = fleet.vehicles[i], fleet.frames
    if flavour == "ardupilot":  # ArduCopter streams nothing until asked (stream rates 0)
        await telemetry.set_rate_position(10.0)
        await telemetry.set_rate_home(1.0)
        await telemetry.set_rate_health(2.0)  # EKF_STATUS_REPORT on ArduPilot

    async with asyncio.timeout(WAIT_S), contextlib.aclosing(telemetry.subscribe_health()) as hs:
        async for health in hs:
            if health.is_global_position_ok and health.is_home_position_ok and health.is_armable:
                break
    assert ap.position_ok(fleet.now_s()), "MAVSDK saw a position before the mock had one"

    await action.arm()
    assert ap.armed

    await action.set_takeoff_altitude(TAKEOFF_M[flavour])
    assert await action.get_takeoff_altitude() == pytest.approx(TAKEOFF_M[flavour])
    await action.takeoff()
    await until(
        f"vehicle {i + 1} to finish its take-off and settle",
        lambda: f.guidance[i] != Guidance.CLIMB and abs(float(f.vel_ned_m_s[i, 2])) < 0.05,
    )
    assert not ap.landed
    height = -float(f.pos_ned_m[i, 2])
    assert height == pytest.approx(TAKEOFF_M[flavour], abs=0.35)
    if flavour == "px4":
        assert ap.custom_mode == HOLD_MODE["px4"]  # AUTO.TAKEOFF ends in Hold
    else:
        assert ap.custom_mode == CopterMode.GUIDED  # MAVSDK's take-off switches to GUIDED

    north, east, yaw_deg = COMMANDS[i]
    await offboard.set_velocity_ned(VelocityNedYaw(north, east, 0.0, yaw_deg))
    await offboard.start()
    assert ap.custom_mode == OFFBOARD_MODE[flavour]
    await sim_sleep(fleet, FLY_S)
    assert await offboard.is_active()
    assert await telemetry.flight_mode() == FlightMode.OFFBOARD
    vel = f.vel_ned_m_s[i]
    np.testing.assert_allclose(vel, [north, east, 0.0], atol=0.15)
    assert heading_error_deg(fleet, i, yaw_deg) < 3.0
    assert -float(f.pos_ned_m[i, 2]) == pytest.approx(height, abs=0.3)

    await offboard.stop()
    assert ap.custom_mode == HOLD_MODE[flavour]
    await sim_sleep(fleet, 3.0)
    assert ap.custom_mode == HOLD_MODE[flavour]
    assert not ap.failsafe
    assert float(np.hypot(*f.vel_ned_m_s[i, :2])) < 0.5
    assert not ap.landed and ap.armed
    assert await telemetry.flight_mode() == FlightMode.HOLD


@contextlib.contextmanager
def mavsdk_complaints() -> Iterator[list[str]]:
    """MAVSDK's warnings and errors while inside (command retries, timeouts, ...)."""
    complaints: list[str] = []

    def record(level: LogLevel, message: str, file: str | None, line: int) -> bool:
        if level >= LogLevel.WARN:
            complaints.append(f"{level.name}: {message} ({file}:{line})")
        return False  # MAVSDK prints it as well

    log_subscribe(record)
    try:
        yield complaints
    finally:
        log_unsubscribe()


@pytest.mark.parametrize("flavour", ["px4", "ardupilot"])
async def test_mavsdk_discovers_arms_takes_off_and_flies_offboard(flavour: Flavour) -> None:
    port = free_udp_port()
    cfg = SitlConfig(
        vehicles=VEHICLES,
        flavour=flavour,
        base_port=0,
        speedup=1.0,
        ardupilot=ARDUPILOT_QUICK_START,  # the slow start has its own tests
        out=("127.0.0.1", port),
        out_step=0,
    )
    config = Configuration.create_with_component_type(ComponentType.GROUND_STATION)
    with mavsdk_complaints() as complaints:
        async with Mavsdk(config) as mavsdk:
            await mavsdk.add_any_connection(f"udpin://127.0.0.1:{port}")  # bound before the mock
            async with SitlFleet(cfg) as fleet:
                systems = await discover(mavsdk, flavour)
                assert sorted(systems) == list(range(1, VEHICLES + 1))
                async with asyncio.TaskGroup() as group:
                    for system in systems.values():
                        group.create_task(fly(fleet, system, flavour))
                summary: dict[str, Any] = fleet.summary()

    assert complaints == []
    mode_changes = {"px4": 2, "ardupilot": 3}[flavour]  # ArduPilot: + GUIDED for the take-off
    for v in summary["vehicles"]:
        assert v["flew"] and v["armed"] and not v["landed"]
        assert set(v["command_results"]) == {"ACCEPTED"}, v["command_results"]
        commands = v["commands"]  # once each: a MAVSDK retry would mean a lost or late ACK
        assert commands["COMPONENT_ARM_DISARM"] == commands["NAV_TAKEOFF"] == 1, commands
        assert commands["DO_SET_MODE"] == mode_changes, commands
        assert v["setpoints_applied"] > 0.5 * 20 * FLY_S  # MAVSDK streams at 20 Hz (wall)
        assert v["link"]["bad_frames"] == 0
        assert v["params_set"] == ({"MIS_TAKEOFF_ALT": 1} if flavour == "px4" else {})
        assert v["params_refused"] == {}
    assert summary["collisions_vehicle_vehicle"] == 0

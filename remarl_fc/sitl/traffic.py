"""Intruders: a scenario's obstacles flying as ADS-B traffic.

They spawn and move exactly as in the simulator — an episode's start (`sim.spawn.EpisodeStart`:
a scenario's from `sim.spawn.spawn_episodes`, or an encounter drawn by `sim.encounters`) places
them and gives their velocities, `sim.kinematics.straight_points` moves them — mapped from the
simulator's frame (x east, y north) into the arena's NED frame at the cruise height. They wait
at their spawn points until the swarm starts its mission (the first vehicle moving faster than
`START_SPEED_M_S` horizontally, or an explicit start time), so that take-off time does not
eat the scenario's geometry.

Reports are exact unless the fleet gives `ReportErrors` (``sitl --adsb-noise``): then each
intruder's broadcast carries the simulator's report error (`sim.config.SensorConfig`: EPU drawn
per intruder, NACv), drawn afresh for every broadcast and the same in every vehicle's
receiver, as one transponder's broadcast is.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from remarl_fc.frames import GeoPoint, course_and_speed, ned_to_geodetic, sim_to_ne, to_deg_e7
from remarl_fc.mavlink.consts import (
    ADSB_ALTITUDE_TYPE_GEOMETRIC,
    ADSB_EMITTER_TYPE_UAV,
    AdsbFlag,
)
from sim.config import SensorConfig
from sim.kinematics import straight_points
from sim.sensors import report_sigmas

FloatArray = NDArray[np.float64]

START_SPEED_M_S = 1.0
"""Traffic starts when the first vehicle flies faster than this horizontally."""

ICAO_BASE = 0xC0_0000
"""ICAO address of intruder k: ICAO_BASE + k (a block no real aircraft of this mock uses)."""

ADSB_FLAGS = int(
    AdsbFlag.VALID_COORDS
    | AdsbFlag.VALID_ALTITUDE
    | AdsbFlag.VALID_HEADING
    | AdsbFlag.VALID_VELOCITY
    | AdsbFlag.VALID_CALLSIGN
    | AdsbFlag.SIMULATED
    | AdsbFlag.VERTICAL_VELOCITY_VALID
)
"""ADSB_VEHICLE.flags of every intruder report (SIMULATED set, as ArduPilot SITL's are)."""


def report_errors_text(sensors: SensorConfig | None = None) -> str:
    """The report errors `ReportErrors.drawn` draws from, in words (for help texts).

    >>> report_errors_text()
    'EPU 10-30 m, NACv 3 m/s'
    """
    s = SensorConfig() if sensors is None else sensors
    lo, hi = s.adsb_epu_m
    return f"EPU {lo:g}-{hi:g} m, NACv {s.adsb_nacv_m_s:g} m/s"


@dataclass(frozen=True)
class ReportErrors:
    """The error of each intruder's ADS-B broadcasts, as the simulator draws a report's.

    Broadcast j of intruder k is the one at ``floor(now · rate_hz) = j``; its error is drawn
    from a generator seeded by (``seed``, k, j), so every vehicle's receiver hears the same
    error for it, and asking twice gives the same report.

    Attributes:
        pos_sigma_m: (M,) position error σ per axis, m (EPU / 2.448).
        vel_sigma_m_s: velocity error σ per axis, m/s (NACv / 2.448).
        rate_hz: broadcasts per second.
        seed: the fleet's seed.
    """

    pos_sigma_m: FloatArray
    vel_sigma_m_s: float
    rate_hz: float
    seed: int

    @classmethod
    def drawn(
        cls, count: int, sensors: SensorConfig, rate_hz: float, seed: int, rng: np.random.Generator
    ) -> ReportErrors:
        """EPU uniform in ``sensors.adsb_epu_m`` per intruder (one draw of ``rng`` each)."""
        epu = rng.uniform(*sensors.adsb_epu_m, size=count)
        return cls(*report_sigmas(epu, sensors.adsb_nacv_m_s), rate_hz, seed)

    def at(self, now_s: float) -> tuple[FloatArray, FloatArray]:
        """(M, 2) position and (M, 2) velocity errors (north, east) of the broadcast at now."""
        j = math.floor(now_s * self.rate_hz)
        pos, vel = np.empty((len(self.pos_sigma_m), 2)), np.empty((len(self.pos_sigma_m), 2))
        for k, sigma in enumerate(self.pos_sigma_m.tolist()):
            draw = np.random.default_rng([self.seed, k, j]).standard_normal(4)
            pos[k], vel[k] = sigma * draw[:2], self.vel_sigma_m_s * draw[2:]
        return pos, vel


class Traffic:
    """M intruders of an episode.

    Args:
        pos_m, vel_m_s: (M, 2) where they spawn and their velocities, in the simulator's frame
            (`sim.spawn.EpisodeStart.obstacle_pos_m` and ``obstacle_vel_m_s`` of one episode).
        cruise_alt_m: height above the origin they fly at.
        start_s: fixed start time, or None to start with the swarm.
        errors: the reports' errors; None: exact reports.
    """

    def __init__(
        self,
        pos_m: FloatArray,
        vel_m_s: FloatArray,
        cruise_alt_m: float,
        start_s: float | None = None,
        errors: ReportErrors | None = None,
    ) -> None:
        self.spawn_ne_m = sim_to_ne(np.asarray(pos_m).reshape(-1, 2))  # (M, 2)
        self.vel_ne_m_s = sim_to_ne(np.asarray(vel_m_s).reshape(-1, 2))
        self.down_m = -cruise_alt_m
        self.start_s = start_s
        self.count = len(self.spawn_ne_m)
        self.errors = errors

    def maybe_start(self, now_s: float, vehicle_vel_ned: FloatArray) -> None:
        """Start the clock when the first vehicle moves (no-op once started)."""
        if self.start_s is not None or self.count == 0:
            return
        speed = np.hypot(vehicle_vel_ned[:, 0], vehicle_vel_ned[:, 1])
        if speed.size and float(speed.max()) > START_SPEED_M_S:
            self.start_s = now_s

    def positions_ned(self, now_s: float) -> FloatArray:
        """(M, 3) intruder positions at ``now_s``."""
        elapsed = 0.0 if self.start_s is None else max(0.0, now_s - self.start_s)
        ne = straight_points(self.spawn_ne_m, self.vel_ne_m_s, elapsed, np.ones(1))[:, 0, :]
        down = np.full((self.count, 1), self.down_m)
        return np.concatenate([ne, down], axis=1)

    def velocities_ned(self, now_s: float) -> FloatArray:
        """(M, 3) intruder velocities (zero before the start)."""
        moving = self.start_s is not None and now_s >= self.start_s
        vel = self.vel_ne_m_s if moving else np.zeros_like(self.vel_ne_m_s)
        return np.concatenate([vel, np.zeros((self.count, 1))], axis=1)

    def reports(self, factory: Any, origin: GeoPoint, now_s: float) -> list[Any]:
        """One ADSB_VEHICLE per intruder: degE7, altitude mm AMSL, heading cdeg, cm/s."""
        pos, vel = self.positions_ned(now_s), self.velocities_ned(now_s)
        if self.errors is not None:
            pos_err, vel_err = self.errors.at(now_s)
            pos[:, :2] += pos_err
            vel[:, :2] += vel_err
        lat, lon, alt = ned_to_geodetic(pos[:, 0], pos[:, 1], pos[:, 2], origin)
        course, speed = course_and_speed(vel[:, 0], vel[:, 1])
        out = []
        for k in range(self.count):
            heading_cdeg = round(math.degrees(float(course[k])) * 100) % 36000
            out.append(
                factory.adsb_vehicle_encode(
                    ICAO_BASE + k,
                    int(to_deg_e7(lat[k])),
                    int(to_deg_e7(lon[k])),
                    ADSB_ALTITUDE_TYPE_GEOMETRIC,
                    round(float(alt[k]) * 1000),
                    heading_cdeg,
                    round(float(speed[k]) * 100),
                    0,
                    f"OBST{k:04d}".encode(),
                    ADSB_EMITTER_TYPE_UAV,
                    0,
                    ADSB_FLAGS,
                    0,
                )
            )
        return out

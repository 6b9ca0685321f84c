"""ADS-B traffic as the runtime sees it: one `Intruder` per track, in the mission frame.

`TrafficPicture.update` takes one decoded ADSB_VEHICLE and its monotonic receive time; nothing
here does I/O. Positions are converted once, at this boundary, into the mission's local frame
(`remarl_fc.frames`).
"""

from __future__ import annotations

import math
from collections import Counter
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from remarl_fc.flight.tracking import MAX_SPEED_M_S, FloatArray
from remarl_fc.frames import GeoPoint, from_deg_e7, geodetic_to_ned


@dataclass
class Intruder:
    """One ADS-B track in the mission frame."""

    ne_m: FloatArray
    height_m: float
    vel_ne_m_s: FloatArray
    t: float
    shared: bool = False  # learnt from another vehicle over the swarm bus

    def predicted_ne_m(self, now: float) -> FloatArray:
        """Position extrapolated at constant velocity to ``now``."""
        out: FloatArray = self.ne_m + self.vel_ne_m_s * max(0.0, now - self.t)
        return out


@dataclass
class TrafficPicture:
    """ADS-B traffic (ADSB_VEHICLE from any component of any system), by ICAO address.

    Attributes:
        origin: the mission origin. max_age_s: a track older than this is dropped.
    """

    origin: GeoPoint
    max_age_s: float = 5.0
    tracks: dict[int, Intruder] = field(default_factory=dict)
    rejected: Counter[str] = field(default_factory=Counter)

    def update(self, msg: Any, now: float) -> None:
        """Take one ADSB_VEHICLE."""
        if not msg.flags & 1:  # VALID_COORDS
            self.rejected["no valid coordinates"] += 1
            return
        speed = msg.hor_velocity / 100.0 if msg.flags & 8 else 0.0
        course = math.radians(msg.heading / 100.0) if msg.flags & 4 else 0.0
        if speed > MAX_SPEED_M_S * 5:
            self.rejected["impossible speed"] += 1
            return
        n, e, d = geodetic_to_ned(
            from_deg_e7(msg.lat), from_deg_e7(msg.lon), msg.altitude / 1000.0, self.origin
        )
        vel = np.array([speed * math.cos(course), speed * math.sin(course)])
        age = float(msg.tslc) if msg.tslc else 0.0
        height = -float(d) if msg.flags & 2 else math.nan  # VALID_ALTITUDE, else unknown
        self.tracks[int(msg.ICAO_address)] = Intruder(
            np.array([float(n), float(e)]), height, vel, now - age
        )

    def current(self, now: float, height_m: float, band_m: float) -> list[Intruder]:
        """Tracks younger than `max_age_s` within ±``band_m`` of ``height_m``.

        Tracks of unknown altitude (no VALID_ALTITUDE flag) are kept, to be safe.
        """
        for icao in [k for k, v in self.tracks.items() if now - v.t > self.max_age_s]:
            del self.tracks[icao]
        return [  # an intruder of unknown altitude counts at every height
            v
            for v in self.tracks.values()
            if math.isnan(v.height_m) or abs(v.height_m - height_m) <= band_m
        ]

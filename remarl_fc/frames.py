"""Every unit and frame conversion at the MAVLink boundary, in one place.

Three frames meet here:

* the simulator's: x east, y north, headings counter-clockwise from +x (east), metres and
  radians (`sim/spawn.py`);
* local NED (north, east, down), yaw clockwise from north, as MAVLink's LOCAL_POSITION_NED,
  SET_POSITION_TARGET_LOCAL_NED and ATTITUDE carry them;
* geodetic WGS-84 latitude/longitude (degrees, on the wire degE7) and altitude (metres, on the
  wire millimetres).

Local NED ↔ geodetic uses the tangent plane at a home point with the WGS-84 radii of curvature
there (meridional M and prime-vertical N). Over the few kilometres a swarm flies the error
against an exact ellipsoidal conversion stays under a centimetre per kilometre squared
(second-order in the distance), far below GPS noise.

Wire units come from the MAVLink message definitions (common.xml): GLOBAL_POSITION_INT
lat/lon degE7, alt mm, vx/vy/vz cm/s, hdg cdeg 0..35999 (65535 unknown); ADSB_VEHICLE heading
cdeg, hor_velocity cm/s, ver_velocity cm/s positive up.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]

WGS84_A_M = 6_378_137.0
"""WGS-84 semi-major axis, metres."""

WGS84_E2 = 6.694_379_990_14e-3
"""WGS-84 first eccentricity squared (dimensionless)."""

DEG_E7 = 1e7
"""MAVLink integer angles: degrees × 10⁷."""

HEADING_UNKNOWN_CDEG = 65535
"""GLOBAL_POSITION_INT.hdg when the heading is unknown (common.xml)."""


@dataclass(frozen=True)
class GeoPoint:
    """A WGS-84 position.

    Attributes:
        lat_deg: latitude, degrees north. lon_deg: longitude, degrees east.
        alt_m: altitude above mean sea level, metres.
    """

    lat_deg: float
    lon_deg: float
    alt_m: float

    def __post_init__(self) -> None:
        if not (-90.0 < self.lat_deg < 90.0):
            raise ValueError(f"latitude {self.lat_deg} is outside (-90, 90) degrees")
        if not (-180.0 <= self.lon_deg <= 180.0):
            raise ValueError(f"longitude {self.lon_deg} is outside [-180, 180] degrees")
        if not math.isfinite(self.alt_m):
            raise ValueError(f"altitude {self.alt_m} is not a finite number of metres")

    @classmethod
    def parse(cls, text: str) -> GeoPoint:
        """Read ``LAT,LON,ALT`` (degrees, degrees, metres AMSL).

        >>> GeoPoint.parse("47.397742,8.545594,488")
        GeoPoint(lat_deg=47.397742, lon_deg=8.545594, alt_m=488.0)
        """
        parts = text.split(",")
        if len(parts) != 3:
            raise ValueError(f"{text!r} is not LAT,LON,ALT (e.g. 47.397742,8.545594,488)")
        try:
            lat, lon, alt = (float(p) for p in parts)
        except ValueError as exc:
            raise ValueError(f"{text!r} is not three numbers LAT,LON,ALT") from exc
        return cls(lat, lon, alt)


def radii_of_curvature_m(lat_deg: float) -> tuple[float, float]:
    """WGS-84 meridional (M) and prime-vertical (N) radii of curvature at a latitude, metres.

    >>> [round(r) for r in radii_of_curvature_m(0.0)]
    [6335439, 6378137]
    """
    s = math.sin(math.radians(lat_deg))
    w = math.sqrt(1.0 - WGS84_E2 * s * s)
    return WGS84_A_M * (1.0 - WGS84_E2) / w**3, WGS84_A_M / w


def ned_to_geodetic(
    north_m: Any, east_m: Any, down_m: Any, home: GeoPoint
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Local NED around ``home`` → (lat_deg, lon_deg, alt_m AMSL); any matching shapes."""
    m_r, n_r = radii_of_curvature_m(home.lat_deg)
    lat = home.lat_deg + np.degrees(np.asarray(north_m, dtype=np.float64) / m_r)
    lon = home.lon_deg + np.degrees(
        np.asarray(east_m, dtype=np.float64) / (n_r * math.cos(math.radians(home.lat_deg)))
    )
    alt = home.alt_m - np.asarray(down_m, dtype=np.float64)
    return lat, lon, alt


def geodetic_to_ned(
    lat_deg: Any, lon_deg: Any, alt_m: Any, home: GeoPoint
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """(lat_deg, lon_deg, alt_m AMSL) → local NED around ``home``; inverse of `ned_to_geodetic`.

    >>> home = GeoPoint(47.0, 8.0, 500.0)
    >>> lla = ned_to_geodetic(120.0, -35.0, -20.0, home)
    >>> [round(float(v), 6) for v in geodetic_to_ned(*lla, home)]
    [120.0, -35.0, -20.0]
    """
    m_r, n_r = radii_of_curvature_m(home.lat_deg)
    north = np.radians(np.asarray(lat_deg, dtype=np.float64) - home.lat_deg) * m_r
    dlon = (np.asarray(lon_deg, dtype=np.float64) - home.lon_deg + 180.0) % 360.0 - 180.0
    east = np.radians(dlon) * n_r * math.cos(math.radians(home.lat_deg))
    down = home.alt_m - np.asarray(alt_m, dtype=np.float64)
    return north, east, down


def sim_to_ne(xy_m: FloatArray) -> FloatArray:
    """Simulator (x east, y north) → (north, east): (..., 2) → (..., 2).

    >>> sim_to_ne(np.array([3.0, 4.0])).tolist()
    [4.0, 3.0]
    """
    return np.asarray(xy_m, dtype=np.float64)[..., ::-1].copy()


def ne_to_sim(ne_m: FloatArray) -> FloatArray:
    """(north, east) → simulator (x east, y north); inverse of `sim_to_ne`."""
    return np.asarray(ne_m, dtype=np.float64)[..., ::-1].copy()


def heading_to_yaw(heading_rad: Any) -> FloatArray:
    """Simulator heading (CCW from east) ↔ NED yaw (CW from north), wrapped to [-π, π).

    The map is its own inverse: yaw = π/2 − heading and heading = π/2 − yaw.

    >>> float(np.degrees(heading_to_yaw(0.0)))  # flying east
    90.0
    >>> float(np.degrees(heading_to_yaw(np.pi / 2)))  # flying north
    0.0
    """
    yaw = math.pi / 2 - np.asarray(heading_rad, dtype=np.float64)
    return (yaw + math.pi) % (2 * math.pi) - math.pi


yaw_to_heading = heading_to_yaw
"""NED yaw → simulator heading: the same self-inverse map as `heading_to_yaw`."""


def wrap_yaw(angle_rad: float) -> float:
    """Wrap one angle to [-π, π), radians.

    >>> round(wrap_yaw(3 * math.pi / 2), 4)
    -1.5708
    """
    return (angle_rad + math.pi) % (2 * math.pi) - math.pi


def to_deg_e7(deg: Any) -> NDArray[np.int64]:
    """Degrees → MAVLink degE7 integers (rounded).

    >>> int(to_deg_e7(47.3977421))
    473977421
    """
    return np.rint(np.asarray(deg, dtype=np.float64) * DEG_E7).astype(np.int64)


def from_deg_e7(value: Any) -> FloatArray:
    """MAVLink degE7 integers → degrees."""
    return np.asarray(value, dtype=np.float64) / DEG_E7


def yaw_to_cdeg(yaw_rad: Any) -> NDArray[np.int64]:
    """Yaw or course (rad, CW from north) → centidegrees 0..35999 (GLOBAL_POSITION_INT.hdg).

    >>> int(yaw_to_cdeg(-np.pi / 2))
    27000
    """
    cdeg = np.rint(np.degrees(np.asarray(yaw_rad, dtype=np.float64)) * 100.0).astype(np.int64)
    return cdeg % 36000


def cdeg_to_yaw(cdeg: Any) -> FloatArray:
    """Centidegrees (CW from north) → yaw in rad wrapped to [-π, π)."""
    rad = np.radians(np.asarray(cdeg, dtype=np.float64) / 100.0)
    return (rad + math.pi) % (2 * math.pi) - math.pi


def course_and_speed(vn_m_s: Any, ve_m_s: Any) -> tuple[FloatArray, FloatArray]:
    """Horizontal NED velocity → (course rad CW from north, ground speed m/s).

    >>> [round(float(v), 3) for v in course_and_speed(0.0, 2.0)]
    [1.571, 2.0]
    """
    vn, ve = np.asarray(vn_m_s, dtype=np.float64), np.asarray(ve_m_s, dtype=np.float64)
    return np.arctan2(ve, vn), np.hypot(vn, ve)

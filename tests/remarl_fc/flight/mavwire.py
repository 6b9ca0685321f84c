"""Telemetry as the link delivers it, for the flight tests: encoded by a vehicle, decoded here."""

from __future__ import annotations

from typing import Any

from remarl_fc.frames import GeoPoint, ned_to_geodetic, to_deg_e7
from remarl_fc.mavlink.codec import Codec
from remarl_fc.mavlink.consts import AdsbFlag, MavAutopilot, MavState

ORIGIN = GeoPoint(47.397742, 8.545594, 488.0)

VEHICLE = Codec(1, 1)
GCS = Codec(255, 190)
F = VEHICLE.factory

ADSB_ALL = (
    AdsbFlag.VALID_COORDS
    | AdsbFlag.VALID_ALTITUDE
    | AdsbFlag.VALID_HEADING
    | AdsbFlag.VALID_VELOCITY
)

# Positions from telemetry are quantised to degE7 (≈ 1.1 cm north, ≈ 0.8 cm east here) and mm.
QUANTUM_M = 0.02


def wire(msg: Any) -> Any:
    """The message as the link delivers it: encoded by the vehicle, decoded by the GCS."""
    (out,) = GCS.decode(VEHICLE.encode(msg), "vehicle")
    return out


def heartbeat(autopilot: int = MavAutopilot.ARDUPILOTMEGA, custom_mode: int = 0, base: int = 0):
    return wire(F.heartbeat_encode(2, autopilot, base, custom_mode, MavState.ACTIVE))


def position(
    north: float,
    east: float,
    height: float,
    vel_ned: tuple[float, float, float] = (0.0, 0.0, 0.0),
    *,
    origin: GeoPoint = ORIGIN,
    hdg: int = 65535,
    t_s: float = 1.0,
) -> Any:
    """GLOBAL_POSITION_INT; ``t_s`` is the vehicle's clock (time_boot_ms)."""
    lat, lon, alt = ned_to_geodetic(north, east, -height, origin)
    vx, vy, vz = (round(v * 100) for v in vel_ned)
    return wire(
        F.global_position_int_encode(
            round(t_s * 1000),
            int(to_deg_e7(lat)),
            int(to_deg_e7(lon)),
            round(float(alt) * 1000),
            round(height * 1000),
            vx,
            vy,
            vz,
            hdg,
        )
    )


def attitude(yaw: float) -> Any:
    return wire(F.attitude_encode(1000, 0.0, 0.0, yaw, 0.0, 0.0, 0.0))


def ekf(flags: int) -> Any:
    return wire(F.ekf_status_report_encode(flags, 0.1, 0.1, 0.1, 0.1, 0.0))


def statustext(text: str, severity: int = 4) -> Any:
    return wire(F.statustext_encode(severity, text.encode()))


def adsb(
    icao: int, north: float, east: float, height: float, *, origin: GeoPoint = ORIGIN, **fields: int
) -> Any:
    """An ADSB_VEHICLE at (north, east, height) m from ``origin``; ``fields`` as `adsb_raw`."""
    lat, lon, alt = ned_to_geodetic(north, east, -height, origin)
    altitude_mm = round(float(alt) * 1000)
    return adsb_raw(icao, int(to_deg_e7(lat)), int(to_deg_e7(lon)), altitude_mm, **fields)


def adsb_raw(
    icao: int,
    lat: int,
    lon: int,
    altitude_mm: int,
    *,
    heading_cdeg: int = 0,
    speed_cm_s: int = 0,
    ver_velocity_cm_s: int = 0,
    flags: int = ADSB_ALL,
    tslc: int = 0,
) -> Any:
    """An ADSB_VEHICLE with the wire fields as given (degE7, mm): for out-of-range reports."""
    return wire(
        F.adsb_vehicle_encode(
            icao,
            lat,
            lon,
            1,  # ADSB_ALTITUDE_TYPE_GEOMETRIC
            altitude_mm,
            heading_cdeg,
            speed_cm_s,
            ver_velocity_cm_s,
            b"INTRUDER",
            14,  # UAV
            tslc,
            flags,
            0,
        )
    )

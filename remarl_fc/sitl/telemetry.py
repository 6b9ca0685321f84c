"""Telemetry messages of a mock vehicle, in the units of the MAVLink definitions.

Each builder reads the batched airframe state and the vehicle's autopilot logic and returns one
pymavlink message, or None where the real autopilot sends nothing yet (ArduPilot sends no
LOCAL_POSITION_NED before its EKF origin is set). Reported positions carry the GPS faults and
noise; the ground truth never does.

The builders see the autopilot logic only through `VehicleState`, the little of it they read:
this module does not depend on `remarl_fc.sitl.autopilot`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np
from numpy.typing import NDArray

from remarl_fc.frames import (
    GeoPoint,
    course_and_speed,
    ned_to_geodetic,
    to_deg_e7,
    yaw_to_cdeg,
)
from remarl_fc.mavlink.consts import (
    EKF_GOOD,
    GPS_FIX_TYPE_3D,
    MAV_PROTOCOL_CAPABILITY_COMMAND_INT,
    MAV_PROTOCOL_CAPABILITY_MAVLINK2,
    MAV_PROTOCOL_CAPABILITY_MISSION_INT,
    MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE,
    MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_C_CAST,
    MAV_PROTOCOL_CAPABILITY_PARAM_FLOAT,
    MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_GLOBAL_INT,
    MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_LOCAL_NED,
    EkfFlag,
    MavFrame,
    MavType,
    MsgId,
)
from remarl_fc.sitl.flavour import FlavourSpec
from remarl_fc.sitl.vehicle import Airframes
from sim.sensors import gps_error

SENSORS_PRESENT = 0x0020_002F
"""MAV_SYS_STATUS_SENSOR bits reported present/enabled/healthy: 3-D gyro (1), accel (2),
mag (4), absolute pressure (8), GPS (32) and AHRS (0x200000)."""

PREARM_CHECK = 0x1000_0000
"""MAV_SYS_STATUS_PREARM_CHECK: present and enabled always, healthy while armed or while the
arming checks pass — ArduPilot's `GCS::update_sensor_status_flags` and PX4's Commander both
report it; MAVSDK's `Health.is_armable` reads it."""

BATTERY_VOLTAGE_MV = 16_200
"""Reported battery voltage: a 4S pack at rest, millivolts."""

GPS_EPH_CM = 80
"""GPS_RAW_INT.eph: horizontal dilution × 100 (HDOP 0.8)."""

GPS_EPV_CM = 120
"""GPS_RAW_INT.epv: vertical dilution × 100 (VDOP 1.2)."""

GPS_SATELLITES = 14
"""GPS_RAW_INT.satellites_visible."""


class VehicleState(Protocol):
    """What the telemetry builders read from a vehicle's autopilot logic.

    `remarl_fc.sitl.autopilot.Autopilot` is one; the builders need nothing else of it.
    """

    @property
    def spec(self) -> FlavourSpec[Any]:
        """The flavour's values (autopilot id, software version, parameter encoding)."""

    @property
    def system_id(self) -> int:
        """MAVLink system id."""

    @property
    def armed(self) -> bool:
        """Whether the motors are armed."""

    @property
    def custom_mode(self) -> int:
        """HEARTBEAT.custom_mode."""

    def position_ok(self, now_s: float) -> bool:
        """Whether the vehicle has an absolute position estimate."""

    def booting(self, now_s: float) -> bool:
        """Whether the vehicle is still in MAV_STATE_BOOT."""

    def time_boot_ms(self, now_s: float) -> int:
        """time_boot_ms of the simulated clock."""

    def active_target(self) -> tuple[int, np.ndarray, np.ndarray, float, float] | None:
        """(type_mask, position, velocity, yaw, yaw rate) of the external target, or None."""

    def landed_state(self) -> int:
        """MAV_LANDED_STATE."""

    def base_mode(self) -> int:
        """HEARTBEAT.base_mode."""

    def system_status(self) -> int:
        """HEARTBEAT.system_status."""


@dataclass
class GpsState:
    """Reported-position faults of one vehicle: a glitch offset (N, E metres) and noise."""

    offset_ne_m: tuple[float, float] = (0.0, 0.0)
    glitching: bool = False


class TelemetryBuilder:
    """Builds every telemetry message of the fleet.

    Args:
        factory: a codec's message factory (``Codec.factory``).
        frames: the fleet's airframes.
        origin: the arena origin (NED (0, 0, 0)).
        homes: each vehicle's home.
        gps_noise_m: standard deviation of the horizontal noise on reported positions.
        rng: the mock's random generator.
    """

    def __init__(
        self,
        factory: Any,
        frames: Airframes,
        origin: GeoPoint,
        homes: list[GeoPoint],
        gps_noise_m: float,
        rng: np.random.Generator,
    ) -> None:
        self.factory, self.frames, self.origin, self.homes = factory, frames, origin, homes
        self.gps_noise_m, self.rng = gps_noise_m, rng
        self.gps = [GpsState() for _ in homes]
        self.builders: dict[int, Callable[[int, VehicleState, float], Any]] = {
            MsgId.SYS_STATUS: self.sys_status,
            MsgId.GPS_RAW_INT: self.gps_raw_int,
            MsgId.ATTITUDE: self.attitude,
            MsgId.LOCAL_POSITION_NED: self.local_position_ned,
            MsgId.GLOBAL_POSITION_INT: self.global_position_int,
            MsgId.POSITION_TARGET_LOCAL_NED: self.position_target_local_ned,
            MsgId.EKF_STATUS_REPORT: self.ekf_status_report,
            MsgId.HOME_POSITION: self.home_position,
            MsgId.EXTENDED_SYS_STATE: self.extended_sys_state,
            MsgId.AUTOPILOT_VERSION: self.autopilot_version,
        }

    def supports(self, msg_id: int) -> bool:
        """Whether this mock can send message ``msg_id``."""
        return msg_id in self.builders

    def build(self, msg_id: int, i: int, ap: VehicleState, now_s: float) -> Any:
        """Message ``msg_id`` of vehicle ``i`` now, or None if it has nothing to send."""
        return self.builders[msg_id](i, ap, now_s)

    # -- positions as reported ----------------------------------------------------------

    def reported_ned(self, i: int) -> NDArray[np.float64]:
        """Vehicle i's position as its GPS/EKF reports it: truth + glitch + noise (NED m)."""
        pos: NDArray[np.float64] = self.frames.pos_ned_m[i].copy()
        g = self.gps[i]
        pos[0] += g.offset_ne_m[0]
        pos[1] += g.offset_ne_m[1]
        pos[:2] += gps_error((2,), self.gps_noise_m, self.rng)  # no draw at zero noise
        return pos

    def _geodetic(self, i: int) -> tuple[int, int, int]:
        pos = self.reported_ned(i)
        lat, lon, alt = ned_to_geodetic(pos[0], pos[1], pos[2], self.origin)
        return int(to_deg_e7(lat)), int(to_deg_e7(lon)), round(float(alt) * 1000)

    # -- builders -----------------------------------------------------------------------

    def sys_status(self, i: int, ap: VehicleState, now_s: float) -> Any:
        """SYS_STATUS (1): sensors, load d%, battery mV / cA / %, comm drop rate c%."""
        ready = ap.position_ok(now_s) and not ap.booting(now_s)
        health = SENSORS_PRESENT if ap.position_ok(now_s) else SENSORS_PRESENT & ~0x20
        if ap.armed or ready:
            health |= PREARM_CHECK
        return self.factory.sys_status_encode(
            SENSORS_PRESENT | PREARM_CHECK,
            SENSORS_PRESENT | PREARM_CHECK,
            health,
            200,
            BATTERY_VOLTAGE_MV,
            -1,
            100,
            0,
            0,
            0,
            0,
            0,
            0,
        )

    def gps_raw_int(self, i: int, ap: VehicleState, now_s: float) -> Any:
        """GPS_RAW_INT (24): time µs, fix, lat/lon degE7, alt mm, eph/epv, vel cm/s, cog cdeg."""
        vel = self.frames.vel_ned_m_s[i]
        course, speed = course_and_speed(vel[0], vel[1])
        if not ap.position_ok(now_s):
            return self.factory.gps_raw_int_encode(
                int(now_s * 1e6), 1, 0, 0, 0, 9999, 9999, 0, 0, 3
            )
        lat, lon, alt = self._geodetic(i)
        return self.factory.gps_raw_int_encode(
            int(now_s * 1e6),
            GPS_FIX_TYPE_3D,
            lat,
            lon,
            alt,
            GPS_EPH_CM,
            GPS_EPV_CM,
            round(float(speed) * 100),
            int(yaw_to_cdeg(course)),
            GPS_SATELLITES,
        )

    def attitude(self, i: int, ap: VehicleState, now_s: float) -> Any:
        """ATTITUDE (30): roll/pitch/yaw rad, rates rad/s (level flight: roll = pitch = 0)."""
        f = self.frames
        return self.factory.attitude_encode(
            ap.time_boot_ms(now_s),
            0.0,
            0.0,
            float(f.yaw_rad[i]),
            0.0,
            0.0,
            float(f.yaw_rate_rad_s[i]),
        )

    def local_position_ned(self, i: int, ap: VehicleState, now_s: float) -> Any:
        """LOCAL_POSITION_NED (32): m and m/s from the vehicle's EKF origin (its home)."""
        if not ap.position_ok(now_s):
            return None
        pos = self.reported_ned(i) - self.frames.home_ned_m[i]
        vel = self.frames.vel_ned_m_s[i]
        return self.factory.local_position_ned_encode(
            ap.time_boot_ms(now_s), *(float(v) for v in pos), *(float(v) for v in vel)
        )

    def global_position_int(self, i: int, ap: VehicleState, now_s: float) -> Any:
        """GLOBAL_POSITION_INT (33): degE7, alt and relative_alt mm, vx/vy/vz cm/s, hdg cdeg.

        Before the position estimate is valid, lat/lon/alt are 0 (as a real autopilot sends).
        """
        f = self.frames
        vel = np.rint(f.vel_ned_m_s[i] * 100).astype(int)
        hdg = int(yaw_to_cdeg(f.yaw_rad[i]))
        if not ap.position_ok(now_s):
            return self.factory.global_position_int_encode(
                ap.time_boot_ms(now_s), 0, 0, 0, 0, 0, 0, 0, hdg
            )
        lat, lon, alt = self._geodetic(i)
        rel = round((f.home_ned_m[i, 2] - self.reported_ned(i)[2]) * 1000)
        return self.factory.global_position_int_encode(
            ap.time_boot_ms(now_s), lat, lon, alt, rel, int(vel[0]), int(vel[1]), int(vel[2]), hdg
        )

    def position_target_local_ned(self, i: int, ap: VehicleState, now_s: float) -> Any:
        """POSITION_TARGET_LOCAL_NED (85): the active target while under external control."""
        target = ap.active_target()
        if target is None:
            return None
        mask, pos, vel, yaw, yaw_rate = target
        home = self.frames.home_ned_m[i]
        return self.factory.position_target_local_ned_encode(
            ap.time_boot_ms(now_s),
            MavFrame.LOCAL_NED,
            mask,
            *(float(p - h) for p, h in zip(pos, home, strict=True)),
            *(float(v) for v in vel),
            0.0,
            0.0,
            0.0,
            yaw,
            yaw_rate,
        )

    def ekf_status_report(self, i: int, ap: VehicleState, now_s: float) -> Any:
        """EKF_STATUS_REPORT (193): flags and variances (ArduPilot)."""
        if ap.position_ok(now_s):
            flags = int(EKF_GOOD)
            if self.gps[i].glitching:
                flags |= EkfFlag.GPS_GLITCHING
            var = 0.5 if self.gps[i].glitching else 0.02
        else:
            flags = int(EkfFlag.ATTITUDE | EkfFlag.VELOCITY_VERT | EkfFlag.CONST_POS_MODE)
            var = 1.0
        return self.factory.ekf_status_report_encode(flags, var, var, var, 0.01, 0.0, 0.0)

    def home_position(self, i: int, ap: VehicleState, now_s: float) -> Any:
        """HOME_POSITION (242): degE7, mm AMSL; local x/y/z of home = 0 (the EKF origin)."""
        if not ap.position_ok(now_s):
            return None
        home = self.homes[i]
        return self.factory.home_position_encode(
            int(to_deg_e7(home.lat_deg)),
            int(to_deg_e7(home.lon_deg)),
            round(home.alt_m * 1000),
            0.0,
            0.0,
            0.0,
            [1.0, 0.0, 0.0, 0.0],
            0.0,
            0.0,
            0.0,
            int(now_s * 1e6),
        )

    def extended_sys_state(self, i: int, ap: VehicleState, now_s: float) -> Any:
        """EXTENDED_SYS_STATE (245): VTOL state (undefined) and MAV_LANDED_STATE."""
        return self.factory.extended_sys_state_encode(0, ap.landed_state())

    def autopilot_version(self, i: int, ap: VehicleState, now_s: float) -> Any:
        """AUTOPILOT_VERSION (148): capabilities, software version, uid = system id."""
        caps = (
            MAV_PROTOCOL_CAPABILITY_MAVLINK2
            | MAV_PROTOCOL_CAPABILITY_COMMAND_INT
            | MAV_PROTOCOL_CAPABILITY_MISSION_INT
            | MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_LOCAL_NED
            | MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_GLOBAL_INT
            | MAV_PROTOCOL_CAPABILITY_PARAM_FLOAT
        )
        if ap.spec.param_table.bytewise:  # PX4
            caps |= MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE
        else:  # ArduPilot
            caps |= MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_C_CAST
        return self.factory.autopilot_version_encode(
            caps,
            ap.spec.flight_sw_version,
            0,
            0,
            0,
            [0] * 8,
            [0] * 8,
            [0] * 8,
            0,
            0,
            ap.system_id,
        )


def heartbeat(factory: Any, ap: VehicleState) -> Any:
    """HEARTBEAT (0): quadrotor, the flavour's autopilot id, base_mode, custom_mode, status."""
    return factory.heartbeat_encode(
        MavType.QUADROTOR,
        ap.spec.autopilot_id,
        ap.base_mode(),
        ap.custom_mode,
        ap.system_status(),
        3,
    )

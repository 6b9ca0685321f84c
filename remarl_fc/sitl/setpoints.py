"""SET_POSITION_TARGET_LOCAL_NED / _GLOBAL_INT → one normalised target, with the validity rules.

`parse_setpoint` turns either message into a `Setpoint` in the arena's NED frame (absolute
positions, NED velocities, yaw as an angle, a rate or neither) and says whether the real
autopilot of the flavour would accept it:

* ArduCopter (GCS_MAVLink_Copter.cpp): frames LOCAL_NED 1, LOCAL_OFFSET_NED 7, BODY_NED 8,
  BODY_OFFSET_NED 9 (yaw relative to the current heading in 8 and 9), and the global frames
  0/3/5/6/10/11. Position, velocity and acceleration must each be given on all three axes or
  on none — a single ignore bit (e.g. 2535 = 2503 + VZ_IGNORE) makes the whole message
  invalid — at least one of them must be given; NaN, |v| > 1000 m/s or FORCE_SET with
  acceleration is invalid. An invalid target makes GUIDED stop and hold.
* PX4 (mavlink_receiver.cpp): frames LOCAL_NED 1 and BODY_NED 8, global 5/6/11; ignored fields
  become "hold" on that axis; a message in another frame is dropped.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from remarl_fc.frames import GeoPoint, from_deg_e7, geodetic_to_ned
from remarl_fc.mavlink.consts import (
    ACCEL_BITS,
    POSITION_BITS,
    VELOCITY_BITS,
    MavFrame,
    MsgId,
    TypeMask,
)

MAX_VELOCITY_M_S = 1000.0
"""ArduCopter rejects velocity targets above this magnitude (GCS_MAVLink_Copter.cpp)."""

ARDUPILOT_LOCAL_FRAMES = frozenset(
    {MavFrame.LOCAL_NED, MavFrame.LOCAL_OFFSET_NED, MavFrame.BODY_NED, MavFrame.BODY_OFFSET_NED}
)
ARDUPILOT_GLOBAL_FRAMES = frozenset(
    {
        MavFrame.GLOBAL,
        MavFrame.GLOBAL_RELATIVE_ALT,
        MavFrame.GLOBAL_INT,
        MavFrame.GLOBAL_RELATIVE_ALT_INT,
        MavFrame.GLOBAL_TERRAIN_ALT,
        MavFrame.GLOBAL_TERRAIN_ALT_INT,
    }
)
PX4_LOCAL_FRAMES = frozenset({MavFrame.LOCAL_NED, MavFrame.BODY_NED})
PX4_GLOBAL_FRAMES = frozenset(
    {MavFrame.GLOBAL_INT, MavFrame.GLOBAL_RELATIVE_ALT_INT, MavFrame.GLOBAL_TERRAIN_ALT_INT}
)
BODY_FRAMES = frozenset({MavFrame.BODY_NED, MavFrame.BODY_OFFSET_NED})
AMSL_FRAMES = frozenset({MavFrame.GLOBAL, MavFrame.GLOBAL_INT})


@dataclass(frozen=True)
class Setpoint:
    """A target normalised to the arena's NED frame.

    Attributes:
        valid: whether the flavour accepts it; reason: why not ("" when valid).
        type_mask: the message's type_mask.
        pos_ned_m: absolute target position (3,) or None; axes the sender ignored are NaN.
        vel_ned_m_s: NED velocity (3,) or None; ignored axes NaN (PX4 only).
        has_accel: acceleration fields were given (flown as a velocity feed-forward of 0).
        yaw_rad: absolute yaw target, or None. yaw_rate_rad_s: yaw rate target, or None.
    """

    valid: bool
    reason: str
    type_mask: int
    pos_ned_m: np.ndarray | None
    vel_ned_m_s: np.ndarray | None
    has_accel: bool
    yaw_rad: float | None
    yaw_rate_rad_s: float | None


def _rejected(reason: str, mask: int) -> Setpoint:
    return Setpoint(False, reason, mask, None, None, False, None, None)


def _group(mask: int, bits: int, strict: bool) -> bool | None:
    """True: the group is given; False: ignored; None: partially ignored and ``strict``."""
    given = mask & bits
    if given == bits:
        return False
    if given == 0:
        return True
    return None if strict else True


def parse_setpoint(
    msg: Any,
    *,
    flavour: str,
    origin: GeoPoint,
    home_ned_m: np.ndarray,
    pos_ned_m: np.ndarray,
    yaw_rad: float,
) -> Setpoint:
    """Normalise a SET_POSITION_TARGET_* message for one vehicle.

    Args:
        msg: the decoded message (id 84 or 86).
        flavour: "ardupilot" or "px4".
        origin: the arena origin. home_ned_m: the vehicle's EKF origin in the arena (3,).
        pos_ned_m: the vehicle's current position (3,); yaw_rad: its current yaw.
    """
    mask, frame = int(msg.type_mask), int(msg.coordinate_frame)
    is_global = msg.get_msgId() == MsgId.SET_POSITION_TARGET_GLOBAL_INT
    ardu = flavour == "ardupilot"
    if ardu:
        frames = ARDUPILOT_GLOBAL_FRAMES if is_global else ARDUPILOT_LOCAL_FRAMES
    else:
        frames = PX4_GLOBAL_FRAMES if is_global else PX4_LOCAL_FRAMES
    if frame not in frames:
        return _rejected(f"frame {frame} not accepted", mask)

    pos_given = _group(mask, POSITION_BITS, ardu)
    vel_given = _group(mask, VELOCITY_BITS, ardu)
    acc_given = _group(mask, ACCEL_BITS, ardu)
    if pos_given is None or vel_given is None or acc_given is None:
        return _rejected("position, velocity and acceleration need all three axes", mask)
    if not (pos_given or vel_given or acc_given):
        return _rejected("no position, velocity or acceleration given", mask)
    if ardu and acc_given and mask & TypeMask.FORCE_SET:
        return _rejected("FORCE_SET with acceleration", mask)

    body = frame in BODY_FRAMES
    cos_y, sin_y = math.cos(yaw_rad), math.sin(yaw_rad)

    vel = None
    if vel_given:
        v = np.array([msg.vx, msg.vy, msg.vz], dtype=np.float64)
        v[
            [bool(mask & b) for b in (TypeMask.VX_IGNORE, TypeMask.VY_IGNORE, TypeMask.VZ_IGNORE)]
        ] = np.nan
        used = v[~np.isnan(v)]
        if (ardu and np.isnan(v).any()) or not np.all(np.isfinite(used)):
            return _rejected("velocity is not a number", mask)
        if float(np.linalg.norm(used)) > MAX_VELOCITY_M_S:
            return _rejected("velocity above 1000 m/s", mask)
        if body:
            v[0], v[1] = cos_y * v[0] - sin_y * v[1], sin_y * v[0] + cos_y * v[1]
        vel = v

    pos = None
    if pos_given:
        if is_global:
            lat, lon = from_deg_e7(msg.lat_int), from_deg_e7(msg.lon_int)
            alt = float(msg.alt)
            if frame not in AMSL_FRAMES:  # relative to home / terrain (flat: home)
                alt += origin.alt_m - float(home_ned_m[2])
            n, e, d = geodetic_to_ned(lat, lon, alt, origin)
            p = np.array([float(n), float(e), float(d)])
        else:
            p = np.array([msg.x, msg.y, msg.z], dtype=np.float64)
            if frame == MavFrame.LOCAL_NED:
                p = p + home_ned_m
            else:  # offsets from the vehicle, rotated by its heading in the body frames
                if body:
                    p[0], p[1] = cos_y * p[0] - sin_y * p[1], sin_y * p[0] + cos_y * p[1]
                p = p + pos_ned_m
        for k, bit in enumerate((TypeMask.X_IGNORE, TypeMask.Y_IGNORE, TypeMask.Z_IGNORE)):
            if mask & bit:
                p[k] = np.nan
        if not np.all(np.isfinite(p[~np.isnan(p)])) or (ardu and np.isnan(p).any()):
            return _rejected("position is not a number", mask)
        pos = p

    yaw = None
    yaw_rate = None
    if not mask & TypeMask.YAW_IGNORE:
        if not math.isfinite(msg.yaw):
            return _rejected("yaw is not a number", mask)
        yaw = float(msg.yaw) + (yaw_rad if ardu and body else 0.0)
    elif not mask & TypeMask.YAW_RATE_IGNORE:
        if not math.isfinite(msg.yaw_rate):
            return _rejected("yaw rate is not a number", mask)
        yaw_rate = float(msg.yaw_rate)
    return Setpoint(True, "", mask, pos, vel, bool(acc_given), yaw, yaw_rate)

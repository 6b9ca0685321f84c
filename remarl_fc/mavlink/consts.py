"""Named MAVLink numbers (message ids, commands, enums), with the definitions they come from.

Values are those of the MAVLink message definitions (minimal.xml, common.xml, ardupilotmega.xml);
a test checks each against pymavlink's generated dialect so they cannot drift.
"""

from __future__ import annotations

from enum import IntEnum, IntFlag


class MsgId(IntEnum):
    """Message ids used by remarl-fc (common.xml unless noted)."""

    HEARTBEAT = 0
    SYS_STATUS = 1
    PARAM_REQUEST_READ = 20
    PARAM_REQUEST_LIST = 21
    PARAM_VALUE = 22
    PARAM_SET = 23
    GPS_RAW_INT = 24
    ATTITUDE = 30
    LOCAL_POSITION_NED = 32
    GLOBAL_POSITION_INT = 33
    REQUEST_DATA_STREAM = 66
    COMMAND_INT = 75
    COMMAND_LONG = 76
    COMMAND_ACK = 77
    SET_POSITION_TARGET_LOCAL_NED = 84
    POSITION_TARGET_LOCAL_NED = 85
    SET_POSITION_TARGET_GLOBAL_INT = 86
    AUTOPILOT_VERSION = 148
    EKF_STATUS_REPORT = 193  # ardupilotmega.xml
    HOME_POSITION = 242
    EXTENDED_SYS_STATE = 245
    ADSB_VEHICLE = 246
    COLLISION = 247
    STATUSTEXT = 253
    RADIO_STATUS = 109
    RADIO = 166  # ardupilotmega.xml


class MavCmd(IntEnum):
    """MAV_CMD values handled or sent by remarl-fc."""

    NAV_RETURN_TO_LAUNCH = 20
    NAV_LAND = 21
    NAV_TAKEOFF = 22
    CONDITION_YAW = 115
    DO_SET_MODE = 176
    DO_CHANGE_SPEED = 178
    COMPONENT_ARM_DISARM = 400
    SET_MESSAGE_INTERVAL = 511
    REQUEST_MESSAGE = 512
    REQUEST_AUTOPILOT_CAPABILITIES = 520


ARM_FORCE_MAGIC = 21196
"""COMPONENT_ARM_DISARM param2 that forces arming/disarming past the checks (common.xml)."""


class MavResult(IntEnum):
    """MAV_RESULT: the result field of COMMAND_ACK."""

    ACCEPTED = 0
    TEMPORARILY_REJECTED = 1
    DENIED = 2
    UNSUPPORTED = 3
    FAILED = 4
    IN_PROGRESS = 5


class MavModeFlag(IntFlag):
    """MAV_MODE_FLAG: HEARTBEAT.base_mode bits (minimal.xml)."""

    CUSTOM_MODE_ENABLED = 1
    TEST_ENABLED = 2
    AUTO_ENABLED = 4
    GUIDED_ENABLED = 8
    STABILIZE_ENABLED = 16
    HIL_ENABLED = 32
    MANUAL_INPUT_ENABLED = 64
    SAFETY_ARMED = 128


class MavState(IntEnum):
    """MAV_STATE: HEARTBEAT.system_status (minimal.xml)."""

    UNINIT = 0
    BOOT = 1
    CALIBRATING = 2
    STANDBY = 3
    ACTIVE = 4
    CRITICAL = 5
    EMERGENCY = 6
    POWEROFF = 7


class MavAutopilot(IntEnum):
    """MAV_AUTOPILOT: HEARTBEAT.autopilot (minimal.xml)."""

    GENERIC = 0
    ARDUPILOTMEGA = 3
    INVALID = 8
    PX4 = 12


class MavType(IntEnum):
    """MAV_TYPE: HEARTBEAT.type (minimal.xml)."""

    QUADROTOR = 2
    GCS = 6
    ONBOARD_CONTROLLER = 18


class MavComponent(IntEnum):
    """MAV_COMPONENT ids (minimal.xml)."""

    ALL = 0
    AUTOPILOT1 = 1
    ADSB = 156
    ONBOARD_COMPUTER = 191


class MavFrame(IntEnum):
    """MAV_FRAME values of the setpoint messages (common.xml)."""

    GLOBAL = 0
    LOCAL_NED = 1
    GLOBAL_RELATIVE_ALT = 3
    GLOBAL_INT = 5
    GLOBAL_RELATIVE_ALT_INT = 6
    LOCAL_OFFSET_NED = 7
    BODY_NED = 8
    BODY_OFFSET_NED = 9
    GLOBAL_TERRAIN_ALT = 10
    GLOBAL_TERRAIN_ALT_INT = 11


class TypeMask(IntFlag):
    """POSITION_TARGET_TYPEMASK: a set bit means *ignore* that field (common.xml)."""

    X_IGNORE = 1
    Y_IGNORE = 2
    Z_IGNORE = 4
    VX_IGNORE = 8
    VY_IGNORE = 16
    VZ_IGNORE = 32
    AX_IGNORE = 64
    AY_IGNORE = 128
    AZ_IGNORE = 256
    FORCE_SET = 512
    YAW_IGNORE = 1024
    YAW_RATE_IGNORE = 2048


POSITION_BITS = TypeMask.X_IGNORE | TypeMask.Y_IGNORE | TypeMask.Z_IGNORE
VELOCITY_BITS = TypeMask.VX_IGNORE | TypeMask.VY_IGNORE | TypeMask.VZ_IGNORE
ACCEL_BITS = TypeMask.AX_IGNORE | TypeMask.AY_IGNORE | TypeMask.AZ_IGNORE

TYPE_MASK_VELOCITY_YAW = int(POSITION_BITS | ACCEL_BITS | TypeMask.YAW_RATE_IGNORE)
"""2503 (0x09C7): velocity and absolute yaw, what MAVSDK's set_velocity_ned sends."""


class CopterMode(IntEnum):
    """ArduCopter flight modes: HEARTBEAT.custom_mode (ardupilotmega.xml COPTER_MODE)."""

    STABILIZE = 0
    ACRO = 1
    ALT_HOLD = 2
    AUTO = 3
    GUIDED = 4
    LOITER = 5
    RTL = 6
    CIRCLE = 7
    LAND = 9
    DRIFT = 11
    SPORT = 13
    FLIP = 14
    AUTOTUNE = 15
    POSHOLD = 16
    BRAKE = 17
    THROW = 18
    AVOID_ADSB = 19
    GUIDED_NOGPS = 20
    SMART_RTL = 21


class Px4MainMode(IntEnum):
    """PX4 main modes: bits 16–23 of HEARTBEAT.custom_mode (px4_custom_mode.h)."""

    MANUAL = 1
    ALTCTL = 2
    POSCTL = 3
    AUTO = 4
    ACRO = 5
    OFFBOARD = 6
    STABILIZED = 7


class Px4AutoSubMode(IntEnum):
    """PX4 AUTO sub-modes: bits 24–31 of HEARTBEAT.custom_mode (px4_custom_mode.h)."""

    NONE = 0
    READY = 1
    TAKEOFF = 2
    LOITER = 3
    MISSION = 4
    RTL = 5
    LAND = 6


def px4_custom_mode(main: int, sub: int = 0) -> int:
    """Pack a PX4 (main, sub) mode into HEARTBEAT.custom_mode.

    >>> px4_custom_mode(Px4MainMode.OFFBOARD)
    393216
    >>> hex(px4_custom_mode(Px4MainMode.AUTO, Px4AutoSubMode.LOITER))
    '0x3040000'
    """
    return (int(main) << 16) | (int(sub) << 24)


def px4_mode_parts(custom_mode: int) -> tuple[int, int]:
    """Unpack HEARTBEAT.custom_mode of a PX4 vehicle into (main, sub).

    >>> px4_mode_parts(0x03040000)
    (4, 3)
    """
    return (custom_mode >> 16) & 0xFF, (custom_mode >> 24) & 0xFF


class EkfFlag(IntFlag):
    """EKF_STATUS_FLAGS: EKF_STATUS_REPORT.flags (ardupilotmega.xml)."""

    ATTITUDE = 1
    VELOCITY_HORIZ = 2
    VELOCITY_VERT = 4
    POS_HORIZ_REL = 8
    POS_HORIZ_ABS = 16
    POS_VERT_ABS = 32
    POS_VERT_AGL = 64
    CONST_POS_MODE = 128
    PRED_POS_HORIZ_REL = 256
    PRED_POS_HORIZ_ABS = 512
    UNINITIALIZED = 1024
    GPS_GLITCHING = 32768


EKF_GOOD = (
    EkfFlag.ATTITUDE
    | EkfFlag.VELOCITY_HORIZ
    | EkfFlag.VELOCITY_VERT
    | EkfFlag.POS_HORIZ_REL
    | EkfFlag.POS_HORIZ_ABS
    | EkfFlag.POS_VERT_ABS
    | EkfFlag.PRED_POS_HORIZ_REL
    | EkfFlag.PRED_POS_HORIZ_ABS
)
"""Flags of a healthy EKF with an absolute position (what a controller waits for)."""


class AdsbFlag(IntFlag):
    """ADSB_FLAGS: ADSB_VEHICLE.flags (common.xml)."""

    VALID_COORDS = 1
    VALID_ALTITUDE = 2
    VALID_HEADING = 4
    VALID_VELOCITY = 8
    VALID_CALLSIGN = 16
    VALID_SQUAWK = 32
    SIMULATED = 64
    VERTICAL_VELOCITY_VALID = 128


ADSB_EMITTER_TYPE_UAV = 14
"""ADSB_EMITTER_TYPE_UAV (common.xml)."""

ADSB_ALTITUDE_TYPE_GEOMETRIC = 1
"""ADSB_ALTITUDE_TYPE_GEOMETRIC: altitude is GNSS height above mean sea level (common.xml)."""


class LandedState(IntEnum):
    """MAV_LANDED_STATE: EXTENDED_SYS_STATE.landed_state (common.xml)."""

    UNDEFINED = 0
    ON_GROUND = 1
    IN_AIR = 2
    TAKEOFF = 3
    LANDING = 4


class MavParamType(IntEnum):
    """MAV_PARAM_TYPE: PARAM_VALUE.param_type and PARAM_SET.param_type (common.xml)."""

    UINT8 = 1
    INT8 = 2
    UINT16 = 3
    INT16 = 4
    UINT32 = 5
    INT32 = 6
    REAL32 = 9


class Severity(IntEnum):
    """MAV_SEVERITY: STATUSTEXT.severity (common.xml)."""

    EMERGENCY = 0
    ALERT = 1
    CRITICAL = 2
    ERROR = 3
    WARNING = 4
    NOTICE = 5
    INFO = 6
    DEBUG = 7


GPS_FIX_TYPE_3D = 3
"""GPS_FIX_TYPE_3D_FIX: GPS_RAW_INT.fix_type of a 3-D fix (common.xml)."""

MAV_PROTOCOL_CAPABILITY_MAVLINK2 = 8192
MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_LOCAL_NED = 128
MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_GLOBAL_INT = 256
MAV_PROTOCOL_CAPABILITY_COMMAND_INT = 8
MAV_PROTOCOL_CAPABILITY_MISSION_INT = 4
MAV_PROTOCOL_CAPABILITY_PARAM_FLOAT = 2
MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE = 16
MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_C_CAST = 131072
"""MAV_PROTOCOL_CAPABILITY bits advertised in AUTOPILOT_VERSION (common.xml)."""

"""Parameter values on the wire: PARAM_VALUE / PARAM_SET's float field and its two encodings.

MAVLink carries every parameter in a float32. ArduPilot converts an integer to that float
(``MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_C_CAST``); PX4 copies the integer's bytes into it
(``…_PARAM_ENCODE_BYTEWISE``), so the same INT32 5 is 5.0 from one and a denormal from the
other. Both the mock (serving) and the runtime (reading) use these functions.
"""

from __future__ import annotations

import struct
from collections.abc import Mapping

from remarl_fc.mavlink.consts import MavParamType

PARAM_ID_LEN = 16
"""PARAM_VALUE.param_id: at most 16 characters (common.xml)."""

INT_FORMATS: Mapping[MavParamType, tuple[str, int, int]] = {
    MavParamType.UINT8: ("<B", 0, 0xFF),
    MavParamType.INT8: ("<b", -0x80, 0x7F),
    MavParamType.UINT16: ("<H", 0, 0xFFFF),
    MavParamType.INT16: ("<h", -0x8000, 0x7FFF),
    MavParamType.UINT32: ("<I", 0, 0xFFFF_FFFF),
    MavParamType.INT32: ("<i", -0x8000_0000, 0x7FFF_FFFF),
}
"""Integer MAV_PARAM_TYPEs: struct format and range."""


def _int_format(ptype: int) -> tuple[str, int, int] | None:
    try:
        return INT_FORMATS.get(MavParamType(ptype))
    except ValueError:  # a type outside MAV_PARAM_TYPE's integers and REAL32: as a float
        return None


def to_wire(value: float, ptype: int, *, bytewise: bool) -> float:
    """PARAM_VALUE.param_value of ``value``.

    The number itself (C cast), or for an integer type under byte-wise encoding the float
    whose bytes are the integer's.
    """
    fmt = _int_format(ptype)
    if not bytewise or fmt is None:
        return float(value)
    packed = struct.pack(fmt[0], int(value)).ljust(4, b"\0")
    result: float = struct.unpack("<f", packed)[0]
    return result


def is_signalling_nan_pattern(value: int, ptype: int) -> bool:
    """Whether an integer's byte-wise float is a signalling NaN, which cannot cross a Python float.

    The message libraries carry param_value as a Python float (a C double): converting such a
    float32 to a double and back sets its quiet bit (CPython before 3.14), so the integers whose
    bits are 0x7F800001–0x7FBFFFFF or 0xFF800001–0xFFBFFFFF (for INT32: 2,139,095,041 to
    2,143,289,343 and −8,388,607 to −4,194,305) do not survive byte-wise encoding. No parameter
    the runtime reads or the mock serves takes such a value.

    >>> is_signalling_nan_pattern(-4194305, MavParamType.INT32), is_signalling_nan_pattern(5, 6)
    (True, False)
    """
    fmt = _int_format(ptype)
    if fmt is None:
        return False
    (bits,) = struct.unpack("<I", struct.pack(fmt[0], value).ljust(4, b"\0"))
    return bool((bits >> 23) & 0xFF == 0xFF and bits & 0x7FFFFF and not bits & 0x400000)


def from_wire(raw: float, ptype: int, *, bytewise: bool) -> float:
    """The value a PARAM_VALUE or PARAM_SET's param_value carries (inverse of `to_wire`)."""
    fmt = _int_format(ptype)
    if not bytewise or fmt is None:
        return float(raw)
    size = struct.calcsize(fmt[0])
    result: int = struct.unpack(fmt[0], struct.pack("<f", raw)[:size])[0]
    return float(result)


def param_name(param_id: str | bytes) -> str:
    """A param_id field as text (pymavlink gives str or bytes, NUL-padded)."""
    if isinstance(param_id, bytes):
        param_id = param_id.decode("ascii", "replace")
    return param_id.split("\0", 1)[0]

"""The pre-flight parameter check: the rules, and the reader's rounds and decoding."""

from __future__ import annotations

import asyncio
import struct

import pytest

from remarl_fc.flight.config import Clock
from remarl_fc.flight.paramcheck import (
    PARAM_READ_ATTEMPTS,
    ParamReader,
    check_params,
    checked_names,
)
from remarl_fc.mavlink.codec import Codec
from remarl_fc.mavlink.consts import MavParamType
from remarl_fc.mavlink.params import param_name, to_wire

PERIOD_S = 0.1  # 10 Hz setpoints

ARDUPILOT_SAFE = {
    "GUID_TIMEOUT": 3.0,
    "FS_GCS_ENABLE": 1.0,
    "AVD_ENABLE": 1.0,
    "AVD_F_ACTION": 1.0,
    "FENCE_ENABLE": 1.0,
}
PX4_SAFE = {
    "COM_OF_LOSS_T": 1.0,
    "COM_OBL_RC_ACT": 5.0,
    "NAV_DLL_ACT": 2.0,
    "COM_RC_IN_MODE": 0.0,
    "GF_ACTION": 1.0,
}


def judged(values: dict[str, float], px4: bool) -> list[tuple[str, str]]:
    found = check_params(values, px4=px4, setpoint_period_s=PERIOD_S)
    return [(f.level, f.text.split(" ", 1)[0]) for f in found]


def test_safe_settings_pass_and_every_checked_name_has_a_value_here():
    assert judged(ARDUPILOT_SAFE, px4=False) == []
    assert judged(PX4_SAFE, px4=True) == []
    assert set(checked_names(False)) == set(ARDUPILOT_SAFE)
    assert set(checked_names(True)) == set(PX4_SAFE)


@pytest.mark.parametrize(
    ("px4", "change", "expected"),
    [
        (False, {"GUID_TIMEOUT": 0.15}, [("error", "GUID_TIMEOUT")]),
        (False, {"GUID_TIMEOUT": 0.2}, []),  # exactly two periods: enough
        (False, {"GUID_TIMEOUT": 5.0}, [("warning", "GUID_TIMEOUT")]),
        (False, {"FS_GCS_ENABLE": 0.0}, [("warning", "FS_GCS_ENABLE")]),
        (False, {"AVD_F_ACTION": 2.0}, [("warning", "AVD_F_ACTION")]),
        (False, {"AVD_F_ACTION": 2.0, "AVD_ENABLE": 0.0}, []),  # avoidance off
        (False, {"FENCE_ENABLE": 0.0}, [("warning", "FENCE_ENABLE")]),
        (True, {"COM_OF_LOSS_T": 0.1}, [("error", "COM_OF_LOSS_T")]),
        (True, {"COM_OBL_RC_ACT": 0.0}, [("warning", "COM_OBL_RC_ACT")]),
        (True, {"COM_OBL_RC_ACT": 4.0}, []),  # Land
        (True, {"NAV_DLL_ACT": 0.0}, [("warning", "NAV_DLL_ACT")]),
        (True, {"COM_RC_IN_MODE": 4.0}, [("warning", "COM_RC_IN_MODE")]),
        (True, {"GF_ACTION": 0.0}, [("warning", "GF_ACTION")]),
    ],
)
def test_each_rule(px4, change, expected):
    values = {**(PX4_SAFE if px4 else ARDUPILOT_SAFE), **change}
    assert judged(values, px4) == expected


def test_missing_values_are_not_judged_and_the_error_says_what_to_do():
    assert judged({}, px4=False) == [] and judged({}, px4=True) == []
    (f,) = check_params({"COM_OF_LOSS_T": 0.05}, px4=True, setpoint_period_s=PERIOD_S)
    assert f.text == (
        "COM_OF_LOSS_T 0.05 s is under two setpoint periods (0.2 s): OFFBOARD would be lost "
        "between setpoints; raise it (default 1 s)"
    )


class FakeVehicle:
    """Answers PARAM_REQUEST_READ for the names it has, dropping the first ``drop`` requests."""

    def __init__(self, reader: ParamReader, codec: Codec, params: dict, *, drop: int = 0):
        self.reader, self.codec, self.params, self.drop = reader, codec, params, drop
        self.requests: list[str] = []

    def send(self, sysid: int, msg) -> None:
        name = param_name(msg.param_id)
        self.requests.append(name)
        if len(self.requests) <= self.drop or name not in self.params:
            return
        value, ptype = self.params[name]
        wire = to_wire(value, ptype, bytewise=True)
        reply = self.codec.factory.param_value_encode(name.encode(), wire, ptype, 1, 0)
        # decoded as the runtime would see it, on the next loop turn
        (decoded,) = self.codec.decode(self.codec.encode(reply), ("127.0.0.1", 1))
        asyncio.get_running_loop().call_soon(
            lambda: self.reader.on_value(sysid, decoded, bytewise=True)
        )


@pytest.mark.asyncio
async def test_reader_decodes_bytewise_retries_and_reports_what_never_came():
    codec = Codec(1, 1)
    clock = Clock(speedup=20.0)
    vehicle = FakeVehicle(
        None,  # type: ignore[arg-type]
        codec,
        {"COM_OBL_RC_ACT": (5, MavParamType.INT32), "COM_OF_LOSS_T": (0.5, MavParamType.REAL32)},
        drop=1,  # the first request is lost: answered in the second round
    )
    reader = ParamReader(vehicle.send, codec.factory, clock.timeout)
    vehicle.reader = reader
    out = await reader.read(7, ("COM_OBL_RC_ACT", "COM_OF_LOSS_T", "GF_ACTION"))
    assert dict(out.values) == {"COM_OBL_RC_ACT": 5.0, "COM_OF_LOSS_T": 0.5}
    assert out.unread == ("GF_ACTION",)
    # round 1: all three; round 2: the lost one and the absent one; then the absent one only
    assert vehicle.requests.count("GF_ACTION") == PARAM_READ_ATTEMPTS
    assert vehicle.requests.count("COM_OBL_RC_ACT") == 2
    assert vehicle.requests.count("COM_OF_LOSS_T") == 1


def test_bytewise_int_is_not_read_as_a_float():
    wire = to_wire(5, MavParamType.INT32, bytewise=True)
    assert struct.unpack("<i", struct.pack("<f", wire))[0] == 5 and wire != 5.0

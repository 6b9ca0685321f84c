"""The mock's parameter protocol: encodings (property tests) and the exchange over UDP."""

from __future__ import annotations

import math
import struct

import pytest
from hypothesis import assume, given
from hypothesis import strategies as st

from remarl_fc.flight.paramcheck import check_params, checked_names
from remarl_fc.mavlink.consts import (
    MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE,
    MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_C_CAST,
    CopterMode,
    MavCmd,
    MavModeFlag,
    MavParamType,
    MavResult,
    MsgId,
)
from remarl_fc.mavlink.params import (
    INT_FORMATS,
    from_wire,
    is_signalling_nan_pattern,
    to_wire,
)
from remarl_fc.sitl.config import ArduPilotParams, Px4Params
from remarl_fc.sitl.params import ARDUPILOT_PARAMS, PX4_PARAMS, ParamRejected, ParamTable

TABLES = {"ardupilot": ARDUPILOT_PARAMS, "px4": PX4_PARAMS}
QUIET_S = 1.0
"""Simulated seconds to listen for an answer that must not come."""


# -- encodings --------------------------------------------------------------------------------


@st.composite
def typed_ints(draw: st.DrawFn) -> tuple[MavParamType, int]:
    ptype = draw(st.sampled_from(sorted(INT_FORMATS)))
    _, low, high = INT_FORMATS[ptype]
    return ptype, draw(st.integers(low, high))


@given(typed_ints(), st.booleans())
def test_integer_values_survive_the_wire_in_both_encodings(typed, bytewise):
    ptype, value = typed
    # a signalling-NaN bit pattern cannot cross a Python float (documented in the encoder)
    assume(not (bytewise and is_signalling_nan_pattern(value, ptype)))
    wire = to_wire(value, ptype, bytewise=bytewise)
    # what a MAVLink frame carries is a float32: pack it as pymavlink does
    (on_the_wire,) = struct.unpack("<f", struct.pack("<f", wire))
    if not bytewise and abs(value) > 2**24:
        return  # a C cast to float32 rounds large integers: ArduPilot's own limit
    assert from_wire(on_the_wire, ptype, bytewise=bytewise) == value


@given(st.floats(allow_nan=False, allow_infinity=False, width=32), st.booleans())
def test_float_values_are_the_number_itself(value, bytewise):
    assert to_wire(value, MavParamType.REAL32, bytewise=bytewise) == value
    assert from_wire(value, MavParamType.REAL32, bytewise=bytewise) == value


def test_bytewise_puts_the_integer_in_the_float_bits():
    wire = to_wire(5, MavParamType.INT32, bytewise=True)
    assert struct.pack("<f", wire) == struct.pack("<i", 5)
    assert to_wire(5, MavParamType.INT32, bytewise=False) == 5.0


@given(st.integers(30, 300_000))
def test_ardupilot_centimetres_read_back_exactly(cm):
    spec = ARDUPILOT_PARAMS.specs[ARDUPILOT_PARAMS.find("RTL_ALT")]  # type: ignore[index]
    values = spec.write(ArduPilotParams(), float(cm))
    assert values.rtl_alt_m == pytest.approx(cm / 100)
    assert spec.read(values) == cm


def test_defaults_read_in_the_autopilots_units():
    ap, px4 = ArduPilotParams(), Px4Params()
    read = {s.name: s.read(ap) for s in ARDUPILOT_PARAMS.specs}
    assert read["RTL_ALT"] == 1500 and read["WPNAV_SPEED_UP"] == 250 and read["LAND_SPEED"] == 50
    assert read["DISARM_DELAY"] == 10 and read["GUID_TIMEOUT"] == 3.0
    read = {s.name: s.read(px4) for s in PX4_PARAMS.specs}
    assert read["COM_OBL_RC_ACT"] == 0 and read["MIS_TAKEOFF_ALT"] == 2.5
    assert read["COM_OF_LOSS_T"] == 1.0 and read["MPC_XY_CRUISE"] == 5.0


def test_values_the_mock_cannot_fly_are_refused():
    table = PX4_PARAMS
    k = table.find("COM_OBL_RC_ACT")
    assert k is not None
    with pytest.raises(ParamRejected, match="not modelled"):
        table.set(Px4Params(), k, to_wire(6, MavParamType.INT32, bytewise=True), 6)
    with pytest.raises(ParamRejected, match="type 9 sent"):
        table.set(Px4Params(), k, 5.0, MavParamType.REAL32)  # a float where an INT32 lives
    k = table.find("MPC_TKO_SPEED")
    assert k is not None
    with pytest.raises(ParamRejected, match="outside"):
        table.set(Px4Params(), k, 0.0, MavParamType.REAL32)
    with pytest.raises(ParamRejected, match="not a number"):
        table.set(Px4Params(), k, math.nan, MavParamType.REAL32)
    # an integer parameter is bounded by its type too: LAND_ALT_LOW is an INT16 (cm)
    k = ARDUPILOT_PARAMS.find("LAND_ALT_LOW")
    assert k is not None
    with pytest.raises(ParamRejected, match=r"outside 0\.\.32767"):
        ARDUPILOT_PARAMS.set(ArduPilotParams(), k, 40_000.0, MavParamType.INT16)
    k = ARDUPILOT_PARAMS.find("DISARM_DELAY")
    assert k is not None
    with pytest.raises(ParamRejected, match=r"outside 0\.\.127"):
        ARDUPILOT_PARAMS.set(ArduPilotParams(), k, 128.0, MavParamType.INT8)
    with pytest.raises(ValueError, match="over 16"):
        ParamTable((type(table.specs[0])("SEVENTEEN_LETTERS", "x"),), bytewise=True)


def test_tables_cover_existing_fields_with_unique_names():
    for table, values in ((ARDUPILOT_PARAMS, ArduPilotParams()), (PX4_PARAMS, Px4Params())):
        names = [s.name for s in table.specs]
        assert len(set(names)) == len(names) and names == sorted(names)
        for spec in table.specs:
            assert hasattr(values, spec.field), spec
            spec.write(values, spec.read(values))  # every default is a value the mock takes


# -- over UDP ---------------------------------------------------------------------------------


def request_list(gcs) -> None:
    gcs.fresh()
    gcs.send(gcs.f.param_request_list_encode(1, 1))


def request_read(gcs, name: str = "", index: int = -1) -> int:
    """Send PARAM_REQUEST_READ; returns the mark of what was heard before it."""
    gcs.fresh()
    gcs.send(gcs.f.param_request_read_encode(1, 1, name.encode(), index))
    return gcs.cursor


def param_set(gcs, name: str, value: float, ptype: int) -> int:
    """Send PARAM_SET; returns the mark of what was heard before it."""
    gcs.fresh()
    gcs.send(gcs.f.param_set_encode(1, 1, name.encode(), value, ptype))
    return gcs.cursor


def heard_since(gcs, mark: int, mtype: str) -> list:
    """Messages of ``mtype`` heard since ``mark`` (a request's return value)."""
    return [m for _, m in gcs.heard[mark:] if m.get_type() == mtype]


async def value_of(gcs, name: str):
    return await gcs.wait_for("PARAM_VALUE", lambda m: m.param_id == name)


def said(text: str):
    """A `Gcs.wait_for` predicate: a STATUSTEXT saying ``text``."""
    return lambda m: m.text == text


async def armed(gcs):
    """Arm; (arrival time, ACK) of the accepted arming."""
    gcs.fresh()
    gcs.send(gcs.f.command_long_encode(1, 1, MavCmd.COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0))
    t, ack = await gcs.wait_for_stamped(
        "COMMAND_ACK", lambda m: m.command == MavCmd.COMPONENT_ARM_DISARM
    )
    assert ack.result == MavResult.ACCEPTED
    return t, ack


@pytest.mark.asyncio
@pytest.mark.network
@pytest.mark.timeout(120)
@pytest.mark.parametrize("flavour", ["ardupilot", "px4"])
async def test_list_read_and_capabilities(sitl, flavour):
    table = TABLES[flavour]
    async with sitl(flavour=flavour) as (fleet, gcs):
        gcs.hello()
        request_list(gcs)
        values = [await gcs.wait_for("PARAM_VALUE") for _ in range(len(table))]
        assert [m.param_index for m in values] == list(range(len(table)))
        assert {m.param_count for m in values} == {len(table)}
        assert [m.param_id for m in values] == [s.name for s in table.specs]
        assert [m.param_type for m in values] == [s.ptype for s in table.specs]
        live = fleet.vehicles[0].params()
        for m, spec in zip(values, table.specs, strict=True):
            decoded = from_wire(m.param_value, m.param_type, bytewise=table.bytewise)
            assert decoded == pytest.approx(spec.read(live))

        name = table.specs[2].name
        request_read(gcs, name)
        assert (await gcs.wait_for("PARAM_VALUE")).param_index == 2
        request_read(gcs, "", 3)  # by index: the name is ignored
        assert (await gcs.wait_for("PARAM_VALUE")).param_id == table.specs[3].name

        mark = request_read(gcs, "NO_SUCH_PARAM")  # as on a vehicle without it: silence
        await gcs.wait_sim(QUIET_S)
        assert not heard_since(gcs, mark, "PARAM_VALUE")
        request_read(gcs, "", len(table))
        await gcs.wait_sim(QUIET_S)
        assert fleet.vehicles[0].counters.params_unknown == {
            "NO_SUCH_PARAM": 1,
            f"#{len(table)}": 1,
        }

        ack = await gcs.command(MavCmd.REQUEST_MESSAGE, MsgId.AUTOPILOT_VERSION)
        assert ack.result == MavResult.ACCEPTED
        caps = (await gcs.wait_for("AUTOPILOT_VERSION")).capabilities
        bytewise = bool(caps & MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE)
        cast = bool(caps & MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_C_CAST)
        assert (bytewise, cast) == ((True, False) if flavour == "px4" else (False, True))


@pytest.mark.asyncio
@pytest.mark.network
@pytest.mark.timeout(120)
async def test_ardupilot_set_converts_units_refuses_and_takes_effect(sitl):
    async with sitl() as (fleet, gcs):
        gcs.hello()
        await gcs.wait_ready()
        ap = fleet.vehicles[0]
        param_set(gcs, "RTL_ALT", 2500.0, MavParamType.REAL32)  # ArduPilot ignores the type
        m = await value_of(gcs, "RTL_ALT")
        assert m.param_value == 2500.0 and m.param_type == MavParamType.INT32
        assert ap.params().rtl_alt_m == 25.0
        assert fleet.cfg.ardupilot.rtl_alt_m == 15.0  # the configuration is not touched

        mark = param_set(gcs, "LAND_SPEED", 0.0, MavParamType.INT16)  # cannot land at 0 cm/s
        assert (await value_of(gcs, "LAND_SPEED")).param_value == 50.0  # unchanged
        (text,) = heard_since(gcs, mark, "STATUSTEXT")  # sent before the PARAM_VALUE
        assert text.text == "LAND_SPEED=0 outside 1..32767"  # INT16 cm/s

        mark = param_set(gcs, "FS_GCS_ENABLE", 1.0, MavParamType.INT8)  # served, not modelled
        assert (await value_of(gcs, "FS_GCS_ENABLE")).param_value == 0.0  # the default stays
        (text,) = heard_since(gcs, mark, "STATUSTEXT")
        assert text.text == "FS_GCS_ENABLE=1 not modelled: use 0"

        mark = param_set(gcs, "FS_THR_ENABLE", 1.0, MavParamType.INT8)  # not served: said so
        await gcs.wait_for("STATUSTEXT", lambda m: m.text == "Unknown parameter FS_THR_ENABLE")
        await gcs.wait_sim(QUIET_S)
        assert not heard_since(gcs, mark, "PARAM_VALUE")

        # DISARM_DELAY 2 s: the vehicle armed on the ground disarms after 2 s, not 10
        param_set(gcs, "DISARM_DELAY", 2.0, MavParamType.INT8)
        assert (await value_of(gcs, "DISARM_DELAY")).param_value == 2.0
        await gcs.command(MavCmd.DO_SET_MODE, 1, CopterMode.GUIDED)
        t_armed, _ = await armed(gcs)
        t_disarmed, _ = await gcs.wait_for_stamped("STATUSTEXT", said("Disarming motors"))
        assert 1.9 < t_disarmed - t_armed < 2.5 and not ap.armed
        summary = fleet.summary()["vehicles"][0]
        assert summary["params_set"] == {"RTL_ALT": 1, "DISARM_DELAY": 1}
        assert summary["params_refused"] == {"LAND_SPEED": 1, "FS_GCS_ENABLE": 1}
        assert summary["params_unknown"] == {"FS_THR_ENABLE": 1}


@pytest.mark.asyncio
@pytest.mark.network
@pytest.mark.timeout(120)
async def test_px4_set_is_bytewise_typed_and_takes_effect(sitl):
    async with sitl(flavour="px4") as (fleet, gcs):
        gcs.hello()
        await gcs.wait_ready()
        ap = fleet.vehicles[0]
        five = to_wire(5, MavParamType.INT32, bytewise=True)
        param_set(gcs, "COM_OBL_RC_ACT", five, MavParamType.INT32)
        m = await value_of(gcs, "COM_OBL_RC_ACT")
        assert from_wire(m.param_value, m.param_type, bytewise=True) == 5
        assert ap.params().com_obl_rc_act == "hold"

        mark = param_set(gcs, "COM_OBL_RC_ACT", 4.0, MavParamType.REAL32)  # a float: refused
        m = await value_of(gcs, "COM_OBL_RC_ACT")
        assert from_wire(m.param_value, m.param_type, bytewise=True) == 5
        (text,) = heard_since(gcs, mark, "STATUSTEXT")
        assert text.text == "COM_OBL_RC_ACT: type 9 sent, parameter is INT32"

        # COM_DISARM_PRFLT 2 s: armed without a take-off, disarmed after 2 s instead of 10
        param_set(gcs, "COM_DISARM_PRFLT", 2.0, MavParamType.REAL32)
        assert (await value_of(gcs, "COM_DISARM_PRFLT")).param_value == 2.0
        t_armed, _ = await armed(gcs)
        t_disarmed, _ = await gcs.wait_for_stamped("STATUSTEXT", said("Disarmed: no takeoff"))
        assert 1.9 < t_disarmed - t_armed < 2.5
        hb = await gcs.heartbeat_after(t_disarmed)
        assert not hb.base_mode & MavModeFlag.SAFETY_ARMED

        # ≤ 0 disables it: armed on the ground stays armed
        param_set(gcs, "COM_DISARM_PRFLT", -1.0, MavParamType.REAL32)
        assert (await value_of(gcs, "COM_DISARM_PRFLT")).param_value == -1.0
        await armed(gcs)
        await gcs.wait_sim(Px4Params().com_disarm_prflt_s + 1.0)
        assert ap.armed


# -- what `remarl-fc fly` reads before a flight ---------------------------------------------

FIRMWARE_DEFAULTS = {
    # ArduCopter (Parameters.cpp, AC_Fence, AP_Avoidance); GUID_TIMEOUT read back on SITL
    "GUID_TIMEOUT": 3.0,
    "FS_GCS_ENABLE": 0.0,
    "AVD_ENABLE": 0.0,
    "AVD_F_ACTION": 1.0,
    "FENCE_ENABLE": 0.0,
    # PX4 v1.16 (commander_params.yaml, geofence_params.yaml)
    "COM_OF_LOSS_T": 1.0,
    "COM_OBL_RC_ACT": 0.0,
    "NAV_DLL_ACT": 0.0,
    "COM_RC_IN_MODE": 3.0,
    "GF_ACTION": 2.0,
}


@pytest.mark.parametrize("flavour", ["ardupilot", "px4"])
def test_every_checked_parameter_is_served_with_the_firmware_default(flavour):
    """Real ArduCopter SITL answers every parameter `fly` checks; so does the mock, with the
    firmware's defaults, and the check then says what it says of the real firmware."""
    px4 = flavour == "px4"
    table, values = TABLES[flavour], Px4Params() if px4 else ArduPilotParams()
    served = table.snapshot(values)
    names = checked_names(px4)
    assert {n: served[n] for n in names} == {n: FIRMWARE_DEFAULTS[n] for n in names}
    findings = check_params(served, px4=px4, setpoint_period_s=0.1)
    assert all(f.level == "warning" for f in findings)  # nothing stops a flight
    flagged = sorted(f.text.split()[0] for f in findings)
    if px4:
        assert flagged == ["COM_OBL_RC_ACT", "NAV_DLL_ACT"]
    else:
        assert flagged == ["FENCE_ENABLE", "FS_GCS_ENABLE"]


@pytest.mark.parametrize(
    ("flavour", "name", "value", "taken"),
    [
        ("ardupilot", "FS_GCS_ENABLE", 1, False),  # no GCS failsafe in the mock
        ("ardupilot", "FENCE_ENABLE", 1, False),  # no fence
        ("ardupilot", "AVD_ENABLE", 1, False),  # no ADS-B avoidance
        ("ardupilot", "AVD_F_ACTION", 6, True),  # inert while AVD_ENABLE is 0
        ("ardupilot", "AVD_F_ACTION", 7, False),  # not an option
        ("px4", "NAV_DLL_ACT", 2, False),  # no data-link-loss failsafe
        ("px4", "COM_RC_IN_MODE", 4, False),  # no RC: the mock flies one way
        ("px4", "GF_ACTION", 0, True),  # inert without a geofence
        ("px4", "GF_ACTION", 6, False),
    ],
)
def test_failsafe_switches_take_only_what_the_mock_flies(flavour, name, value, taken):
    table = TABLES[flavour]
    values = Px4Params() if flavour == "px4" else ArduPilotParams()
    spec = table.specs[table.find(name)]  # type: ignore[index]
    if taken:
        assert spec.read(spec.write(values, value)) == value
    else:
        with pytest.raises(ParamRejected):
            spec.write(values, value)

"""The parameter protocol of a mock vehicle: the autopilot parameters the mock honours, by name.

Each flavour publishes the parameters of its `remarl_fc.sitl.config` dataclass under the real
names, types and units (ArduCopter in centimetres, PX4 in metres), answers PARAM_REQUEST_LIST,
PARAM_REQUEST_READ and PARAM_SET with PARAM_VALUE (https://mavlink.io/en/services/parameter.html),
and a value set takes effect at once: a new MIS_TAKEOFF_ALT changes the next take-off.

Integer parameters travel in PARAM_VALUE's float field the way each autopilot puts them there
(`remarl_fc.mavlink.params`): ArduPilot converts the number, PX4 copies its bytes. Only the
parameters that change the mock's behaviour are served, and the failsafe switches that
`remarl-fc fly` reads before a flight (with the firmware defaults, taking only the values the
mock flies alike); the others a ground station asks for get no answer, as on a vehicle without
them.

`ParamTable` is a flavour's served parameters; `ParamServer` is one vehicle's end of the
protocol.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any, Generic, TypeVar

from remarl_fc.mavlink.consts import MavParamType, MsgId, Severity
from remarl_fc.mavlink.params import INT_FORMATS, PARAM_ID_LEN, from_wire, param_name, to_wire
from remarl_fc.sitl.channel import Channel
from remarl_fc.sitl.config import PX4_COM_RC_IN_MODE

P = TypeVar("P")


class ParamRejected(ValueError):
    """A PARAM_SET the mock does not take.

    The current value is sent back, as the protocol asks, with a STATUSTEXT saying why.
    """


@dataclass(frozen=True)
class ParamSpec:
    """One served parameter: its name and type on the wire and the config field behind it."""

    name: str
    """The autopilot's parameter name."""
    field: str
    """Attribute of `ArduPilotParams` / `Px4Params` it reads and writes."""
    ptype: MavParamType = MavParamType.REAL32
    per_unit: float = 1.0
    """Parameter units per field unit: 100 for ArduPilot's cm and cm/s from m and m/s."""
    low: float = 0.0
    """Smallest value the mock can fly, in parameter units (an integer type's range also
    bounds it)."""
    high: float = math.inf
    """Largest value the mock can fly, in parameter units (an integer type's range also
    bounds it)."""
    choices: Mapping[int, object] | None = None
    """For an enumerated parameter: wire value → field value (the options the mock models)."""

    def bounds(self) -> tuple[float, float]:
        """The values the mock takes: `low`..`high` within the type's range."""
        fmt = INT_FORMATS.get(self.ptype)
        if fmt is None:
            return self.low, self.high
        return max(self.low, fmt[1]), min(self.high, fmt[2])

    def read(self, values: object) -> float:
        """The parameter's value, in its own units, from a config dataclass."""
        raw = getattr(values, self.field)
        if self.choices is not None:
            return float(next(k for k, v in self.choices.items() if v == raw))
        value = float(raw) * self.per_unit
        return float(round(value)) if self.ptype in INT_FORMATS else value

    def write(self, values: P, value: float) -> P:
        """A copy of ``values`` with this parameter set to ``value`` (its own units)."""
        if not math.isfinite(value):
            raise ParamRejected(f"{self.name}: {value} is not a number")
        if self.ptype in INT_FORMATS:
            value = float(round(value))
        if self.choices is not None:
            if int(value) not in self.choices:
                modelled = ",".join(str(k) for k in self.choices)
                raise ParamRejected(f"{self.name}={int(value)} not modelled: use {modelled}")
            new: Any = self.choices[int(value)]
        else:
            low, high = self.bounds()
            if not low <= value <= high:
                raise ParamRejected(f"{self.name}={value:g} outside {low:g}..{high:g}")
            new = value / self.per_unit
        return dataclasses.replace(values, **{self.field: new})  # type: ignore[type-var]


class ParamTable:
    """The served parameters of one flavour, in index order."""

    def __init__(self, specs: tuple[ParamSpec, ...], *, bytewise: bool) -> None:
        for spec in specs:
            if len(spec.name) > PARAM_ID_LEN:
                raise ValueError(f"parameter name {spec.name!r} is over {PARAM_ID_LEN} characters")
        self.specs, self.bytewise = specs, bytewise
        self._index = {spec.name: k for k, spec in enumerate(specs)}

    def __len__(self) -> int:
        return len(self.specs)

    def find(self, name: str, index: int = -1) -> int | None:
        """PARAM_REQUEST_READ's lookup: by ``index`` when it is ≥ 0, else by ``name``."""
        if index >= 0:
            return index if index < len(self.specs) else None
        return self._index.get(name)

    def snapshot(self, values: object) -> dict[str, float]:
        """Every served parameter's value, by name, in the autopilot's units."""
        return {spec.name: spec.read(values) for spec in self.specs}

    def value_message(self, factory: Any, values: object, k: int) -> Any:
        """PARAM_VALUE of parameter ``k``."""
        spec = self.specs[k]
        wire = to_wire(spec.read(values), spec.ptype, bytewise=self.bytewise)
        return factory.param_value_encode(
            spec.name.encode("ascii"), wire, int(spec.ptype), len(self.specs), k
        )

    def set(self, values: P, k: int, raw: float, sent_type: int) -> P:
        """``values`` after a PARAM_SET of parameter ``k`` to the wire value ``raw``.

        ArduPilot ignores the sender's param_type and converts; PX4 decodes the bytes and so
        refuses a type other than the parameter's.
        """
        spec = self.specs[k]
        if self.bytewise and sent_type != spec.ptype:
            want = MavParamType(spec.ptype).name
            raise ParamRejected(f"{spec.name}: type {sent_type} sent, parameter is {want}")
        return spec.write(values, from_wire(raw, spec.ptype, bytewise=self.bytewise))


class ParamServer(Generic[P]):
    """One vehicle's end of the parameter protocol.

    Args:
        table: the flavour's served parameters.
        channel: how the vehicle answers; it counts parameters set, refused and asked for
            in vain.
    """

    def __init__(self, table: ParamTable, channel: Channel) -> None:
        self.table, self.channel = table, channel

    def handle(self, msg: Any, values: P) -> P:
        """Answer PARAM_REQUEST_LIST, PARAM_REQUEST_READ or PARAM_SET; returns the new values.

        PARAM_REQUEST_LIST → every parameter; PARAM_REQUEST_READ → one; PARAM_SET → set it and
        send its value (the unchanged one, and a STATUSTEXT saying why, if refused). A name the
        flavour does not serve gets no PARAM_VALUE, as on a real vehicle; a PARAM_SET of one
        also gets a STATUSTEXT, so that nobody takes the silence for success.
        """
        table, ch, mid = self.table, self.channel, msg.get_msgId()
        if mid == MsgId.PARAM_REQUEST_LIST:
            for each in range(len(table)):
                ch.emit(table.value_message(ch.factory, values, each))
            return values
        name = param_name(msg.param_id)
        index = int(msg.param_index) if mid == MsgId.PARAM_REQUEST_READ else -1
        k = table.find(name, index)
        if k is None:
            ch.counters.params_unknown[name or f"#{index}"] += 1
            if mid == MsgId.PARAM_SET:
                ch.say(Severity.WARNING, f"Unknown parameter {name}")
            return values
        if mid == MsgId.PARAM_SET:
            try:
                values = table.set(values, k, float(msg.param_value), int(msg.param_type))
                ch.counters.params_set[name] += 1
            except ParamRejected as exc:
                ch.counters.params_refused[name] += 1
                ch.say(Severity.WARNING, str(exc))
        ch.emit(table.value_message(ch.factory, values, k))
        return values


CM = 100.0
"""ArduCopter's centimetres (and cm/s) per metre."""

ONLY_ZERO: Mapping[int, object] = MappingProxyType({0: 0})
"""``choices`` of a served switch whose other settings the mock does not model (0 only)."""

ARDUPILOT_PARAMS = ParamTable(
    (
        ParamSpec("AVD_ENABLE", "avd_enable", MavParamType.INT8, choices=ONLY_ZERO),
        ParamSpec("AVD_F_ACTION", "avd_f_action", MavParamType.INT8, high=6),
        ParamSpec("DISARM_DELAY", "disarm_delay_s", MavParamType.INT8),
        ParamSpec("FENCE_ENABLE", "fence_enable", MavParamType.INT8, choices=ONLY_ZERO),
        ParamSpec("FS_GCS_ENABLE", "fs_gcs_enable", MavParamType.INT8, choices=ONLY_ZERO),
        ParamSpec("GUID_TIMEOUT", "guid_timeout_s"),
        ParamSpec("LAND_ALT_LOW", "land_alt_low_m", MavParamType.INT16, CM),
        ParamSpec("LAND_SPEED", "land_speed_m_s", MavParamType.INT16, CM, low=1),
        ParamSpec("RTL_ALT", "rtl_alt_m", MavParamType.INT32, CM),
        ParamSpec("WPNAV_SPEED", "rtl_speed_m_s", per_unit=CM, low=1),
        ParamSpec("WPNAV_SPEED_DN", "wpnav_speed_dn_m_s", per_unit=CM, low=1),
        ParamSpec("WPNAV_SPEED_UP", "wpnav_speed_up_m_s", per_unit=CM, low=1),
    ),
    bytewise=False,
)
"""ArduCopter's parameters the mock honours (`ArduPilotParams`), alphabetical as ArduPilot
lists them; types as in ArduCopter's Parameters.h (AP_Int8/16/32, AP_Float). The failsafe
switches `remarl-fc fly` checks (FS_GCS_ENABLE, FENCE_ENABLE, AVD_*) are served with the
firmware defaults, as ArduCopter SITL answers them; the mock takes only values it flies alike."""

PX4_PARAMS = ParamTable(
    (
        ParamSpec("COM_DISARM_LAND", "com_disarm_land_s", low=-1),
        ParamSpec("COM_DISARM_PRFLT", "com_disarm_prflt_s", low=-1),
        ParamSpec("COM_FAIL_ACT_T", "com_fail_act_t_s"),
        ParamSpec(
            "COM_OBL_RC_ACT",
            "com_obl_rc_act",
            MavParamType.INT32,
            choices={0: "position", 3: "return", 4: "land", 5: "hold"},
        ),
        ParamSpec("COM_OF_LOSS_T", "com_of_loss_t_s"),
        ParamSpec(
            "COM_RC_IN_MODE",
            "com_rc_in_mode",
            MavParamType.INT32,
            choices=MappingProxyType({PX4_COM_RC_IN_MODE: PX4_COM_RC_IN_MODE}),
        ),
        ParamSpec("GF_ACTION", "gf_action", MavParamType.INT32, high=5),
        ParamSpec("MIS_TAKEOFF_ALT", "mis_takeoff_alt_m", low=0.1),
        ParamSpec("MPC_LAND_SPEED", "mpc_land_speed_m_s", low=0.1),
        ParamSpec("MPC_TKO_SPEED", "mpc_tko_speed_m_s", low=0.1),
        ParamSpec("MPC_XY_CRUISE", "rtl_speed_m_s", low=0.1),
        ParamSpec("NAV_DLL_ACT", "nav_dll_act", MavParamType.INT32, choices=ONLY_ZERO),
        ParamSpec("RTL_RETURN_ALT", "rtl_return_alt_m"),
    ),
    bytewise=True,
)
"""PX4's parameters the mock honours (`Px4Params`); INT32 and FLOAT as in PX4's parameter
definitions. COM_OBL_RC_ACT takes the options the mock flies (not 1 Altitude, 2 Manual,
6 Terminate, 7 Disarm). The failsafe settings `remarl-fc fly` checks (NAV_DLL_ACT,
COM_RC_IN_MODE, GF_ACTION) are served with PX4's defaults; the mock takes only values it flies
alike."""


def parse_override(text: str) -> tuple[str, float]:
    """``NAME=VALUE`` (the autopilot's name and units) → (NAME, value)."""
    name, sep, value = text.partition("=")
    try:
        if not sep or not name:
            raise ValueError
        return name.strip().upper(), float(value)
    except ValueError:
        raise ValueError(f"{text!r} is not NAME=VALUE (e.g. COM_OBL_RC_ACT=5)") from None


def with_overrides(values: P, table: ParamTable, overrides: list[tuple[str, float]]) -> P:
    """``values`` with each (NAME, value) set as a PARAM_SET would set it.

    Raises ValueError naming the served parameters for a name the flavour does not serve, and
    `ParamRejected` for a value the mock cannot fly.
    """
    for name, value in overrides:
        k = table.find(name)
        if k is None:
            served = ", ".join(s.name for s in table.specs)
            raise ValueError(f"parameter {name} is not modelled here; this flavour serves {served}")
        values = table.specs[k].write(values, value)
    return values

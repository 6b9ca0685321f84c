"""What tells the two autopilot flavours apart where they differ only in values, as data.

`FlavourSpec` holds one flavour's identity and tables: its parameters, streams, mode numbers,
the modes a pilot can select by name, and the refusals it shares in shape with the other
flavour. `ModeRules` is one row of a flavour's mode table. The flavours' behaviour (what a
mode does, when a take-off ends) is code: `remarl_fc.sitl.autopilot.Autopilot`'s abstract
methods, implemented by `remarl_fc.sitl.ardupilot` and `remarl_fc.sitl.px4`.

A leaf module: data types only, so that the telemetry builders can read a flavour's identity
without importing the autopilot logic.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Generic, Protocol, TypeVar

from remarl_fc.mavlink.consts import MavAutopilot, MavModeFlag, MavResult
from remarl_fc.sitl.config import Flavour, SitlConfig
from remarl_fc.sitl.params import ParamTable


class FlavourParams(Protocol):
    """What the autopilot logic reads from either flavour's parameter dataclass."""

    @property
    def boot_s(self) -> float:
        """Seconds in MAV_STATE_BOOT after start."""

    @property
    def position_estimate_s(self) -> float:
        """Seconds after start until a global position is valid."""


P = TypeVar("P", bound=FlavourParams)

Result = tuple[int, str]
"""A command's outcome: (MAV_RESULT, STATUSTEXT or "" for none)."""


@dataclass(frozen=True)
class ModeRules:
    """What one flight mode of a flavour allows (a row of its mode table)."""

    flags: MavModeFlag
    """HEARTBEAT.base_mode bits of the mode, besides CUSTOM_MODE_ENABLED and SAFETY_ARMED."""
    needs_position: bool = False
    """Entering the mode needs an absolute position estimate."""
    external_control: bool = False
    """Setpoints are flown in this mode (ArduPilot GUIDED, PX4 OFFBOARD)."""
    armable: bool = True
    """Arming is allowed in this mode (ArduPilot's `Mode::allows_arming`)."""
    takeoff: bool = False
    """MAV_CMD_NAV_TAKEOFF is taken in this mode (ArduPilot; PX4 switches mode instead)."""
    pilot_descends: bool = False
    """A pilot mode that, with no RC input, sinks as with the throttle stick at minimum."""


@dataclass(frozen=True)
class FlavourSpec(Generic[P]):
    """One flavour's values: identity, parameters, streams, modes and shared refusals.

    ``P`` is the flavour's parameter dataclass (`remarl_fc.sitl.config.ArduPilotParams` or
    `remarl_fc.sitl.config.Px4Params`).
    """

    name: Flavour
    autopilot_id: MavAutopilot
    """HEARTBEAT.autopilot."""
    flight_sw_version: int
    """AUTOPILOT_VERSION.flight_sw_version."""
    config_params: Callable[[SitlConfig], P]
    """The flavour's parameters in a fleet configuration (the values a vehicle starts with)."""
    param_table: ParamTable
    """The parameters served over MAVLink (`remarl_fc.sitl.params`)."""
    default_streams: Mapping[int, float]
    """Message id → interval s streamed before anyone asks."""
    supported_streams: frozenset[int]
    """Messages a GCS may ask to stream (MAV_CMD_SET_MESSAGE_INTERVAL)."""
    data_stream_groups: Mapping[int, tuple[int, ...]]
    """REQUEST_DATA_STREAM ids → messages (empty: the request changes nothing)."""
    unsigned_allowed: frozenset[int]
    """Messages accepted unsigned once signing is on."""
    initial_mode: int
    """HEARTBEAT.custom_mode at start (and, on ArduPilot, once boot ends)."""
    land_mode: int
    """custom_mode that MAV_CMD_NAV_LAND switches to."""
    rtl_mode: int
    """custom_mode that MAV_CMD_NAV_RETURN_TO_LAUNCH switches to."""
    pilot_modes: Mapping[str, int]
    """Mode names a pilot can select (the `pilot-mode` fault) → custom_mode."""
    vehicle_profile: str
    """The vehicle profile (`sim.vehicle`) fitted to this autopilot's SITL traces."""
    set_mode_not_custom: MavResult
    """DO_SET_MODE without CUSTOM_MODE_ENABLED in p1 is refused with this."""
    arm_without_position: Result
    """Refusal of an arming request while booting or without a position."""
    disarm_in_flight: Result
    """Refusal of an unforced disarm in the air."""

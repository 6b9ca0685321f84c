"""Autopilot logic of one mock vehicle: modes, arming, commands, setpoints, streams, timeouts.

Sans-IO: `Autopilot.handle` takes a decoded message and the simulated time and emits replies
through a callback; `Autopilot.tick` runs the timers (setpoint timeouts, auto-disarm, mode
phases). The vehicle's motion is set through its row of the batched `Airframes`
(`remarl_fc.sitl.motion`).

`Autopilot` is the flavour interface, an abstract base class: what both autopilots do alike is
implemented here once; where they differ only in values, the values are the flavour's
`remarl_fc.sitl.flavour.FlavourSpec` (`Autopilot.spec`) and its mode table
(`Autopilot.mode_rules`); where they behave differently, an abstract method says what the
flavour decides. The two flavours, as strict as the real ones (references in the docstrings of
each rule): `remarl_fc.sitl.ardupilot.ArduCopterLogic` and `remarl_fc.sitl.px4.Px4Logic`. A
rule the mock does not model answers with a refusal and a STATUSTEXT saying so, never with a
silent success.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections.abc import Callable
from typing import Any, ClassVar, Generic

import numpy as np

from remarl_fc.frames import GeoPoint
from remarl_fc.mavlink.consts import (
    LandedState,
    MavCmd,
    MavComponent,
    MavModeFlag,
    MavResult,
    MavState,
    MsgId,
)
from remarl_fc.sitl.channel import Channel, Emit
from remarl_fc.sitl.commands import Command, CommandServer, Handler, forced
from remarl_fc.sitl.config import SitlConfig
from remarl_fc.sitl.flavour import FlavourSpec, ModeRules, P, Result
from remarl_fc.sitl.motion import Motion
from remarl_fc.sitl.params import ParamServer
from remarl_fc.sitl.setpoints import Setpoint, parse_setpoint
from remarl_fc.sitl.streams import StreamSchedule
from remarl_fc.sitl.vehicle import Airframes, Guidance

TICK_HZ = 10.0
"""Rate of the autopilot timers (simulated Hz)."""


class Autopilot(ABC, Generic[P]):
    """Logic shared by both flavours; a flavour gives its `spec` and the abstract methods.

    Args:
        index: the vehicle's index in the fleet (system id − 1).
        cfg: the fleet's configuration (the vehicle starts with the flavour's parameters in it).
        frames: the fleet's airframes.
        origin: the arena origin.
        factory: the vehicle's MAVLink message factory.
        emit: sends one message to the vehicle's peers.
    """

    spec: ClassVar[FlavourSpec[Any]]
    """The flavour's values (identity, parameters, streams, mode numbers, refusals)."""

    def __init__(
        self,
        index: int,
        cfg: SitlConfig,
        frames: Airframes,
        origin: GeoPoint,
        factory: Any,
        emit: Emit,
    ) -> None:
        spec = self.spec
        self.index, self.cfg, self.frames, self.origin = index, cfg, frames, origin
        self.system_id = index + 1
        self.channel = Channel(factory, emit)
        self.factory, self.emit, self.counters = factory, emit, self.channel.counters
        self.p: P = spec.config_params(cfg)
        self.motion = Motion(frames, index, cfg.model)
        self.armed = False
        self.custom_mode = spec.initial_mode
        self.failsafe = False
        self.flew = False  # has been airborne
        self.streams = StreamSchedule(
            {**spec.default_streams, MsgId.ADSB_VEHICLE: 1.0 / cfg.adsb_hz},
            spec.supported_streams,
            spec.data_stream_groups,
        )
        # the ADS-B receiver's first report comes one period after start
        self.streams.first_due(MsgId.ADSB_VEHICLE, 1.0 / cfg.adsb_hz)
        self.command_server = CommandServer(self.channel)
        self.param_server: ParamServer[P] = ParamServer(spec.param_table, self.channel)
        self.last_setpoint_s = -math.inf
        self.setpoint: Setpoint | None = None
        self._armed_at_s = 0.0
        self._landed_since_s: float | None = 0.0
        self._status: int = MavState.BOOT
        """HEARTBEAT.system_status, as the last `tick` found it (BOOT before the first)."""

    # -- the flavour's decisions ----------------------------------------------------------

    @abstractmethod
    def mode_rules(self) -> ModeRules:
        """The current mode's row of the flavour's mode table."""

    @abstractmethod
    def request_mode(self, cmd: Command, now_s: float) -> Result:
        """MAV_CMD_DO_SET_MODE whose p1 has CUSTOM_MODE_ENABLED: decode the mode, enter it."""

    @abstractmethod
    def enter_mode(self, mode: int, now_s: float) -> Result:
        """A GCS asks for custom_mode ``mode``: the flavour's checks, then the switch."""

    @abstractmethod
    def take_pilot_mode(self, mode: int) -> None:
        """The pilot flips the mode switch to custom_mode ``mode`` (no checks: a fault)."""

    @abstractmethod
    def mode_arm_refusal(self, now_s: float) -> Result | None:
        """Refusal to arm in the current mode (the position is checked already), or None."""

    @abstractmethod
    def cmd_takeoff(self, cmd: Command, now_s: float) -> Result:
        """MAV_CMD_NAV_TAKEOFF."""

    @abstractmethod
    def on_setpoint(self, sp: Setpoint, now_s: float) -> bool:
        """Take a setpoint; True if it now drives the vehicle."""

    @abstractmethod
    def resting_status(self) -> MavState:
        """HEARTBEAT.system_status when neither booting nor in failsafe: STANDBY or ACTIVE."""

    @abstractmethod
    def mode_timers(self, now_s: float) -> None:
        """Step 1 of `tick`: the flavour's timers that may change the mode or the failsafe.

        Boot end, setpoint timeouts, take-off end, RTL's landing.
        """

    @abstractmethod
    def ground_timers(self, now_s: float, was_flying: bool) -> None:
        """Step 4 of `tick`: the flavour's touch-down and auto-disarm timers.

        ``was_flying``: the vehicle was airborne at the previous tick.
        """

    def after_arm(self) -> None:
        """What arming starts besides spinning the motors (nothing by default)."""

    def command_handlers(self) -> dict[int, Handler]:
        """MAV_CMD → handler returning (MAV_RESULT, STATUSTEXT or ""); a flavour may add."""
        return {
            MavCmd.SET_MESSAGE_INTERVAL: self.streams.cmd_set_message_interval,
            MavCmd.REQUEST_MESSAGE: self.streams.cmd_request_message,
            MavCmd.REQUEST_AUTOPILOT_CAPABILITIES: self.streams.cmd_request_capabilities,
            MavCmd.DO_SET_MODE: self.cmd_set_mode,
            MavCmd.COMPONENT_ARM_DISARM: self.cmd_arm_disarm,
            MavCmd.NAV_TAKEOFF: self.cmd_takeoff,
            MavCmd.NAV_LAND: self.cmd_land,
            MavCmd.NAV_RETURN_TO_LAUNCH: self.cmd_rtl,
        }

    # -- identity and state -------------------------------------------------------------

    def params(self) -> P:
        """The flavour's live parameter values (a `remarl_fc.sitl.config` dataclass)."""
        return self.p

    def set_params(self, values: P) -> None:
        """Replace the live parameter values (they apply from the next message or tick)."""
        self.p = values

    def boot_s(self) -> float:
        """Seconds in MAV_STATE_BOOT after start (the flavour's ``boot_s``)."""
        return self.p.boot_s

    def position_estimate_s(self) -> float:
        """Seconds after start until a global position is valid."""
        return self.p.position_estimate_s

    def time_boot_ms(self, now_s: float) -> int:
        """time_boot_ms of the simulated clock (wraps at 2³²)."""
        return int(now_s * 1000) & 0xFFFF_FFFF

    def position_ok(self, now_s: float) -> bool:
        """Whether the vehicle has an absolute position estimate."""
        return now_s >= self.position_estimate_s()

    def booting(self, now_s: float) -> bool:
        """Whether the vehicle is still in MAV_STATE_BOOT."""
        return now_s < self.boot_s()

    @property
    def landed(self) -> bool:
        """Whether the airframe is on the ground."""
        return self.motion.landed

    def landed_state(self) -> int:
        """MAV_LANDED_STATE for EXTENDED_SYS_STATE."""
        g = self.motion.guidance
        if self.landed:
            return LandedState.ON_GROUND
        if g == Guidance.CLIMB:
            return LandedState.TAKEOFF
        if g == Guidance.LAND:
            return LandedState.LANDING
        return LandedState.IN_AIR

    def base_mode(self) -> int:
        """HEARTBEAT.base_mode: CUSTOM_MODE_ENABLED, the mode's flags, + SAFETY_ARMED."""
        mode = MavModeFlag.CUSTOM_MODE_ENABLED | self.mode_rules().flags
        if self.armed:
            mode |= MavModeFlag.SAFETY_ARMED
        return int(mode)

    def under_external_control(self) -> bool:
        """Whether setpoints are being flown (GUIDED / OFFBOARD)."""
        return self.mode_rules().external_control

    def system_status(self) -> int:
        """HEARTBEAT.system_status, as the last `tick` found it (BOOT before the first)."""
        return self._status

    def current_status(self, now_s: float) -> int:
        """MAV_STATE now: BOOT, CRITICAL in a failsafe, else the flavour's resting status."""
        if self.booting(now_s):
            return MavState.BOOT
        if self.failsafe:
            return MavState.CRITICAL
        return self.resting_status()

    def armed_on_ground(self) -> bool:
        """Armed, on the ground and not climbing away: where the auto-disarm timers run."""
        return self.armed and self.landed and self.motion.guidance != Guidance.CLIMB

    def active_target(self) -> tuple[int, np.ndarray, np.ndarray, float, float] | None:
        """(type_mask, position, velocity, yaw, yaw rate) of the external target being flown."""
        if not self.under_external_control() or self.setpoint is None:
            return None
        sp = self.setpoint
        pos = sp.pos_ned_m if sp.pos_ned_m is not None else self.frames.pos_ned_m[self.index]
        vel = sp.vel_ned_m_s if sp.vel_ned_m_s is not None else np.zeros(3)
        return (
            sp.type_mask,
            np.nan_to_num(pos),
            np.nan_to_num(vel),
            sp.yaw_rad if sp.yaw_rad is not None else 0.0,
            sp.yaw_rate_rad_s if sp.yaw_rate_rad_s is not None else 0.0,
        )

    # -- messages -----------------------------------------------------------------------

    def for_me(self, target_system: int, target_component: int) -> bool:
        """Addressed to this vehicle's autopilot (or broadcast)."""
        return target_system in (0, self.system_id) and target_component in (
            MavComponent.ALL,
            MavComponent.AUTOPILOT1,
        )

    def handle(self, msg: Any, now_s: float) -> None:
        """React to one message from a peer (those not addressed to this vehicle are ignored)."""
        handler = self._message_handlers.get(msg.get_msgId())
        if handler is not None and self.for_me(msg.target_system, msg.target_component):
            handler(self, msg, now_s)

    def on_command(self, msg: Any, now_s: float) -> None:
        """COMMAND_LONG / COMMAND_INT (`CommandServer`, with `command_handlers`)."""
        self.command_server.handle(msg, self.command_handlers(), now_s)

    def on_setpoint_message(self, msg: Any, now_s: float) -> None:
        """SET_POSITION_TARGET_LOCAL_NED / _GLOBAL_INT: normalise, then the flavour's rules."""
        self.counters.setpoints_received += 1
        i = self.index
        sp = parse_setpoint(
            msg,
            flavour=self.spec.name,
            origin=self.origin,
            home_ned_m=self.frames.home_ned_m[i],
            pos_ned_m=self.frames.pos_ned_m[i],
            yaw_rad=float(self.frames.yaw_rad[i]),
        )
        if self.on_setpoint(sp, now_s):
            self.counters.setpoints_applied += 1

    def on_request_data_stream(self, msg: Any, now_s: float) -> None:
        """REQUEST_DATA_STREAM (the flavour's stream groups; PX4 has none)."""
        self.streams.on_request_data_stream(msg, now_s)

    def on_param_message(self, msg: Any, now_s: float) -> None:
        """PARAM_REQUEST_LIST, PARAM_REQUEST_READ, PARAM_SET (`ParamServer`)."""
        self.set_params(self.param_server.handle(msg, self.params()))

    _message_handlers: ClassVar[dict[int, Callable[[Autopilot[Any], Any, float], None]]] = {
        MsgId.COMMAND_LONG: on_command,
        MsgId.COMMAND_INT: on_command,
        MsgId.SET_POSITION_TARGET_LOCAL_NED: on_setpoint_message,
        MsgId.SET_POSITION_TARGET_GLOBAL_INT: on_setpoint_message,
        MsgId.REQUEST_DATA_STREAM: on_request_data_stream,
        MsgId.PARAM_REQUEST_LIST: on_param_message,
        MsgId.PARAM_REQUEST_READ: on_param_message,
        MsgId.PARAM_SET: on_param_message,
    }
    """Message id → what handles it, once it is addressed to this vehicle (the same for both
    flavours: they differ in what the handlers call)."""

    def param_snapshot(self) -> dict[str, float]:
        """Every served parameter's live value, by name, in the autopilot's units."""
        return self.spec.param_table.snapshot(self.params())

    def ignore_setpoint(self, reason: str) -> bool:
        """Count a setpoint that changes nothing; returns False."""
        self.counters.ignored_reasons[reason] += 1
        return False

    def say(self, severity: int, text: str) -> None:
        """Send a STATUSTEXT."""
        self.channel.say(severity, text)

    # -- commands both flavours handle alike -------------------------------------------

    def cmd_set_mode(self, cmd: Command, now_s: float) -> Result:
        """MAV_CMD_DO_SET_MODE: p1 must have CUSTOM_MODE_ENABLED; the flavour reads the mode."""
        if not cmd.int_param(0, 0, 255) & MavModeFlag.CUSTOM_MODE_ENABLED:
            return self.spec.set_mode_not_custom, ""
        return self.request_mode(cmd, now_s)

    def cmd_land(self, cmd: Command, now_s: float) -> Result:
        """MAV_CMD_NAV_LAND: switch to the flavour's landing mode."""
        return self.enter_mode(self.spec.land_mode, now_s)

    def cmd_rtl(self, cmd: Command, now_s: float) -> Result:
        """MAV_CMD_NAV_RETURN_TO_LAUNCH: switch to the flavour's return mode."""
        return self.enter_mode(self.spec.rtl_mode, now_s)

    def cmd_arm_disarm(self, cmd: Command, now_s: float) -> Result:
        """MAV_CMD_COMPONENT_ARM_DISARM: p1 1 arm / 0 disarm, p2 21196 force."""
        arm, force = cmd.params[0] >= 0.5, forced(cmd.params[1])
        if arm:
            if self.armed:
                return MavResult.ACCEPTED, ""
            refusal = None if force else self.arm_refusal(now_s)
            if refusal is not None:
                return refusal
            self.do_arm(now_s)
            self.after_arm()
            return MavResult.ACCEPTED, ""
        if not self.armed:
            return MavResult.ACCEPTED, ""
        if not self.landed and not force:
            return self.spec.disarm_in_flight
        self.do_disarm()
        return MavResult.ACCEPTED, ""

    def arm_refusal(self, now_s: float) -> Result | None:
        """(result, STATUSTEXT) when the flavour refuses to arm now, else None."""
        if self.booting(now_s) or not self.position_ok(now_s):
            return self.spec.arm_without_position
        return self.mode_arm_refusal(now_s)

    def do_arm(self, now_s: float) -> None:
        """Arm: motors spin, the vehicle stays on the ground."""
        self.armed = True
        self._armed_at_s = now_s
        if self.landed:
            self.motion.idle()

    def do_disarm(self) -> None:
        """Disarm: motors stop (in the air the vehicle drops to the ground)."""
        self.armed = False
        if self.landed:
            self.motion.idle()
        else:
            self.motion.drop()

    def pilot_mode(self, mode: str, now_s: float) -> bool:
        """The pilot flips the mode switch to ``mode`` (a fault); False if no such mode."""
        number = self.spec.pilot_modes.get(mode.upper())
        if number is None:
            return False
        self.take_pilot_mode(number)
        return True

    # -- timers -------------------------------------------------------------------------

    def tick(self, now_s: float) -> None:
        """Run the timers (called at `TICK_HZ`).

        In this order:

        1. the flavour's `mode_timers` (they may change the mode or the failsafe);
        2. the ground tracking (``flew``, and since when the vehicle is on the ground);
        3. the status: HEARTBEAT.system_status until the next tick, as the autopilot's own
           10 Hz update would report it — a disarm in step 4 shows in the next one;
        4. the flavour's `ground_timers` (touch-down, auto-disarm).
        """
        self.mode_timers(now_s)
        was_flying = self.flew and self._landed_since_s is None
        if not self.landed:
            self.flew = True
            self._landed_since_s = None
        elif self._landed_since_s is None:
            self._landed_since_s = now_s
        self._status = self.current_status(now_s)
        self.ground_timers(now_s, was_flying)

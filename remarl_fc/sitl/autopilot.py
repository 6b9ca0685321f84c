"""Autopilot logic of one mock vehicle: modes, arming, commands, setpoints, streams, timeouts.

Sans-IO: `Autopilot.handle` takes a decoded message and the simulated time and emits replies
through a callback; `Autopilot.tick` runs the timers (setpoint timeouts, auto-disarm, mode
phases). The vehicle's motion is set through its row of the batched `Airframes`.

Two flavours, as strict as the real ones (references in the docstrings of each rule):
`remarl_fc.sitl.ardupilot.ArduCopterLogic` and `remarl_fc.sitl.px4.Px4Logic`. A rule the mock
does not model answers with a refusal and a STATUSTEXT saying so, never with a silent success.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from remarl_fc.frames import GeoPoint, wrap_yaw
from remarl_fc.mavlink.consts import (
    ARM_FORCE_MAGIC,
    LandedState,
    MavAutopilot,
    MavCmd,
    MavComponent,
    MavModeFlag,
    MavResult,
    MavState,
    MsgId,
    Severity,
)
from remarl_fc.mavlink.params import param_name
from remarl_fc.sitl.config import SitlConfig
from remarl_fc.sitl.params import ParamRejected, ParamTable
from remarl_fc.sitl.setpoints import Setpoint, parse_setpoint
from remarl_fc.sitl.telemetry import statustext
from remarl_fc.sitl.vehicle import Airframes, Guidance, YawMode

Emit = Callable[[Any], None]
"""Sends one message to the vehicle's peers."""

TICK_HZ = 10.0
"""Rate of the autopilot timers (simulated Hz)."""


CLIMB_DONE_M = 0.3
"""A take-off is complete within this distance below its height (the climb slows into it)."""

MAX_INTERVAL_HZ = 50.0
"""Highest message rate a stream can be set to (the physics rate caps it anyway)."""


@dataclass
class Counters:
    """What one vehicle received and did with it (goes into the ground-truth summary)."""

    setpoints_received: int = 0
    setpoints_applied: int = 0
    setpoints_ignored: int = 0
    commands: Counter[str] = field(default_factory=Counter)
    results: Counter[str] = field(default_factory=Counter)
    ignored_reasons: Counter[str] = field(default_factory=Counter)
    params_set: Counter[str] = field(default_factory=Counter)
    params_refused: Counter[str] = field(default_factory=Counter)
    params_unknown: Counter[str] = field(default_factory=Counter)

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        return {
            "setpoints_received": self.setpoints_received,
            "setpoints_applied": self.setpoints_applied,
            "setpoints_ignored": self.setpoints_ignored,
            "setpoints_ignored_by_reason": dict(self.ignored_reasons),
            "commands": dict(self.commands),
            "command_results": dict(self.results),
            "params_set": dict(self.params_set),
            "params_refused": dict(self.params_refused),
            "params_unknown": dict(self.params_unknown),
        }


@dataclass(frozen=True)
class Command:
    """A COMMAND_LONG or COMMAND_INT, normalised (COMMAND_INT x/y → params 5/6, z → 7)."""

    command: int
    params: tuple[float, float, float, float, float, float, float]
    frame: int | None  # None for COMMAND_LONG
    source: tuple[int, int]


class Autopilot:
    """Logic shared by both flavours. Subclasses fill in modes and rules."""

    autopilot_id: ClassVar[int] = MavAutopilot.GENERIC
    flavour: ClassVar[str] = ""
    param_table: ClassVar[ParamTable] = ParamTable((), bytewise=False)
    """The parameters the flavour serves (`remarl_fc.sitl.params`)."""

    def __init__(
        self,
        index: int,
        cfg: SitlConfig,
        frames: Airframes,
        origin: GeoPoint,
        factory: Any,
        emit: Emit,
    ) -> None:
        self.index, self.cfg, self.frames, self.origin = index, cfg, frames, origin
        self.system_id = index + 1
        self.factory, self.emit = factory, emit
        self.armed = False
        self.custom_mode = 0
        self.failsafe = False
        self.flew = False  # has been airborne
        self.counters = Counters()
        self.stream_interval_s: dict[int, float] = self.default_streams()
        self.stream_due_s: dict[int, float] = {}
        self.requested: list[int] = []  # one-shot messages to send with the next telemetry
        self.last_setpoint_s = -math.inf
        self.setpoint: Setpoint | None = None
        self._armed_at_s = 0.0
        self._landed_since_s: float | None = 0.0

    # -- identity and state -------------------------------------------------------------

    def boot_s(self) -> float:
        """Seconds in MAV_STATE_BOOT after start."""
        raise NotImplementedError

    def position_estimate_s(self) -> float:
        """Seconds after start until a global position is valid."""
        raise NotImplementedError

    def default_streams(self) -> dict[int, float]:
        """Message id → interval s the flavour streams before anyone asks."""
        raise NotImplementedError

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
        return bool(self.frames.landed[self.index])

    def landed_state(self) -> int:
        """MAV_LANDED_STATE for EXTENDED_SYS_STATE."""
        g = self.frames.guidance[self.index]
        if self.landed:
            return LandedState.ON_GROUND
        if g == Guidance.CLIMB:
            return LandedState.TAKEOFF
        if g == Guidance.LAND:
            return LandedState.LANDING
        return LandedState.IN_AIR

    def base_mode(self) -> int:
        """HEARTBEAT.base_mode: the flavour's mode flags, + SAFETY_ARMED."""
        mode = self.mode_flags()
        if self.armed:
            mode |= MavModeFlag.SAFETY_ARMED
        return int(mode)

    def mode_flags(self) -> MavModeFlag:
        """base_mode bits of the current mode (without SAFETY_ARMED)."""
        raise NotImplementedError

    def system_status(self) -> int:
        """HEARTBEAT.system_status (needs the time: use `status_at`)."""
        return self._status

    def status_at(self, now_s: float) -> None:
        """Refresh the cached system status for the next heartbeat."""
        if self.booting(now_s):
            self._status = MavState.BOOT
        elif self.failsafe:
            self._status = MavState.CRITICAL
        else:
            self._status = self.resting_status()

    def resting_status(self) -> int:
        """STANDBY or ACTIVE, per flavour."""
        raise NotImplementedError

    _status: int = MavState.BOOT

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

    def under_external_control(self) -> bool:
        """Whether setpoints are being flown (GUIDED / OFFBOARD)."""
        raise NotImplementedError

    # -- messages -----------------------------------------------------------------------

    def for_me(self, target_system: int, target_component: int) -> bool:
        """Addressed to this vehicle's autopilot (or broadcast)."""
        return target_system in (0, self.system_id) and target_component in (
            MavComponent.ALL,
            MavComponent.AUTOPILOT1,
        )

    def handle(self, msg: Any, now_s: float) -> None:
        """React to one message from a peer."""
        mid = msg.get_msgId()
        if mid in (MsgId.COMMAND_LONG, MsgId.COMMAND_INT):
            if not self.for_me(msg.target_system, msg.target_component):
                return
            self._command(self._normalise(msg), now_s)
        elif mid in (MsgId.SET_POSITION_TARGET_LOCAL_NED, MsgId.SET_POSITION_TARGET_GLOBAL_INT):
            if not self.for_me(msg.target_system, msg.target_component):
                return
            self.counters.setpoints_received += 1
            i = self.index
            sp = parse_setpoint(
                msg,
                flavour=self.flavour,
                origin=self.origin,
                home_ned_m=self.frames.home_ned_m[i],
                pos_ned_m=self.frames.pos_ned_m[i],
                yaw_rad=float(self.frames.yaw_rad[i]),
            )
            if self.on_setpoint(sp, now_s):
                self.counters.setpoints_applied += 1
        elif mid == MsgId.REQUEST_DATA_STREAM and self.for_me(
            msg.target_system, msg.target_component
        ):
            self.on_request_data_stream(msg, now_s)
        elif mid in (
            MsgId.PARAM_REQUEST_LIST,
            MsgId.PARAM_REQUEST_READ,
            MsgId.PARAM_SET,
        ) and self.for_me(msg.target_system, msg.target_component):
            self.on_param_message(msg)

    # -- parameters ---------------------------------------------------------------------

    def params(self) -> object:
        """The flavour's live parameter values (a `remarl_fc.sitl.config` dataclass)."""
        raise NotImplementedError

    def set_params(self, values: Any) -> None:
        """Replace the live parameter values (they apply from the next message or tick)."""
        raise NotImplementedError

    def on_param_message(self, msg: Any) -> None:
        """Answer the parameter protocol's three requests with PARAM_VALUE.

        PARAM_REQUEST_LIST → every parameter; PARAM_REQUEST_READ → one; PARAM_SET → set it and
        send its value (the unchanged one, and a STATUSTEXT saying why, if refused). A name the
        flavour does not serve gets no PARAM_VALUE, as on a real vehicle; a PARAM_SET of one
        also gets a STATUSTEXT, so that nobody takes the silence for success.
        """
        table, mid = self.param_table, msg.get_msgId()
        if mid == MsgId.PARAM_REQUEST_LIST:
            for each in range(len(table)):
                self.emit(table.value_message(self.factory, self.params(), each))
            return
        name = param_name(msg.param_id)
        index = int(msg.param_index) if mid == MsgId.PARAM_REQUEST_READ else -1
        k = table.find(name, index)
        if k is None:
            self.counters.params_unknown[name or f"#{index}"] += 1
            if mid == MsgId.PARAM_SET:
                self.say(Severity.WARNING, f"Unknown parameter {name}")
            return
        if mid == MsgId.PARAM_SET:
            try:
                self.set_params(
                    table.set(self.params(), k, float(msg.param_value), int(msg.param_type))
                )
                self.counters.params_set[name] += 1
            except ParamRejected as exc:
                self.counters.params_refused[name] += 1
                self.say(Severity.WARNING, str(exc))
        self.emit(table.value_message(self.factory, self.params(), k))

    def ignore_setpoint(self, reason: str) -> bool:
        """Count a setpoint that changes nothing; returns False."""
        self.counters.setpoints_ignored += 1
        self.counters.ignored_reasons[reason] += 1
        return False

    @staticmethod
    def _normalise(msg: Any) -> Command:
        src = (msg.get_srcSystem(), msg.get_srcComponent())
        if msg.get_msgId() == MsgId.COMMAND_LONG:
            p = (msg.param1, msg.param2, msg.param3, msg.param4, msg.param5, msg.param6)
            return Command(int(msg.command), (*p, msg.param7), None, src)
        p = (msg.param1, msg.param2, msg.param3, msg.param4, float(msg.x), float(msg.y))
        return Command(int(msg.command), (*p, msg.z), int(msg.frame), src)

    def _command(self, cmd: Command, now_s: float) -> None:
        try:
            name = MavCmd(cmd.command).name
        except ValueError:
            name = str(cmd.command)
        self.counters.commands[name] += 1
        handler = self.command_handlers().get(cmd.command)
        if handler is None:
            result, text = int(MavResult.UNSUPPORTED), ""
        else:
            result, text = handler(cmd, now_s)
        self.counters.results[MavResult(result).name] += 1
        self.emit(
            self.factory.command_ack_encode(
                cmd.command, int(result), 0, 0, cmd.source[0], cmd.source[1]
            )
        )
        if text:
            severity = Severity.INFO if result == MavResult.ACCEPTED else Severity.CRITICAL
            self.say(severity, text)

    def say(self, severity: int, text: str) -> None:
        """Send a STATUSTEXT."""
        self.emit(statustext(self.factory, severity, text))

    def command_handlers(
        self,
    ) -> dict[int, Callable[[Command, float], tuple[int, str]]]:
        """MAV_CMD → handler returning (MAV_RESULT, STATUSTEXT or "")."""
        return {
            MavCmd.SET_MESSAGE_INTERVAL: self.cmd_set_message_interval,
            MavCmd.REQUEST_MESSAGE: self.cmd_request_message,
            MavCmd.REQUEST_AUTOPILOT_CAPABILITIES: self.cmd_request_capabilities,
            MavCmd.DO_SET_MODE: self.cmd_set_mode,
            MavCmd.COMPONENT_ARM_DISARM: self.cmd_arm_disarm,
            MavCmd.NAV_TAKEOFF: self.cmd_takeoff,
            MavCmd.NAV_LAND: self.cmd_land,
            MavCmd.NAV_RETURN_TO_LAUNCH: self.cmd_rtl,
        }

    # -- streams ------------------------------------------------------------------------

    supported_streams: ClassVar[frozenset[int]] = frozenset(
        {
            MsgId.SYS_STATUS,
            MsgId.GPS_RAW_INT,
            MsgId.ATTITUDE,
            MsgId.LOCAL_POSITION_NED,
            MsgId.GLOBAL_POSITION_INT,
            MsgId.POSITION_TARGET_LOCAL_NED,
            MsgId.HOME_POSITION,
            MsgId.EXTENDED_SYS_STATE,
        }
    )

    def set_interval(self, msg_id: int, interval_s: float | None, now_s: float) -> None:
        """Stream ``msg_id`` every ``interval_s`` (None: stop)."""
        if interval_s is None:
            self.stream_interval_s.pop(msg_id, None)
            self.stream_due_s.pop(msg_id, None)
            return
        self.stream_interval_s[msg_id] = max(interval_s, 1.0 / MAX_INTERVAL_HZ)
        self.stream_due_s[msg_id] = now_s

    def due_streams(self, now_s: float) -> list[int]:
        """Message ids due now (their next time is advanced)."""
        due = []
        for mid, interval in self.stream_interval_s.items():
            t = self.stream_due_s.get(mid, now_s)
            if now_s + 1e-9 >= t:
                due.append(mid)
                nxt = t + interval
                self.stream_due_s[mid] = nxt if nxt > now_s else now_s + interval
        return due

    def cmd_set_message_interval(self, cmd: Command, now_s: float) -> tuple[int, str]:
        """MAV_CMD_SET_MESSAGE_INTERVAL: p1 message id, p2 µs (−1 off, 0 default)."""
        msg_id, interval_us = int(cmd.params[0]), cmd.params[1]
        if msg_id not in self.supported_streams:
            return MavResult.FAILED, ""
        if interval_us < 0:
            self.set_interval(msg_id, None, now_s)
        elif interval_us == 0:
            default = self.default_streams().get(msg_id)
            self.set_interval(msg_id, default, now_s)
        else:
            self.set_interval(msg_id, interval_us * 1e-6, now_s)
        return MavResult.ACCEPTED, ""

    def cmd_request_message(self, cmd: Command, now_s: float) -> tuple[int, str]:
        """MAV_CMD_REQUEST_MESSAGE: p1 message id, sent once after the ACK."""
        msg_id = int(cmd.params[0])
        if msg_id not in self.supported_streams | {MsgId.AUTOPILOT_VERSION}:
            return MavResult.UNSUPPORTED, ""
        self.requested.append(msg_id)
        return MavResult.ACCEPTED, ""

    def cmd_request_capabilities(self, cmd: Command, now_s: float) -> tuple[int, str]:
        """MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES: AUTOPILOT_VERSION follows the ACK."""
        self.requested.append(MsgId.AUTOPILOT_VERSION)
        return MavResult.ACCEPTED, ""

    def on_request_data_stream(self, msg: Any, now_s: float) -> None:
        """REQUEST_DATA_STREAM (66): not supported unless the flavour says otherwise."""

    # -- flavour rules ------------------------------------------------------------------

    def on_setpoint(self, sp: Setpoint, now_s: float) -> bool:
        """Take a setpoint; True if it now drives the vehicle."""
        raise NotImplementedError

    def cmd_set_mode(self, cmd: Command, now_s: float) -> tuple[int, str]:
        """MAV_CMD_DO_SET_MODE."""
        raise NotImplementedError

    def cmd_arm_disarm(self, cmd: Command, now_s: float) -> tuple[int, str]:
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
            return self.disarm_refusal()
        self.do_disarm()
        return MavResult.ACCEPTED, ""

    def arm_refusal(self, now_s: float) -> tuple[int, str] | None:
        """(result, STATUSTEXT) when the flavour refuses to arm now, else None."""
        raise NotImplementedError

    def after_arm(self) -> None:
        """What arming starts besides spinning the motors (nothing by default)."""

    def disarm_refusal(self) -> tuple[int, str]:
        """(result, STATUSTEXT) for a disarm in flight without force."""
        raise NotImplementedError

    def cmd_takeoff(self, cmd: Command, now_s: float) -> tuple[int, str]:
        """MAV_CMD_NAV_TAKEOFF."""
        raise NotImplementedError

    def cmd_land(self, cmd: Command, now_s: float) -> tuple[int, str]:
        """MAV_CMD_NAV_LAND: switch to the flavour's landing mode."""
        raise NotImplementedError

    def cmd_rtl(self, cmd: Command, now_s: float) -> tuple[int, str]:
        """MAV_CMD_NAV_RETURN_TO_LAUNCH: switch to the flavour's return mode."""
        raise NotImplementedError

    def tick(self, now_s: float) -> None:
        """Run the timers (called at `TICK_HZ`)."""
        if not self.landed:
            self.flew = True
            self._landed_since_s = None
        elif self._landed_since_s is None:
            self._landed_since_s = now_s
        self.status_at(now_s)

    def pilot_mode(self, mode: str, now_s: float) -> bool:
        """The pilot flips the mode switch to ``mode`` (a fault); False if unknown."""
        raise NotImplementedError

    # -- motion helpers -----------------------------------------------------------------

    def do_arm(self, now_s: float) -> None:
        """Arm: motors spin, the vehicle stays on the ground."""
        self.armed = True
        self._armed_at_s = now_s
        if self.landed:
            self.frames.set_idle(self.index)

    def do_disarm(self) -> None:
        """Disarm: motors stop (in the air the vehicle drops to the ground)."""
        self.armed = False
        f, i = self.frames, self.index
        if self.landed:
            f.set_idle(i)
        else:
            self.fly_land(self.cfg.model.max_climb_m_s, self.cfg.model.max_climb_m_s, 0.0)

    def fly_hold(self) -> None:
        """Hold position and heading (on the ground: stay idle)."""
        if self.landed:
            self.frames.set_idle(self.index)
        else:
            self.frames.set_hold(self.index)

    def fly_land(self, fast_m_s: float, slow_m_s: float, slow_below_m: float) -> None:
        """Descend where the vehicle is, slowing to ``slow_m_s`` below ``slow_below_m``."""
        f, i = self.frames, self.index
        f.set_hold(i)
        f.guidance[i] = Guidance.LAND
        f.fast_descent_m_s[i], f.slow_descent_m_s[i] = fast_m_s, slow_m_s
        f.slow_below_m[i] = slow_below_m

    def fly_climb(self, height_m: float, rate_m_s: float) -> None:
        """Climb vertically to ``height_m`` above the ground at ``rate_m_s``."""
        f, i = self.frames, self.index
        f.set_hold(i)
        f.guidance[i] = Guidance.CLIMB
        f.pos_target_ned_m[i, 2] = -height_m
        f.climb_m_s[i] = rate_m_s

    def fly_return(self, alt_m: float, speed_m_s: float, climb_m_s: float) -> None:
        """Climb to ``alt_m`` if lower, fly home at ``speed_m_s``, then the flavour lands."""
        f, i = self.frames, self.index
        f.set_hold(i)
        f.guidance[i] = Guidance.RETURN
        f.return_alt_m[i] = alt_m
        f.speed_limit_m_s[i] = speed_m_s
        f.climb_m_s[i] = climb_m_s

    def climb_done(self) -> bool:
        """A take-off climb is within `CLIMB_DONE_M` of its height."""
        f, i = self.frames, self.index
        return bool(f.pos_ned_m[i, 2] <= f.pos_target_ned_m[i, 2] + CLIMB_DONE_M)

    def finish_climb(self) -> None:
        """Hold at the take-off height (not where the climb happens to be)."""
        f, i = self.frames, self.index
        target = f.pos_target_ned_m[i, 2]
        f.set_hold(i)
        f.hold_ned_m[i, 2] = target

    def home_reached(self) -> bool:
        """A return has arrived over home."""
        f, i = self.frames, self.index
        d = f.home_ned_m[i, :2] - f.pos_ned_m[i, :2]
        return bool(np.hypot(d[0], d[1]) < 1.0 and f.guidance[i] == Guidance.RETURN)

    def fly_setpoint(self, sp: Setpoint, *, default_yaw: YawMode) -> None:
        """Fly a valid setpoint: velocity, position, or both (velocity as feed-forward)."""
        f, i = self.frames, self.index
        if sp.vel_ned_m_s is not None and sp.pos_ned_m is None:
            v = sp.vel_ned_m_s
            f.guidance[i] = Guidance.VELOCITY
            f.vel_target_m_s[i] = np.where(np.isnan(v), 0.0, v)
            if np.isnan(v[2]):  # PX4: vertical axis ignored → hold the height
                f.guidance[i] = Guidance.VELOCITY
        elif sp.pos_ned_m is not None:
            p = sp.pos_ned_m
            f.guidance[i] = Guidance.POSITION
            f.pos_target_ned_m[i] = np.where(np.isnan(p), f.pos_ned_m[i], p)
            f.speed_limit_m_s[i] = self.cfg.model.max_speed_m_s
        else:  # acceleration only: hold the current velocity (feed-forward of 0 m/s²)
            f.guidance[i] = Guidance.VELOCITY
            f.vel_target_m_s[i] = f.vel_ned_m_s[i]
        if sp.yaw_rad is not None:
            f.yaw_mode[i] = YawMode.ANGLE
            f.yaw_target_rad[i] = wrap_yaw(sp.yaw_rad)
        elif sp.yaw_rate_rad_s is not None:
            f.yaw_mode[i] = YawMode.RATE
            f.yaw_rate_target_rad_s[i] = sp.yaw_rate_rad_s
        else:
            f.yaw_mode[i] = default_yaw
            f.yaw_target_rad[i] = f.yaw_rad[i]

    def stop_velocity(self) -> None:
        """Velocity target → 0 and yaw → hold, staying under external control."""
        f, i = self.frames, self.index
        if f.guidance[i] == Guidance.VELOCITY:
            f.vel_target_m_s[i] = 0.0
        if f.yaw_mode[i] in (YawMode.RATE, YawMode.TRAVEL):
            f.yaw_mode[i] = YawMode.HOLD
            f.yaw_target_rad[i] = f.yaw_rad[i]

    def command_frame_ok(self, frame: int | None, allowed: tuple[int, ...]) -> bool:
        """COMMAND_INT frame check (COMMAND_LONG has none)."""
        return frame is None or frame in allowed


def forced(param2: float) -> bool:
    """Whether COMPONENT_ARM_DISARM p2 is the force magic (21196).

    NaN (an unset parameter, as MAVSDK and PX4's own commands send it) is not: ArduPilot
    compares floats and PX4 rounds p2; neither converts NaN to a number.

    >>> forced(21196.0), forced(float("nan")), forced(0.0)
    (True, False, False)
    """
    return abs(param2 - ARM_FORCE_MAGIC) < 0.5

"""ArduCopter 4.x in GUIDED, as the mock imitates it (see `remarl_fc.sitl.autopilot`)."""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any, ClassVar

from remarl_fc.frames import wrap_yaw
from remarl_fc.mavlink.consts import (
    MavAutopilot,
    MavCmd,
    MavFrame,
    MavModeFlag,
    MavResult,
    MavState,
    MsgId,
    Severity,
)
from remarl_fc.sitl.autopilot import (
    Autopilot,
    Command,
)
from remarl_fc.sitl.config import ArduPilotParams
from remarl_fc.sitl.params import ARDUPILOT_PARAMS
from remarl_fc.sitl.setpoints import Setpoint
from remarl_fc.sitl.vehicle import Guidance, YawMode

PILOT_DESCENT_M_S = 2.5
"""Sink rate of an ArduCopter pilot mode with the throttle stick at minimum (no RC), as
measured on ArduCopter SITL."""

REQUEST_DATA_STREAM_GROUPS: dict[int, tuple[int, ...]] = {
    1: (),  # RAW_SENSORS: not modelled
    2: (MsgId.SYS_STATUS, MsgId.GPS_RAW_INT, MsgId.POSITION_TARGET_LOCAL_NED),  # EXTENDED_STATUS
    3: (),  # RC_CHANNELS
    6: (MsgId.GLOBAL_POSITION_INT, MsgId.LOCAL_POSITION_NED),  # POSITION
    10: (MsgId.ATTITUDE,),  # EXTRA1
    11: (),  # EXTRA2 (VFR_HUD): not modelled
    12: (MsgId.EKF_STATUS_REPORT, MsgId.EXTENDED_SYS_STATE),  # EXTRA3
}
"""ArduPilot stream groups (MAV_DATA_STREAM ids → messages), as its SRx_ parameters map them."""


class ArduCopterLogic(Autopilot):
    """ArduCopter 4.x in GUIDED (GCS_MAVLink_Copter.cpp, mode_guided.cpp, AP_Arming).

    Modes modelled: STABILIZE, ALT_HOLD, LOITER, POSHOLD (pilot modes: without RC input they
    descend, as SITL does with the throttle stick at minimum), GUIDED, RTL, LAND, BRAKE.
    Others (AUTO without a mission, ACRO, …) are refused with FAILED and a STATUSTEXT.
    """

    autopilot_id = MavAutopilot.ARDUPILOTMEGA
    flavour = "ardupilot"
    param_table = ARDUPILOT_PARAMS
    PILOT_MODES: ClassVar[frozenset[int]] = frozenset({0, 2, 5, 16})
    POSITION_MODES: ClassVar[frozenset[int]] = frozenset({4, 5, 6, 16, 17})
    ARMABLE: ClassVar[frozenset[int]] = frozenset({0, 2, 4, 5, 16})
    TAKEOFF_MODES: ClassVar[frozenset[int]] = frozenset({2, 4, 5, 16})
    MODELLED: ClassVar[frozenset[int]] = frozenset({0, 2, 4, 5, 6, 9, 16, 17})
    INITIAL_MODE: ClassVar[int] = 0  # STABILIZE
    supported_streams = Autopilot.supported_streams | {MsgId.EKF_STATUS_REPORT}

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.p = self.cfg.ardupilot
        self.custom_mode = self.INITIAL_MODE
        self.pilot_holding = False
        self.takeoff_active = False

    def params(self) -> ArduPilotParams:
        """The live ArduCopter parameters."""
        return self.p

    def set_params(self, values: ArduPilotParams) -> None:
        """Replace the live ArduCopter parameters."""
        self.p = values

    def boot_s(self) -> float:
        """ArduCopter boot time (`ArduPilotParams.boot_s`)."""
        return self.p.boot_s

    def position_estimate_s(self) -> float:
        """Time to an EKF origin (`ArduPilotParams.position_estimate_s`)."""
        return self.p.position_estimate_s

    def default_streams(self) -> dict[int, float]:
        """Nothing but HEARTBEAT until asked: ArduCopter's stream rates default to 0."""
        return {}

    def mode_flags(self) -> MavModeFlag:
        """CUSTOM_MODE_ENABLED | STABILIZE | MANUAL_INPUT, + GUIDED in position modes."""
        mode = MavModeFlag.CUSTOM_MODE_ENABLED | MavModeFlag.STABILIZE_ENABLED
        mode |= MavModeFlag.MANUAL_INPUT_ENABLED
        if self.custom_mode in self.POSITION_MODES:
            mode |= MavModeFlag.GUIDED_ENABLED
        return mode

    def resting_status(self) -> int:
        """STANDBY on the ground, ACTIVE in the air."""
        return MavState.STANDBY if self.landed else MavState.ACTIVE

    def under_external_control(self) -> bool:
        """GUIDED."""
        return self.custom_mode == 4

    def on_request_data_stream(self, msg: Any, now_s: float) -> None:
        """REQUEST_DATA_STREAM: set every message of the group(s) to req_message_rate Hz."""
        stream, rate, start = int(msg.req_stream_id), int(msg.req_message_rate), msg.start_stop
        groups = REQUEST_DATA_STREAM_GROUPS.keys() if stream == 0 else [stream]
        for g in groups:
            for mid in REQUEST_DATA_STREAM_GROUPS.get(g, ()):
                if start and rate > 0:
                    self.set_interval(mid, 1.0 / rate, now_s)
                else:
                    self.set_interval(mid, None, now_s)

    def command_handlers(self) -> dict[int, Callable[[Command, float], tuple[int, str]]]:
        """Shared commands + CONDITION_YAW and DO_CHANGE_SPEED."""
        handlers = super().command_handlers()
        handlers[MavCmd.CONDITION_YAW] = self.cmd_condition_yaw
        handlers[MavCmd.DO_CHANGE_SPEED] = self.cmd_change_speed
        return handlers

    def _enter(self, mode: int, now_s: float) -> tuple[int, str]:
        if mode not in self.MODELLED:
            name = _copter_name(mode)
            return MavResult.FAILED, f"Mode change to {name} failed: not in this mock"
        if mode in self.POSITION_MODES and not self.position_ok(now_s):
            return (
                MavResult.FAILED,
                f"Mode change to {_copter_name(mode)} failed: requires position",
            )
        self.custom_mode = mode
        self.pilot_holding = False
        self.takeoff_active = False
        self._apply_mode()
        return MavResult.ACCEPTED, ""

    def _apply_mode(self) -> None:
        mode, p = self.custom_mode, self.p
        if mode == 9:  # LAND
            self.fly_land(p.wpnav_speed_dn_m_s, p.land_speed_m_s, p.land_alt_low_m)
        elif mode == 6:  # RTL
            if self.landed:
                self.fly_hold()
            else:
                self.fly_return(p.rtl_alt_m, p.rtl_speed_m_s, p.wpnav_speed_up_m_s)
        elif mode in self.PILOT_MODES and not self.pilot_holding and not self.landed:
            self.fly_land(PILOT_DESCENT_M_S, PILOT_DESCENT_M_S, 0.0)
        else:  # GUIDED, BRAKE, a pilot holding the sticks: stop and hold
            self.fly_hold()

    def cmd_set_mode(self, cmd: Command, now_s: float) -> tuple[int, str]:
        """p1 must have CUSTOM_MODE_ENABLED, p2 = mode number; refusals → FAILED."""
        if not int(cmd.params[0]) & MavModeFlag.CUSTOM_MODE_ENABLED:
            return MavResult.FAILED, ""
        mode = int(cmd.params[1])
        if self.booting(now_s):  # accepted, then overwritten by the initial mode at boot end
            self.custom_mode = mode
            return MavResult.ACCEPTED, ""
        return self._enter(mode, now_s)

    def arm_refusal(self, now_s: float) -> tuple[int, str] | None:
        """Arm in STABILIZE/ALT_HOLD/LOITER/POSHOLD/GUIDED once the EKF has a position."""
        if self.booting(now_s) or not self.position_ok(now_s):
            return MavResult.FAILED, "PreArm: Need Position Estimate"
        if self.custom_mode not in self.ARMABLE:
            return MavResult.FAILED, "Arm: Mode not armable"
        return None

    def disarm_refusal(self) -> tuple[int, str]:
        """Disarming in flight needs force."""
        return MavResult.FAILED, "Disarm: vehicle is flying (force to override)"

    def cmd_takeoff(self, cmd: Command, now_s: float) -> tuple[int, str]:
        """p7 = height above home, m; armed, landed, take-off mode; COMMAND_INT frame 3."""
        if not self.command_frame_ok(cmd.frame, (MavFrame.GLOBAL_RELATIVE_ALT,)):
            return MavResult.DENIED, ""
        height = cmd.params[6]
        if not self.armed or not self.landed or self.custom_mode not in self.TAKEOFF_MODES:
            return MavResult.FAILED, ""
        if not math.isfinite(height) or height <= 0.0:
            return MavResult.FAILED, ""
        self.takeoff_active = True
        self.fly_climb(height, self.p.wpnav_speed_up_m_s)
        return MavResult.ACCEPTED, ""

    def cmd_land(self, cmd: Command, now_s: float) -> tuple[int, str]:
        """→ LAND (9)."""
        return self._enter(9, now_s)

    def cmd_rtl(self, cmd: Command, now_s: float) -> tuple[int, str]:
        """→ RTL (6)."""
        return self._enter(6, now_s)

    def cmd_condition_yaw(self, cmd: Command, now_s: float) -> tuple[int, str]:
        """p1 angle 0–360°, p2 rate °/s, p3 direction −1/0/1, p4 0 absolute / 1 relative."""
        angle, _rate, direction, relative = cmd.params[:4]
        if not 0.0 <= angle <= 360.0 or not -1.0 <= direction <= 1.0 or self.landed:
            return MavResult.FAILED, ""
        f, i = self.frames, self.index
        base = float(f.yaw_rad[i]) if relative else 0.0
        sign = -1.0 if relative and direction < 0 else 1.0
        f.yaw_mode[i] = YawMode.ANGLE
        f.yaw_target_rad[i] = wrap_yaw(base + sign * math.radians(angle))
        return MavResult.ACCEPTED, ""

    def cmd_change_speed(self, cmd: Command, now_s: float) -> tuple[int, str]:
        """p2 speed m/s (> 0) for position targets."""
        if not cmd.params[1] > 0:
            return MavResult.DENIED, ""
        self.frames.speed_limit_m_s[self.index] = cmd.params[1]
        return MavResult.ACCEPTED, ""

    def on_setpoint(self, sp: Setpoint, now_s: float) -> bool:
        """GUIDED only; invalid → stop and hold; on the ground nothing moves."""
        if self.custom_mode != 4:
            return self.ignore_setpoint("not in GUIDED")
        if not sp.valid:
            if not self.landed:
                self.fly_hold()
            self.setpoint = None
            return self.ignore_setpoint(f"invalid: {sp.reason}")
        if sp.has_accel and sp.vel_ned_m_s is None and sp.pos_ned_m is None:
            return self.ignore_setpoint("acceleration-only targets are not modelled")
        self.last_setpoint_s = now_s
        self.setpoint = sp
        if not self.armed or (self.landed and not self.takeoff_active):
            return self.ignore_setpoint("on the ground")
        self.takeoff_active = False
        self.fly_setpoint(sp, default_yaw=YawMode.TRAVEL)
        return True

    def tick(self, now_s: float) -> None:
        """Boot, GUID_TIMEOUT, take-off end, landing, RTL phases, DISARM_DELAY."""
        f, i, p = self.frames, self.index, self.p
        if not self.booting(now_s) and self._boot_pending:
            self._boot_pending = False
            self.custom_mode = self.INITIAL_MODE  # overwrites a mode set during boot
        timed_out = now_s - self.last_setpoint_s > p.guid_timeout_s
        if self.custom_mode == 4 and timed_out and f.guidance[i] == Guidance.VELOCITY:
            self.stop_velocity()  # GUID_TIMEOUT: stop, stay in GUIDED
        if self.takeoff_active and f.guidance[i] == Guidance.CLIMB and self.climb_done():
            self.takeoff_active = False
            if self.custom_mode in self.PILOT_MODES and not self.pilot_holding:
                self._apply_mode()
            else:
                self.finish_climb()
        if self.custom_mode == 6 and self.home_reached():
            self.fly_land(p.wpnav_speed_dn_m_s, p.land_speed_m_s, p.land_alt_low_m)
        was_flying = self.flew and self._landed_since_s is None
        super().tick(now_s)
        if self.armed and self.landed and f.guidance[i] != Guidance.CLIMB:
            if was_flying and self.custom_mode in (6, 9):
                self.do_disarm()  # LAND and RTL disarm on touch-down
            elif was_flying:
                f.set_idle(i)
            landed_at = self._landed_since_s if self._landed_since_s is not None else now_s
            since = max(self._armed_at_s, landed_at)
            if self.armed and 0 < p.disarm_delay_s <= now_s - since:
                self.do_disarm()
                self.say(Severity.INFO, "Disarming motors")

    _boot_pending = True

    def pilot_mode(self, mode: str, now_s: float) -> bool:
        """The pilot selects ``mode`` (a COPTER_MODE name) and holds the sticks centred."""
        try:
            number = _COPTER_BY_NAME[mode.upper()]
        except KeyError:
            return False
        self.custom_mode = number
        self.pilot_holding = True
        self.takeoff_active = False
        self._apply_mode()
        return True


def _copter_name(mode: int) -> str:
    for name, number in _COPTER_BY_NAME.items():
        if number == mode:
            return name
    return str(mode)


_COPTER_BY_NAME = {
    "STABILIZE": 0,
    "ACRO": 1,
    "ALT_HOLD": 2,
    "AUTO": 3,
    "GUIDED": 4,
    "LOITER": 5,
    "RTL": 6,
    "CIRCLE": 7,
    "LAND": 9,
    "POSHOLD": 16,
    "BRAKE": 17,
}

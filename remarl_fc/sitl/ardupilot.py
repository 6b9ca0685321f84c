"""ArduCopter 4.x in GUIDED, as the mock imitates it (see `remarl_fc.sitl.autopilot`)."""

from __future__ import annotations

import math
from typing import Any

from remarl_fc.mavlink.consts import (
    CopterMode,
    MavAutopilot,
    MavCmd,
    MavFrame,
    MavModeFlag,
    MavResult,
    MavState,
    MsgId,
    Severity,
)
from remarl_fc.sitl.autopilot import Autopilot
from remarl_fc.sitl.commands import Command, Handler
from remarl_fc.sitl.config import ArduPilotParams
from remarl_fc.sitl.flavour import FlavourSpec, ModeRules, Result
from remarl_fc.sitl.params import ARDUPILOT_PARAMS
from remarl_fc.sitl.setpoints import Setpoint
from remarl_fc.sitl.streams import SUPPORTED_STREAMS
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

_FLAGS = MavModeFlag.STABILIZE_ENABLED | MavModeFlag.MANUAL_INPUT_ENABLED
"""base_mode bits of every ArduCopter mode; position modes add GUIDED_ENABLED."""
_POSITION_FLAGS = _FLAGS | MavModeFlag.GUIDED_ENABLED

COPTER_MODES: dict[int, ModeRules] = {
    CopterMode.STABILIZE: ModeRules(_FLAGS, pilot_descends=True),
    CopterMode.ALT_HOLD: ModeRules(_FLAGS, takeoff=True, pilot_descends=True),
    CopterMode.GUIDED: ModeRules(
        _POSITION_FLAGS, needs_position=True, external_control=True, takeoff=True
    ),
    CopterMode.LOITER: ModeRules(
        _POSITION_FLAGS, needs_position=True, takeoff=True, pilot_descends=True
    ),
    CopterMode.RTL: ModeRules(_POSITION_FLAGS, needs_position=True, armable=False),
    CopterMode.LAND: ModeRules(_FLAGS, armable=False),
    CopterMode.POSHOLD: ModeRules(
        _POSITION_FLAGS, needs_position=True, takeoff=True, pilot_descends=True
    ),
    CopterMode.BRAKE: ModeRules(_POSITION_FLAGS, needs_position=True, armable=False),
}
"""The ArduCopter modes the mock models (mode.h: requires_GPS, allows_arming,
has_user_takeoff); others are refused by DO_SET_MODE."""

UNMODELLED = ModeRules(_FLAGS, armable=False)
"""A mode outside `COPTER_MODES` (entered during boot, or by the pilot): it holds."""

PILOT_MODE_NAMES = {
    name: int(CopterMode[name])
    for name in (
        "STABILIZE",
        "ACRO",
        "ALT_HOLD",
        "AUTO",
        "GUIDED",
        "LOITER",
        "RTL",
        "CIRCLE",
        "LAND",
        "POSHOLD",
        "BRAKE",
    )
}
"""The COPTER_MODE names a pilot can select and STATUSTEXTs name (others by number)."""

ARDUCOPTER = FlavourSpec[ArduPilotParams](
    name="ardupilot",
    autopilot_id=MavAutopilot.ARDUPILOTMEGA,
    flight_sw_version=(4 << 24) | (6 << 16) | (0 << 8) | 255,  # 4.6.0, release type 255
    config_params=lambda cfg: cfg.ardupilot,
    param_table=ARDUPILOT_PARAMS,
    default_streams={},  # nothing but HEARTBEAT until asked: the stream rates default to 0
    supported_streams=SUPPORTED_STREAMS | {MsgId.EKF_STATUS_REPORT},
    data_stream_groups=REQUEST_DATA_STREAM_GROUPS,
    unsigned_allowed=frozenset({MsgId.RADIO_STATUS, MsgId.RADIO}),  # GCS_Signing.cpp
    initial_mode=int(CopterMode.STABILIZE),
    land_mode=int(CopterMode.LAND),
    rtl_mode=int(CopterMode.RTL),
    vehicle_profile="arducopter",
    pilot_modes=PILOT_MODE_NAMES,
    set_mode_not_custom=MavResult.FAILED,
    arm_without_position=(MavResult.FAILED, "PreArm: Need Position Estimate"),
    disarm_in_flight=(MavResult.FAILED, "Disarm: vehicle is flying (force to override)"),
)
"""ArduCopter 4.6's values."""


def copter_mode_name(mode: int) -> str:
    """The COPTER_MODE name of ``mode`` as STATUSTEXTs give it, else its number.

    >>> copter_mode_name(4), copter_mode_name(20)
    ('GUIDED', '20')
    """
    for name, number in PILOT_MODE_NAMES.items():
        if number == mode:
            return name
    return str(mode)


class ArduCopterLogic(Autopilot[ArduPilotParams]):
    """ArduCopter 4.x in GUIDED (GCS_MAVLink_Copter.cpp, mode_guided.cpp, AP_Arming).

    Modes modelled: STABILIZE, ALT_HOLD, LOITER, POSHOLD (pilot modes: without RC input they
    descend, as SITL does with the throttle stick at minimum), GUIDED, RTL, LAND, BRAKE.
    Others (AUTO without a mission, ACRO, …) are refused with FAILED and a STATUSTEXT.
    """

    spec = ARDUCOPTER

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.pilot_holding = False
        self.takeoff_active = False
        self._boot_pending = True  # a mode set during boot is overwritten when it ends
        self._climb_at_s: float | None = None  # a take-off's climb waits for this time
        self._climb_height_m = 0.0

    def mode_rules(self) -> ModeRules:
        """The row of `COPTER_MODES` (`UNMODELLED` for a mode outside it)."""
        return COPTER_MODES.get(self.custom_mode, UNMODELLED)

    def resting_status(self) -> MavState:
        """STANDBY on the ground, ACTIVE in the air."""
        return MavState.STANDBY if self.landed else MavState.ACTIVE

    def command_handlers(self) -> dict[int, Handler]:
        """Shared commands + CONDITION_YAW and DO_CHANGE_SPEED."""
        handlers = super().command_handlers()
        handlers[MavCmd.CONDITION_YAW] = self.cmd_condition_yaw
        handlers[MavCmd.DO_CHANGE_SPEED] = self.cmd_change_speed
        return handlers

    def request_mode(self, cmd: Command, now_s: float) -> Result:
        """p2 = mode number; during boot accepted, then overwritten by the initial mode."""
        mode = cmd.int_param(1)
        if self.booting(now_s):
            self.custom_mode = mode
            return MavResult.ACCEPTED, ""
        return self.enter_mode(mode, now_s)

    def enter_mode(self, mode: int, now_s: float) -> Result:
        """A modelled mode, with a position where it needs one; refusals → FAILED."""
        rules = COPTER_MODES.get(mode)
        if rules is None:
            name = copter_mode_name(mode)
            return MavResult.FAILED, f"Mode change to {name} failed: not in this mock"
        if rules.needs_position and not self.position_ok(now_s):
            return (
                MavResult.FAILED,
                f"Mode change to {copter_mode_name(mode)} failed: requires position",
            )
        self.custom_mode = mode
        self.pilot_holding = False
        self._end_takeoff()
        self._apply_mode()
        return MavResult.ACCEPTED, ""

    def take_pilot_mode(self, mode: int) -> None:
        """The pilot selects ``mode`` and holds the sticks centred."""
        self.custom_mode = mode
        self.pilot_holding = True
        self._end_takeoff()
        self._apply_mode()

    def _end_takeoff(self) -> None:
        """No take-off under way any more (a pending climb is dropped)."""
        self.takeoff_active = False
        self._climb_at_s = None

    def climb_pending(self) -> bool:
        """A take-off was accepted and its climb has not started yet (`takeoff_delay_s`)."""
        return self._climb_at_s is not None

    def _apply_mode(self) -> None:
        mode, p, motion = self.custom_mode, self.p, self.motion
        if mode == CopterMode.LAND:
            motion.land(p.wpnav_speed_dn_m_s, p.land_speed_m_s, p.land_alt_low_m)
        elif mode == CopterMode.RTL:
            if self.landed:
                motion.hold()
            else:
                motion.return_home(p.rtl_alt_m, p.rtl_speed_m_s, p.wpnav_speed_up_m_s)
        elif self.mode_rules().pilot_descends and not self.pilot_holding and not self.landed:
            motion.land(PILOT_DESCENT_M_S, PILOT_DESCENT_M_S, 0.0)
        else:  # GUIDED, BRAKE, a pilot holding the sticks: stop and hold
            motion.hold()

    def mode_arm_refusal(self, now_s: float) -> Result | None:
        """Arm in STABILIZE/ALT_HOLD/LOITER/POSHOLD/GUIDED only."""
        if not self.mode_rules().armable:
            return MavResult.FAILED, "Arm: Mode not armable"
        return None

    def cmd_takeoff(self, cmd: Command, now_s: float) -> Result:
        """p7 = height above home, m; armed, landed, take-off mode; COMMAND_INT frame 3.

        The climb starts `ArduPilotParams.takeoff_delay_s` after the ACK (spool-up and
        throttle ramp on ArduCopter; the vehicle stays on the ground meanwhile). A repeat
        while the climb is pending is ACCEPTED and changes nothing (a client's retry).
        """
        if not cmd.frame_in((MavFrame.GLOBAL_RELATIVE_ALT,)):
            return MavResult.DENIED, ""
        height = cmd.params[6]
        if not self.armed or not self.landed or not self.mode_rules().takeoff:
            return MavResult.FAILED, ""
        if not math.isfinite(height) or height <= 0.0:
            return MavResult.FAILED, ""
        if self.climb_pending():
            return MavResult.ACCEPTED, ""
        self.takeoff_active = True
        self._climb_height_m = height
        self._climb_at_s = now_s + self.p.takeoff_delay_s
        if self.p.takeoff_delay_s <= 0.0:
            self._start_climb()
        return MavResult.ACCEPTED, ""

    def _start_climb(self) -> None:
        self._climb_at_s = None
        self.motion.climb(self._climb_height_m, self.p.wpnav_speed_up_m_s)

    def cmd_condition_yaw(self, cmd: Command, now_s: float) -> Result:
        """p1 angle 0–360°, p2 rate °/s, p3 direction −1/0/1, p4 0 absolute / 1 relative."""
        angle, _rate, direction, relative = cmd.params[:4]
        if not 0.0 <= angle <= 360.0 or not -1.0 <= direction <= 1.0 or self.landed:
            return MavResult.FAILED, ""
        base = self.motion.yaw_rad() if relative else 0.0
        sign = -1.0 if relative and direction < 0 else 1.0
        self.motion.set_yaw(base + sign * math.radians(angle))
        return MavResult.ACCEPTED, ""

    def cmd_change_speed(self, cmd: Command, now_s: float) -> Result:
        """p2 speed m/s (> 0) for position targets."""
        if not cmd.params[1] > 0:
            return MavResult.DENIED, ""
        self.motion.set_speed(cmd.params[1])
        return MavResult.ACCEPTED, ""

    def on_setpoint(self, sp: Setpoint, now_s: float) -> bool:
        """GUIDED only; invalid → stop and hold; on the ground nothing moves."""
        if not self.under_external_control():
            return self.ignore_setpoint("not in GUIDED")
        if not sp.valid:
            if not self.landed:
                self.motion.hold()
            self.setpoint = None
            return self.ignore_setpoint(f"invalid: {sp.reason}")
        if sp.has_accel and sp.vel_ned_m_s is None and sp.pos_ned_m is None:
            return self.ignore_setpoint("acceleration-only targets are not modelled")
        self.last_setpoint_s = now_s
        self.setpoint = sp
        on_ground = self.landed and (not self.takeoff_active or self.climb_pending())
        if not self.armed or on_ground:
            return self.ignore_setpoint("on the ground")
        self.takeoff_active = False
        self.motion.fly(sp, default_yaw=YawMode.TRAVEL)
        return True

    def mode_timers(self, now_s: float) -> None:
        """Boot end, GUID_TIMEOUT, take-off start and end, RTL's landing."""
        p, motion = self.p, self.motion
        if not self.booting(now_s) and self._boot_pending:
            self._boot_pending = False
            self.custom_mode = self.spec.initial_mode  # overwrites a mode set during boot
        if self._climb_at_s is not None and now_s >= self._climb_at_s:
            if self.armed and self.landed and self.takeoff_active:
                self._start_climb()
            else:
                self._end_takeoff()
        timed_out = now_s - self.last_setpoint_s > p.guid_timeout_s
        if self.under_external_control() and timed_out and motion.guidance == Guidance.VELOCITY:
            motion.stop_velocity()  # GUID_TIMEOUT: stop, stay in GUIDED
        if self.takeoff_active and motion.guidance == Guidance.CLIMB and motion.climb_done():
            self.takeoff_active = False
            if self.mode_rules().pilot_descends and not self.pilot_holding:
                self._apply_mode()
            else:
                motion.finish_climb()
        if self.custom_mode == CopterMode.RTL and motion.home_reached():
            motion.land(p.wpnav_speed_dn_m_s, p.land_speed_m_s, p.land_alt_low_m)

    def ground_timers(self, now_s: float, was_flying: bool) -> None:
        """LAND and RTL disarm at touch-down; DISARM_DELAY after landing or arming."""
        if not self.armed_on_ground():
            return
        if was_flying and self.custom_mode in (CopterMode.RTL, CopterMode.LAND):
            self.do_disarm()
        elif was_flying:
            self.motion.idle()
        landed_at = self._landed_since_s if self._landed_since_s is not None else now_s
        since = max(self._armed_at_s, landed_at)
        if self.armed and 0 < self.p.disarm_delay_s <= now_s - since:
            self.do_disarm()
            self.say(Severity.INFO, "Disarming motors")

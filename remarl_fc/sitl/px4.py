"""PX4 v1.14+ multicopter, as the mock imitates it (see `remarl_fc.sitl.autopilot`)."""

from __future__ import annotations

import math
from typing import Any

from remarl_fc.mavlink.consts import (
    MavAutopilot,
    MavModeFlag,
    MavResult,
    MavState,
    MsgId,
    Px4AutoSubMode,
    Px4MainMode,
    Severity,
    px4_custom_mode,
    px4_mode_parts,
)
from remarl_fc.sitl.autopilot import Autopilot
from remarl_fc.sitl.commands import Command
from remarl_fc.sitl.config import Px4Params
from remarl_fc.sitl.flavour import FlavourSpec, ModeRules, Result
from remarl_fc.sitl.params import PX4_PARAMS
from remarl_fc.sitl.setpoints import Setpoint
from remarl_fc.sitl.streams import SUPPORTED_STREAMS
from remarl_fc.sitl.vehicle import Guidance, YawMode

POSCTL = px4_custom_mode(Px4MainMode.POSCTL)
OFFBOARD = px4_custom_mode(Px4MainMode.OFFBOARD)
TAKEOFF = px4_custom_mode(Px4MainMode.AUTO, Px4AutoSubMode.TAKEOFF)
HOLD = px4_custom_mode(Px4MainMode.AUTO, Px4AutoSubMode.LOITER)
RTL = px4_custom_mode(Px4MainMode.AUTO, Px4AutoSubMode.RTL)
LAND = px4_custom_mode(Px4MainMode.AUTO, Px4AutoSubMode.LAND)

_MANUAL = MavModeFlag.MANUAL_INPUT_ENABLED
_STABILIZED = _MANUAL | MavModeFlag.STABILIZE_ENABLED
_GUIDED = _STABILIZED | MavModeFlag.GUIDED_ENABLED
_AUTO = _GUIDED | MavModeFlag.AUTO_ENABLED

PX4_MODES: dict[int, ModeRules] = {
    Px4MainMode.MANUAL: ModeRules(_MANUAL),
    Px4MainMode.ALTCTL: ModeRules(_STABILIZED),
    Px4MainMode.POSCTL: ModeRules(_GUIDED, needs_position=True),
    Px4MainMode.AUTO: ModeRules(_AUTO, needs_position=True),
    Px4MainMode.OFFBOARD: ModeRules(_AUTO, needs_position=True, external_control=True),
    Px4MainMode.STABILIZED: ModeRules(_STABILIZED),
}
"""The PX4 main modes the mock models, with the base_mode bits PX4's HEARTBEAT carries in
each and whether Commander needs a global position to enter it; others are refused."""

AUTO_SUB_MODES = frozenset(
    {Px4AutoSubMode.TAKEOFF, Px4AutoSubMode.LOITER, Px4AutoSubMode.RTL, Px4AutoSubMode.LAND}
)
"""The AUTO sub-modes the mock models (not MISSION, READY)."""

OFFBOARD_LOSS_ACTIONS = {"position": POSCTL, "hold": HOLD, "return": RTL, "land": LAND}
"""COM_OBL_RC_ACT (`Px4Params.com_obl_rc_act`) → the mode it switches to."""

PX4 = FlavourSpec[Px4Params](
    name="px4",
    autopilot_id=MavAutopilot.PX4,
    flight_sw_version=0x010F00FF,  # 1.15.0, release type 255
    config_params=lambda cfg: cfg.px4,
    param_table=PX4_PARAMS,
    default_streams={  # PX4's default stream set for a GCS/offboard link (approximated)
        MsgId.SYS_STATUS: 1.0,
        MsgId.EXTENDED_SYS_STATE: 1.0,
        MsgId.ATTITUDE: 1 / 20,
        MsgId.GLOBAL_POSITION_INT: 1 / 10,
        MsgId.LOCAL_POSITION_NED: 1 / 10,
        MsgId.GPS_RAW_INT: 1.0,
        MsgId.HOME_POSITION: 2.0,
        MsgId.POSITION_TARGET_LOCAL_NED: 1 / 5,
    },
    supported_streams=SUPPORTED_STREAMS,
    data_stream_groups={},  # REQUEST_DATA_STREAM is not supported
    unsigned_allowed=frozenset(  # the PX4 docs' list
        {MsgId.HEARTBEAT, MsgId.RADIO_STATUS, MsgId.ADSB_VEHICLE, MsgId.COLLISION}
    ),
    initial_mode=POSCTL,
    land_mode=LAND,
    rtl_mode=RTL,
    vehicle_profile="px4",
    pilot_modes={
        "POSCTL": POSCTL,
        "ALTCTL": px4_custom_mode(Px4MainMode.ALTCTL),
        "MANUAL": px4_custom_mode(Px4MainMode.MANUAL),
        "STABILIZED": px4_custom_mode(Px4MainMode.STABILIZED),
        "HOLD": HOLD,
        "LOITER": HOLD,
        "RTL": RTL,
        "LAND": LAND,
    },
    set_mode_not_custom=MavResult.DENIED,
    arm_without_position=(MavResult.TEMPORARILY_REJECTED, "Arming denied: no global position"),
    disarm_in_flight=(MavResult.TEMPORARILY_REJECTED, "Disarming denied: not landed"),
)
"""PX4 1.15's values."""


class Px4Logic(Autopilot[Px4Params]):
    """PX4 v1.14+ multicopter (Commander, mavlink_receiver, the offboard and takeoff docs).

    Modes modelled: MANUAL, ALTCTL, POSCTL, STABILIZED (hold without RC), OFFBOARD, and AUTO
    TAKEOFF, LOITER (Hold), RTL, LAND. Refused transitions → TEMPORARILY_REJECTED. The mode
    is ``custom_mode``: the main mode in bits 16–23, the sub-mode in bits 24–31.
    """

    spec = PX4

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.failsafe_since_s: float | None = None

    @property
    def main(self) -> int:
        """The main mode (`Px4MainMode`)."""
        return px4_mode_parts(self.custom_mode)[0]

    @property
    def sub(self) -> int:
        """The sub-mode (`Px4AutoSubMode` in AUTO)."""
        return px4_mode_parts(self.custom_mode)[1]

    def mode_rules(self) -> ModeRules:
        """The row of `PX4_MODES` of the main mode."""
        return PX4_MODES[self.main]

    def resting_status(self) -> MavState:
        """STANDBY disarmed, ACTIVE armed."""
        return MavState.ACTIVE if self.armed else MavState.STANDBY

    def stream_alive(self, now_s: float) -> bool:
        """A setpoint arrived within COM_OF_LOSS_T."""
        return now_s - self.last_setpoint_s <= self.p.com_of_loss_t_s

    def _switch(self, mode: int) -> None:
        """Into custom_mode ``mode`` and what it flies (no checks)."""
        self.custom_mode = mode
        p, motion = self.p, self.motion
        if mode == LAND:
            motion.land(p.mpc_land_speed_m_s, p.mpc_land_speed_m_s, 0.0)
        elif mode == RTL:
            if self.landed:
                motion.hold()
            else:
                motion.return_home(p.rtl_return_alt_m, p.rtl_speed_m_s, p.mpc_tko_speed_m_s)
        elif mode == TAKEOFF:
            if self.armed and self.landed:
                motion.climb(p.mis_takeoff_alt_m, p.mpc_tko_speed_m_s)
        elif self.under_external_control() and self.setpoint is not None and self.setpoint.valid:
            self._fly_offboard(self.setpoint)
        else:
            motion.hold()

    def _fly_offboard(self, sp: Setpoint) -> None:
        if not self.armed:
            return
        climbing = sp.vel_ned_m_s is not None and (sp.vel_ned_m_s[2] < 0)
        going_up = (
            sp.pos_ned_m is not None and sp.pos_ned_m[2] < self.frames.pos_ned_m[self.index, 2]
        )
        if self.landed and not (climbing or going_up):
            return
        self.motion.fly(sp, default_yaw=YawMode.HOLD)

    def request_mode(self, cmd: Command, now_s: float) -> Result:
        """p2 = main mode, p3 = sub mode, each cast to uint8 as PX4 does."""
        main, sub = cmd.int_param(1) & 0xFF, cmd.int_param(2) & 0xFF
        return self.enter_mode(px4_custom_mode(main, sub), now_s)

    def enter_mode(self, mode: int, now_s: float) -> Result:
        """A modelled mode, with a position where it needs one and OFFBOARD with a stream."""
        main, sub = px4_mode_parts(mode)
        if main == 0:  # a packed word in p2 truncates to 0: accepted, nothing changes
            return MavResult.ACCEPTED, ""
        rules = PX4_MODES.get(main)
        if rules is None or (main == Px4MainMode.AUTO and sub not in AUTO_SUB_MODES):
            return MavResult.TEMPORARILY_REJECTED, "Mode not available in this mock"
        if rules.needs_position and not self.position_ok(now_s):
            return MavResult.TEMPORARILY_REJECTED, "Mode requires a global position"
        if rules.external_control and not self.stream_alive(now_s):
            return MavResult.TEMPORARILY_REJECTED, "Switching to Offboard is not available"
        self.failsafe, self.failsafe_since_s = False, None
        self._switch(mode)
        return MavResult.ACCEPTED, ""

    def take_pilot_mode(self, mode: int) -> None:
        """The pilot's switch ends any failsafe."""
        self.failsafe, self.failsafe_since_s = False, None
        self._switch(mode)

    def mode_arm_refusal(self, now_s: float) -> Result | None:
        """In OFFBOARD, arming needs the setpoint stream."""
        if self.under_external_control() and not self.stream_alive(now_s):
            return MavResult.TEMPORARILY_REJECTED, "Arming denied: offboard signal lost"
        return None

    def after_arm(self) -> None:
        """Armed in AUTO.TAKEOFF: climb; in OFFBOARD: fly the latest setpoint."""
        if self.custom_mode == TAKEOFF:
            self._switch(TAKEOFF)
        elif self.under_external_control() and self.setpoint is not None:
            self._fly_offboard(self.setpoint)

    def cmd_takeoff(self, cmd: Command, now_s: float) -> Result:
        """Switch to AUTO.TAKEOFF; p7 AMSL altitude if finite, else MIS_TAKEOFF_ALT."""
        result, text = self.enter_mode(TAKEOFF, now_s)
        if result == MavResult.ACCEPTED and self.armed and self.landed:
            alt = cmd.params[6]
            if math.isfinite(alt):
                height = alt - (self.origin.alt_m - float(self.frames.home_ned_m[self.index, 2]))
                self.motion.climb(max(height, 1.0), self.p.mpc_tko_speed_m_s)
        return result, text

    def on_setpoint(self, sp: Setpoint, now_s: float) -> bool:
        """Any mode keeps the stream alive; only OFFBOARD flies it."""
        if not sp.valid:
            return self.ignore_setpoint(f"invalid: {sp.reason}")
        self.last_setpoint_s = now_s
        self.setpoint = sp
        if not self.under_external_control():
            return self.ignore_setpoint("not in OFFBOARD (kept as proof of life)")
        if not self.armed:
            return self.ignore_setpoint("disarmed")
        self._fly_offboard(sp)
        return True

    def mode_timers(self, now_s: float) -> None:
        """COM_OF_LOSS_T, COM_FAIL_ACT_T, take-off end, RTL's landing."""
        p, motion = self.p, self.motion
        if self.under_external_control() and not self.stream_alive(now_s):
            self.failsafe, self.failsafe_since_s = True, now_s
            self._switch(HOLD)  # Hold first ...
        if (
            self.failsafe_since_s is not None
            and now_s - self.failsafe_since_s >= p.com_fail_act_t_s
        ):
            action = OFFBOARD_LOSS_ACTIONS[p.com_obl_rc_act]  # ... then the action
            self.failsafe_since_s = None
            self._switch(action)
        taking_off = self.custom_mode == TAKEOFF and not self.landed
        if taking_off and motion.guidance == Guidance.CLIMB and motion.climb_done():
            self._switch(HOLD)
            motion.finish_climb()
        if self.custom_mode == RTL and motion.home_reached():
            motion.land(p.mpc_land_speed_m_s, p.mpc_land_speed_m_s, 0.0)

    def ground_timers(self, now_s: float, was_flying: bool) -> None:
        """COM_DISARM_LAND after a landing, COM_DISARM_PRFLT without a take-off.

        A failsafe ends once the vehicle is down and disarmed.
        """
        if self.armed_on_ground():
            if self.flew and self._landed_since_s is not None:
                self.motion.idle()
                if 0 < self.p.com_disarm_land_s <= now_s - self._landed_since_s:
                    self.do_disarm()
            elif not self.flew and 0 < self.p.com_disarm_prflt_s <= now_s - self._armed_at_s:
                self.do_disarm()
                self.say(Severity.INFO, "Disarmed: no takeoff")
        if not self.armed and self.landed and self.failsafe and self.failsafe_since_s is None:
            self.failsafe = False

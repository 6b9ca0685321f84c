"""PX4 v1.14+ multicopter, as the mock imitates it (see `remarl_fc.sitl.autopilot`)."""

from __future__ import annotations

import math
from typing import Any, ClassVar

from remarl_fc.mavlink.consts import (
    MavAutopilot,
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
from remarl_fc.sitl.config import Px4Params
from remarl_fc.sitl.params import PX4_PARAMS
from remarl_fc.sitl.setpoints import Setpoint
from remarl_fc.sitl.vehicle import Guidance, YawMode


class Px4Logic(Autopilot):
    """PX4 v1.14+ multicopter (Commander, mavlink_receiver, the offboard and takeoff docs).

    Modes modelled: MANUAL, ALTCTL, POSCTL, STABILIZED (hold without RC), OFFBOARD, and AUTO
    TAKEOFF, LOITER (Hold), RTL, LAND. Refused transitions → TEMPORARILY_REJECTED.
    """

    autopilot_id = MavAutopilot.PX4
    flavour = "px4"
    param_table = PX4_PARAMS
    MAIN_MODES: ClassVar[frozenset[int]] = frozenset({1, 2, 3, 4, 6, 7})
    AUTO_SUBS: ClassVar[frozenset[int]] = frozenset({2, 3, 5, 6})
    OFFBOARD, AUTO, POSCTL = 6, 4, 3
    TAKEOFF, LOITER, RTL, LAND = 2, 3, 5, 6

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.p = self.cfg.px4
        self.main, self.sub = self.POSCTL, 0
        self.custom_mode = self._pack()
        self.failsafe_since_s: float | None = None

    def _pack(self) -> int:
        return (self.main << 16) | (self.sub << 24)

    def params(self) -> Px4Params:
        """The live PX4 parameters."""
        return self.p

    def set_params(self, values: Px4Params) -> None:
        """Replace the live PX4 parameters."""
        self.p = values

    def boot_s(self) -> float:
        """PX4 boot time (`Px4Params.boot_s`)."""
        return self.p.boot_s

    def position_estimate_s(self) -> float:
        """Time to a valid global position (`Px4Params.position_estimate_s`)."""
        return self.p.position_estimate_s

    def default_streams(self) -> dict[int, float]:
        """PX4's default stream set for a GCS/offboard link (the mock's approximation)."""
        return {
            MsgId.SYS_STATUS: 1.0,
            MsgId.EXTENDED_SYS_STATE: 1.0,
            MsgId.ATTITUDE: 1 / 20,
            MsgId.GLOBAL_POSITION_INT: 1 / 10,
            MsgId.LOCAL_POSITION_NED: 1 / 10,
            MsgId.GPS_RAW_INT: 1.0,
            MsgId.HOME_POSITION: 2.0,
            MsgId.POSITION_TARGET_LOCAL_NED: 1 / 5,
        }

    def mode_flags(self) -> MavModeFlag:
        """CUSTOM_MODE_ENABLED | MANUAL_INPUT, + STABILIZE, GUIDED, AUTO by mode."""
        mode = MavModeFlag.CUSTOM_MODE_ENABLED | MavModeFlag.MANUAL_INPUT_ENABLED
        if self.main != 1:
            mode |= MavModeFlag.STABILIZE_ENABLED
        if self.main in (self.POSCTL, self.AUTO, self.OFFBOARD):
            mode |= MavModeFlag.GUIDED_ENABLED
        if self.main in (self.AUTO, self.OFFBOARD):
            mode |= MavModeFlag.AUTO_ENABLED
        return mode

    def resting_status(self) -> int:
        """STANDBY disarmed, ACTIVE armed."""
        return MavState.ACTIVE if self.armed else MavState.STANDBY

    def under_external_control(self) -> bool:
        """OFFBOARD."""
        return self.main == self.OFFBOARD

    def stream_alive(self, now_s: float) -> bool:
        """A setpoint arrived within COM_OF_LOSS_T."""
        return now_s - self.last_setpoint_s <= self.p.com_of_loss_t_s

    def _set(self, main: int, sub: int = 0) -> None:
        self.main, self.sub = main, sub
        self.custom_mode = self._pack()
        p = self.p
        if main == self.AUTO and sub == self.LAND:
            self.fly_land(p.mpc_land_speed_m_s, p.mpc_land_speed_m_s, 0.0)
        elif main == self.AUTO and sub == self.RTL:
            if self.landed:
                self.fly_hold()
            else:
                self.fly_return(p.rtl_return_alt_m, p.rtl_speed_m_s, p.mpc_tko_speed_m_s)
        elif main == self.AUTO and sub == self.TAKEOFF:
            if self.armed and self.landed:
                self.fly_climb(p.mis_takeoff_alt_m, p.mpc_tko_speed_m_s)
        elif main == self.OFFBOARD and self.setpoint is not None and self.setpoint.valid:
            self._fly_offboard(self.setpoint)
        else:
            self.fly_hold()

    def _fly_offboard(self, sp: Setpoint) -> None:
        if not self.armed:
            return
        climbing = sp.vel_ned_m_s is not None and (sp.vel_ned_m_s[2] < 0)
        going_up = (
            sp.pos_ned_m is not None and sp.pos_ned_m[2] < self.frames.pos_ned_m[self.index, 2]
        )
        if self.landed and not (climbing or going_up):
            return
        self.fly_setpoint(sp, default_yaw=YawMode.HOLD)

    def _enter(self, main: int, sub: int, now_s: float) -> tuple[int, str]:
        if main == 0:  # a packed word in p2 truncates to 0: accepted, nothing changes
            return MavResult.ACCEPTED, ""
        if main not in self.MAIN_MODES or (main == self.AUTO and sub not in self.AUTO_SUBS):
            return MavResult.TEMPORARILY_REJECTED, "Mode not available in this mock"
        if main in (self.POSCTL, self.AUTO, self.OFFBOARD) and not self.position_ok(now_s):
            return MavResult.TEMPORARILY_REJECTED, "Mode requires a global position"
        if main == self.OFFBOARD and not self.stream_alive(now_s):
            return MavResult.TEMPORARILY_REJECTED, "Switching to Offboard is not available"
        self.failsafe, self.failsafe_since_s = False, None
        self._set(main, sub)
        return MavResult.ACCEPTED, ""

    def cmd_set_mode(self, cmd: Command, now_s: float) -> tuple[int, str]:
        """p1 & CUSTOM_MODE_ENABLED, p2 = main mode, p3 = sub mode (cast to uint8)."""
        if not int(cmd.params[0]) & MavModeFlag.CUSTOM_MODE_ENABLED:
            return MavResult.DENIED, ""
        main, sub = int(cmd.params[1]) & 0xFF, int(cmd.params[2]) & 0xFF
        return self._enter(main, sub, now_s)

    def arm_refusal(self, now_s: float) -> tuple[int, str] | None:
        """Arming needs a position and, in OFFBOARD, a setpoint stream."""
        if self.booting(now_s) or not self.position_ok(now_s):
            return MavResult.TEMPORARILY_REJECTED, "Arming denied: no global position"
        if self.main == self.OFFBOARD and not self.stream_alive(now_s):
            return MavResult.TEMPORARILY_REJECTED, "Arming denied: offboard signal lost"
        return None

    def after_arm(self) -> None:
        """Armed in AUTO.TAKEOFF: climb; in OFFBOARD: fly the latest setpoint."""
        if self.main == self.AUTO and self.sub == self.TAKEOFF:
            self._set(self.AUTO, self.TAKEOFF)
        elif self.main == self.OFFBOARD and self.setpoint is not None:
            self._fly_offboard(self.setpoint)

    def disarm_refusal(self) -> tuple[int, str]:
        """Disarming in flight needs force."""
        return MavResult.TEMPORARILY_REJECTED, "Disarming denied: not landed"

    def cmd_takeoff(self, cmd: Command, now_s: float) -> tuple[int, str]:
        """Switch to AUTO.TAKEOFF; p7 AMSL altitude if finite, else MIS_TAKEOFF_ALT."""
        result, text = self._enter(self.AUTO, self.TAKEOFF, now_s)
        if result == MavResult.ACCEPTED and self.armed and self.landed:
            alt = cmd.params[6]
            if math.isfinite(alt):
                height = alt - (self.origin.alt_m - float(self.frames.home_ned_m[self.index, 2]))
                self.fly_climb(max(height, 1.0), self.p.mpc_tko_speed_m_s)
        return result, text

    def cmd_land(self, cmd: Command, now_s: float) -> tuple[int, str]:
        """→ AUTO.LAND."""
        return self._enter(self.AUTO, self.LAND, now_s)

    def cmd_rtl(self, cmd: Command, now_s: float) -> tuple[int, str]:
        """→ AUTO.RTL."""
        return self._enter(self.AUTO, self.RTL, now_s)

    def on_setpoint(self, sp: Setpoint, now_s: float) -> bool:
        """Any mode keeps the stream alive; only OFFBOARD flies it."""
        if not sp.valid:
            return self.ignore_setpoint(f"invalid: {sp.reason}")
        self.last_setpoint_s = now_s
        self.setpoint = sp
        if self.main != self.OFFBOARD:
            return self.ignore_setpoint("not in OFFBOARD (kept as proof of life)")
        if not self.armed:
            return self.ignore_setpoint("disarmed")
        self._fly_offboard(sp)
        return True

    _FAILSAFE_ACTIONS: ClassVar[dict[str, tuple[int, int]]] = {
        "position": (3, 0),
        "hold": (4, 3),
        "return": (4, 5),
        "land": (4, 6),
    }

    def tick(self, now_s: float) -> None:
        """COM_OF_LOSS_T, COM_FAIL_ACT_T, take-off end, RTL landing, auto-disarm."""
        f, i, p = self.frames, self.index, self.p
        if self.main == self.OFFBOARD and not self.stream_alive(now_s):
            self.failsafe, self.failsafe_since_s = True, now_s
            self._set(self.AUTO, self.LOITER)  # Hold first ...
        if (
            self.failsafe_since_s is not None
            and now_s - self.failsafe_since_s >= p.com_fail_act_t_s
        ):
            main, sub = self._FAILSAFE_ACTIONS[p.com_obl_rc_act]  # ... then the action
            self.failsafe_since_s = None
            self._set(main, sub)
        taking_off = self.main == self.AUTO and self.sub == self.TAKEOFF and not self.landed
        if taking_off and f.guidance[i] == Guidance.CLIMB and self.climb_done():
            self._set(self.AUTO, self.LOITER)
            self.finish_climb()
        if self.main == self.AUTO and self.sub == self.RTL and self.home_reached():
            self.fly_land(p.mpc_land_speed_m_s, p.mpc_land_speed_m_s, 0.0)
        super().tick(now_s)
        if self.armed and self.landed and f.guidance[i] != Guidance.CLIMB:
            if self.flew and self._landed_since_s is not None:
                f.set_idle(i)
                if 0 < p.com_disarm_land_s <= now_s - self._landed_since_s:
                    self.do_disarm()
            elif not self.flew and 0 < p.com_disarm_prflt_s <= now_s - self._armed_at_s:
                self.do_disarm()
                self.say(Severity.INFO, "Disarmed: no takeoff")
        if not self.armed and self.landed and self.failsafe and self.failsafe_since_s is None:
            self.failsafe = False

    def pilot_mode(self, mode: str, now_s: float) -> bool:
        """The pilot selects ``mode``: POSCTL, ALTCTL, MANUAL, STABILIZED, HOLD, RTL, LAND."""
        table = {
            "POSCTL": (3, 0),
            "ALTCTL": (2, 0),
            "MANUAL": (1, 0),
            "STABILIZED": (7, 0),
            "HOLD": (4, 3),
            "LOITER": (4, 3),
            "RTL": (4, 5),
            "LAND": (4, 6),
        }
        if mode.upper() not in table:
            return False
        self.failsafe, self.failsafe_since_s = False, None
        self._set(*table[mode.upper()])
        return True

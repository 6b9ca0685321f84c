"""How an autopilot steers its airframe: one vehicle's row of the batched `Airframes`.

`Motion` turns the autopilots' intents — hold, land, climb, return, fly a setpoint — into the
guidance and targets that `remarl_fc.sitl.vehicle.step` flies, and answers the questions the
mode timers ask (has the climb ended, is the return over home).
"""

from __future__ import annotations

import numpy as np

from remarl_fc.frames import wrap_yaw
from remarl_fc.sitl.config import VehicleModelConfig
from remarl_fc.sitl.setpoints import Setpoint
from remarl_fc.sitl.vehicle import Airframes, Guidance, YawMode

CLIMB_DONE_M = 0.3
"""A take-off is complete within this distance below its height (the climb slows into it)."""

HOME_REACHED_M = 1.0
"""A return is over home within this horizontal distance."""


class Motion:
    """Vehicle ``index``'s guidance in ``frames``.

    Args:
        frames: the fleet's airframes.
        index: the vehicle's row.
        model: the vehicle model (its speed limits).
    """

    def __init__(self, frames: Airframes, index: int, model: VehicleModelConfig) -> None:
        self.frames, self.index, self.model = frames, index, model

    @property
    def landed(self) -> bool:
        """Whether the airframe is on the ground."""
        return bool(self.frames.landed[self.index])

    @property
    def guidance(self) -> Guidance:
        """What the vehicle's velocity command follows now."""
        return Guidance(self.frames.guidance[self.index])

    def idle(self) -> None:
        """Sit on the ground without moving."""
        self.frames.set_idle(self.index)

    def hold(self) -> None:
        """Hold position and heading (on the ground: stay idle)."""
        if self.landed:
            self.frames.set_idle(self.index)
        else:
            self.frames.set_hold(self.index)

    def land(self, fast_m_s: float, slow_m_s: float, slow_below_m: float) -> None:
        """Descend where the vehicle is, slowing to ``slow_m_s`` below ``slow_below_m``."""
        f, i = self.frames, self.index
        f.set_hold(i)
        f.guidance[i] = Guidance.LAND
        f.fast_descent_m_s[i], f.slow_descent_m_s[i] = fast_m_s, slow_m_s
        f.slow_below_m[i] = slow_below_m

    def drop(self) -> None:
        """Motors stopped in the air: fall to the ground at the model's climb limit."""
        climb = self.model.vertical.max_climb_m_s
        self.land(climb, climb, 0.0)

    def climb(self, height_m: float, rate_m_s: float) -> None:
        """Climb vertically to ``height_m`` above the ground at ``rate_m_s``."""
        f, i = self.frames, self.index
        f.set_hold(i)
        f.guidance[i] = Guidance.CLIMB
        f.pos_target_ned_m[i, 2] = -height_m
        f.climb_m_s[i] = rate_m_s

    def return_home(self, alt_m: float, speed_m_s: float, climb_m_s: float) -> None:
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
        return bool(np.hypot(d[0], d[1]) < HOME_REACHED_M and f.guidance[i] == Guidance.RETURN)

    def fly(self, sp: Setpoint, *, default_yaw: YawMode) -> None:
        """Fly a valid setpoint.

        A velocity alone is flown as a velocity (an axis the sender ignored, NaN on PX4, as
        0 m/s: the height holds); a position, with or without a velocity, as a position; an
        acceleration alone holds the current velocity (a feed-forward of 0 m/s²). The yaw
        follows the setpoint's angle or rate, else ``default_yaw``.
        """
        f, i = self.frames, self.index
        if sp.vel_ned_m_s is not None and sp.pos_ned_m is None:
            v = sp.vel_ned_m_s
            f.guidance[i] = Guidance.VELOCITY
            f.vel_target_m_s[i] = np.where(np.isnan(v), 0.0, v)
        elif sp.pos_ned_m is not None:
            p = sp.pos_ned_m
            f.guidance[i] = Guidance.POSITION
            f.pos_target_ned_m[i] = np.where(np.isnan(p), f.pos_ned_m[i], p)
            f.speed_limit_m_s[i] = self.model.max_speed_m_s
        else:
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

    def set_yaw(self, yaw_rad: float) -> None:
        """Turn to ``yaw_rad`` and hold it."""
        f, i = self.frames, self.index
        f.yaw_mode[i] = YawMode.ANGLE
        f.yaw_target_rad[i] = wrap_yaw(yaw_rad)

    def set_speed(self, speed_m_s: float) -> None:
        """Horizontal speed limit of position targets."""
        self.frames.speed_limit_m_s[self.index] = speed_m_s

    def yaw_rad(self) -> float:
        """The true heading now."""
        return float(self.frames.yaw_rad[self.index])

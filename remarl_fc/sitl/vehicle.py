"""The mock's multirotors: every vehicle's kinematics in one batched numpy step.

Positions are local NED in metres from the arena origin (down = 0 on the ground); yaw is in
radians clockwise from north. Each vehicle follows a *guidance* set by its autopilot logic —
hold a point, fly a velocity, go to a position, climb for take-off, land, return — which
becomes a commanded velocity; the airframe tracks it to first order with acceleration and
speed limits, and tracks its yaw target with a rate limit. No per-vehicle Python loop runs
here: the physics rate is independent of the fleet size.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import IntEnum

import numpy as np
from numpy.typing import NDArray

from remarl_fc.sitl.config import VehicleModelConfig
from sim.kinematics import wrap_angle
from sim.vehicle import DelayLine, VehicleProfile, track_velocity

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]
BoolArray = NDArray[np.bool_]

GROUND_DOWN_M = 0.0
"""Down coordinate of the ground (flat terrain at the origin's altitude)."""

BRAKE_DONE_M_S = 0.2
"""A braking vehicle holds where it is once slower than this (BRAKE / Hold stop in place)."""

LANDED_SPEED_M_S = 0.3
"""Touch-down: below this sink rate at the ground the vehicle counts as landed."""


class Guidance(IntEnum):
    """What a vehicle's velocity command follows."""

    IDLE = 0  # on the ground, motors off or spinning: no motion
    HOLD = 1  # hold `hold_ned_m` (position hold, brake, loiter)
    VELOCITY = 2  # fly `vel_target_m_s` (GUIDED / OFFBOARD velocity setpoints)
    POSITION = 3  # go to `pos_target_ned_m`
    CLIMB = 4  # take-off: climb at `climb_m_s` to `pos_target_ned_m` down, holding x/y
    LAND = 5  # descend at `descent rates` holding x/y
    RETURN = 6  # climb to `return_alt_m`, fly home, then descend


class YawMode(IntEnum):
    """How the yaw command is formed."""

    HOLD = 0  # keep `yaw_target_rad`
    ANGLE = 1  # turn to `yaw_target_rad`
    RATE = 2  # turn at `yaw_rate_target_rad_s`
    TRAVEL = 3  # face the direction of horizontal travel


@dataclass
class Airframes:
    """State and commands of N vehicles; every array has the vehicle index first.

    Attributes:
        pos_ned_m (N, 3), vel_ned_m_s (N, 3): true state.
        yaw_rad (N,), yaw_rate_rad_s (N,): true heading (CW from north) and its rate.
        home_ned_m (N, 3): each vehicle's home (its spawn point on the ground).
        guidance (N,): `Guidance` values. hold_ned_m, pos_target_ned_m (N, 3); vel_target_m_s
            (N, 3); climb_m_s (N,) take-off climb rate; speed_limit_m_s (N,) for POSITION and
            RETURN; return_alt_m (N,) RETURN climbs to at least this height.
        yaw_mode (N,): `YawMode` values; yaw_target_rad, yaw_rate_target_rad_s (N,).
        gust_m_s (N, 3): current uncorrected gust velocity.
        landed (N,): on the ground.
    """

    pos_ned_m: FloatArray
    vel_ned_m_s: FloatArray
    yaw_rad: FloatArray
    yaw_rate_rad_s: FloatArray
    home_ned_m: FloatArray
    guidance: IntArray
    hold_ned_m: FloatArray
    pos_target_ned_m: FloatArray
    vel_target_m_s: FloatArray
    climb_m_s: FloatArray
    speed_limit_m_s: FloatArray
    return_alt_m: FloatArray
    fast_descent_m_s: FloatArray
    slow_descent_m_s: FloatArray
    slow_below_m: FloatArray
    yaw_mode: IntArray
    yaw_target_rad: FloatArray
    yaw_rate_target_rad_s: FloatArray
    gust_m_s: FloatArray
    landed: BoolArray
    braking: BoolArray

    @classmethod
    def on_ground(cls, home_ned_m: FloatArray, yaw_rad: FloatArray) -> Airframes:
        """N vehicles standing at their homes (N, 3) facing ``yaw_rad`` (N,), motors idle."""
        n = len(home_ned_m)
        home = np.asarray(home_ned_m, dtype=np.float64).copy()
        home[:, 2] = GROUND_DOWN_M
        z3, z1 = np.zeros((n, 3)), np.zeros(n)
        yaw = np.asarray(yaw_rad, dtype=np.float64).copy()
        return cls(
            pos_ned_m=home.copy(),
            vel_ned_m_s=z3.copy(),
            yaw_rad=yaw,
            yaw_rate_rad_s=z1.copy(),
            home_ned_m=home,
            guidance=np.full(n, int(Guidance.IDLE)),
            hold_ned_m=home.copy(),
            pos_target_ned_m=home.copy(),
            vel_target_m_s=z3.copy(),
            climb_m_s=z1.copy(),
            speed_limit_m_s=z1.copy(),
            return_alt_m=z1.copy(),
            fast_descent_m_s=z1.copy(),
            slow_descent_m_s=z1.copy(),
            slow_below_m=z1.copy(),
            yaw_mode=np.full(n, int(YawMode.HOLD)),
            yaw_target_rad=yaw.copy(),
            yaw_rate_target_rad_s=z1.copy(),
            gust_m_s=z3.copy(),
            landed=np.ones(n, dtype=bool),
            braking=np.zeros(n, dtype=bool),
        )

    def __len__(self) -> int:
        return len(self.yaw_rad)

    def height_m(self) -> FloatArray:
        """(N,) height above the ground, metres."""
        return GROUND_DOWN_M - self.pos_ned_m[:, 2]

    def set_hold(self, i: int) -> None:
        """Vehicle i brakes to a stop and holds where it stopped (height and heading kept)."""
        self.guidance[i] = Guidance.HOLD
        self.hold_ned_m[i] = self.pos_ned_m[i]
        self.braking[i] = True
        self.yaw_mode[i] = YawMode.HOLD
        self.yaw_target_rad[i] = self.yaw_rad[i]

    def set_idle(self, i: int) -> None:
        """Vehicle i sits on the ground without moving."""
        self.guidance[i] = Guidance.IDLE
        self.vel_target_m_s[i] = 0.0
        self.yaw_mode[i] = YawMode.HOLD
        self.yaw_target_rad[i] = self.yaw_rad[i]


def _clip_norm(v: FloatArray, limit: FloatArray | float) -> FloatArray:
    """Scale rows of v (..., k) so their norm is at most ``limit``."""
    norm = np.linalg.norm(v, axis=-1, keepdims=True)
    lim = np.asarray(limit, dtype=np.float64)
    if lim.ndim:
        lim = lim[..., None]
    scale = np.minimum(1.0, lim / np.maximum(norm, 1e-12))
    out: FloatArray = v * scale
    return out


def commanded_velocity(a: Airframes, cfg: VehicleModelConfig) -> FloatArray:
    """(N, 3) velocity command of every vehicle from its guidance.

    Each guidance mode is computed only where some vehicle flies it: the mock steps this at its
    physics rate, and most of a flight has every vehicle in one mode.
    """
    g = a.guidance
    present = set(g.tolist())
    cmd = np.zeros_like(a.vel_ned_m_s)
    gain = cfg.position_gain_1_s

    if Guidance.HOLD in present:
        hold = g == Guidance.HOLD
        cmd[hold] = gain * (a.hold_ned_m[hold] - a.pos_ned_m[hold])
        brake = hold & a.braking
        cmd[brake, :2] = 0.0  # stop first; the hold point is where the vehicle stops

    if Guidance.VELOCITY in present:
        vel = g == Guidance.VELOCITY
        cmd[vel] = a.vel_target_m_s[vel]

    if Guidance.POSITION in present:
        pos = g == Guidance.POSITION
        cmd[pos] = gain * (a.pos_target_ned_m[pos] - a.pos_ned_m[pos])
        cmd[pos, :2] = _clip_norm(cmd[pos, :2], a.speed_limit_m_s[pos])

    if Guidance.CLIMB in present:
        climb = g == Guidance.CLIMB
        cmd[climb, :2] = gain * (a.hold_ned_m[climb, :2] - a.pos_ned_m[climb, :2])
        climb_err = a.pos_target_ned_m[climb, 2] - a.pos_ned_m[climb, 2]  # < 0 below target
        cmd[climb, 2] = np.maximum(-a.climb_m_s[climb], gain * climb_err)

    height = a.height_m()
    if Guidance.LAND in present:
        land = g == Guidance.LAND
        cmd[land, :2] = gain * (a.hold_ned_m[land, :2] - a.pos_ned_m[land, :2])
        slow = height < a.slow_below_m
        cmd[land, 2] = np.where(slow[land], a.slow_descent_m_s[land], a.fast_descent_m_s[land])

    if Guidance.RETURN in present:
        ret = g == Guidance.RETURN
        to_home = a.home_ned_m[ret, :2] - a.pos_ned_m[ret, :2]
        low = height[ret] < a.return_alt_m[ret] - 0.5
        horiz = _clip_norm(gain * to_home, a.speed_limit_m_s[ret])
        horiz[low] = 0.0
        vert = np.where(low, -a.climb_m_s[ret], 0.0)
        cmd[ret, :2] = horiz
        cmd[ret, 2] = vert
    return cmd


def step(
    a: Airframes,
    cfg: VehicleModelConfig,
    dt_s: float,
    rng: np.random.Generator,
    profile: VehicleProfile,
    delay: DelayLine | None = None,
) -> None:
    """Advance every vehicle by ``dt_s`` seconds in place.

    Horizontally the vehicles answer their (``delay``-ed) velocity command as the fitted
    ``profile`` says (`sim.vehicle`, the simulator's model); vertically to first order with
    ``cfg``'s acceleration limit.
    """
    cmd = commanded_velocity(a, cfg)
    cmd[:, :2] = _clip_norm(cmd[:, :2], cfg.max_speed_m_s)
    cmd[:, 2] = np.clip(cmd[:, 2], -cfg.vertical.max_climb_m_s, cfg.vertical.max_climb_m_s)

    horizontal = cmd[:, :2] if delay is None else delay.push(cmd[:, :2])
    a.vel_ned_m_s[:, :2] = track_velocity(a.vel_ned_m_s[:, :2], horizontal, profile, dt_s)
    vert_accel = (cmd[:, 2] - a.vel_ned_m_s[:, 2]) / cfg.vertical.tau_s
    a.vel_ned_m_s[:, 2] += (
        np.clip(vert_accel, -cfg.vertical.max_accel_m_s2, cfg.vertical.max_accel_m_s2) * dt_s
    )

    if cfg.gust_m_s > 0:  # Ornstein–Uhlenbeck gusts
        theta = dt_s / cfg.gust_tau_s
        noise = rng.standard_normal(a.gust_m_s.shape) * cfg.gust_m_s * math.sqrt(2 * theta)
        a.gust_m_s += -theta * a.gust_m_s + noise
        a.gust_m_s[a.landed] = 0.0

    idle = (a.guidance == Guidance.IDLE) | a.landed & (cmd[:, 2] >= 0)
    a.vel_ned_m_s[idle] = 0.0
    a.pos_ned_m += (a.vel_ned_m_s + a.gust_m_s) * dt_s

    stopped = a.braking & (np.hypot(a.vel_ned_m_s[:, 0], a.vel_ned_m_s[:, 1]) < BRAKE_DONE_M_S)
    a.hold_ned_m[stopped, :2] = a.pos_ned_m[stopped, :2]
    a.braking &= ~stopped
    a.braking &= a.guidance == Guidance.HOLD

    # the ground
    below = a.pos_ned_m[:, 2] >= GROUND_DOWN_M
    a.pos_ned_m[below, 2] = GROUND_DOWN_M
    touching = below & (a.vel_ned_m_s[:, 2] >= -1e-9)
    a.vel_ned_m_s[touching, 2] = 0.0
    a.landed = touching & (np.linalg.norm(a.vel_ned_m_s[:, :2], axis=1) < LANDED_SPEED_M_S)
    a.landed &= cmd[:, 2] >= 0

    # yaw
    modes = set(a.yaw_mode.tolist())
    rate = np.zeros_like(a.yaw_rad)
    if YawMode.ANGLE in modes or YawMode.HOLD in modes:
        track = (a.yaw_mode == YawMode.ANGLE) | (a.yaw_mode == YawMode.HOLD)
        rate[track] = wrap_angle(a.yaw_target_rad[track] - a.yaw_rad[track]) / profile.yaw_tau_s
    if YawMode.RATE in modes:
        ratem = a.yaw_mode == YawMode.RATE
        rate[ratem] = a.yaw_rate_target_rad_s[ratem]
    if YawMode.TRAVEL in modes:
        travel = a.yaw_mode == YawMode.TRAVEL
        speed = np.hypot(a.vel_ned_m_s[:, 0], a.vel_ned_m_s[:, 1])
        moving = travel & (speed > 0.5)
        course = np.arctan2(a.vel_ned_m_s[moving, 1], a.vel_ned_m_s[moving, 0])
        rate[moving] = wrap_angle(course - a.yaw_rad[moving]) / profile.yaw_tau_s
    rate = np.clip(rate, -profile.max_yaw_rate_rad_s, profile.max_yaw_rate_rad_s)
    rate[a.landed & (a.guidance == Guidance.IDLE)] = 0.0
    a.yaw_rate_rad_s = rate
    a.yaw_rad = wrap_angle(a.yaw_rad + rate * dt_s)

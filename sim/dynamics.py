"""The simulator's vehicles flown with the fitted response of real autopilots (`sim.vehicle`).

With the "ideal" profile (the paper) a UAV flies the arc of its decision exactly, from the
instant it is decided (`sim.transition.fly`). With any other profile the decision is a
*command*, as `remarl-fc fly` sends it: a velocity setpoint that turns at a constant rate along
the decided arc (`remarl_fc.flight.control`), which the vehicle follows late and smoothly:

* the command in force at time s of a step is the one sent at s − delay: the previous step's
  arc while s < delay (the delay must stay below the decision step);
* the velocity tracks it to first order with the vehicle's time constant, the acceleration
  capped (`sim.vehicle.follow_velocity`, the mock's model too, exact over each integration
  step);
* positions are integrated by the trapezoid rule on a grid of `INTEGRATION_STEP_S` or finer that
  contains the T + 1 sub-step instants of the swept checks, so the collision checks and the
  reward see the track actually flown, not the commanded arc.

A vehicle that arrived is commanded to stop (speed 0: ``fly`` holds it) and brakes with the same
model. Each UAV has its own response (`Response`), drawn per episode where the scenario's
``dynamics_randomisation`` asks for it. The commanded heading stays the simulator's heading:
it is what the runtime's controller knows and builds the observation frame from.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from sim.arrays import BoolArray, Float32Array, FloatArray
from sim.config import ScenarioConfig
from sim.vehicle import VehicleProfile, follow_velocity, load_profile

INTEGRATION_STEP_S = 0.125
"""Longest integration step of the vehicle model, seconds: a command sampled at the middle of
it is off the continuously turning setpoint by at most a_max/dt · step/2 (1.4° at π/4 in 2 s),
and the setpoint stream of the runtime is 10 Hz (0.1 s)."""

IDEAL_TAU_S = 1e-6
"""Velocity time constant standing for an ideal vehicle inside a mixed batch, seconds."""

IDEAL_ACCEL_M_S2 = 1e9
"""Acceleration cap standing for an ideal vehicle inside a mixed batch, m/s²."""


@dataclass(frozen=True)
class Response:
    """How each UAV answers its commands, (B, N) each (per UAV and episode).

    Attributes:
        delay_s: transport delay. tau_s: velocity time constant. accel_m_s2: acceleration cap.
    """

    delay_s: FloatArray
    tau_s: FloatArray
    accel_m_s2: FloatArray


def _values(profile: VehicleProfile) -> tuple[float, float, float]:
    if profile.ideal:
        return 0.0, IDEAL_TAU_S, IDEAL_ACCEL_M_S2
    return profile.delay_s, profile.velocity_tau_s, profile.max_accel_m_s2


def is_ideal(cfg: ScenarioConfig) -> bool:
    """Whether every UAV of the scenario flies the paper's exact arcs (no response to model)."""
    return load_profile(cfg.dynamics).ideal and not cfg.dynamics_randomisation.randomised


def draw_response(cfg: ScenarioConfig, b: int, n: int, rng: np.random.Generator) -> Response | None:
    """Every UAV's response for B new episodes; None where the scenario is ideal.

    Draws only what the scenario randomises (an unrandomised scenario consumes nothing of
    ``rng``): a profile per UAV from ``dynamics_randomisation.profiles``, then a uniform factor
    per parameter from its range.
    """
    if is_ideal(cfg):
        return None
    rand = cfg.dynamics_randomisation
    names = rand.profiles or (cfg.dynamics,)
    table = np.array([_values(load_profile(name)) for name in names])  # (P, 3)
    chosen = table[rng.integers(len(names), size=(b, n))] if len(names) > 1 else table[0]
    scales = [
        rng.uniform(lo, hi, size=(b, n)) if lo < hi else np.full((b, n), lo)
        for lo, hi in (rand.delay_scale, rand.velocity_tau_scale, rand.max_accel_scale)
    ]
    delay = chosen[..., 0] * scales[0]
    if (delay >= cfg.dt_s).any():
        raise ValueError(
            f"a drawn delay reaches the decision step ({cfg.dt_s} s); lower "
            "dynamics_randomisation.delay_scale"
        )
    return Response(delay, chosen[..., 1] * scales[1], chosen[..., 2] * scales[2])


def longest_delay_s(cfg: ScenarioConfig) -> float:
    """The longest transport delay the scenario can draw, seconds."""
    names = cfg.dynamics_randomisation.profiles or (cfg.dynamics,)
    longest = max(_values(load_profile(name))[0] for name in names)
    return longest * cfg.dynamics_randomisation.delay_scale[1]


@dataclass(frozen=True)
class Commands:
    """The command stream of one step: this step's arc and the one before it.

    Attributes:
        heading_rad: (B, N) commanded heading at the start of the step.
        turn_rad, speed_m_s: (B, N) this step's arc: heading change and speed.
        last_turn_rad, last_speed_m_s: (B, N) the previous step's arc (in force for the first
            ``delay_s`` of this step).
    """

    heading_rad: FloatArray
    turn_rad: FloatArray
    speed_m_s: FloatArray
    last_turn_rad: FloatArray
    last_speed_m_s: FloatArray


def delayed_command(
    cmd: Commands, response: Response, s: float, dt_s: float
) -> tuple[FloatArray, FloatArray]:
    """The commanded (vx, vy) in force at time ``s`` of the step, each (B, N)."""
    u = s - response.delay_s
    late = u < 0.0
    heading = np.where(
        late,
        cmd.heading_rad + cmd.last_turn_rad * (u / dt_s),  # u < 0: back along the last arc
        cmd.heading_rad + cmd.turn_rad * (u / dt_s),
    )
    speed = np.where(late, cmd.last_speed_m_s, cmd.speed_m_s)
    return speed * np.cos(heading), speed * np.sin(heading)


def integration_grid(substeps: int, dt_s: float) -> int:
    """Integration steps per sub-step (≥ 1): the sub-step split to `INTEGRATION_STEP_S`."""
    return max(1, math.ceil(dt_s / substeps / INTEGRATION_STEP_S - 1e-9))


@dataclass(frozen=True)
class Track:
    """A step flown with the vehicle model.

    Attributes:
        x, y: (T + 1, B, N) float32 positions at the sub-step instants (time first).
        pos_m: (B, N, 2) end positions. vel_m_s: (B, N, 2) end velocities.
        flown_m: (B, N) distance flown over the step.
    """

    x: Float32Array
    y: Float32Array
    pos_m: FloatArray
    vel_m_s: FloatArray
    flown_m: FloatArray


def fly_response(
    pos_m: FloatArray,
    vel_m_s: FloatArray,
    cmd: Commands,
    response: Response,
    moving: BoolArray,
    substeps: int,
    dt_s: float,
) -> Track:
    """Fly one decision step of every UAV with its response to the command stream.

    Args:
        pos_m, vel_m_s: (B, N, 2) positions and velocities at the start of the step.
        cmd: this step's and the previous step's arcs.
        response: each UAV's response.
        moving: (B, N) UAVs that fly this step (flying or braking to a hover); the others
            stay where they are, velocity unchanged (episodes that ended).
        substeps: T; dt_s: the decision step.
    """
    per_sub = integration_grid(substeps, dt_s)
    h = dt_s / (substeps * per_sub)
    pos, vel = pos_m.copy(), vel_m_s.copy()
    still = ~moving[..., None]
    flown = np.zeros(moving.shape)
    xs = np.empty((substeps + 1, *moving.shape), dtype=np.float32)
    ys = np.empty_like(xs)
    xs[0], ys[0] = pos[..., 0], pos[..., 1]
    for k in range(substeps * per_sub):
        command = np.stack(delayed_command(cmd, response, (k + 0.5) * h, dt_s), axis=-1)
        new_vel = follow_velocity(vel, command, response.tau_s, response.accel_m_s2, h)
        new_vel = np.where(still, vel, new_vel)
        move = np.where(still, 0.0, (0.5 * h) * (vel + new_vel))
        pos += move
        flown += np.hypot(move[..., 0], move[..., 1])
        vel = new_vel
        if (k + 1) % per_sub == 0:
            xs[(k + 1) // per_sub], ys[(k + 1) // per_sub] = pos[..., 0], pos[..., 1]
    return Track(xs, ys, pos, vel, flown)

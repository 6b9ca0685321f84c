"""The simulator's vehicles flown with the fitted response of real autopilots (`sim.vehicle`).

With the "ideal" profile (the paper) a UAV flies the arc of its decision exactly, from the
instant it is decided (`sim.transition.fly`). With any other profile the decision is a
*command*, as `remarl-fc fly` sends it: a velocity setpoint that turns at a constant rate along
the decided arc (`remarl_fc.flight.control`), which the vehicle follows late and smoothly:

* the command in force at time s of a step is the one sent at s − delay: the previous step's
  arc while s < delay (the delay must stay below the decision step);
* the velocity tracks it to first order with the vehicle's time constant, the acceleration
  capped (`sim.vehicle.approach`, the mock's model too, exact over each integration step);
* positions are integrated by the trapezoid rule on a grid of `INTEGRATION_STEP_S` or finer that
  contains the T + 1 sub-step instants of the swept checks, so the collision checks and the
  reward see the track actually flown, not the commanded arc.

A vehicle that arrived is commanded to stop (speed 0: ``fly`` holds it) and brakes with the same
model. Each UAV has its own response (`Response`), drawn per episode where the scenario's
``dynamics_randomisation`` asks for it. The commanded heading stays the simulator's heading:
it is what the runtime's controller knows and builds the observation frame from.

The safety shield predicts with the same model (`predict_response`): candidate arcs flown from
a UAV's velocity now and after its last command (`Motion`), then the lag in closed form.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np
from numpy.typing import NDArray

from sim.arrays import BoolArray, Float32Array, FloatArray
from sim.config import ScenarioConfig
from sim.vehicle import VehicleProfile, approach, closing_fraction, load_profile

INTEGRATION_STEP_S = 0.25
"""Longest integration step of the vehicle model, seconds (one sub-step at the defaults): the
response is exact over each step for the command at its middle. Against a 0.01 s integration,
UAVs of random ArduCopter/PX4 responses flying eight full random turns (16 s) end at most
0.26 m away (0.125 s: 0.06 m), a hundredth of d_col and below what the fitted model itself
misses on the real traces (0.2 m/s RMS); the step costs half as much."""

IDEAL_TAU_S = 1e-6
"""Velocity time constant standing for an ideal vehicle inside a mixed batch, seconds."""

IDEAL_ACCEL_M_S2 = 1e9
"""Acceleration cap standing for an ideal vehicle inside a mixed batch, m/s²."""


@dataclass(frozen=True)
class Response:
    """How each UAV answers its commands: (B, N) arrays (per UAV and episode).

    Attributes:
        delay_s: transport delay. tau_s: velocity time constant. accel_m_s2: acceleration cap.
        closing: the share of a velocity error closed over one integration step of the
            scenario (`ResponseSpec.step_s`), ``closing_fraction(tau_s, step_s)``.
        cap_m_s: the acceleration cap times that step.
    """

    delay_s: FloatArray
    tau_s: FloatArray
    accel_m_s2: FloatArray
    closing: FloatArray
    cap_m_s: FloatArray


def response_values(profile: VehicleProfile) -> tuple[float, float, float]:
    """A profile's (delay s, velocity time constant s, acceleration cap m/s²).

    For an ideal profile, the stand-ins of an ideal vehicle in a mixed batch: no delay,
    `IDEAL_TAU_S`, `IDEAL_ACCEL_M_S2`.
    """
    if profile.ideal:
        return 0.0, IDEAL_TAU_S, IDEAL_ACCEL_M_S2
    return profile.delay_s, profile.velocity_tau_s, profile.max_accel_m_s2


@dataclass(frozen=True)
class ResponseSpec:
    """What a scenario draws each UAV's response from, resolved once (profiles read, scaled).

    Attributes:
        table: (P, 3) delay, time constant, acceleration cap of each profile to draw from.
        scales: the (low, high) factor ranges of the three, in that order (every delay they
            can give is below the decision step: checked here once).
        step_s: the integration step of `fly_response` in the scenario.
    """

    table: FloatArray
    scales: tuple[tuple[float, float], tuple[float, float], tuple[float, float]]
    step_s: float

    @classmethod
    def from_scenario(cls, cfg: ScenarioConfig) -> ResponseSpec | None:
        """The scenario's spec; None where every UAV is ideal and nothing is randomised."""
        rand = cfg.dynamics_randomisation
        names = rand.profiles or (cfg.dynamics,)
        profiles = [load_profile(name) for name in names]
        if all(p.ideal for p in profiles) and not rand.randomised:
            return None
        if longest_delay_s(cfg) >= cfg.dt_s:  # the loader says so first, naming the key
            raise ValueError(
                f"a vehicle delay can reach the decision step ({cfg.dt_s} s); lower "
                "dynamics_randomisation.delay_scale"
            )
        table = np.array([response_values(p) for p in profiles])
        scales = (rand.delay_scale, rand.velocity_tau_scale, rand.max_accel_scale)
        step_s = cfg.dt_s / (cfg.substeps * integration_grid(cfg.substeps, cfg.dt_s))
        return cls(table, scales, step_s)

    def draw(self, b: int, n: int, rng: np.random.Generator) -> Response:
        """Every UAV's response for B new episodes of N UAVs.

        Draws only what is randomised (a spec without ranges or a profile choice consumes
        nothing of ``rng``): a profile per UAV, then a uniform factor per parameter.
        """
        count = len(self.table)
        chosen = self.table[rng.integers(count, size=(b, n))] if count > 1 else self.table[0]
        factors = [
            rng.uniform(lo, hi, size=(b, n)) if lo < hi else np.full((b, n), lo)
            for lo, hi in self.scales
        ]
        delay = chosen[..., 0] * factors[0]
        tau, accel = chosen[..., 1] * factors[1], chosen[..., 2] * factors[2]
        return Response(delay, tau, accel, closing_fraction(tau, self.step_s), accel * self.step_s)


def longest_delay_s(cfg: ScenarioConfig) -> float:
    """The longest transport delay the scenario can draw, seconds."""
    names = cfg.dynamics_randomisation.profiles or (cfg.dynamics,)
    longest = max(response_values(load_profile(name))[0] for name in names)
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
        response: each UAV's response, drawn for this scenario's integration step.
        moving: (B, N) UAVs that fly this step (flying or braking to a hover); the others
            stay where they are, velocity unchanged (episodes that ended).
        substeps: T; dt_s: the decision step.
    """
    per_sub = integration_grid(substeps, dt_s)
    steps = substeps * per_sub
    h = dt_s / steps
    moving_f = moving.astype(np.float64)
    fraction = response.closing * moving_f  # a still UAV keeps its velocity
    cap = response.cap_m_s
    # The delayed command at the middle of integration step k, s_k = (k + ½)·h, is the arc sent
    # at s_k − delay: this step's arc once s_k ≥ delay, the last step's before (only in the
    # first few steps: the delay is below the decision step). Each arc's direction turns by a
    # fixed angle per integration step: a complex rotation, no trigonometry in the loop. Only
    # the velocity response needs a loop over the steps; the commands before it and the
    # positions after it are computed for all steps at once, with the same operations in the
    # same order as step by step. Real factors of complex numbers are cast to complex once
    # (what each complex product would do with them).
    start = (0.5 * h - response.delay_s) / dt_s  # (B, N): fraction of the arc at s_0
    shape = moving.shape
    middles = (np.arange(steps) + 0.5) * h  # s_k
    lagging = int(
        np.count_nonzero(middles < np.maximum.reduce(response.delay_s, axis=None, initial=0.0))
    )
    # e^(i·angle) of this step's first direction and turn, and of the last arc's first direction
    angles = np.empty((3 if lagging else 2, *shape))
    np.multiply(cmd.turn_rad, start, out=angles[0])
    np.add(cmd.heading_rad, angles[0], out=angles[0])
    np.multiply(cmd.turn_rad, h / dt_s, out=angles[1])
    if lagging:
        np.multiply(cmd.last_turn_rad, start, out=angles[2])
        np.add(cmd.heading_rad, angles[2], out=angles[2])
    rotations = np.empty(angles.shape, dtype=np.complex128)
    np.cos(angles, out=rotations.real)
    np.sin(angles, out=rotations.imag)
    now_dir = np.empty((steps, *shape), dtype=np.complex128)  # (k, B, N) at each s_k
    now_dir[0] = rotations[0]
    for k in range(1, steps):
        np.multiply(now_dir[k - 1], rotations[1], out=now_dir[k])
    commands = np.multiply(cmd.speed_m_s.astype(np.complex128), now_dir)
    if lagging:
        late = middles[:lagging, None, None] < response.delay_s  # (lagging, B, N)
        last_speed = cmd.last_speed_m_s.astype(np.complex128)
        np.copyto(commands[0], last_speed * rotations[2], where=late[0])
        if lagging > 1:
            _last_arc_later(commands, rotations[2], last_speed, late, cmd, h / dt_s)

    # Only the velocity needs a loop; the positions follow from it by the trapezoid rule.
    vel = np.empty((steps + 1, *shape), dtype=np.complex128)  # at the integration instants
    vel[0] = vel_m_s[..., 0] + 1j * vel_m_s[..., 1]
    fraction_c = fraction.astype(np.complex128)
    for k in range(steps):
        approach(vel[k], commands[k], fraction_c, cap, out=vel[k + 1])
    move = np.add(vel[:-1], vel[1:])  # (k, B, N)
    move *= 0.5 * h
    if not moving.all():
        move *= moving_f.astype(np.complex128)
    track = np.empty((steps + 1, *shape), dtype=np.complex128)
    track[0] = pos_m[..., 0] + 1j * pos_m[..., 1]
    for k in range(steps):
        np.add(track[k], move[k], out=track[k + 1])
    # along the time axis: added in order, as step by step (`np.add.reduce`: ``.sum``'s numbers
    # without its Python wrapper)
    flown = np.add.reduce(np.abs(move), axis=0)
    at_substeps = track[::per_sub]
    xs = at_substeps.real.astype(np.float32)  # (T + 1, B, N)
    ys = at_substeps.imag.astype(np.float32)
    # (B, N) complex as (B, N, 2) [real, imaginary]: the same numbers as stacking the parts
    return Track(xs, ys, _pairs(track[-1]), _pairs(vel[-1]), flown)


def _pairs(z: NDArray[np.complex128]) -> FloatArray:
    """(..., 2) [real, imaginary] parts of ``z`` (...), a new array."""
    out: FloatArray = np.ascontiguousarray(z).view(np.float64).reshape(*z.shape, 2).copy()
    return out


def _last_arc_later(
    commands: NDArray[np.complex128],
    first_dir: NDArray[np.complex128],
    last_speed: NDArray[np.complex128],
    late: BoolArray,
    cmd: Commands,
    turn_fraction: float,
) -> None:
    """Put the last arc's commands into ``commands`` (k, B, N) for integration steps k ≥ 1.

    Only the UAVs whose delay outlasts the middle of step 1 (``late[1]``) still follow the
    last arc there, fewer than those at step 0: its direction is turned on from
    ``first_dir`` (B, N) for them alone, with the numbers of turning it for every UAV.
    """
    some = np.flatnonzero(late[1])
    angle = cmd.last_turn_rad.reshape(-1)[some] * turn_fraction
    turn = np.empty(angle.shape, dtype=np.complex128)
    np.cos(angle, out=turn.real)
    np.sin(angle, out=turn.imag)
    direction = first_dir.reshape(-1)[some]
    speed = last_speed.reshape(-1)[some]
    for k in range(1, len(late)):
        direction = direction * turn
        still = late[k].reshape(-1)[some]
        row = commands[k].reshape(-1)
        row[some[still]] = (speed * direction)[still]


@dataclass(frozen=True)
class Motion:
    """What a prediction of the fitted response needs of R UAVs beyond their commands.

    Attributes:
        vel_m_s: (R, 2) velocities now. last_turn_rad, last_speed_m_s: (R,) the arc commanded
        at the last decision (in force for the first ``delay_s`` of the coming step).
        delay_s, tau_s, accel_m_s2: (R,) each UAV's response (`Response`).
    """

    vel_m_s: FloatArray
    last_turn_rad: FloatArray
    last_speed_m_s: FloatArray
    delay_s: FloatArray
    tau_s: FloatArray
    accel_m_s2: FloatArray

    def _arrays(self) -> list[FloatArray]:
        return [getattr(self, f.name) for f in fields(self)]

    def of(self, rows: BoolArray | NDArray[np.intp]) -> Motion:
        """The UAVs selected by ``rows`` (an index or a mask of the leading axis)."""
        return Motion(*(v[rows] for v in self._arrays()))

    def flat(self, axes: int) -> Motion:
        """The same UAVs with their ``axes`` leading axes (B, N, ...) made one (R, ...)."""
        return Motion(*(np.reshape(v, (-1, *v.shape[axes:])) for v in self._arrays()))


def _lag_m(
    error_m_s: FloatArray, tau_s: FloatArray, accel_m_s2: FloatArray, s: FloatArray
) -> FloatArray:
    """(R, K, 2, L) how far a vehicle falls behind a constant command over the times ``s`` (L,).

    ``error_m_s`` (R, K, 2): the command minus the velocity at s = 0. The error keeps its
    direction and shrinks by the acceleration cap a while the first-order response would ask
    more (|e| > a·τ), then decays with τ: behind by ∫|e| = |e₀|·s₁ − a·s₁²/2 + τ·e₁·(1 − e^(−s₂/τ)),
    s₁ the time spent capped (at most (|e₀| − a·τ)/a), s₂ the rest, e₁ = min(|e₀|, a·τ).
    """
    size = np.hypot(error_m_s[..., 0], error_m_s[..., 1])[..., None]  # (R, K, 1)
    tau, accel = tau_s[..., None], accel_m_s2[..., None]
    capped = np.maximum(size - accel * tau, 0.0) / accel
    s1 = np.minimum(s, capped)  # (R, K, L)
    s2 = s - s1
    behind = (
        size * s1
        - 0.5 * accel * s1 * s1
        - np.minimum(size, accel * tau) * tau * np.expm1(-s2 / tau)
    )
    unit = error_m_s / np.maximum(size, 1e-12)
    out: FloatArray = unit[..., None] * behind[..., None, :]
    return out


AT_REST_M_S = 0.1
"""A braking vehicle slower than this is at rest, m/s (`brake`): a hover's drift."""


@dataclass(frozen=True)
class Braking:
    """Where K vehicles told to stop are, ``elapsed_s`` after their velocity was known.

    Attributes:
        disp_m: (K, 2) displacement since then. vel_m_s: (K, 2) velocity now.
        moving_s: (K,) how long of ``elapsed_s`` each was still moving (faster than
            `AT_REST_M_S`): after that it holds its place.
    """

    disp_m: FloatArray
    vel_m_s: FloatArray
    moving_s: FloatArray


def brake(
    vel_m_s: FloatArray,
    delay_s: FloatArray,
    tau_s: FloatArray,
    accel_m_s2: FloatArray,
    elapsed_s: FloatArray,
) -> Braking:
    """K vehicles commanded to stop (speed 0), flown with their fitted responses (K,) each.

    The model of the simulator (`fly_response`, an arrived UAV braking) in closed form: for the
    delay the vehicle flies on at ``vel_m_s`` (K, 2); then the stop command closes its velocity
    error (`_lag_m` for a command of 0), capped by the acceleration, then to first order.
    """
    vel = np.asarray(vel_m_s, dtype=np.float64).reshape(-1, 2)
    delay, tau, accel, elapsed = (
        np.asarray(v, dtype=np.float64).reshape(-1) for v in (delay_s, tau_s, accel_m_s2, elapsed_s)
    )
    late = np.minimum(elapsed, delay)  # the command in force: flying on
    s = np.maximum(elapsed - delay, 0.0)
    stopped = -_lag_m(-vel[:, None], tau[:, None], accel[:, None], s[:, None, None])[:, 0, :, 0]
    disp = vel * late[:, None] + stopped
    speed = np.hypot(vel[:, 0], vel[:, 1])
    capped = np.maximum(speed - accel * tau, 0.0) / accel  # braking at the cap
    gentle = np.minimum(speed, accel * tau)  # the speed where the first order takes over
    left = np.where(
        s <= capped, speed - accel * s, gentle * np.exp(-np.maximum(s - capped, 0.0) / tau)
    )
    unit = vel / np.maximum(speed, 1e-12)[:, None]
    tail = tau * np.log(np.maximum(gentle, AT_REST_M_S) / AT_REST_M_S)
    moving = np.where(speed > AT_REST_M_S, delay + capped + tail, 0.0)
    return Braking(disp, unit * left[:, None], np.minimum(moving, elapsed))


PREDICTED_STEPS = 2
"""Decision steps `predict_response` flies exactly with the response before its closed-form
tail (`_lag_m`), at least 2 (an instant inside them lies on the chord between their chords).
At the paper's 10 m/s and 2 s, for the fitted ArduCopter (the slowest profile, capped at
2.5 m/s²) from rest, from full speed, turning, slowing and stopping, the tail stays within
0.01 m of flying twelve steps exactly. Against the same command stream replayed at 10 ms the
prediction is as close as the simulator's own integration (`INTEGRATION_STEP_S`, the delayed
command taken at the middle of each step): 0.8 m for ArduCopter from rest, 1.05 m for PX4."""


def predict_response(
    heading_rad: FloatArray,
    turn_rad: FloatArray,
    first_m_s: float | FloatArray,
    then_m_s: float | FloatArray,
    motion: Motion,
    dt_s: float,
    chords: int,
    later_s: FloatArray,
    second_rad: FloatArray | None = None,
) -> tuple[FloatArray, FloatArray]:
    """Displacements (x, y), each (..., K, chords + 1 + L), of K candidate arcs of UAVs (...).

    What `sim.prediction.displacements` predicts for the ideal vehicle, flown with each UAV's
    fitted response (`fly_response`, the simulator's own model): the coming step commands the
    arc of ``turn_rad`` (..., K) at ``first_m_s`` (broadcast to it), after the last decision's
    arc for the delay; the next step the arc of ``second_rad`` (..., K; None: no turn) at
    ``then_m_s``, and the steps after it hold its final heading. ``motion``: the UAVs of
    ``heading_rad`` (...). Sampled at the ``chords`` chords of the coming step, then at
    ``later_s`` (L,), instants after it: flown exactly for `PREDICTED_STEPS` steps (linear
    between the chords of each); from there on in closed form (`_lag_m`): the command holds,
    and the velocity error keeps its direction.
    """
    lead, k = heading_rad.shape, turn_rad.shape[-1]
    r = math.prod(lead)
    shape = (r, k)
    motion = motion.flat(len(lead))
    heading = np.broadcast_to(heading_rad.reshape(r, 1), shape)
    turn_rad = turn_rad.reshape(shape)
    first = np.broadcast_to(np.asarray(first_m_s, dtype=np.float64), (*lead, k)).reshape(shape)
    then = np.broadcast_to(np.asarray(then_m_s, dtype=np.float64), (*lead, k)).reshape(shape)
    h = dt_s / (chords * integration_grid(chords, dt_s))  # `fly_response`'s integration step

    def wide(values: FloatArray) -> FloatArray:
        return np.broadcast_to(values[:, None], shape)

    tau, accel = wide(motion.tau_s), wide(motion.accel_m_s2)
    response = Response(wide(motion.delay_s), tau, accel, closing_fraction(tau, h), accel * h)
    moving = np.ones(shape, dtype=bool)
    vel = np.broadcast_to(motion.vel_m_s[:, None], (*shape, 2))
    last = (wide(motion.last_turn_rad), wide(motion.last_speed_m_s))
    cmd = Commands(heading, turn_rad, first, *last)
    track = fly_response(np.zeros((*shape, 2)), vel, cmd, response, moving, chords, dt_s)
    arc = [np.moveaxis(d, 0, -1).astype(np.float64) for d in (track.x, track.y)]
    final = heading + turn_rad
    second = np.zeros(shape) if second_rad is None else second_rad.reshape(shape)
    flown = [track.pos_m]  # (R, K, 2) at the first step's end, then each chord after it
    cmd = Commands(final, second, then, turn_rad, first)
    final = final + second
    for _ in range(PREDICTED_STEPS - 1):
        track = fly_response(flown[-1], track.vel_m_s, cmd, response, moving, chords, dt_s)
        flown += [np.stack([track.x[i], track.y[i]], axis=-1) for i in range(1, chords)]
        flown.append(track.pos_m)
        cmd = Commands(final, np.zeros(shape), then, cmd.turn_rad, then)  # the last turn late
    later = np.asarray(later_s, dtype=np.float64)
    c = np.stack([then * np.cos(final), then * np.sin(final)], axis=-1)  # (R, K, 2)
    s = np.maximum(later - PREDICTED_STEPS * dt_s, 0.0)  # (L,) into the tail
    tail = flown[-1][..., None] + c[..., None] * s - _lag_m(c - track.vel_m_s, tau, accel, s)
    # (R, K, 2, L); before the tail: linear between the chords of the steps flown
    knots = dt_s * (1 + np.arange(chords * (PREDICTED_STEPS - 1) + 1) / chords)
    points = np.stack(flown, axis=-1).astype(np.float64)  # (R, K, 2, knots)
    place = np.clip(np.searchsorted(knots, later) - 1, 0, len(knots) - 2)
    w = np.clip((later - knots[place]) / (dt_s / chords), 0.0, 1.0)
    near = points[..., place] + w * (points[..., place + 1] - points[..., place])
    rest = np.where(later < knots[-1], near, tail)
    x = np.concatenate([arc[0], rest[..., 0, :]], axis=-1)
    y = np.concatenate([arc[1], rest[..., 1, :]], axis=-1)
    return x.reshape(*lead, k, -1), y.reshape(*lead, k, -1)

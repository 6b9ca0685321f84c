"""One transition of the swarm simulator, as pure batched functions (`sim.swarm.SwarmSim.step`).

Each function is one stage of the step described in `sim.swarm`: `fly` or `fly_with_response`
(1: arcs, or the vehicles' response to them, and straight lines at the sub-step instants),
`closest_approaches` (2: swept distances), `outcome` (3: collisions, arrivals, the end of
episodes), `score` and `accumulate` (4: the contour windows, the reward and the episode
accumulators), `begin_avoidance` (5: contour levels by PSO). None keeps state or loops over
agents; arrays are batch first, sub-step samples time first.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import cast

import numpy as np

from sim.arrays import BoolArray, Float32Array, FloatArray, IntArray
from sim.config import ScenarioConfig
from sim.contour import ArcWindow, arc_external_xy
from sim.dynamics import Commands, fly_response
from sim.field import FieldSources
from sim.kinematics import heading_velocity, sinc_series, wrap_angle
from sim.metrics import swept_min_distance_xy
from sim.observation import Observations
from sim.reward import RewardTerms, assign_contour_levels, reward
from sim.state import EpisodeStats, SwarmState


def pair_members(n: int) -> IntArray:
    """(N, N − 1): the indices of the pairs (`np.triu_indices` order, i < j) of each UAV.

    >>> pair_members(3).tolist()
    [[0, 1], [0, 2], [1, 2]]
    """
    i, j = np.triu_indices(n, k=1)
    member = np.concatenate([i, j])
    pair = np.concatenate([np.arange(len(i)), np.arange(len(i))])
    table: IntArray = np.sort(pair[np.argsort(member, kind="stable")].reshape(n, n - 1), axis=1)
    return table


@dataclass(frozen=True)
class Flight:
    """Where everything is during one step (step 1 of the module docstring).

    Attributes:
        uav_x, uav_y: (T + 1, B, N) UAV coordinates at the sub-step instants, float32, time
            first (the grid of the swept checks and of the reward's quadrature).
        obstacle_x, obstacle_y: (T + 1, B, M) obstacle coordinates at the same instants.
        pos_m: (B, N, 2) UAV positions at the end of the step (float64).
        heading_rad: (B, N) UAV (commanded) headings at the end of the step.
        vel_m_s: (B, N, 2) UAV velocities at the end of the step.
        flown_m: (B, N) distance each UAV flew in the step.
    """

    uav_x: Float32Array
    uav_y: Float32Array
    obstacle_x: Float32Array
    obstacle_y: Float32Array
    pos_m: FloatArray
    heading_rad: FloatArray
    vel_m_s: FloatArray
    flown_m: FloatArray


def fly(
    state: SwarmState,
    turn: FloatArray,
    acted: BoolArray,
    fractions: FloatArray,
    length_m: FloatArray,
    dt_s: float,
) -> Flight:
    """Fly one step (step 1) with the paper's ideal vehicle: arcs, and obstacles' straight lines.

    Every UAV that ``acted`` (B, N) flies the arc of heading change ``turn`` (B, N) and length
    ``length_m`` (B, N: its commanded speed × dt), sampled at the sub-step ``fractions``
    (T + 1,) of the step; the others stay put (zero length, zero velocity at the end).
    The sub-step grid is float32 (millimetres at kilometre range, for the collision checks and
    the reward quadrature); the state itself advances in float64.
    """
    f32 = np.float32
    u = fractions.astype(f32)[:, None, None]  # time first: (T + 1, B, N) slices are contiguous
    half = (f32(0.5) * u) * turn.astype(f32)
    length = np.where(acted, length_m, 0.0)
    chord = (length.astype(f32) * u) * sinc_series(half)  # |half| ≤ a_max/2 ≤ π/4
    direction = state.heading_rad.astype(f32) + half
    px = state.pos_m[..., 0].astype(f32) + chord * np.cos(direction)  # (T + 1, B, N)
    py = state.pos_m[..., 1].astype(f32) + chord * np.sin(direction)
    end_half = 0.5 * turn
    end_chord = length * sinc_series(end_half)
    end_dir = state.heading_rad + end_half
    new_pos = state.pos_m + end_chord[..., None] * np.stack(
        [np.cos(end_dir), np.sin(end_dir)], axis=-1
    )
    new_heading = np.where(acted, wrap_angle(state.heading_rad + turn), state.heading_rad)
    vel = heading_velocity(new_heading, (length / dt_s)[..., None])
    ox, oy = obstacles_flown(state, fractions, dt_s)
    return Flight(px, py, ox, oy, new_pos, new_heading, vel, length)


def obstacles_flown(
    state: SwarmState, fractions: FloatArray, dt_s: float
) -> tuple[Float32Array, Float32Array]:
    """Obstacle coordinates (T + 1, B, M) at the sub-step instants: straight, constant speed."""
    f32 = np.float32
    tdt = (dt_s * fractions).astype(f32)[:, None, None]
    obs_pos, obs_vel = state.obstacle_pos_m.astype(f32), state.obstacle_vel_m_s.astype(f32)
    ox = obs_pos[..., 0] + tdt * obs_vel[..., 0]  # (T + 1, B, M)
    oy = obs_pos[..., 1] + tdt * obs_vel[..., 1]
    return ox, oy


def fly_with_response(
    state: SwarmState,
    turn: FloatArray,
    speed_m_s: FloatArray,
    acted: BoolArray,
    present: BoolArray,
    fractions: FloatArray,
    dt_s: float,
) -> Flight:
    """Fly one step (step 1) with each UAV's fitted response (`sim.dynamics`).

    The UAVs that ``acted`` are commanded along the arc of ``turn`` at ``speed_m_s``, which
    the caller has set to 0 for every other UAV: those still ``present`` (arrived, hovering)
    are commanded to stop; the rest stay put.
    """
    assert state.response is not None
    cmd = Commands(
        heading_rad=state.heading_rad,
        turn_rad=turn,
        speed_m_s=speed_m_s,
        last_turn_rad=state.last_turn_rad,
        last_speed_m_s=state.speed_m_s,
    )
    substeps = len(fractions) - 1
    track = fly_response(state.pos_m, state.vel_m_s, cmd, state.response, present, substeps, dt_s)
    new_heading = np.where(acted, wrap_angle(state.heading_rad + turn), state.heading_rad)
    ox, oy = obstacles_flown(state, fractions, dt_s)
    return Flight(track.x, track.y, ox, oy, track.pos_m, new_heading, track.vel_m_s, track.flown_m)


@dataclass(frozen=True)
class Approaches:
    """Swept closest approaches during one step (+inf where there is no such pair).

    Attributes:
        min_u2o_m: (B, N) each UAV's closest approach to any obstacle.
        min_u2u_m: (B, N) each UAV's closest approach to any other UAV (both flying).
        target_m: (B, N) each UAV's closest approach to its own target.
    """

    min_u2o_m: FloatArray
    min_u2u_m: FloatArray
    target_m: FloatArray


def closest_approaches(
    flight: Flight,
    target_m: FloatArray,
    acted: BoolArray,
    present: BoolArray,
    pairs: tuple[IntArray, IntArray],
    members: IntArray,
) -> Approaches:
    """Every kind of closest approach of a step in one float32 call (step 2).

    UAV–obstacle (N·M), UAV–UAV pairs (P, ``pairs`` i < j in `np.triu_indices` order), UAV–own
    target (N): the relative positions of all of them, (T + 1, N·M + P + N, B) per coordinate
    with the batch innermost, are float32 differences (the targets cast to float32 first).
    Separations count for every UAV ``present`` (flying, or hovering where it arrived) — a pair
    of UAVs when at least one of them flies; the approach to the target only for the UAVs that
    ``acted``. ``members`` (N, N − 1) (`pair_members`) lists the pairs of each UAV.
    """
    i, j = pairs
    steps, b, n = flight.uav_x.shape
    m = flight.obstacle_x.shape[-1]
    k_uo, k_uu = n * m, len(i)
    rel = []
    for p, o, t in (
        (flight.uav_x, flight.obstacle_x, target_m[..., 0]),
        (flight.uav_y, flight.obstacle_y, target_m[..., 1]),
    ):
        # (T + 1, kind, B): the batch innermost keeps numpy's inner loops long
        r = np.empty((steps, k_uo + k_uu + n, b), dtype=np.float32)  # [obstacles, pairs, targets]
        uav = np.ascontiguousarray(p.transpose(0, 2, 1))  # (T + 1, N, B)
        np.subtract(
            uav[:, :, None],
            o.transpose(0, 2, 1)[:, None],
            out=r[:, :k_uo].reshape(steps, n, m, b),
        )
        # the pairs of UAV a (a < b, `np.triu_indices` order) are one run: x_a − x_b for all b
        # > a by broadcasting, no gathered copies
        start = k_uo
        for a in range(n - 1):
            np.subtract(uav[:, a : a + 1], uav[:, a + 1 :], out=r[:, start : start + n - 1 - a])
            start += n - 1 - a
        np.subtract(uav, t.T.astype(np.float32), out=r[:, k_uo + k_uu :])
        rel.append(r)
    swept = swept_min_distance_xy(*rel).astype(np.float64)  # (N·M + P + N, B)
    d_uo = swept[:k_uo].reshape(n, m, b).transpose(2, 0, 1)  # (B, N, M)
    counted = present[:, i] & present[:, j] & (acted[:, i] | acted[:, j])
    d_pair = np.where(counted.T, swept[k_uo : k_uo + k_uu], np.inf)  # (P, B)
    # Each UAV's pairs gathered pair-major, (N, N − 1, B): the minimum runs along the batch.
    # (`np.minimum.reduce` and the like below: the methods' numbers without their wrappers)
    min_uu = np.ascontiguousarray(np.minimum.reduce(d_pair[members], axis=1, initial=np.inf).T)
    return Approaches(
        min_u2o_m=np.where(present, np.minimum.reduce(d_uo, axis=-1, initial=np.inf), np.inf),
        min_u2u_m=min_uu,
        target_m=np.where(acted, swept[k_uo + k_uu :].T, np.inf),
    )


@dataclass(frozen=True)
class Outcome:
    """What the approaches of a step decide (step 3); (B, N) per UAV, (B,) per environment.

    Attributes:
        collided_u2o, collided_u2u: UAVs that came closer than d_col, by kind.
        arrived: UAVs that reached their target this step (without colliding).
        reached: UAVs that have reached their target so far.
        active: UAVs that fly the next step.
        steps: decision steps of each episode, this one included.
        terminated: a collision, or every UAV arrived.  truncated: the step limit.
        success: every UAV arrived and nothing collided.
    """

    collided_u2o: BoolArray
    collided_u2u: BoolArray
    arrived: BoolArray
    reached: BoolArray
    active: BoolArray
    steps: IntArray
    terminated: BoolArray
    truncated: BoolArray
    success: BoolArray

    @property
    def collided(self) -> BoolArray:
        """(B, N) UAVs that collided, either kind."""
        both: BoolArray = self.collided_u2o | self.collided_u2u
        return both

    @property
    def over(self) -> BoolArray:
        """(B,) environments whose episode ended this step."""
        ended: BoolArray = self.terminated | self.truncated
        return ended


def outcome(
    state: SwarmState, acted: BoolArray, near: Approaches, d_col_m: float, max_steps: int
) -> Outcome:
    """Collisions, arrivals and the end of episodes (step 3 of the module docstring).

    A collision counts for every UAV whose separation counted (`closest_approaches`): a
    hovering UAV that is run into has collided too.
    """
    collided_u2o = near.min_u2o_m < d_col_m
    collided_u2u = near.min_u2u_m < d_col_m
    collided = collided_u2o | collided_u2u
    arrived = acted & ~collided & (near.target_m <= d_col_m)
    any_collision = cast(BoolArray, np.logical_or.reduce(collided, axis=-1))
    reached = state.reached | arrived
    all_reached = cast(BoolArray, np.logical_and.reduce(reached, axis=-1))
    running = cast(BoolArray, np.logical_or.reduce(acted, axis=-1))
    terminated = running & (any_collision | all_reached)
    steps = state.steps + running
    truncated = running & ~terminated & (steps >= max_steps)
    over = terminated | truncated
    return Outcome(
        collided_u2o=collided_u2o,
        collided_u2u=collided_u2u,
        arrived=arrived,
        reached=reached,
        active=acted & ~arrived & ~over[:, None],
        steps=steps,
        terminated=terminated,
        truncated=truncated,
        success=terminated & all_reached & ~any_collision,
    )


def score(
    state: SwarmState,
    flight: Flight,
    turn: FloatArray,
    acted: BoolArray,
    collided: BoolArray,
    cfg: ScenarioConfig,
    heading_cos_sin: tuple[FloatArray, FloatArray] | None = None,
) -> tuple[ArcWindow, RewardTerms]:
    """Score the new arcs on the mid-step field, push them into the windows, reward (step 4).

    ``heading_cos_sin``: cos and sin of the headings after the step, where the caller has them.

    Returns:
        The contour windows with this step's arcs, and every reward term (B, N), zero for the
        UAVs that did not fly.
    """
    mid = state.sources(cfg.uav.speed_m_s, 0.5 * cfg.dt_s)
    stride = cfg.substeps // cfg.reward.quadrature_intervals
    qx = flight.uav_x[::stride].transpose(1, 2, 0)  # (B, N, Q + 1)
    qy = flight.uav_y[::stride].transpose(1, 2, 0)
    ext = arc_external_xy(
        np.ascontiguousarray(qx),
        np.ascontiguousarray(qy),
        state.levels.astype(np.float32),
        mid,
        cfg.field,
        cfg.reward,
    ).astype(np.float64)
    window = state.window.push(turn, ext, acted)
    terms = reward(
        window,
        flight.heading_rad,
        flight.pos_m,
        state.target_m,
        collided,
        cfg.uav.max_turn_rad,
        cfg.reward,
        heading_cos_sin,
    )
    zeroed = (np.where(acted, getattr(terms, f.name), 0.0) for f in dataclasses.fields(terms))
    return window, RewardTerms(*zeroed)


def accumulate(
    stats: EpisodeStats,
    turn: FloatArray,
    flown_m: FloatArray,
    near: Approaches,
    terms: RewardTerms,
) -> EpisodeStats:
    """The episode accumulators after one step (``flown_m`` (B, N): distance flown in it)."""
    return EpisodeStats(
        energy_rad=stats.energy_rad + np.abs(turn),
        flown_m=stats.flown_m + flown_m,
        min_u2o_m=np.minimum(stats.min_u2o_m, np.minimum.reduce(near.min_u2o_m, axis=-1)),
        min_u2u_m=np.minimum(stats.min_u2u_m, np.minimum.reduce(near.min_u2u_m, axis=-1)),
        swarming_return=stats.swarming_return + terms.swarming,
        total_return=stats.total_return + terms.total,
    )


def begin_avoidance(
    state: SwarmState,
    obs: Observations,
    over: BoolArray,
    cfg: ScenarioConfig,
    rng: np.random.Generator,
) -> tuple[SwarmState, BoolArray]:
    """Reassign the contour levels where avoidance begins (step 5).

    Avoidance begins in an environment whose episode goes on, on the first step on which a
    flying UAV senses an obstacle in ``obs``.

    Returns:
        The state with the new levels, and (B,) where they were assigned.
    """
    active = state.active
    begin = (
        ~state.avoiding & ~over & np.logical_or.reduce(obs.sensed & active[..., None], axis=(1, 2))
    )
    if not begin.any():
        return state, begin
    sub = FieldSources(
        state.obstacle_pos_m[begin],
        state.obstacle_speed_m_s[begin],
        state.centre_m[begin],
        cfg.uav.speed_m_s,
        state.obstacle_visible[begin],
    )
    levels, _ = assign_contour_levels(
        state.pos_m[begin], sub, cfg.field, cfg.pso, rng, active[begin]
    )
    new_levels = state.levels.copy()
    new_levels[begin] = levels
    return state.evolve(levels=new_levels, avoiding=state.avoiding | begin), begin

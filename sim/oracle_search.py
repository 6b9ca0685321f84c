"""The oracle's search (`sim.oracle`): prioritised space-time beam search over known futures.

Given episodes whose every obstacle it may know, `plan_known` plans every UAV: obstacles fly
straight at constant velocity and never react; UAVs fly exactly the arcs they are told to. It
searches heading changes within the turn limit for *every* UAV of an episode and labels the
episode solvable only when the simulator itself flies the plan to success. `sim.oracle` decides
what the UAVs may know when (late pop-ups) and calls this search once per phase.

**Method.** UAVs are planned one at a time, in a priority order, each against the obstacles'
tracks and the fixed trajectories of the UAVs planned before it: a planned UAV is avoided up to
and including the step on which it arrives and is gone after it, as in the simulator. A UAV
first tries the straight line to its target (no action); where that collides it flies straight
until ``lookback_steps`` before the collision, then beam-searches, batched over episodes and
over beam × candidates: every node (position, heading) expands by ``turns`` evenly spaced turns
in [−a_max, a_max] and the turn toward its target; a candidate arc whose swept distance
(`sim.metrics`, on the simulator's T + 1 sub-steps) to an obstacle or live planned UAV is below
d_col + ``margin_m`` is pruned (`_hits`: cheap lower bounds first); one within d_col −
``arrive_margin_m`` of its target ends the search (the earliest arrival); the rest are ranked by
the steps still to go (distance beyond the arrival radius in step lengths, plus the heading
error in turn limits), the best of each position cell and heading bin stays, and the best
``beam`` are kept. Where that finds nothing, a ``wide_beam`` search runs from the start. Each
plan is replayed with the simulator's arithmetic (`_follow`) before the next UAV plans against
it. An episode where a UAV finds no plan is retried in another priority order (`_orders`),
unless that UAV was planned first, against the obstacles alone (other orders only add to them).

Memory: the movers' grids, 8·S·(T + 1)·B·(M + N) bytes (46 MB for 200 episodes of 50u8o).

One module for one concept, over the usual 400 lines: the search, its pruning bounds and the
replay share one context and must repeat the simulator's arithmetic exactly; split, they would
expose that context between modules for no reader's benefit.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from sim.arrays import BoolArray, Float32Array, FloatArray, IntArray
from sim.config import ScenarioConfig
from sim.kinematics import sinc_series, wrap_angle
from sim.metrics import substep_fractions, swept_min_distance_xy
from sim.spawn import EpisodeStart
from sim.swarm import SwarmSim

F32 = np.float32

FAN_SAMPLES = 257
"""Turns sampled over [−a_max, a_max] to size the discs that hold a node's arcs (`_context`):
neighbouring samples' points lie millimetres apart, far inside ``FAN_SLACK_M``."""

FAN_SLACK_M = 0.05
"""Added to the radius of those discs, metres: covers their sampling and the float32 grid."""

SEARCH_SLACK_M = 0.01
"""How much stricter the search's checks are than the replay's (`_follow`), metres: the search
rotates precomputed arcs (errors below 1e-4 m), the replay repeats the simulator's arithmetic."""

ROUND_DECIMALS = 6
"""Distances to the target are rounded to micrometres for the priority order, so that the UAVs
of one formation row tie exactly (and go by their threat)."""


@dataclass(frozen=True)
class OracleConfig:
    """Search settings of the oracle (`plan_episodes`)."""

    beam: int = 32
    """W: nodes kept per step and episode (50u8o, 100 episodes, one order, no wide search: 12
    plan 0.39 of them, 16 and 32 all; 32 leaves room for harder families at 1.5× the time)."""

    wide_beam: int = 128
    """W of a second search, from the start, for the few UAVs whose first one found nothing."""

    turns: int = 9
    """Evenly spaced heading changes over [−a_max, a_max] per expansion (odd: 0 is one), 11.25°
    apart at a_max = 45°; the turn toward the target is added to them."""

    margin_m: float = 0.5
    """Added to d_col for the collision checks, metres. The replay repeats the simulator's
    float32 grid, so this only absorbs last-bit differences; verification is the real guard."""

    arrive_margin_m: float = 0.05
    """Taken from d_col for arrival, metres: a planned arrival is one the simulator also sees
    (an earlier one in the simulator is harmless; a later one would leave the UAV flying)."""

    cell_m: float = 20.0
    """Side of the position cells of the beam's duplicates, metres (one step): coarse cells
    spread the beam (the 50u8o episodes above at W = 32: 5, 10, 15, 20, 30 m plan 0.41, 0.91,
    1, 1, 1; 20u4o with obstacles at 8 m/s, all defaults: 10 m 0.96, 20 m 1)."""

    heading_bins: int = 16
    """Heading bins (over 2π) of the beam's duplicates: 22.5°, two turn-grid spacings."""

    heading_weight: float = 0.5
    """Weight of the heading error (in turn limits) in the steps to go: among nodes equally far
    from their target, those pointing at it first."""

    lookback_steps: int = 8
    """A UAV whose straight flight collides searches from this many steps before the collision
    (160 m at the defaults), flying straight until then (4 and 12 did no better)."""

    orders: int = 6
    """Priority orders (attempts) per episode, at most; an order already tried is skipped."""

    seed: int = 0
    """Seed of the random priority orders."""


@dataclass(frozen=True)
class OraclePlans:
    """The oracle's plans and labels for B episodes.

    Attributes:
        actions: (B, S, N) normalised actions per decision step, S = ``cfg.max_steps`` (0 after
            a UAV's planned arrival, and everywhere in an episode without a plan).
        planned: (B,) the planner found a plan it believes.
        solvable: (B,) the simulator flew the plan to success (the label).
    """

    actions: Float32Array
    planned: BoolArray
    solvable: BoolArray


@dataclass
class _Context:
    """One batch: the movers' sub-step grids (obstacles, then planned UAVs) and constants."""

    cfg: ScenarioConfig
    oracle: OracleConfig
    start: FloatArray  # (B, N, 2)
    target: FloatArray  # (B, N, 2)
    heading: FloatArray  # (B, N): initial headings
    movers_x: Float32Array  # (S, T + 1, B, M + N)
    movers_y: Float32Array
    live: BoolArray  # (S, B, M + N): the mover flies (is checked against) at that step
    reach_m: FloatArray  # (B, M + N): how far each mover moves in one step
    fractions: Float32Array  # (T + 1,)
    fan_along_m: FloatArray  # (T + 1,): discs, in a node's frame, holding all its arcs' points
    fan_radius_m: FloatArray


def _arc(
    pos: FloatArray, heading: FloatArray, turn: FloatArray, cfg: ScenarioConfig, frac: Float32Array
) -> tuple[Float32Array, Float32Array, FloatArray, FloatArray]:
    """`sim.transition.fly`'s arc of ``turn`` (…): grid x, y (T + 1, …), end position, heading."""
    u = frac.reshape((-1,) + (1,) * turn.ndim)
    half = (F32(0.5) * u) * turn.astype(F32)
    chord = (F32(cfg.step_length_m) * u) * sinc_series(half)
    direction = heading.astype(F32) + half
    px = pos[..., 0].astype(F32) + chord * np.cos(direction)
    py = pos[..., 1].astype(F32) + chord * np.sin(direction)
    end_chord, end_dir = cfg.step_length_m * sinc_series(0.5 * turn), heading + 0.5 * turn
    new_pos = pos + end_chord[..., None] * np.stack([np.cos(end_dir), np.sin(end_dir)], axis=-1)
    return px, py, new_pos, wrap_angle(heading + turn)


def _context(cfg: ScenarioConfig, ep: EpisodeStart, oracle: OracleConfig) -> _Context:
    s, b, n, m = cfg.max_steps, ep.num_envs, cfg.uav.count, cfg.obstacles.count
    frac = substep_fractions(cfg.substeps)
    frac32 = frac.astype(F32)
    tdt = (cfg.dt_s * frac).astype(F32)[:, None, None]
    mx = np.zeros((s, cfg.substeps + 1, b, m + n), dtype=F32)
    my = np.zeros_like(mx)
    pos, vel = ep.obstacle_pos_m.copy(), ep.obstacle_vel_m_s
    for t in range(s):  # the simulator's float64 accumulation, then its float32 grid
        mx[t, :, :, :m] = pos[..., 0].astype(F32) + tdt * vel[..., 0].astype(F32)
        my[t, :, :, :m] = pos[..., 1].astype(F32) + tdt * vel[..., 1].astype(F32)
        pos = pos + cfg.dt_s * vel
    live = np.zeros((s, b, m + n), dtype=bool)
    live[:, :, :m] = True
    speed = np.hypot(vel[..., 0], vel[..., 1])
    reach = np.concatenate([cfg.dt_s * speed, np.full((b, n), cfg.step_length_m)], axis=-1)
    a_max = cfg.uav.max_turn_rad
    fan_turn = np.linspace(-a_max, a_max, FAN_SAMPLES)
    fx, fy, _, _ = _arc(np.zeros((FAN_SAMPLES, 2)), 0 * fan_turn, fan_turn, cfg, frac32)
    along = 0.5 * (fx.max(axis=1) + fx.min(axis=1)).astype(np.float64)
    radius = np.hypot(fx - along[:, None], fy).max(axis=1) + FAN_SLACK_M
    return _Context(
        cfg,
        oracle,
        ep.start_m,
        ep.target_m,
        ep.headings(),
        mx,
        my,
        live,
        reach,
        frac32,
        along,
        radius,
    )


def _nearest(gap: FloatArray, limit: float) -> tuple[IntArray, BoolArray] | None:
    """Indices (…, k) of the smallest ``gap`` (…, K) and which of them are below ``limit``.

    k is the most below it in any row; None where none is.
    """
    near: BoolArray = gap < limit
    k = int(near.sum(axis=-1).max(initial=0))
    if k == 0:
        return None
    if k < gap.shape[-1]:
        idx: IntArray = np.argpartition(gap, k - 1, axis=-1)[..., :k]
    else:
        idx = np.broadcast_to(np.arange(gap.shape[-1]), gap.shape)
    return idx, np.take_along_axis(near, idx, axis=-1)


def _hits(
    ctx: _Context,
    t: int,
    eps: IntArray,
    node: tuple[FloatArray, FloatArray, BoolArray],
    px: Float32Array,
    py: Float32Array,
    d_safe: float,
) -> BoolArray:
    """(A, W, C) candidates whose swept distance to a live mover at step ``t`` is < ``d_safe``.

    ``node``: the position (A, W, 2), heading and validity (not an empty slot) of the nodes
    whose candidates' grids are ``px``, ``py`` (T + 1, A, W, C). Two lower bounds of the swept
    distance drop far movers per node: from the start of the step (both move at most their
    reach), then from the discs that hold all the node's arcs at each sub-step (minus half a
    sub-step of both motions); the exact swept check runs on the (node, mover) pairs left.
    """
    cfg, (pos, heading, valid) = ctx.cfg, node
    tt, a, w, c = px.shape
    hits = np.zeros((a * w, c), dtype=bool)
    mx, my = ctx.movers_x[t][:, eps], ctx.movers_y[t][:, eps]  # (T + 1, A, K)
    reach = ctx.reach_m[eps]  # (A, K)
    gap = np.hypot(pos[..., 0, None] - mx[0, :, None], pos[..., 1, None] - my[0, :, None])
    gap -= reach[:, None, :] + cfg.step_length_m
    gap[~(ctx.live[t][eps, None, :] & valid[..., None])] = np.inf
    if (found := _nearest(gap, d_safe)) is None:
        return hits.reshape(a, w, c)
    rows, movers, near = np.arange(a)[:, None, None], found[0], found[1]  # (A, W, k)
    gx, gy = mx[:, rows, movers], my[:, rows, movers]  # (T + 1, A, W, k)
    along = ctx.fan_along_m[:, None, None]
    cx, cy = pos[..., 0] + along * np.cos(heading), pos[..., 1] + along * np.sin(heading)
    fan = np.hypot(gx - cx[..., None], gy - cy[..., None]) - ctx.fan_radius_m[:, None, None, None]
    lower = fan.min(axis=0) - (cfg.step_length_m + reach[rows, movers]) / (2 * cfg.substeps)
    near &= lower < d_safe
    nodes = np.flatnonzero(near.any(axis=-1))
    found = _nearest(np.where(near, lower, np.inf).reshape(a * w, -1)[nodes], d_safe)
    if found is None:
        return hits.reshape(a, w, c)
    pick, close = found  # (P, k2)
    gx = np.take_along_axis(gx.reshape(tt, a * w, -1)[:, nodes], pick[None], axis=-1)
    gy = np.take_along_axis(gy.reshape(tt, a * w, -1)[:, nodes], pick[None], axis=-1)
    qx, qy = px.reshape(tt, a * w, c)[:, nodes], py.reshape(tt, a * w, c)[:, nodes]
    swept = swept_min_distance_xy(
        np.subtract(qx[..., None], gx[:, :, None, :], order="C"),
        np.subtract(qy[..., None], gy[:, :, None, :], order="C"),
    )  # (P, C, k2)
    hits[nodes] = ((swept < d_safe) & close[:, None, :]).any(axis=-1)
    return hits.reshape(a, w, c)


def _to_target(px: Float32Array, py: Float32Array, target: FloatArray) -> NDArray[Any]:
    """Swept distance (A, …) of grids (T + 1, A, …) to their targets (A, 2)."""
    tx, ty = (target[:, k].reshape(-1, *(1,) * (px.ndim - 2)).astype(F32) for k in (0, 1))
    return swept_min_distance_xy(px - tx, py - ty)


def _expand(
    ctx: _Context, pos: FloatArray, heading: FloatArray, target: FloatArray
) -> tuple[Float32Array, Float32Array, Float32Array, FloatArray, FloatArray]:
    """Candidates of nodes (A, W): actions (A, W, C), grids (T + 1, A, W, C), ends, headings.

    The evenly spaced turns are precomputed arcs rotated onto each node; the turn toward the
    target is flown by `_arc`.
    """
    cfg, a_max = ctx.cfg, ctx.cfg.uav.max_turn_rad
    bearing = np.arctan2(target[:, None, 1] - pos[..., 1], target[:, None, 0] - pos[..., 0])
    toward = np.clip(wrap_angle(bearing - heading) / a_max, -1.0, 1.0).astype(F32)
    tx, ty, t_end, t_head = _arc(
        pos, heading, toward.astype(np.float64) * a_max, cfg, ctx.fractions
    )
    grid = np.linspace(-1.0, 1.0, ctx.oracle.turns, dtype=F32)
    turns = grid.astype(np.float64) * a_max  # as `sim.kinematics.scale_action`
    gx, gy, grid_end, _ = _arc(np.zeros((len(grid), 2)), 0 * turns, turns, cfg, ctx.fractions)
    ex, ey = grid_end.T
    cos, sin = np.cos(heading)[..., None], np.sin(heading)[..., None]
    c32, s32 = cos.astype(F32), sin.astype(F32)
    px = pos[..., 0, None].astype(F32) + (c32 * gx[:, None, None] - s32 * gy[:, None, None])
    py = pos[..., 1, None].astype(F32) + (s32 * gx[:, None, None] + c32 * gy[:, None, None])
    end = pos[..., None, :] + np.stack([cos * ex - sin * ey, sin * ex + cos * ey], axis=-1)
    grid_head = wrap_angle(heading[..., None] + turns)
    acts = np.broadcast_to(grid, grid_head.shape)
    return (
        np.concatenate([acts, toward[..., None]], axis=-1),
        np.concatenate([px, tx[..., None]], axis=-1),
        np.concatenate([py, ty[..., None]], axis=-1),
        np.concatenate([end, t_end[..., None, :]], axis=-2),
        np.concatenate([grid_head, t_head[..., None]], axis=-1),
    )


def _select(
    cost: FloatArray, pos: FloatArray, heading: FloatArray, o: OracleConfig, beam: int
) -> IntArray:
    """Columns (A, beam) of the cheapest ``cost`` (A, X), the cheapest of each cell and bin."""
    cx, cy = (np.floor(pos[..., k] / o.cell_m).astype(np.int64) for k in (0, 1))
    bins = np.floor((heading + np.pi) / (2 * np.pi) * o.heading_bins).astype(np.int64)
    keys = ((cx * 1_000_003 + cy) * (o.heading_bins + 1) + bins).reshape(cost.shape)
    by_cost = np.argsort(cost, axis=-1, kind="stable")
    ordered = np.take_along_axis(keys, by_cost, -1)
    by_key = np.argsort(ordered, axis=-1, kind="stable")  # stable: the cheapest first in a key
    grouped = np.take_along_axis(ordered, by_key, -1)
    dup = np.zeros(grouped.shape, dtype=bool)
    dup[:, 1:] = grouped[:, 1:] == grouped[:, :-1]
    np.put_along_axis(dup, by_key, dup.copy(), -1)  # back to cost order
    best = np.argsort(
        np.where(dup, np.inf, np.take_along_axis(cost, by_cost, -1)), -1, kind="stable"
    )
    keep: IntArray = np.take_along_axis(by_cost, best[:, :beam], -1)
    return keep


def _search(
    ctx: _Context, eps: IntArray, uav: IntArray, beam: int, first: IntArray
) -> Float32Array:
    """Beam-search one UAV per episode ``eps`` (E,): actions (E, S), zeros where none is found.

    Each UAV flies straight to its target until step ``first`` (E,) and searches from there.
    """
    cfg, o = ctx.cfg, ctx.oracle
    s, e, a_max = cfg.max_steps, len(eps), cfg.uav.max_turn_rad
    d_safe = cfg.d_col_m + o.margin_m + SEARCH_SLACK_M
    d_arrive = cfg.d_col_m - o.arrive_margin_m - SEARCH_SLACK_M
    target, start = ctx.target[eps, uav], ctx.start[eps, uav]
    course = ctx.heading[eps, uav]  # straight on, until the search starts
    straight = start + (first * cfg.step_length_m)[:, None] * np.stack(
        [np.cos(course), np.sin(course)], axis=-1
    )
    alive = np.zeros(0, dtype=np.int64)  # the episodes searching now: A
    pos, heading, valid = np.zeros((0, beam, 2)), np.zeros((0, beam)), np.zeros((0, beam), bool)
    parents = np.zeros((s, e, beam), dtype=np.int64)
    taken = np.zeros((s, e, beam), dtype=F32)
    end_step, end_slot, end_action = np.full(e, -1), np.zeros(e, np.int64), np.zeros(e, F32)
    for t in range(s):
        join = np.flatnonzero(first == t)
        alive = np.concatenate([alive, join])
        pos = np.concatenate([pos, np.repeat(straight[join, None], beam, axis=1)])
        heading = np.concatenate([heading, np.repeat(course[join, None], beam, axis=1)])
        valid = np.concatenate([valid, np.arange(beam) == np.zeros((len(join), 1))])
        if len(alive) == 0:
            continue
        tgt = target[alive]
        acts, px, py, end_pos, end_head = _expand(ctx, pos, heading, tgt)
        a, w, c = acts.shape
        ok = valid[..., None] & ~_hits(ctx, t, eps[alive], (pos, heading, valid), px, py, d_safe)
        arrived = (ok & (_to_target(px, py, tgt) <= d_arrive)).reshape(a, w * c)
        done, rest = arrived.any(axis=-1), ~arrived.any(axis=-1)
        pick = np.argmax(arrived[done], axis=-1)
        ids = alive[done]
        end_step[ids], end_slot[ids] = t, pick // c
        end_action[ids] = acts.reshape(a, w * c)[done][np.arange(len(ids)), pick]
        gap = tgt[rest, None, None, :] - end_pos[rest]
        dist = np.hypot(gap[..., 0], gap[..., 1])
        err = np.abs(wrap_angle(np.arctan2(gap[..., 1], gap[..., 0]) - end_head[rest]))
        h = np.maximum(dist - d_arrive, 0.0) / cfg.step_length_m + o.heading_weight * err / a_max
        h = np.where(ok[rest], h, np.inf).reshape(-1, w * c)
        keep = _select(h, end_pos[rest], end_head[rest], o, beam)
        alive = alive[rest]
        parents[t, alive] = keep // c
        taken[t, alive] = np.take_along_axis(acts.reshape(a, w * c)[rest], keep, -1)
        pos = np.take_along_axis(end_pos.reshape(a, w * c, 2)[rest], keep[..., None], 1)
        heading = np.take_along_axis(end_head.reshape(a, w * c)[rest], keep, -1)
        valid = np.isfinite(np.take_along_axis(h, keep, -1))
        more = valid.any(axis=-1)
        alive, pos, heading, valid = alive[more], pos[more], heading[more], valid[more]
        if len(alive) == 0 and t >= first.max():
            break
    actions = np.zeros((e, s), dtype=F32)
    found = end_step >= 0
    actions[found, end_step[found]] = end_action[found]
    for t in range(s - 2, -1, -1):  # back through the parents
        sel = np.flatnonzero((end_step > t) & (first <= t))
        actions[sel, t] = taken[t, sel, end_slot[sel]]
        end_slot[sel] = parents[t, sel, end_slot[sel]]
    return actions


def _follow(
    ctx: _Context, eps: IntArray, uav: IntArray, actions: Float32Array
) -> tuple[IntArray, IntArray, Float32Array, Float32Array]:
    """Replay actions (E, S) with the simulator's arithmetic against the movers.

    Returns:
        (the arrival step, −1 where the UAV collides or never arrives; the step of the
        collision, S where none; the UAV's grids (S, T + 1, E)).
    """
    cfg, o = ctx.cfg, ctx.oracle
    s, e = cfg.max_steps, len(eps)
    target, pos = ctx.target[eps, uav], ctx.start[eps, uav].copy()
    heading = ctx.heading[eps, uav].copy()
    px = np.zeros((s, cfg.substeps + 1, e), dtype=F32)
    py = np.zeros_like(px)
    end, crash, flying = np.full(e, -1), np.full(e, s), np.arange(e)
    for t in range(s):
        if len(flying) == 0:
            break
        turn = actions[flying, t].astype(np.float64) * cfg.uav.max_turn_rad
        gx, gy, new_pos, new_head = _arc(pos[flying], heading[flying], turn, cfg, ctx.fractions)
        px[t][:, flying], py[t][:, flying] = gx, gy
        node = (pos[flying, None], heading[flying, None], np.ones((len(flying), 1), dtype=bool))
        grid = (gx[:, :, None, None], gy[:, :, None, None])
        hit = _hits(ctx, t, eps[flying], node, *grid, cfg.d_col_m + o.margin_m)[:, 0, 0]
        arrived = ~hit & (_to_target(gx, gy, target[flying]) <= cfg.d_col_m - o.arrive_margin_m)
        end[flying[arrived]], crash[flying[hit]] = t, t
        pos[flying], heading[flying] = new_pos, new_head
        flying = flying[~hit & ~arrived]
    return end, crash, px, py


def _orders(cfg: ScenarioConfig, ep: EpisodeStart, count: int, seed: int) -> IntArray:
    """(count, B, N) priority orders of the UAVs, the first planned first.

    Nearest the target first (a formation's front row first, the most threatened within a row
    first), most threatened first (closest approach of its straight flight to an obstacle),
    nearest the target last, then seeded random orders. Alone, with no wide search, they plan
    1.0, 0.66, 0.08 and 0.35 of 100 50u8o episodes. The random orders are the same for every
    episode (drawn from ``seed`` and N alone), so that an episode's plan and label never depend
    on which episodes are planned beside it, nor on where it stands among them.
    """
    b, n, s = ep.num_envs, cfg.uav.count, cfg.max_steps
    delta = ep.target_m - ep.start_m
    dist = np.hypot(delta[..., 0], delta[..., 1])
    t = cfg.dt_s * np.arange(s + 1)  # straight flight, sampled at the decision instants
    frac = np.minimum(t * cfg.uav.speed_m_s / np.maximum(dist, 1e-9)[..., None], 1.0)
    path = ep.start_m[..., None, :] + frac[..., None] * delta[..., None, :]  # (B, N, S + 1, 2)
    obs = ep.obstacle_pos_m[:, :, None, :] + t[:, None] * ep.obstacle_vel_m_s[:, :, None, :]
    gap = path[:, :, None] - obs[:, None]  # (B, N, M, S + 1, 2)
    threat = np.hypot(gap[..., 0], gap[..., 1]).min(axis=(2, 3), initial=np.inf)
    front = np.lexsort((threat, np.round(dist, ROUND_DECIMALS)), axis=-1)
    rng = np.random.default_rng(seed)
    base = [front, np.argsort(threat, axis=-1, kind="stable"), front[:, ::-1]]
    extra = [np.broadcast_to(rng.permutation(n), (b, n)) for _ in range(count)]
    return np.stack((base + extra)[:count])


def plan_known(
    cfg: ScenarioConfig, episodes: EpisodeStart, oracle: OracleConfig = OracleConfig()
) -> OraclePlans:
    """Plan every UAV of every episode, knowing every obstacle; label them by flying the plans.

    The caller (`sim.oracle.plan_episodes`) hides what the UAVs may not know yet.

    Args:
        cfg: the scenario (speed, turn limit, d_col, step, sub-steps, step limit).
        episodes: B episodes of ``cfg``'s N UAVs and M obstacles.
        oracle: the search settings.

    Raises:
        ValueError: the episodes do not have the scenario's N UAVs and M obstacles.
    """
    b, n, s, m = episodes.num_envs, cfg.uav.count, cfg.max_steps, cfg.obstacles.count
    episodes.check(cfg)
    ctx = _context(cfg, episodes, oracle)
    orders = _orders(cfg, episodes, oracle.orders, oracle.seed)
    actions = np.zeros((b, s, n), dtype=F32)
    planned, solvable = np.zeros(b, dtype=bool), np.zeros(b, dtype=bool)
    hopeless = np.zeros(b, dtype=bool)  # a UAV found no plan against the obstacles alone
    for attempt in range(oracle.orders):
        tried = (orders[:attempt] == orders[attempt]).all(axis=-1).any(axis=0)
        todo = np.flatnonzero(~solvable & ~tried & ~hopeless)
        if len(todo) == 0:
            continue
        ctx.live[:, todo, m:] = False
        plan = np.zeros((len(todo), s, n), dtype=F32)
        ok = np.ones(len(todo), dtype=bool)
        for rank in range(n):
            sel = np.flatnonzero(ok)
            eps, uav = todo[sel], orders[attempt, todo[sel], rank]
            acts = np.zeros((len(sel), s), dtype=F32)
            end, crash, px, py = _follow(ctx, eps, uav, acts)  # straight to the target first
            # Straight on collides: search from a little before; never arrives: from the start.
            first = np.where(crash < s, np.maximum(crash - oracle.lookback_steps, 0), 0)
            for beam in (oracle.beam, oracle.wide_beam):
                if len(bent := np.flatnonzero(end < 0)) == 0:
                    break
                acts[bent] = _search(ctx, eps[bent], uav[bent], beam, first[bent])
                end[bent], _, px[..., bent], py[..., bent] = _follow(
                    ctx, eps[bent], uav[bent], acts[bent]
                )
                first[:] = 0  # the wide search starts at the beginning
            ok[sel] = got = end >= 0
            hopeless[eps[~got]] |= rank == 0
            if not got.any():
                break
            plan[sel[got], :, uav[got]] = acts[got]
            ctx.movers_x[:, :, eps[got], m + uav[got]] = px[..., got]  # now a mover for the next
            ctx.movers_y[:, :, eps[got], m + uav[got]] = py[..., got]
            ctx.live[:, eps[got], m + uav[got]] = np.arange(s)[:, None] <= end[got]
        new = todo[ok]
        actions[new], planned[new] = plan[ok], True
        solvable[new] = fly_plans(cfg, episodes.take(new), plan[ok])
    return OraclePlans(actions=actions, planned=planned, solvable=solvable)


def fly_plans(cfg: ScenarioConfig, episodes: EpisodeStart, actions: Float32Array) -> BoolArray:
    """Fly (B, S, N) actions in the simulator (unscored); (B,) whether each episode succeeded."""
    success = np.zeros(episodes.num_envs, dtype=bool)
    if episodes.num_envs == 0:
        return success
    sim, rng = SwarmSim(cfg, scored=False), np.random.default_rng(0)
    state = sim.start(episodes, rng)
    for t in range(actions.shape[1]):
        state, result = sim.step(state, actions[:, t], rng)
        success |= result.success
        if not state.active.any():
            break
    return success

"""A reciprocal velocity-obstacle controller (ORCA) for constant-speed, turn-limited UAVs.

A classical, hand-written baseline: no learning, no field. Per decision step every active UAV

1. lists C = K + 1 candidate heading changes: K evenly spaced over [−a_max, a_max] (0 included)
   and the turn that points it at its target, clipped to the turn limit;
2. predicts its own motion for each candidate: the constant-turn-rate arc the simulator flies
   during the first step (`sim.prediction`, sampled at its `ARC_SEGMENTS` chords), then
   straight flight on the arc's final heading — the swept arc, not only the velocity held at
   its end;
3. checks every candidate against every sensed obstacle and every other active UAV (below);
4. flies the free candidate whose final heading is nearest the goal heading (the direction to
   its own target); when none is free, see *No free candidate*.

**Obstacles** do not avoid, and fly straight at constant velocity — exactly what the simulator
does — so their check is exact rather than linearised: the closest approach of the relative
motion r(t) = (p_A − p_o) + d_A(t) − v_o·t over [0, τ_o] (d_A the candidate's displacement),
segment by segment in closed form, must stay outside R = d_col + ``margin_m``. A UAV knows an
obstacle only while it senses it: within ``cfg.sensing.range_m`` *and* inside the aperture
``cfg.sensing.aperture_rad`` around its heading, the observation builder's test
(`sim.observation`).

**Neighbours share the avoidance: ORCA** (van den Berg, Guy, Lin, Manocha, "Reciprocal n-body
collision avoidance", 2011; the RVO2 library's construction, line for line). For each pair A, B
with relative position p = p_B − p_A and relative velocity v = v_A − v_B, the velocity obstacle
VO^τ is the cone of relative velocities that bring B within R of A before τ_u, truncated by the
disc of centre p/τ_u and radius R/τ_u. Let u be the smallest change of v that leaves VO^τ (to
the nearest point of its boundary) and n the boundary's outward normal there. A takes half of
it: its admissible velocities are the half-plane (v'_A − (v_A + u/2))·n ≥ 0; B, computing the
same pair with the signs swapped, gets (v'_B − (v_B − u/2))·n ≤ 0. Both agree on u and n, so
they escape to complementary sides, and when both stay in their half-planes the relative
velocity leaves VO^τ. A pair already closer than R uses the step instead of τ_u (leave the
overlap within one decision step), as RVO2 does. In an exactly symmetric head-on encounter both
take the same leg of the cone (RVO2's tie rule), which is a right turn for both.

*Right of way (departure from plain ORCA's halves).* A UAV whose way to its goal an obstacle
blocks (its goal-heading candidate is not clear of the obstacles) is busy: it gives its share
of every pair with an unblocked neighbour to that neighbour, by `OBSTACLE_PRIORITY` (ORCA with
unequal responsibilities: A moves the line to v_A + α_A·u and B to v_B − (1 − α_A)·u, so they
still agree). At the default the busy UAV's line passes through its own velocity (it may not
turn further into the neighbour, and need not turn away), and the neighbour takes all of u.
Without it the middle UAVs, sidestepping an obstacle into their wingmen's lanes, meet wingmen
that give way by only half (sweep, defaults otherwise: 97.0% and 95.0% success in 5u2o and
7u2o instead of 100%; 85.0% and 84.0% at a 2.5 m margin).

Our candidates have one speed and a limited turn, so we test rather than optimise: a candidate's
velocity is the *mean* velocity of its predicted motion over τ_u, d_A(τ_u)/τ_u — the arc flown
during the first step, then straight — so a hard turn is credited with what it achieves over the
horizon, not with its final heading at once. It satisfies the pair when it lies in the half-plane.
Neighbours are every other *active* UAV with its current velocity, at any distance (the swarm
shares its states; a far neighbour's half-plane lies far from anything A can fly). UAVs that
arrived or whose episode ended are inactive: the simulator keeps them in place and checks no
collision against them (`sim.transition.closest_approaches`), so they are not neighbours, and
their action is 0.

**No free candidate.** Obstacles come first: they do not cooperate and their check is exact,
while a neighbour shares the avoidance and re-plans at its own next decision. So: among the
candidates clear of every obstacle, the one that violates the neighbours' half-planes least
(the smallest largest violation, in m/s — what ORCA's fallback linear program minimises);
if none is clear of the obstacles, the one with the largest obstacle clearance, the smallest
(closest approach − R) over the obstacles — the least penetration, not the latest
time-to-collision, which would trade a certain collision later for nothing.

Exact ties between candidates equally near the goal go to the right-hand turn
(`RIGHT_OF_WAY_BIAS_RAD`, the rules of the air).

Everything is batched over (B environments, N UAVs, C candidates, M obstacles or N neighbours,
P time points) in numpy, with no Python loop over UAVs, candidates or threats.

One module over the usual 400 lines: one controller, most of it the documentation of its
construction and of the sweeps behind its constants.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from sim.arrays import BoolArray, FloatArray, IntArray
from sim.config import ScenarioConfig
from sim.kinematics import sinc_series, wrap_angle
from sim.prediction import TINY, closest_approach, displacements, time_points
from sim.state import SwarmState

HORIZON_S = 10.0
"""τ_o: how far ahead every candidate is checked against obstacles, seconds (5 decision steps,
100 m of flight at the default speed): a head-on obstacle at the 100 m sensing range closes at
12.5 m/s and arrives in 8 s, so it is in view of the check from the moment it is sensed.
In the sweep (`tools/orca_table.py --sweep`, 200 episodes per paper scenario) 14 s gave the
same results; 6 s matched it at the defaults but not everywhere (plain ORCA at τ_u = 6 s: 97.8%
mean success against 99.0%; at τ_u = 8 s 5u1o fell to 58.5%)."""

NEIGHBOUR_HORIZON_S = 6.0
"""τ_u: ORCA's time horizon against other UAVs, seconds (3 decision steps). Shorter than τ_o,
as in RVO2: both UAVs of a pair re-plan every step. In the sweep, with the defaults' margin and
right of way, 4, 6 and 8 s all reach 100% on the paper's scenarios; without the right of way a
longer horizon is worse (mean 99.8 / 99.0 / 95.2%, 7u2o down to 71.5% at 8 s), the wingmen's
velocity obstacles forbidding the sidesteps. Crossing traffic wants the longer horizon: of 300
two-UAV encounters at random angles (`tests/sim/test_orca.py`) 16 collide at 4 s, none at 6 s."""

OBSTACLE_PRIORITY = 0.5
"""Share of the avoidance that a UAV whose goal heading an obstacle blocks hands to each
unblocked neighbour, in [0, 0.5]: its responsibility for the pair is 0.5 − this, the
neighbour's 0.5 + this (plain ORCA: 0). At 0.5 the neighbour takes all of it, as the rules of
the air give the manoeuvring aircraft the right of way. The sweep's best at every horizon and
margin; at the defaults 99.0 / 99.4 / 100% mean success for 0 / 0.25 / 0.5."""

CANDIDATES = 31
"""K: evenly spaced heading changes over [−a_max, a_max], odd so that 0 is one of them:
3° apart at the paper's a_max = 45° (the ends of two neighbouring 20 m arcs lie 0.5 m apart)."""

MARGIN_M = 1.0
"""Added to d_col to get the radius R of every velocity obstacle, metres: covers the chord error
of the predicted arcs (0.12 m) with room to spare. Larger margins cost more than they buy: two
obstacles spawn 60–100 m apart, the gap between their R-discs shrinks as 60 − 2R, and the middle
UAV that no longer fits sidesteps into its wingmen (sweep, defaults otherwise: 100 / 100 / 99.2
/ 99.2% mean success at 0 / 1 / 2.5 / 5 m; plain ORCA 98.2 / 99.0 / 96.1 / 94.7%)."""

RIGHT_OF_WAY_BIAS_RAD = 1e-6
"""Added to the goal-heading error of left (counter-clockwise) turns, rad: breaks exact ties
toward the right-hand turn (the rules of the air) without changing any other choice — far below
any heading difference that matters, far above float64 rounding of angles near π."""

CLOSING_TOLERANCE_M = 1e-6
"""An obstacle already inside R counts as closing in only when its closest approach falls below
its current distance by more than this, metres (float64 rounding of the distance itself)."""


@dataclass(frozen=True)
class OrcaPlan:
    """The candidates of one decision and what the controller found about them.

    Attributes:
        turn_rad: (B, N, C) candidate heading changes, C = K + 1 (the K evenly spaced ones,
            then the clipped turn toward the goal).
        obstacle_clearance_m: (B, N, C) smallest (closest approach − R) over the sensed
            obstacles during τ_o; +inf when none is sensed. Free of obstacles when ≥ 0.
        neighbour_violation_m_s: (B, N, C) largest violation of the neighbours' ORCA
            half-planes by the candidate's mean velocity over τ_u; −inf with no neighbour.
            Free of neighbours when ≤ 0.
        goal_error_rad: (B, N, C) |final heading − goal heading|, in [0, π].
        choice: (B, N) index of the chosen candidate.
        actions: (B, N) float32 normalised heading changes in [−1, 1], 0 for inactive UAVs.
    """

    turn_rad: FloatArray
    obstacle_clearance_m: FloatArray
    neighbour_violation_m_s: FloatArray
    goal_error_rad: FloatArray
    choice: IntArray
    actions: NDArray[np.float32]

    @property
    def obstacle_free(self) -> BoolArray:
        """(B, N, C) candidates whose motion stays outside R of every sensed obstacle."""
        ok: BoolArray = self.obstacle_clearance_m >= 0.0
        return ok

    @property
    def free(self) -> BoolArray:
        """(B, N, C) candidates free of obstacles and inside every neighbour's half-plane."""
        ok: BoolArray = self.obstacle_free & (self.neighbour_violation_m_s <= 0.0)
        return ok


def orca_actions(state: SwarmState, cfg: ScenarioConfig, **settings: Any) -> NDArray[np.float32]:
    """Every UAV's action (B, N), float32 in [−1, 1], the simulator's convention (a = action·a_max).

    ``settings`` are `orca_plan`'s keywords (horizons, candidates, margin, priority); the plan
    also holds the candidates and what was found about them.
    """
    return orca_plan(state, cfg, **settings).actions


def goal_bearing_rad(state: SwarmState) -> FloatArray:
    """(B, N) the bearing from each UAV to its target, rad (world frame)."""
    to_goal = state.target_m - state.pos_m
    return np.arctan2(to_goal[..., 1], to_goal[..., 0])


def goal_turn_rad(state: SwarmState, cfg: ScenarioConfig) -> FloatArray:
    """(B, N) the turn toward each UAV's target this step, clipped to ±a_max, rad.

    What a UAV alone flies; ORCA's last candidate, and what a teacher's label departs from
    when it avoids something (`policies.generalist_dagger.label_weights`).
    """
    a_max = cfg.uav.max_turn_rad
    return np.clip(wrap_angle(goal_bearing_rad(state) - state.heading_rad), -a_max, a_max)


def orca_plan(
    state: SwarmState,
    cfg: ScenarioConfig,
    *,
    horizon_s: float = HORIZON_S,
    neighbour_horizon_s: float = NEIGHBOUR_HORIZON_S,
    candidates: int = CANDIDATES,
    margin_m: float = MARGIN_M,
    priority: float = OBSTACLE_PRIORITY,
) -> OrcaPlan:
    """One ORCA decision for B environments of N UAVs (module docstring, steps 1–4).

    Args:
        state: the simulator state (positions, headings, targets, obstacles, ``active``).
        cfg: its scenario (speed, dt, turn limit, d_col, sensing).
        horizon_s: τ_o, the horizon against obstacles, seconds, ≥ one decision step ``dt_s``.
        neighbour_horizon_s: τ_u, ORCA's horizon against other UAVs, seconds, ≥ ``dt_s``.
        candidates: K, odd and ≥ 3, so that 0 is a candidate.
        margin_m: R = d_col + margin_m, metres, ≥ 0.
        priority: the share of the avoidance a UAV blocked by an obstacle hands to each
            unblocked neighbour, in [0, 0.5] (0: plain ORCA; see `OBSTACLE_PRIORITY`).

    Raises:
        ValueError: a bad horizon, candidate count, margin or priority.
    """
    for name, value in (("horizon_s", horizon_s), ("neighbour_horizon_s", neighbour_horizon_s)):
        if not (math.isfinite(value) and value >= cfg.dt_s):
            raise ValueError(f"{name} must be >= dt_s ({cfg.dt_s}), got {value!r}")
    if candidates < 3 or candidates % 2 == 0:
        raise ValueError(f"candidates must be odd and >= 3 (0 included), got {candidates!r}")
    if not (math.isfinite(margin_m) and margin_m >= 0):
        raise ValueError(f"margin_m must be >= 0, got {margin_m!r}")
    if not 0.0 <= priority <= 0.5:
        raise ValueError(f"priority must be in [0, 0.5], got {priority!r}")
    a_max = cfg.uav.max_turn_rad
    heading, active = state.heading_rad, state.active
    b, n = heading.shape

    goal = goal_bearing_rad(state)
    toward = goal_turn_rad(state, cfg)
    grid = np.broadcast_to(np.linspace(-a_max, a_max, candidates), (b, n, candidates))
    turn = np.concatenate([grid, toward[..., None]], axis=-1)  # (B, N, C)
    goal_error = np.abs(wrap_angle(heading[..., None] + turn - goal[..., None]))

    radius_m = cfg.d_col_m + margin_m
    obstacle_clear = obstacle_clearance(state, cfg, turn, radius_m, horizon_s)
    # A UAV whose way to the goal an obstacle blocks gets the right of way over neighbours.
    blocked = obstacle_clear[..., -1] < 0.0
    violation = neighbour_violation(
        state, cfg, turn, radius_m, neighbour_horizon_s, blocked, priority
    )

    obstacle_free = obstacle_clear >= 0.0
    free = obstacle_free & (violation <= 0.0)
    cost = goal_error + RIGHT_OF_WAY_BIAS_RAD * (turn > 0)
    nearest_free = np.argmin(np.where(free, cost, np.inf), axis=-1)
    least_violation = np.argmin(np.where(obstacle_free, violation, np.inf), axis=-1)
    widest_for_obstacles = np.argmax(obstacle_clear, axis=-1)
    choice = np.where(
        free.any(axis=-1),
        nearest_free,
        np.where(obstacle_free.any(axis=-1), least_violation, widest_for_obstacles),
    )
    chosen = np.take_along_axis(turn, choice[..., None], axis=-1)[..., 0]
    actions = np.where(active, np.clip(chosen / a_max, -1.0, 1.0), 0.0).astype(np.float32)
    return OrcaPlan(turn, obstacle_clear, violation, goal_error, choice.astype(np.int64), actions)


def obstacle_clearance(
    state: SwarmState, cfg: ScenarioConfig, turn_rad: FloatArray, radius_m: float, horizon_s: float
) -> FloatArray:
    """(B, N, C) min over sensed obstacles of (closest approach over [0, τ_o] − R), +inf if none.

    The relative position r(t) = (p_A − p_o) + d_A(t) − v_o·t of every sensed (UAV, obstacle)
    pair, candidate and instant, (S, C, P), is piecewise linear in t between `time_points`.
    Only the S sensed pairs are computed (gathered by index, no loop): most of the N·M are not.
    An obstacle already inside R gets its current distance as radius: "do not close in
    further".
    """
    pos, heading = state.pos_m, state.heading_rad
    b, n, c = turn_rad.shape
    m = state.obstacle_pos_m.shape[1]
    cx = pos[:, :, None, 0] - state.obstacle_pos_m[:, None, :, 0]  # (B, N, M)
    cy = pos[:, :, None, 1] - state.obstacle_pos_m[:, None, :, 1]
    dist = np.sqrt(cx * cx + cy * cy)
    sensed = (dist <= cfg.sensing.range_m) & state.active[..., None]
    sensed &= state.obstacle_visible[:, None]  # a late pop-up is not sensed before it appears
    if cfg.sensing.aperture_rad < 2 * math.pi:  # the observation builder's sector test
        ahead = -(cx * np.cos(heading)[..., None] + cy * np.sin(heading)[..., None])
        sensed &= ahead >= dist * math.cos(0.5 * cfg.sensing.aperture_rad)
    per_obstacle = np.full((b, n, m, c), np.inf)
    env, uav, obs = np.nonzero(sensed)  # the S sensed pairs
    if env.size:
        pair = (env, uav, obs)
        times = time_points(cfg.dt_s, horizon_s)  # (P,)
        dx, dy = displacements(
            heading[env, uav], turn_rad[env, uav], cfg.uav.speed_m_s, cfg.dt_s, horizon_s
        )  # (S, C, P)
        w = state.obstacle_vel_m_s[env, obs]  # (S, 2)
        rx = (cx[pair][:, None] - w[:, 0, None] * times)[:, None] + dx
        ry = (cy[pair][:, None] - w[:, 1, None] * times)[:, None] + dy
        radius = np.minimum(radius_m, dist[pair] - CLOSING_TOLERANCE_M)
        per_obstacle[pair] = closest_approach(rx, ry) - radius[:, None]
    clearance: FloatArray = per_obstacle.min(axis=2, initial=np.inf)
    return clearance


def neighbour_violation(
    state: SwarmState,
    cfg: ScenarioConfig,
    turn_rad: FloatArray,
    radius_m: float,
    horizon_s: float,
    blocked: BoolArray,
    priority: float,
) -> FloatArray:
    """(B, N, C) largest violation of the ORCA half-planes of the other UAVs, m/s.

    Args:
        turn_rad: (B, N, C) the candidates.
        radius_m: R.  horizon_s: τ_u.
        blocked: (B, N) UAVs whose goal heading an obstacle blocks (right of way).
        priority: the share a blocked UAV hands to an unblocked neighbour.

    Returns:
        Positive: the candidate's mean velocity over τ_u lies outside some neighbour's
        half-plane by that much; ≤ 0: inside all of them; −inf with no neighbour.
    """
    own = blocked.astype(np.float64)
    share = 0.5 - priority * (own[:, :, None] - own[:, None, :])  # (B, N, N), A's responsibility
    point, direction, counts = orca_lines(state, cfg, radius_m, horizon_s, share)
    vx, vy = _mean_velocity(state.heading_rad, turn_rad, cfg.uav.speed_m_s, cfg.dt_s, horizon_s)
    # RVO2: v violates the line when det(direction, point − v) > 0 (its distance beyond it).
    # det = det(direction, point) + (−v_y, v_x)·direction: the candidate part is one matmul.
    ux, uy = direction[..., 0], direction[..., 1]  # (B, N, N)
    fixed = np.where(counts, ux * point[..., 1] - uy * point[..., 0], -np.inf)
    turned = np.stack([-vy, vx], axis=-1) @ np.stack([ux, uy], axis=-2)  # (B, N, C, N)
    violation: FloatArray = (turned + fixed[:, :, None]).max(axis=-1)
    return violation


def orca_lines(
    state: SwarmState, cfg: ScenarioConfig, radius_m: float, horizon_s: float, share: FloatArray
) -> tuple[FloatArray, FloatArray, BoolArray]:
    """ORCA half-planes of every UAV A against every other UAV B (RVO2's construction).

    Args:
        radius_m: R.  horizon_s: τ_u.
        share: (B, N, N) A's responsibility for the pair (A, B), 0.5 in plain ORCA; the
            pair's two entries sum to 1.

    Returns:
        point: (B, N, N, 2) v_A + share·u, a point on the boundary line, m/s.
        direction: (B, N, N, 2) the line's unit direction; admissible velocities v lie on its
            left: det(direction, point − v) ≤ 0.
        counts: (B, N, N) pairs that count (A active, B active or hovering where it arrived,
            A ≠ B); A takes the whole responsibility for a hovering B.
    """
    pos, heading, active = state.pos_m, state.heading_rad, state.active
    hovering = state.hovering(cfg.arrival)  # arrived: stays put, takes no share
    n = heading.shape[1]
    speed, dt = cfg.uav.speed_m_s, cfg.dt_s
    vel = speed * np.stack([np.cos(heading), np.sin(heading)], axis=-1)  # (B, N, 2)
    vel = np.where(hovering[..., None], 0.0, vel)
    share = np.where(hovering[:, None, :], 1.0, share)
    rel_pos = pos[:, None] - pos[:, :, None]  # [b, a, o] = p_o − p_a
    rel_vel = vel[:, :, None] - vel[:, None]  # [b, a, o] = v_a − v_o
    px, py = rel_pos[..., 0], rel_pos[..., 1]
    dist_sq = np.maximum(px * px + py * py, TINY)
    r, r_sq = radius_m, radius_m * radius_m
    apart = dist_sq > r_sq

    # Apart: w from the centre of the cut-off disc p/τ to the relative velocity.
    wx, wy = rel_vel[..., 0] - px / horizon_s, rel_vel[..., 1] - py / horizon_s
    w_sq = wx * wx + wy * wy
    dot1 = wx * px + wy * py
    on_disc = (dot1 < 0.0) & (dot1 * dot1 > r_sq * w_sq)  # nearest boundary: the cut-off disc
    w_len = np.sqrt(np.maximum(w_sq, TINY))
    disc_dir = np.stack([wy / w_len, -wx / w_len], axis=-1)
    disc_u = ((r / horizon_s - w_len) / w_len)[..., None] * np.stack([wx, wy], axis=-1)
    leg = np.sqrt(np.maximum(dist_sq - r_sq, 0.0))
    left = px * wy - py * wx > 0.0  # det(p, w): project on the left leg, else the right one
    left_dir = np.stack([px * leg - py * r, px * r + py * leg], axis=-1) / dist_sq[..., None]
    right_dir = -np.stack([px * leg + py * r, -px * r + py * leg], axis=-1) / dist_sq[..., None]
    leg_dir = np.where(left[..., None], left_dir, right_dir)
    along = np.einsum("...i,...i->...", rel_vel, leg_dir)
    leg_u = along[..., None] * leg_dir - rel_vel

    # Overlapping (closer than R): leave the overlap within one decision step.
    cx, cy = rel_vel[..., 0] - px / dt, rel_vel[..., 1] - py / dt
    c_len = np.sqrt(np.maximum(cx * cx + cy * cy, TINY))
    over_dir = np.stack([cy / c_len, -cx / c_len], axis=-1)
    over_u = ((r / dt - c_len) / c_len)[..., None] * np.stack([cx, cy], axis=-1)

    direction = np.where(
        apart[..., None], np.where(on_disc[..., None], disc_dir, leg_dir), over_dir
    )
    u = np.where(apart[..., None], np.where(on_disc[..., None], disc_u, leg_u), over_u)
    point = vel[:, :, None] + share[..., None] * u
    counts = active[:, :, None] & (active | hovering)[:, None, :] & ~np.eye(n, dtype=bool)
    return point, direction, counts


def _mean_velocity(
    heading_rad: FloatArray, turn_rad: FloatArray, speed_m_s: float, dt_s: float, horizon_s: float
) -> tuple[FloatArray, FloatArray]:
    """Mean velocity (x, y), each (B, N, C), of every candidate's motion over [0, τ], m/s.

    The arc's chord L·sinc(a/2) along h + a/2, then (τ − dt)·v along h + a, divided by τ.
    """
    half = 0.5 * turn_rad
    chord = speed_m_s * dt_s * sinc_series(half)
    arc_heading = heading_rad[..., None] + half
    final = heading_rad[..., None] + turn_rad
    rest = speed_m_s * (horizon_s - dt_s)
    vx = (chord * np.cos(arc_heading) + rest * np.cos(final)) / horizon_s
    vy = (chord * np.sin(arc_heading) + rest * np.sin(final)) / horizon_s
    return vx, vy

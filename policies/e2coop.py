"""E2Coop, the contour meta-heuristic of the paper's Table 2, ported to the 2-D simulator.

The original (a MATLAB planner) gives every avoiding UAV its own PSO ("species PSO") over the
curvature and heading of its next arc, scored by E = ½·E_int − ½·E_ext: E_int the bending
(Σ‖second difference‖ over 10 samples of the previous arc and 10 of the candidate), E_ext the
edge map of the UAV's own contour level summed over the same samples — so the UAV follows its
contour round the obstacles. UAVs whose predicted end points come within d_col of each other are
then separated (the original picks altitude offsets with a second PSO).

This port keeps that algorithm and changes what the 2-D simulator forces:

* the arc starts at the UAV's current heading (the simulator's kinematics), so the decision
  variable is the turn of the arc, a ∈ [−max_turn, max_turn] — the curvature a/L; a free start
  heading would be a jump the simulator cannot fly;
* the edge map is the analytic level edge of `sim.contour` (a Gaussian in the signed distance to
  the UAV's level φ_i), the smooth counterpart of the original's binarised-and-differentiated
  field; φ_i is the field at the UAV when its avoidance begins;
* the GVF snake that predicts the whole avoidance path becomes a receding horizon: the PSO
  plans the next `E2CoopConfig.horizon` arcs against the field predicted while each is flown
  (obstacles and p* move on) and the first arc is flown;
* the altitude deconfliction becomes a lateral one: each cost adds a penalty for coming within
  1.5·d_col of the other UAVs' planned arcs at the same instants, in two sweeps over the UAVs;
  a UAV heading home makes way to the arcs already planned;
* the PSO is the constriction PSO (χ = 0.7298, c1 = c2 = 2.05, as the original's coefficients)
  without the original's adaptive inertia and gbest perturbation.

Avoidance begins for a UAV when an obstacle is within sensing range and ends when every such
obstacle is behind it (the original's dot-product test); otherwise the UAV turns toward its
target. `E2Coop` is a policy over the simulator state (``uses_state``), so `sim.evaluation`
measures it — success, distances, energy Σ|a| — with the same code as every other method.
numpy only.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from sim.arrays import FloatArray
from sim.config import ScenarioConfig
from sim.contour import external_density_xy
from sim.field import FieldSources, potential_and_gradient_xy
from sim.kinematics import arc_points_xy, wrap_angle
from sim.swarm import SwarmState

PASSES = 2
"""Planning sweeps over the UAVs of a swarm (the second re-plans against everyone's arcs)."""

SEPARATION_MARGIN = 1.5
"""Planned arcs of two UAVs are kept this many d_col apart (the spawn spacing factor)."""


@dataclass(frozen=True)
class E2CoopConfig:
    """The planner's settings (defaults: the original's PSO budget)."""

    particles: int = 200
    """Particles per UAV (the original's 200)."""
    iterations: int = 100
    """PSO iterations (the original's 100)."""
    samples: int = 10
    """Samples per arc in the energies (the original's every-10th of 100)."""
    horizon: int = 3
    """Arcs planned ahead (the first is flown): the original predicts the whole avoidance
    path with a GVF snake before its PSO; a one-arc PSO sees the contour move too late."""
    chi: float = 0.7298
    """Clerc constriction factor."""
    c: float = 2.05
    """Cognitive and social coefficients (before constriction)."""
    separation_weight: float = 1.0
    """Penalty per m² of end-point intrusion within d_col (the lateral deconfliction)."""
    level_source: str = "assigned"
    """"assigned": follow the contour level the simulator's PSO gave the UAV (reMARL's
    separated levels, E2Coop's descendant); "current": the level at the UAV each step."""
    capture_m: float = 40.0
    """Width of the edge map's basin, m: the original extends its edge map's reach with a
    gradient-vector-flow snake (600 diffusion iterations); a level edge as narrow as the
    reward's (10 m) loses the contour once an approaching obstacle pushes it away."""


class E2Coop:
    """The planner as a policy: ``act(obs, state) -> (B, N)`` normalised turns.

    Args:
        cfg: the scenario (field, sensing, speed, d_col).
        planner: PSO settings.
        seed: seed of the PSO's random generator.
    """

    uses_state = True

    def __init__(
        self, cfg: ScenarioConfig, planner: E2CoopConfig | None = None, seed: int = 0
    ) -> None:
        self.cfg = cfg
        self.planner = planner or E2CoopConfig()
        self.rng = np.random.default_rng(seed)
        self.reward_cfg = replace(
            cfg.reward, external="level-edge", edge_width_m=self.planner.capture_m
        )
        self.length_m = cfg.uav.speed_m_s * cfg.dt_s
        self.max_turn = cfg.uav.max_turn_rad
        self.levels: FloatArray | None = None  # (B, N) NaN: not avoiding
        self.level_source = self.planner.level_source
        self.prev_turn: FloatArray | None = None  # (B, N)

    def __call__(self, obs: NDArray[np.float32], state: SwarmState) -> NDArray[np.float32]:
        """Plan every UAV's next arc."""
        b, n = state.heading_rad.shape
        if self.levels is None or self.levels.shape != (b, n):
            self.levels = np.full((b, n), np.nan)
            self.prev_turn = np.zeros((b, n))
        assert self.prev_turn is not None
        fresh = state.steps == 0  # a new episode in that environment
        self.levels[fresh] = np.nan
        self.prev_turn[fresh] = 0.0
        # the field half a step ahead: the obstacles move while the arc is flown
        src = state.sources(self.cfg.uav.speed_m_s, self.cfg.dt_s / 2)
        avoiding = self._avoiding(state)
        phi, _, _ = potential_and_gradient_xy(
            state.pos_m[..., 0], state.pos_m[..., 1], src, self.cfg.field
        )
        # z0, the level whose edge map the PSO follows
        if self.level_source == "assigned":  # the contour levels the simulator's PSO assigned
            self.levels = np.where(avoiding, state.levels, np.nan)
        else:  # the field at the UAV now (the original re-binarises at its current level)
            self.levels = np.where(avoiding, phi, np.nan)

        to_target = state.target_m - state.pos_m
        bearing = np.arctan2(to_target[..., 1], to_target[..., 0])
        turn = np.clip(wrap_angle(bearing - state.heading_rad), -self.max_turn, self.max_turn)
        if avoiding.any():
            turn = self._plan(state, avoiding, turn)
        self.prev_turn = np.where(state.active, turn, 0.0)
        out: NDArray[np.float32] = (turn / self.max_turn).astype(np.float32)
        return out

    def _avoiding(self, state: SwarmState) -> NDArray[np.bool_]:
        """(B, N): an obstacle within sensing range that is not yet behind the UAV."""
        rel = state.obstacle_pos_m[:, None, :, :] - state.pos_m[:, :, None, :]  # (B, N, M, 2)
        dist = np.linalg.norm(rel, axis=-1)
        to_target = (state.target_m - state.pos_m)[:, :, None, :]
        ahead = np.einsum("bnmk,bnmk->bnm", rel, np.broadcast_to(to_target, rel.shape)) > 0
        near = dist <= self.cfg.sensing.range_m
        found: NDArray[np.bool_] = (near & ahead).any(axis=-1) & state.active
        return found

    def _arcs(
        self, state: SwarmState, b: int, i: int, turns: FloatArray
    ) -> tuple[FloatArray, FloatArray]:
        """Sample points (P, H, Q) of the H chained arcs of UAV (b, i) for turns (P, H)."""
        q = np.linspace(0.0, 1.0, self.planner.samples + 1)[1:]
        p, h = turns.shape
        xs, ys = np.empty((p, h, len(q))), np.empty((p, h, len(q)))
        start = np.broadcast_to(state.pos_m[b, i], (p, 2)).copy()
        heading = np.full(p, state.heading_rad[b, i])
        for k in range(h):
            x, y = arc_points_xy(start, heading, turns[:, k], self.length_m, q)
            xs[:, k], ys[:, k] = x, y
            start = np.stack([x[:, -1], y[:, -1]], axis=-1)
            heading = heading + turns[:, k]
        return xs, ys

    def _previous(self, state: SwarmState, b: int, i: int) -> tuple[FloatArray, FloatArray]:
        """Sample points (Q,) of the previous arc, ending at the UAV (walked backwards)."""
        assert self.prev_turn is not None
        q = np.linspace(0.0, 1.0, self.planner.samples + 1)[1:]
        back_heading = np.array([state.heading_rad[b, i] + math.pi])
        x, y = arc_points_xy(
            state.pos_m[b, i][None], back_heading, -self.prev_turn[b, i : i + 1], self.length_m, q
        )
        return x[0, ::-1], y[0, ::-1]

    def _cost(
        self,
        state: SwarmState,
        b: int,
        i: int,
        turns: FloatArray,
        others_end: FloatArray,
    ) -> FloatArray:
        """Σ over the horizon of ½·E_int − ½·E_ext (+ separation) for turns (P, H)."""
        assert self.levels is not None
        x, y = self._arcs(state, b, i, turns)  # (P, H, Q)
        p, h, q = x.shape
        px, py = self._previous(state, b, i)
        p0 = state.pos_m[b, i]
        allx = np.concatenate(
            [np.broadcast_to(px, (p, q)), np.full((p, 1), p0[0]), x.reshape(p, h * q)], axis=1
        )
        ally = np.concatenate(
            [np.broadcast_to(py, (p, q)), np.full((p, 1), p0[1]), y.reshape(p, h * q)], axis=1
        )
        ddx = allx[:, 2:] - 2 * allx[:, 1:-1] + allx[:, :-2]
        ddy = ally[:, 2:] - 2 * ally[:, 1:-1] + ally[:, :-2]
        # in radians: a second difference over sample spacing h is h·(angle turned), so
        # dividing by h makes E_int ≈ Σ|a_k| + Σ|a_k − a_{k−1}| whatever the step length
        e_int = np.hypot(ddx, ddy).sum(axis=1) / (self.length_m / self.planner.samples)
        e_ext = np.zeros(p)
        for k in range(h):  # the field while arc k is flown: obstacles and p* move on
            src = state.sources(self.cfg.uav.speed_m_s, (k + 0.5) * self.cfg.dt_s)
            one = _single_env_sources(src, b)
            dens = external_density_xy(
                x[None, :, k],
                y[None, :, k],
                np.full((1, 1, 1), self.levels[b, i]),
                one,
                self.cfg.field,
                self.reward_cfg,
            )[0]
            e_ext += dens.sum(axis=1)
        cost = 0.5 * e_int - 0.5 * e_ext
        if len(others_end):  # others' first arcs (K, Q, 2), sampled at the same instants
            mine = np.stack([x[:, 0], y[:, 0]], axis=-1)  # (P, Q, 2)
            gap = np.linalg.norm(mine[:, None] - others_end[None], axis=-1).min(axis=-1)  # (P, K)
            intrusion = np.maximum(0.0, SEPARATION_MARGIN * self.cfg.d_col_m - gap)
            cost = cost + self.planner.separation_weight * (intrusion**2).sum(axis=1)
        out: FloatArray = cost
        return out

    def _plan(
        self,
        state: SwarmState,
        avoiding: NDArray[np.bool_],
        turn: FloatArray,
    ) -> FloatArray:
        """PSO for every avoiding UAV with lateral deconfliction, in `PASSES` sweeps.

        The first sweep plans the UAVs one after another, each keeping clear of the arcs
        chosen before it; the next sweeps re-plan each against everyone's latest arcs, so the
        first UAV planned does not get right of way.
        """
        turn = turn.copy()
        b_count, n = turn.shape
        q = self.planner.samples
        for b in range(b_count):
            if not avoiding[b].any():
                continue
            paths: dict[int, FloatArray] = {}
            for sweep in range(PASSES):
                for i in range(n):
                    if not state.active[b, i]:
                        continue
                    others = np.array([p for j, p in paths.items() if j != i]).reshape(-1, q, 2)
                    if avoiding[b, i]:
                        turn[b, i] = self._pso(state, b, i, others)
                    elif len(others) and sweep == PASSES - 1:  # heading home: make way
                        turn[b, i] = self._make_way(state, b, i, turn[b, i], others)
                    x, y = self._arcs(state, b, i, turn[b, i : i + 1, None])
                    paths[i] = np.stack([x[0, 0], y[0, 0]], axis=-1)
        return turn

    def _intrusion(
        self, state: SwarmState, b: int, i: int, turns: FloatArray, others: FloatArray
    ) -> FloatArray:
        """Σ squared intrusion (m²) of candidate first arcs (P,) into the others' arcs."""
        x, y = self._arcs(state, b, i, turns[:, None])
        mine = np.stack([x[:, 0], y[:, 0]], axis=-1)
        gap = np.linalg.norm(mine[:, None] - others[None], axis=-1).min(axis=-1)
        out: FloatArray = (np.maximum(0.0, SEPARATION_MARGIN * self.cfg.d_col_m - gap) ** 2).sum(1)
        return out

    def _make_way(
        self, state: SwarmState, b: int, i: int, goal: float, others: FloatArray
    ) -> float:
        """The turn closest to ``goal`` whose arc keeps clear of the others' (a grid search)."""
        grid = np.linspace(-self.max_turn, self.max_turn, 31)
        cost = self._intrusion(state, b, i, grid, others) + 100.0 * (grid - goal) ** 2
        if self._intrusion(state, b, i, np.array([goal]), others)[0] == 0.0:
            return goal
        return float(grid[int(np.argmin(cost))])

    def _pso(self, state: SwarmState, b: int, i: int, others_end: FloatArray) -> float:
        """Constriction PSO over the next H turns of UAV (b, i); returns the first."""
        p, lim = self.planner, self.max_turn
        shape = (p.particles, p.horizon)
        pos = self.rng.uniform(-lim, lim, shape)
        vel = self.rng.uniform(-lim, lim, shape) * 0.1
        cost = self._cost(state, b, i, pos, others_end)
        best_pos, best_cost = pos.copy(), cost.copy()
        g = int(np.argmin(cost))
        g_pos, g_cost = pos[g].copy(), float(cost[g])
        for _ in range(p.iterations):
            r1, r2 = self.rng.random(shape), self.rng.random(shape)
            vel = p.chi * (vel + p.c * r1 * (best_pos - pos) + p.c * r2 * (g_pos - pos))
            pos = np.clip(pos + vel, -lim, lim)
            cost = self._cost(state, b, i, pos, others_end)
            better = cost < best_cost
            best_pos[better], best_cost[better] = pos[better], cost[better]
            k = int(np.argmin(best_cost))
            if best_cost[k] < g_cost:
                g_pos, g_cost = best_pos[k].copy(), float(best_cost[k])
        return float(g_pos[0])


def _single_env_sources(src: FieldSources, b: int) -> FieldSources:
    """The field sources of environment ``b`` alone (batch of one)."""
    mask = src.obstacle_mask
    return FieldSources(
        obstacle_pos_m=src.obstacle_pos_m[b : b + 1],
        obstacle_speed_m_s=src.obstacle_speed_m_s[b : b + 1],
        centre_m=src.centre_m[b : b + 1],
        swarm_speed_m_s=src.swarm_speed_m_s,
        obstacle_mask=None if mask is None else mask[b : b + 1],
    )

"""Contour-level separation by particle swarm optimisation (paper Eq. psocost, pso).

Each particle is a candidate position for all N UAVs (2N numbers). The cost is

    f_pso = f_thres + f_shift,     f_shift = max_i |q_i − q'_i|

with f_thres enforcing the hard constraint min_{i<j} |q'_i − q'_j| ≥ d̄_U2U (the paper writes
d_U2O; its text means UAV–UAV spacing). Two departures from the literal formula, both in
`docs/MODEL.md`:

* on the feasible set f_thres = d̄_U2U (the paper: the minimum distance itself). At any optimum
  where the constraint is active the two agree; where it is inactive, the literal form would pull
  an already well-spaced swarm together to the threshold, which nothing in the method wants.
* an infeasible particle costs `INFEASIBLE_COST` + its total violation Σ_{i<j} max(0, d̄² − d_ij²)
  (the paper: Inf). Every feasible particle still beats every infeasible one, but infeasible
  particles are ranked, so a swarm that starts infeasible is guided toward feasibility instead
  of wandering blind.

The update is the standard global-best PSO of Eq. pso with the inertia μ ~ U[0, 1] drawn per
particle and iteration and the usual per-dimension r₁, r₂ ~ U[0, 1] on c₁ and c₂, vectorised
over particles and over the batch of environments. The first particle of every swarm is the
current positions themselves and the second a constructive repair of them (every pair closer
than the threshold pushed apart by half its deficit, repeatedly): a good feasible start that
lets a small swarm reach near-optimal shifts. Positions that already meet the threshold are
their own optimum (f_thres = d̄ is its floor and f_shift = 0), so they are returned without a
search: the call costs almost nothing when there is nothing to separate.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sim.arrays import BoolArray, FloatArray
from sim.config import PSOConfig

INFEASIBLE_COST = 1e9
"""Cost offset of a particle that violates d̄_U2U, metres; larger than any feasible cost."""


@dataclass(frozen=True)
class PSOResult:
    """Outcome of one PSO call for a batch of B environments.

    Attributes:
        positions_m: (B, N, 2) the adjusted positions (the global best).
        cost: (B,) f_pso of the global best (≥ `INFEASIBLE_COST` if no feasible one was found).
        max_shift_m: (B,) f_shift of the global best.
        min_distance_m: (B,) minimum pairwise distance of the global best (+inf for N < 2).
        feasible: (B,) whether the global best meets the threshold.
        searched: (B,) whether PSO ran: positions that already meet the threshold are their
            own optimum (no shift, f_pso = d̄) and are returned as they are.
        evaluations: cost evaluations per searched environment.
    """

    positions_m: FloatArray
    cost: FloatArray
    max_shift_m: FloatArray
    min_distance_m: FloatArray
    feasible: BoolArray
    searched: BoolArray
    evaluations: int


class _Cost:
    """f_pso for particles (B, P, 2, N) — coordinate-major — against reference positions.

    Pairwise differences come from one matrix product with the pair-difference operator
    (N, pairs), the fastest form numpy offers for many small swarms.
    """

    def __init__(self, reference: FloatArray, active: BoolArray, threshold_m: float) -> None:
        n = reference.shape[-1]
        i, j = np.triu_indices(n, k=1)
        pairs = np.arange(len(i))
        self.diff_op = np.zeros((n, len(i)))  # (N, pairs): column k is e_i − e_j
        self.diff_op[i, pairs], self.diff_op[j, pairs] = 1.0, -1.0
        self.reference = reference[:, None]  # (B, 1, 2, N)
        pair_active = active[:, i] & active[:, j]  # (B, pairs)
        self.pair_penalty = (
            None if pair_active.all() else np.where(pair_active, 0.0, np.inf)[:, None]
        )
        self.inactive = None if active.all() else ~active[:, None]  # (B, 1, N)
        self.threshold = threshold_m
        self.threshold2 = threshold_m**2

    def __call__(self, x: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
        """(cost (B, P), max shift (B, P), min distance (B, P)) of particles (B, P, 2, N)."""
        # One 2-D GEMM (B·P·2, N) @ (N, pairs): far faster than B·P tiny batched products.
        d = (x.reshape(-1, x.shape[-1]) @ self.diff_op).reshape(*x.shape[:-1], -1)
        d *= d
        d2 = d[..., 0, :] + d[..., 1, :]
        if self.pair_penalty is not None:
            d2 += self.pair_penalty
        if not d2.shape[-1]:  # a single UAV: nothing to separate
            dmin = np.full(d2.shape[:-1], np.inf)
            violation = np.zeros(d2.shape[:-1])
        else:
            dmin = np.sqrt(d2.min(axis=-1))
            # Total violation, in m², ranks infeasible particles: Σ max(0, d̄² − d_ij²).
            np.subtract(self.threshold2, d2, out=d2)
            violation = np.maximum(d2, 0.0, out=d2).sum(axis=-1)
        sh = x - self.reference
        sh *= sh
        shift2 = sh[..., 0, :] + sh[..., 1, :]  # (B, P, N)
        if self.inactive is not None:
            shift2[np.broadcast_to(self.inactive, shift2.shape)] = 0.0
        shift = np.sqrt(shift2.max(axis=-1))
        f_thres = np.where(dmin >= self.threshold, self.threshold, INFEASIBLE_COST + violation)
        return f_thres + shift, shift, dmin


def pso_separate(
    positions_m: FloatArray,
    cfg: PSOConfig,
    rng: np.random.Generator,
    active: BoolArray | None = None,
) -> PSOResult:
    """Move UAV positions as little as possible so every pair is ≥ d̄_U2U apart.

    Args:
        positions_m: (B, N, 2) current positions q.
        cfg: threshold, particles, iterations, c1, c2, initial noise.
        rng: the caller's generator (the only source of randomness).
        active: (B, N) UAVs that take part; inactive ones are ignored and never moved.

    Returns:
        The global best of every environment; see `PSOResult`.
    """
    q = np.asarray(positions_m, dtype=np.float64)
    b, n, _ = q.shape
    act = np.ones((b, n), dtype=bool) if active is None else np.asarray(active, dtype=bool)
    dmin = _min_distance(q, act)
    search = dmin < cfg.threshold_m
    positions, cost = q.copy(), np.full(b, cfg.threshold_m)
    shift, feasible = np.zeros(b), ~search
    if search.any():
        found = _search(q[search].swapaxes(-1, -2), act[search], cfg, rng)
        positions[search] = found.positions_m
        cost[search], shift[search] = found.cost, found.max_shift_m
        dmin[search], feasible[search] = found.min_distance_m, found.feasible
    return PSOResult(positions, cost, shift, dmin, feasible, search, cfg.evaluations)


def _min_distance(q: FloatArray, active: BoolArray) -> FloatArray:
    """Minimum pairwise distance among the active UAVs of each environment, (B,)."""
    i, j = np.triu_indices(q.shape[1], k=1)
    diff = q[:, i] - q[:, j]
    dist = np.hypot(diff[..., 0], diff[..., 1])
    dist = np.where(active[:, i] & active[:, j], dist, np.inf)
    smallest: FloatArray = dist.min(axis=-1, initial=np.inf)
    return smallest


REPAIR_SWEEPS = 30
"""Sweeps of the constructive repair that seeds one particle (`_spread`)."""

REPAIR_MARGIN = 1e-3
"""Relative margin the repair adds to the threshold, so its result is feasible, not borderline."""


def _spread(q: FloatArray, act: BoolArray, threshold_m: float) -> FloatArray:
    """Push every pair closer than the threshold apart, half the deficit each, repeatedly.

    A cheap constructive candidate (position-based projection, vectorised over environments);
    positions (B, 2, N) → (B, 2, N). Coincident UAVs are separated along fixed directions.
    """
    n = q.shape[-1]
    pair = act[:, :, None] & act[:, None, :] & ~np.eye(n, dtype=bool)  # (B, N, N)
    angle = 2 * np.pi * np.arange(n) / n
    apart = np.stack([np.cos(angle), np.sin(angle)])  # (2, N): fallback directions
    fallback = apart[:, :, None] - apart[:, None, :]  # (2, N, N)
    x = q.copy()
    for _ in range(REPAIR_SWEEPS):
        diff = x[:, :, :, None] - x[:, :, None, :]  # (B, 2, N, N)
        dist = np.sqrt(np.einsum("bcij,bcij->bij", diff, diff))
        deficit = np.where(pair, np.maximum(threshold_m * (1 + REPAIR_MARGIN) - dist, 0.0), 0.0)
        if not deficit.any():
            break
        unit = np.where(dist[:, None] > 0, diff / np.maximum(dist, 1e-12)[:, None], fallback)
        x += 0.5 * (unit * deficit[:, None]).sum(axis=-1)
    return x


def _search(q: FloatArray, act: BoolArray, cfg: PSOConfig, rng: np.random.Generator) -> PSOResult:
    """The particle swarm itself, on positions (B, 2, N) — coordinate-major."""
    b, _, n = q.shape
    cost_fn = _Cost(q, act, cfg.threshold_m)
    move = None if act.all() else act[:, None, None, :].astype(np.float64)  # (B, 1, 1, N)

    p = cfg.particles
    x = q[:, None] + rng.normal(0.0, cfg.init_noise_m, size=(b, p, 2, n))  # (B, P, 2, N)
    x[:, 0] = q  # the current positions are a candidate
    if p > 1:
        x[:, 1] = _spread(q, act, cfg.threshold_m)  # and so is a constructive repair of them
    v = rng.normal(0.0, cfg.init_speed_m, size=x.shape)
    if move is not None:
        x = q[:, None] + (x - q[:, None]) * move
    cost, shift, dmin = cost_fn(x)
    envs = np.arange(b)
    g = cost.argmin(axis=1)
    gcost, gshift, gdmin = cost[envs, g], shift[envs, g], dmin[envs, g]
    # best[0] holds each particle's personal best, best[1] the global best (broadcast).
    best = np.stack([x, np.broadcast_to(x[envs, g][:, None], x.shape)])  # (2, B, P, 2, N)
    pbest_cost = cost
    coef = np.array([cfg.c1, cfg.c2]).reshape(2, 1, 1, 1, 1)

    for _ in range(cfg.iterations - 1):
        v *= rng.random((b, p, 1, 1))  # μ ~ U[0, 1]
        r = rng.random((2, b, p, 2, n))  # r₁, r₂ ~ U[0, 1]
        r *= coef
        r *= best - x
        v += r[0]
        v += r[1]
        if move is not None:
            v *= move
        x += v
        cost, shift, dmin = cost_fn(x)
        better = cost < pbest_cost  # (B, P)
        np.copyto(best[0], x, where=better[..., None, None])
        pbest_cost = np.minimum(cost, pbest_cost)
        g = cost.argmin(axis=1)
        gc = cost[envs, g]
        improved = gc < gcost
        if improved.any():
            best[1] = np.where(improved[:, None, None, None], x[envs, g][:, None], best[1])
            gshift = np.where(improved, shift[envs, g], gshift)
            gdmin = np.where(improved, dmin[envs, g], gdmin)
            gcost = np.where(improved, gc, gcost)
    gbest = best[1, :, 0]

    return PSOResult(
        searched=np.ones(b, dtype=bool),
        positions_m=gbest.swapaxes(-1, -2).copy(),
        cost=gcost,
        max_shift_m=gshift,
        min_distance_m=gdmin,
        feasible=gcost < INFEASIBLE_COST,
        evaluations=cfg.evaluations,
    )

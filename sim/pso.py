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
lets a small swarm reach near-optimal shifts.

Two kinds of environment are settled without a search, because their optimum is known:

* positions that already meet the threshold are their own optimum (f_thres = d̄ is its floor
  and f_shift = 0) and are returned as they are;
* positions whose repair is *certified*: any feasible answer moves one UAV of every close pair
  by at least half the pair's deficit, so f_shift ≥ max_{i<j} (d̄ − d_ij)/2 over the close
  pairs. Where the repair is feasible and its largest shift is within `CERTIFIED_GAP` of that
  bound, no particle can do better by more than the gap, and the repair is returned. This is
  the common case in the simulator (close pairs that share no UAV, each pushed apart once), and
  the repair moves only the UAVs that must move, where a search jitters the others within the
  largest shift. The call therefore costs a search only where the UAVs crowd in chains.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sim.arrays import BoolArray, FloatArray, IntArray
from sim.config import PSOConfig

INFEASIBLE_COST = 1e9
"""Cost offset of a particle that violates d̄_U2U, metres; larger than any feasible cost."""

REPAIR_SWEEPS = 30
"""Sweeps of the constructive repair that seeds one particle (`_spread`), at most."""

REPAIR_MARGIN = 1e-3
"""Relative margin the repair adds to the threshold, so its result is feasible, not borderline."""

REPAIR_TOLERANCE = 0.5
"""The repair of an environment stops once every pair's deficit (to the threshold plus the
margin) is at most this fraction of the margin: every pair is then at least d̄·(1 + margin/2)
apart, strictly feasible (an exact fixed point is reached only to rounding: the last
micrometres would cost every remaining sweep)."""

CERTIFIED_GAP = 2 * REPAIR_MARGIN
"""A feasible repair whose largest shift exceeds the lower bound max (d̄ − d_ij)/2 by at most
this fraction of d̄ (6 cm at 30 m) is returned without a search. A close pair pushed apart once
exceeds it by d̄·margin/2, half the gap; the other half absorbs rounding."""

COEFFICIENT_BITS = 16
"""Resolution of the random coefficients μ, r₁, r₂ ~ U[0, 1): multiples of 2⁻¹⁶, four per
64-bit word of the generator. Random numbers are most of a small search's cost, and a PSO
coefficient needs no more than 65,536 levels."""


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
            own optimum (no shift, f_pso = d̄) and are returned as they are, and a certified
            repair is returned without a search (see the module docstring).
        evaluations: cost evaluations per searched environment.
    """

    positions_m: FloatArray
    cost: FloatArray
    max_shift_m: FloatArray
    min_distance_m: FloatArray
    feasible: BoolArray
    searched: BoolArray
    evaluations: int


@dataclass(frozen=True)
class _Pairs:
    """The pairs i < j of N UAVs and the operators between UAVs and pairs."""

    i: IntArray
    j: IntArray
    difference: FloatArray  # (pairs, N): row k is e_i − e_j
    push: FloatArray  # (N, pairs): half a pair's push moves i forward, half moves j back

    @classmethod
    def of(cls, n: int) -> _Pairs:
        """The pairs of N UAVs, in `np.triu_indices` order."""
        pairs = [(a, b) for a in range(n) for b in range(a + 1, n)]
        i = np.array([a for a, _ in pairs], dtype=np.intp)
        j = np.array([b for _, b in pairs], dtype=np.intp)
        difference = np.zeros((len(pairs), n))
        k = np.arange(len(pairs))
        difference[k, i], difference[k, j] = 1.0, -1.0
        return cls(i, j, difference, 0.5 * difference.T)


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
        rng: the caller's generator (the only source of randomness; drawn from only where a
            search runs).
        active: (B, N) UAVs that take part; inactive ones are ignored and never moved.

    Returns:
        The global best of every environment; see `PSOResult`.
    """
    q = np.asarray(positions_m, dtype=np.float64)
    b, n, _ = q.shape
    act = np.ones((b, n), dtype=bool) if active is None else np.asarray(active, dtype=bool)
    pairs = _Pairs.of(n)
    qt = np.ascontiguousarray(q.transpose(2, 1, 0))  # (2, N, B): coordinate-major
    pair_active = (act[:, pairs.i] & act[:, pairs.j]).T  # (pairs, B)
    dist = _pair_distances(qt, pairs, pair_active)  # (pairs, B)
    dmin: FloatArray = dist.min(axis=0, initial=np.inf)
    positions, cost = q.copy(), np.full(b, cfg.threshold_m)
    shift, feasible = np.zeros(b), dmin >= cfg.threshold_m
    searched = np.zeros(b, dtype=bool)
    close = np.flatnonzero(~feasible)
    if not len(close):
        return PSOResult(positions, cost, shift, dmin, feasible, searched, cfg.evaluations)

    sub_q, sub_act, sub_pairs = qt[:, :, close], act[close], pair_active[:, close]
    repaired = _spread(sub_q, pairs, sub_pairs, cfg.threshold_m)
    rep_shift = _max_shift(repaired, sub_q)
    rep_dmin = _pair_distances(repaired, pairs, sub_pairs).min(axis=0)
    bound = 0.5 * np.maximum(cfg.threshold_m - dist[:, close], 0.0).max(axis=0)
    certified = (rep_dmin >= cfg.threshold_m) & (
        rep_shift <= bound + CERTIFIED_GAP * cfg.threshold_m
    )
    done = close[certified]
    positions[done] = repaired[:, :, certified].transpose(2, 1, 0)
    cost[done] = cfg.threshold_m + rep_shift[certified]
    shift[done], dmin[done], feasible[done] = rep_shift[certified], rep_dmin[certified], True

    rest = ~certified
    if rest.any():
        run = close[rest]
        found = _search(sub_q[:, :, rest], sub_act[rest], repaired[:, :, rest], pairs, cfg, rng)
        positions[run] = found.positions_m
        cost[run], shift[run] = found.cost, found.max_shift_m
        dmin[run], feasible[run] = found.min_distance_m, found.feasible
        searched[run] = True
    return PSOResult(positions, cost, shift, dmin, feasible, searched, cfg.evaluations)


def _pair_distances(q: FloatArray, pairs: _Pairs, pair_active: BoolArray) -> FloatArray:
    """Distances (pairs, B) of positions (2, N, B); +inf for a pair with an inactive UAV."""
    diff = q[:, pairs.i] - q[:, pairs.j]  # (2, pairs, B)
    dist: FloatArray = np.hypot(diff[0], diff[1])
    if not pair_active.all():
        dist[~pair_active] = np.inf
    return dist


def _max_shift(x: FloatArray, q: FloatArray) -> FloatArray:
    """Largest displacement (B,) from positions q to x, both (2, N, B)."""
    d = x - q
    shift: FloatArray = np.hypot(d[0], d[1]).max(axis=0)
    return shift


def _spread(q: FloatArray, pairs: _Pairs, pair_active: BoolArray, threshold_m: float) -> FloatArray:
    """Push every pair closer than the threshold apart, half the deficit each, repeatedly.

    A cheap constructive candidate (position-based projection, vectorised over environments);
    positions (2, N, B) → (2, N, B), ``pair_active`` (pairs, B). Coincident UAVs are separated
    along fixed directions. Each sweep works only on the environments that still have a deficit
    above the tolerance (`REPAIR_TOLERANCE`); most need one sweep.
    """
    goal = threshold_m * (1 + REPAIR_MARGIN)
    tolerance = REPAIR_TOLERANCE * REPAIR_MARGIN * threshold_m
    out = q.copy()
    envs = np.arange(q.shape[2])
    x = out
    weight = None if pair_active.all() else pair_active.astype(np.float64)
    for _ in range(REPAIR_SWEEPS):
        diff = np.matmul(pairs.difference, x)  # (2, pairs, B')
        dist = np.hypot(diff[0], diff[1])
        deficit = goal - dist
        if weight is not None:
            deficit *= weight  # pairs with an inactive UAV: no deficit
        todo = deficit.max(axis=0, initial=0.0) > tolerance
        if not todo.all():
            out[:, :, envs] = x
            if not todo.any():
                return out
            envs, x = envs[todo], x[:, :, todo]
            diff, dist, deficit = diff[:, :, todo], dist[:, todo], deficit[:, todo]
            weight = None if weight is None else weight[:, todo]
        np.maximum(deficit, 0.0, out=deficit)
        if dist.all():
            diff /= dist
        else:  # coincident UAVs: apart along fixed directions
            diff = np.where(dist > 0, diff / np.where(dist > 0, dist, 1.0), _fallback(pairs))
        diff *= deficit
        x = x + np.matmul(pairs.push, diff)
    out[:, :, envs] = x
    return out


def _fallback(pairs: _Pairs) -> FloatArray:
    """(2, pairs, 1) unit directions that separate coincident UAVs.

    UAV k is pushed toward angle 2πk/N, so every pair gets a different direction.
    """
    n = pairs.difference.shape[1]
    angle = 2 * np.pi * np.arange(n) / n
    apart = np.stack([np.cos(angle), np.sin(angle)])  # (2, N)
    direction = apart[:, pairs.i] - apart[:, pairs.j]
    direction /= np.hypot(direction[0], direction[1])
    fallback: FloatArray = direction[..., None]
    return fallback


class _Cost:
    """f_pso of particles against reference positions (2, N, B).

    Particles are (2, N, P, B): coordinates, UAVs, particles, environments last. One matrix
    product with [pair-difference operator; identity] (pairs + N, N) gives every pairwise
    difference and every position at once; every reduction (over pairs, over UAVs) runs along
    a leading axis, and every per-environment constant broadcasts along the contiguous last
    one.
    """

    def __init__(
        self, reference: FloatArray, active: BoolArray, pairs: _Pairs, threshold_m: float
    ) -> None:
        n = reference.shape[1]
        self.pairs = len(pairs.i)
        self.operator = np.concatenate([pairs.difference, np.eye(n)])  # (pairs + N, N)
        self.reference = reference[:, :, None]  # (2, N, 1, B)
        pair_active = active[:, pairs.i] & active[:, pairs.j]  # (B, pairs)
        self.pair_penalty = (
            None if pair_active.all() else np.where(pair_active, 0.0, np.inf).T[:, None]
        )  # (pairs, 1, B)
        self.moving = None if active.all() else active.T[:, None].astype(np.float64)
        self.threshold = threshold_m
        self.threshold2 = threshold_m**2

    def _squares(self, x: FloatArray) -> tuple[FloatArray, FloatArray]:
        """(squared pair distances (pairs, P, B), squared shifts (N, P, B)) of particles x."""
        _, n, p, b = x.shape
        d = np.matmul(self.operator, x.reshape(2, n, p * b)).reshape(2, -1, p, b)
        d[:, self.pairs :] -= self.reference
        d *= d
        sq = d[0]
        sq += d[1]
        d2, shift2 = sq[: self.pairs], sq[self.pairs :]
        if self.pair_penalty is not None:
            d2 += self.pair_penalty
        if self.moving is not None:
            shift2 *= self.moving  # inactive UAVs never move; their (zero) shift stays zero
        return d2, shift2

    def rank(self, x: FloatArray) -> FloatArray:
        """f_pso (P, B) of particles (2, N, P, B), feasibility read off the total violation.

        The same cost as `__call__` but for a particle whose smallest distance rounds onto the
        threshold itself; the search ranks with it, the result is re-evaluated exactly.
        """
        d2, shift2 = self._squares(x)
        np.subtract(self.threshold2, d2, out=d2)
        violation = np.maximum(d2, 0.0, out=d2).sum(axis=0)  # Σ max(0, d̄² − d_ij²), m²
        cost: FloatArray = np.sqrt(shift2.max(axis=0))
        infeasible = violation > 0.0
        violation += INFEASIBLE_COST - self.threshold
        violation *= infeasible
        cost += violation
        cost += self.threshold
        return cost

    def __call__(self, x: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
        """(cost (P, B), max shift (P, B), min distance (P, B)) of particles (2, N, P, B)."""
        d2, shift2 = self._squares(x)
        p, b = x.shape[2:]
        if not d2.shape[0]:  # a single UAV: nothing to separate
            dmin = np.full((p, b), np.inf)
            violation = np.zeros((p, b))
        else:
            dmin = np.sqrt(d2.min(axis=0))
            # Total violation, in m², ranks infeasible particles: Σ max(0, d̄² − d_ij²).
            np.subtract(self.threshold2, d2, out=d2)
            violation = np.maximum(d2, 0.0, out=d2).sum(axis=0)
        shift = np.sqrt(shift2.max(axis=0))
        violation += INFEASIBLE_COST
        f_thres = np.where(dmin >= self.threshold, self.threshold, violation)
        f_thres += shift
        return f_thres, shift, dmin


COEFFICIENT_BLOCK = 1 << 20
"""Random coefficients drawn per call of the generator, at most (8 MiB as float64): the
iterations of a small search draw theirs at once, a large one in blocks."""


def _coefficients(
    rng: np.random.Generator, iterations: int, rows: int, p: int, b: int, scale: FloatArray
) -> FloatArray:
    """(iterations, rows, P, B) coefficients U[0, 1) (`COEFFICIENT_BITS`), row k × scale[k]."""
    count = iterations * rows * p * b
    words = rng.bit_generator.random_raw(-(-count * COEFFICIENT_BITS // 64))
    levels = np.asarray(words).view(np.uint16)[:count].reshape(iterations, rows, p, b)
    out: FloatArray = levels * scale
    return out


def _search(
    q: FloatArray,
    act: BoolArray,
    repaired: FloatArray,
    pairs: _Pairs,
    cfg: PSOConfig,
    rng: np.random.Generator,
) -> PSOResult:
    """The particle swarm itself, on positions (2, N, B), particles (2, N, P, B).

    ``repaired`` (2, N, B) is the constructive repair of q (`_spread`), the second particle.
    """
    _, n, b = q.shape
    p = cfg.particles
    cost_fn = _Cost(q, act, pairs, cfg.threshold_m)
    reference = q[:, :, None]  # (2, N, 1, B)
    move = None if act.all() else act.T[:, None].astype(np.float64)  # (N, 1, B)

    z = rng.standard_normal((2, 2, n, p, b))
    x = z[0]
    x *= cfg.init_noise_m
    x += reference
    x[:, :, 0] = q  # the current positions are a candidate
    if p > 1:
        x[:, :, 1] = repaired  # and so is a constructive repair of them
    v = z[1]
    v *= cfg.init_speed_m
    if move is not None:
        x = reference + (x - reference) * move
    # Rows of each iteration's coefficients: c₁·r₁ (2N), c₂·r₂ (2N), μ (1).
    rows = 4 * n + 1
    unit = 2.0**-COEFFICIENT_BITS
    scale = np.repeat([cfg.c1 * unit, cfg.c2 * unit, unit], [2 * n, 2 * n, 1])[:, None, None]
    per_block = max(1, COEFFICIENT_BLOCK // (rows * p * b))

    pbest_cost = cost_fn.rank(x)
    pbest = x.copy()
    envs = np.arange(b)
    gbest = pbest[:, :, pbest_cost.argmin(axis=0), envs][:, :, None]  # (2, N, 1, B)
    pull = np.empty_like(x)
    steps = cfg.iterations - 1
    for t in range(steps):
        if t % per_block == 0:
            block = _coefficients(rng, min(per_block, steps - t), rows, p, b, scale)
        coef = block[t % per_block]
        v *= coef[-1]  # μ ~ U[0, 1) per particle
        np.subtract(pbest, x, out=pull)
        pull *= coef[: 2 * n].reshape(2, n, p, b)  # c₁·r₁
        v += pull
        np.subtract(gbest, x, out=pull)
        pull *= coef[2 * n : 4 * n].reshape(2, n, p, b)  # c₂·r₂
        v += pull
        if move is not None:
            v *= move
        x += v
        cost = cost_fn.rank(x)
        np.copyto(pbest, x, where=cost < pbest_cost)
        np.minimum(pbest_cost, cost, out=pbest_cost)
        gbest = pbest[:, :, pbest_cost.argmin(axis=0), envs][:, :, None]

    gcost, gshift, gdmin = (a[0] for a in cost_fn(gbest))
    return PSOResult(
        searched=np.ones(b, dtype=bool),
        positions_m=np.ascontiguousarray(gbest[:, :, 0].transpose(2, 1, 0)),
        cost=gcost,
        max_shift_m=gshift,
        min_distance_m=gdmin,
        feasible=gcost < INFEASIBLE_COST,
        evaluations=cfg.evaluations,
    )

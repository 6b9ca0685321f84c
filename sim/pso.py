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
        i, j = _pair_indices(n)
        k = np.arange(len(i))
        difference = np.zeros((len(i), n))
        difference[k, i], difference[k, j] = 1.0, -1.0
        return cls(i, j, difference, 0.5 * difference.T)


def _pair_indices(n: int) -> tuple[IntArray, IntArray]:
    """(i, j) of the pairs i < j of N UAVs, in `np.triu_indices` order (a fraction of its cost)."""
    pairs = [(a, b) for a in range(n) for b in range(a + 1, n)]
    i = np.array([a for a, _ in pairs], dtype=np.intp)
    j = np.array([b for _, b in pairs], dtype=np.intp)
    return i, j


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
    i, j = _pair_indices(n)
    qt = np.ascontiguousarray(q.transpose(2, 1, 0))  # (2, N, B): coordinate-major
    diff = qt.take(i, axis=1)
    diff -= qt.take(j, axis=1)  # (2, pairs, B)
    dist = np.hypot(diff[0], diff[1])  # (pairs, B)
    act: BoolArray | None = None
    pair_active: BoolArray | None = None
    if active is not None:
        act = np.asarray(active, dtype=bool)
        act_t = act.T  # (N, B)
        pair_active = act_t.take(i, axis=0) & act_t.take(j, axis=0)
        if pair_active.all():
            pair_active = None
        else:
            dist[~pair_active] = np.inf
    # `np.minimum.reduce` and the like: the array methods' numbers without their Python
    # wrappers (a search calls them every iteration)
    dmin: FloatArray = np.minimum.reduce(dist, axis=0, initial=np.inf)
    feasible = dmin >= cfg.threshold_m
    positions, cost = q.copy(), np.full(b, cfg.threshold_m)
    shift, searched = np.zeros(b), np.zeros(b, dtype=bool)
    close = np.flatnonzero(~feasible)
    if not len(close):  # the common case at episode start: nothing to separate
        return PSOResult(positions, cost, shift, dmin, feasible, searched, cfg.evaluations)

    pairs = _Pairs.of(n)
    sub_q = qt.take(close, axis=2)  # (2, N, B')
    sub_act = np.ones((len(close), n), dtype=bool) if act is None else act[close]
    sub_pairs = None if pair_active is None else pair_active[:, close]  # (pairs, B')
    repaired, rep_dist = _spread(sub_q, pairs, sub_pairs, cfg.threshold_m)
    rep_shift = _max_shift(repaired, sub_q)
    rep_dmin = rep_dist.min(axis=0)
    bound = 0.5 * np.maximum(cfg.threshold_m - dist.take(close, axis=1), 0.0).max(axis=0)
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


def _max_shift(x: FloatArray, q: FloatArray) -> FloatArray:
    """Largest displacement (B,) from positions q to x, both (2, N, B)."""
    d = x - q
    shift: FloatArray = np.hypot(d[0], d[1]).max(axis=0)
    return shift


def _spread(
    q: FloatArray, pairs: _Pairs, pair_active: BoolArray | None, threshold_m: float
) -> tuple[FloatArray, FloatArray]:
    """Push every pair closer than the threshold apart, half the deficit each, repeatedly.

    A cheap constructive candidate (position-based projection, vectorised over environments);
    positions (2, N, B) → (2, N, B), ``pair_active`` (pairs, B) or None where every pair takes
    part. Coincident UAVs are separated along fixed directions. An environment whose deficits
    are all within the tolerance (`REPAIR_TOLERANCE`) stops there (most after one sweep) and
    keeps its place while the others go on: its pushes are zeroed while at least half the
    environments still move, and once most are done the sweeps go on with the others only.

    Returns:
        The repaired positions (2, N, B) and their pair distances (pairs, B), +inf for a pair
        with an inactive UAV.
    """
    goal = threshold_m * (1 + REPAIR_MARGIN)
    tolerance = REPAIR_TOLERANCE * REPAIR_MARGIN * threshold_m
    out = q.copy()
    out_dist = np.empty((len(pairs.i), q.shape[2]))
    envs = np.arange(q.shape[2])
    x = out
    weight = None if pair_active is None else pair_active.astype(np.float64)
    for sweep in range(REPAIR_SWEEPS + 1):
        diff = np.matmul(pairs.difference, x)  # (2, pairs, B'): exact differences
        dist = np.hypot(diff[0], diff[1])
        if sweep == REPAIR_SWEEPS:
            break
        deficit = np.subtract(goal, dist)
        if weight is not None:
            deficit *= weight  # pairs with an inactive UAV: no deficit
        todo = np.maximum.reduce(deficit, axis=0, initial=0.0) > tolerance
        left = np.count_nonzero(todo)
        moving = None
        if 2 * left <= len(todo):  # most are done: go on with the others only
            out[:, :, envs], out_dist[:, envs] = x, dist
            if not left:
                return out, _inactive_apart(out_dist, pair_active)
            envs, x = envs[todo], x[:, :, todo]
            diff, dist, deficit = diff[:, :, todo], dist[:, todo], deficit[:, todo]
            weight = None if weight is None else weight[:, todo]
        elif left < len(todo):
            moving = todo
        np.maximum(deficit, 0.0, out=deficit)
        if moving is not None:
            deficit *= moving  # the environments that are done keep their place
        if dist.all():
            diff /= dist
        else:  # coincident UAVs: apart along fixed directions
            diff = np.where(dist > 0, diff / np.where(dist > 0, dist, 1.0), _fallback(pairs))
        diff *= deficit
        x = x + np.matmul(pairs.push, diff)
    out[:, :, envs], out_dist[:, envs] = x, dist
    return out, _inactive_apart(out_dist, pair_active)


def _inactive_apart(dist: FloatArray, pair_active: BoolArray | None) -> FloatArray:
    """Pair distances (pairs, B) with +inf where a pair has an inactive UAV."""
    if pair_active is not None:
        dist[~pair_active] = np.inf
    return dist


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
    """f_pso of particles against reference positions q (2, N, B).

    A particle state is (4N, P, B): rows 0..2N−1 the particles' coordinates (x of every UAV,
    then y), rows 2N..4N−1 the reference q repeated over the P particles. Two row gathers and
    one subtraction give every pairwise difference and every displacement at once (exact, as
    x_i − x_j is one rounding however it is formed); every reduction (over pairs, over UAVs)
    runs along the leading axis, over contiguous rows.
    """

    def __init__(
        self, reference: FloatArray, active: BoolArray, pairs: _Pairs, threshold_m: float
    ) -> None:
        n = reference.shape[1]
        self.n = n
        self.pairs = len(pairs.i)
        # Rows of the differences, per coordinate: the pairs (x_i − x_j), then the UAVs' shifts
        # (x_u − q_u, q in the second half of the state).
        plus = pairs.i.tolist() + list(range(n))
        minus = pairs.j.tolist() + list(range(2 * n, 3 * n))
        self.plus = np.array(plus + [r + n for r in plus], dtype=np.intp)
        self.minus = np.array(minus + [r + n for r in minus], dtype=np.intp)
        self.reference = reference.reshape(2 * n, -1)  # (2N, B)
        self.pair_penalty: FloatArray | None = None
        self.moving: FloatArray | None = None
        if not active.all():
            pair_active = active[:, pairs.i] & active[:, pairs.j]  # (B, pairs)
            if not pair_active.all():
                self.pair_penalty = np.where(pair_active, 0.0, np.inf).T[:, None]  # (pairs, 1, B)
            self.moving = active.T[:, None].astype(np.float64)  # (N, 1, B)
        self.threshold = threshold_m
        self.threshold2 = threshold_m**2

    def _squares(self, state: FloatArray) -> tuple[FloatArray, FloatArray]:
        """(squared pair distances (pairs, P, B), squared shifts (N, P, B)) of a state."""
        rows, p, b = state.shape
        flat = state.reshape(rows, p * b)
        d = flat.take(self.plus, axis=0)
        d -= flat.take(self.minus, axis=0)
        d *= d
        half = self.pairs + self.n
        sq = d[:half]
        sq += d[half:]
        sq3 = sq.reshape(half, p, b)
        d2, shift2 = sq3[: self.pairs], sq3[self.pairs :]
        if self.pair_penalty is not None:
            d2 += self.pair_penalty
        if self.moving is not None:
            shift2 *= self.moving  # inactive UAVs never move; their (zero) shift stays zero
        return d2, shift2

    def rank(self, state: FloatArray) -> FloatArray:
        """f_pso (P, B) of a state's particles (4N, P, B), feasibility read off the violation.

        The same cost as `exact` but for a particle whose smallest distance rounds onto the
        threshold itself; the search ranks with it, the result is re-evaluated exactly.
        """
        d2, shift2 = self._squares(state)
        np.subtract(self.threshold2, d2, out=d2)
        violation = np.add.reduce(np.maximum(d2, 0.0, out=d2), axis=0)  # Σ max(0, d̄² − d_ij²), m²
        cost: FloatArray = np.sqrt(np.maximum.reduce(shift2, axis=0))
        infeasible = violation > 0.0
        violation += INFEASIBLE_COST - self.threshold
        violation *= infeasible
        cost += violation
        cost += self.threshold
        return cost

    def exact(self, x: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
        """(cost (B,), max shift (B,), min distance (B,)) of one particle x (2N, B) each."""
        d2, shift2 = self._squares(np.concatenate([x, self.reference])[:, None])
        b = x.shape[1]
        if not self.pairs:  # a single UAV: nothing to separate
            dmin = np.full(b, np.inf)
            violation = np.zeros(b)
        else:
            dmin = np.sqrt(d2.min(axis=0)[0])
            # Total violation, in m², ranks infeasible particles: Σ max(0, d̄² − d_ij²).
            np.subtract(self.threshold2, d2, out=d2)
            violation = np.maximum(d2, 0.0, out=d2).sum(axis=0)[0]
        shift = np.sqrt(shift2.max(axis=0)[0])
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
    """The particle swarm itself, on positions (2, N, B), particles (2N, P, B).

    ``repaired`` (2, N, B) is the constructive repair of q (`_spread`), the second particle.
    The particles live in the first half of a `_Cost` state (4N, P, B), the reference in the
    second, so that every update works in place on contiguous rows.
    """
    _, n, b = q.shape
    p = cfg.particles
    cost_fn = _Cost(q, act, pairs, cfg.threshold_m)
    reference = q[:, :, None]  # (2, N, 1, B)
    move = None if act.all() else act.T[:, None].astype(np.float64)  # (N, 1, B)

    state = np.empty((4 * n, p, b))
    state[2 * n :] = cost_fn.reference[:, None]
    x4 = state[: 2 * n].reshape(2, n, p, b)
    z = rng.standard_normal((2, 2, n, p, b))
    np.multiply(z[0], cfg.init_noise_m, out=x4)
    x4 += reference
    x4[:, :, 0] = q  # the current positions are a candidate
    if p > 1:
        x4[:, :, 1] = repaired  # and so is a constructive repair of them
    if move is not None:
        x4 -= reference
        x4 *= move
        x4 += reference
    x = state[: 2 * n]  # (2N, P, B), contiguous
    v = z[1].reshape(2 * n, p, b)
    v *= cfg.init_speed_m
    move2 = None if move is None else np.concatenate([move, move])  # (2N, 1, B)
    # Rows of each iteration's coefficients: c₁·r₁ (2N), c₂·r₂ (2N), μ (1).
    rows = 4 * n + 1
    unit = 2.0**-COEFFICIENT_BITS
    scale = np.array([cfg.c1 * unit] * (2 * n) + [cfg.c2 * unit] * (2 * n) + [unit])[:, None, None]
    per_block = max(1, COEFFICIENT_BLOCK // (rows * p * b))

    pbest_cost = cost_fn.rank(state)
    pbest = x.copy()
    flat_pbest = pbest.reshape(2 * n, p * b)
    envs = np.arange(b)
    gbest = flat_pbest.take(pbest_cost.argmin(axis=0) * b + envs, axis=1)[:, None]  # (2N, 1, B)
    pull = np.empty_like(x)
    steps = cfg.iterations - 1
    for t in range(steps):
        if t % per_block == 0:
            block = _coefficients(rng, min(per_block, steps - t), rows, p, b, scale)
        coef = block[t % per_block]
        v *= coef[-1]  # μ ~ U[0, 1) per particle
        np.subtract(pbest, x, out=pull)
        pull *= coef[: 2 * n]  # c₁·r₁
        v += pull
        np.subtract(gbest, x, out=pull)
        pull *= coef[2 * n : 4 * n]  # c₂·r₂
        v += pull
        if move2 is not None:
            v *= move2
        x += v
        cost = cost_fn.rank(state)
        np.copyto(pbest, x, where=cost < pbest_cost)
        np.minimum(pbest_cost, cost, out=pbest_cost)
        gbest = flat_pbest.take(pbest_cost.argmin(axis=0) * b + envs, axis=1)[:, None]

    found = gbest[:, 0]  # (2N, B)
    gcost, gshift, gdmin = cost_fn.exact(found)
    return PSOResult(
        searched=np.ones(b, dtype=bool),
        positions_m=np.ascontiguousarray(found.reshape(2, n, b).transpose(2, 1, 0)),
        cost=gcost,
        max_shift_m=gshift,
        min_distance_m=gdmin,
        feasible=gcost < INFEASIBLE_COST,
        evaluations=cfg.evaluations,
    )

"""Benchmark the contour-level PSO against a per-particle loop reference, in the same run.

The reference evaluates the same cost particle by particle in Python, the structure of the
authors' loop (their figure: 270 ms per call for 3 UAVs and 450 ms for 10 on a 2-core CPU).
Both make the same number of cost evaluations; the ratio is what this script is for.

    python tools/bench_pso.py [--uavs 3 10 20] [--repeats 20] [--json]
"""

from __future__ import annotations

import argparse
import json
import statistics
import time

import numpy as np

from remarl_fc.bench.sim import AUTHORS_BUDGET, bench_pso, crowded_line
from sim.config import PSOConfig
from sim.pso import INFEASIBLE_COST


def loop_pso(positions: np.ndarray, cfg: PSOConfig, rng: np.random.Generator) -> float:
    """Same algorithm and cost, one particle at a time; returns the best cost."""
    q = positions[0]
    n = len(q)

    def cost(x: np.ndarray) -> float:
        dmin, violation = np.inf, 0.0
        for i in range(n):
            for j in range(i + 1, n):
                d = float(np.hypot(*(x[i] - x[j])))
                dmin = min(dmin, d)
                violation += max(0.0, cfg.threshold_m**2 - d * d)
        shift = max(float(np.hypot(*(x[i] - q[i]))) for i in range(n))
        f_thres = cfg.threshold_m if dmin >= cfg.threshold_m else INFEASIBLE_COST + violation
        return f_thres + shift

    xs = [q + rng.normal(0, cfg.init_noise_m, q.shape) for _ in range(cfg.particles)]
    vs = [rng.normal(0, cfg.init_speed_m, q.shape) for _ in range(cfg.particles)]
    pbest = [x.copy() for x in xs]
    pcost = [cost(x) for x in xs]
    g = int(np.argmin(pcost))
    gbest, gcost = pbest[g].copy(), pcost[g]
    for _ in range(cfg.iterations - 1):
        for k in range(cfg.particles):
            r1, r2 = rng.random(q.shape), rng.random(q.shape)
            vs[k] = rng.random() * vs[k] + cfg.c1 * r1 * (pbest[k] - xs[k])
            vs[k] += cfg.c2 * r2 * (gbest - xs[k])
            xs[k] = xs[k] + vs[k]
            c = cost(xs[k])
            if c < pcost[k]:
                pbest[k], pcost[k] = xs[k].copy(), c
            if c < gcost:
                gbest, gcost = xs[k].copy(), c
    return gcost


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--uavs", type=int, nargs="+", default=[3, 10])
    parser.add_argument("--repeats", type=int, default=20)
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    cfg: PSOConfig = AUTHORS_BUDGET
    rows = []
    for n in args.uavs:
        ours = bench_pso(uavs=n, repeats=args.repeats, cfg=cfg)
        rng = np.random.default_rng(0)
        positions = crowded_line(n, 1, cfg.threshold_m, rng)
        times = []
        for _ in range(3):
            t0 = time.perf_counter()
            loop_pso(positions, cfg, rng)
            times.append(time.perf_counter() - t0)
        ref_ms = 1e3 * statistics.median(times)
        rows.append(
            {
                "uavs": n,
                "evaluations": cfg.evaluations,
                "ms_per_call": ours["ms_per_call"],
                "reference_loop_ms_per_call": ref_ms,
                "speedup": ref_ms / ours["ms_per_call"],
                "feasible_fraction": ours["feasible_fraction"],
            }
        )
    if args.json:
        print(json.dumps({"benchmark": "pso_vs_loop", "rows": rows}))
        return
    print(f"{'UAVs':>4} {'evals':>6} {'vectorised ms':>14} {'loop ms':>9} {'speed-up':>9}")
    for r in rows:
        print(
            f"{r['uavs']:>4} {r['evaluations']:>6} {r['ms_per_call']:>14.2f} "
            f"{r['reference_loop_ms_per_call']:>9.1f} {r['speedup']:>8.0f}x"
        )


if __name__ == "__main__":
    main()

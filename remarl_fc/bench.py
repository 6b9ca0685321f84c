"""Micro-benchmarks behind ``remarl-fc bench`` (figures, not pass/fail tests)."""

from __future__ import annotations

import statistics
import time
from typing import Any

import numpy as np

from sim.config import PSOConfig
from sim.pso import pso_separate

CROWDING = 0.7
"""Bench layout: UAVs on a line at this fraction of the threshold spacing, so PSO must work."""

AUTHORS_EVALUATIONS = 6000
"""Cost evaluations per call of the authors' PSO loop (100 particles × 30 iterations × 2)."""

AUTHORS_BUDGET = PSOConfig(particles=AUTHORS_EVALUATIONS // 30, iterations=30)
"""The PSO budget of ``bench pso`` by default: as many evaluations as the authors' loop."""


def crowded_line(uavs: int, envs: int, threshold_m: float, rng: np.random.Generator) -> np.ndarray:
    """(envs, uavs, 2) positions on a jittered line, neighbours closer than the threshold."""
    y = (np.arange(uavs) - (uavs - 1) / 2) * CROWDING * threshold_m
    base = np.stack([np.zeros(uavs), y], axis=-1)
    return base + rng.normal(0.0, 1.0, size=(envs, uavs, 2))


def bench_pso(
    uavs: int, envs: int = 1, repeats: int = 50, seed: int = 0, cfg: PSOConfig | None = None
) -> dict[str, Any]:
    """Time `sim.pso.pso_separate` on crowded swarms; report per-call figures.

    ``cfg`` defaults to `AUTHORS_BUDGET` (6,000 evaluations), for a like-for-like comparison.

    Returns:
        ms_per_call (median over repeats), ms_p90, evaluations (per environment and call),
        and the quality of the results (feasible fraction, mean max shift, mean min distance).
    """
    cfg = cfg or AUTHORS_BUDGET
    rng = np.random.default_rng(seed)
    positions = crowded_line(uavs, envs, cfg.threshold_m, rng)
    pso_separate(positions, cfg, rng)  # warm-up
    times, results = [], []
    for _ in range(repeats):
        t0 = time.perf_counter()
        res = pso_separate(positions, cfg, rng)
        times.append(time.perf_counter() - t0)
        results.append(res)
    times.sort()
    return {
        "benchmark": "pso",
        "uavs": uavs,
        "envs": envs,
        "particles": cfg.particles,
        "iterations": cfg.iterations,
        "evaluations": cfg.evaluations,
        "ms_per_call": 1e3 * statistics.median(times),
        "ms_p90": 1e3 * times[int(0.9 * (len(times) - 1))],
        "feasible_fraction": float(np.mean([r.feasible.mean() for r in results])),
        "mean_max_shift_m": float(np.mean([r.max_shift_m.mean() for r in results])),
        "mean_min_distance_m": float(np.mean([r.min_distance_m.mean() for r in results])),
        "threshold_m": cfg.threshold_m,
    }

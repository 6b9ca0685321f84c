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


ACTION_MODES = ("uniform", "noise")
"""``bench sim`` actions: uniform in [−1, 1] (the usual throughput method), or N(0, 0.1) —
exploration around straight flight, closer to what training feeds the simulator."""

NOISE_SIGMA = 0.1
"""Standard deviation of the "noise" actions (normalised units)."""


def bench_sim(
    scenario: str, batch: int, actions: str = "uniform", seconds: float = 2.0, seed: int = 0
) -> dict[str, Any]:
    """Agent-steps per second of the batched simulator with the full reMARL reward.

    Times `sim.env.SwarmVectorEnv.step` (autoreset, observations, rewards, PSO where it runs)
    on pre-drawn actions for about ``seconds``.
    """
    from sim.env import make_vector_env

    if actions not in ACTION_MODES:
        raise ValueError(f"actions must be one of {', '.join(ACTION_MODES)}, got {actions!r}")
    env = make_vector_env(scenario, batch)
    env.reset(seed=seed)
    n = env.num_agents
    rng = np.random.default_rng(seed)
    shape = (16, batch, n)
    if actions == "uniform":
        drawn = rng.uniform(-1.0, 1.0, shape)
    else:
        drawn = np.clip(rng.normal(0.0, NOISE_SIGMA, shape), -1.0, 1.0)
    drawn = drawn.astype(np.float32)
    for k in range(3):  # warm-up
        env.step(drawn[k])
    steps, t0 = 0, time.perf_counter()
    while True:
        env.step(drawn[steps % len(drawn)])
        steps += 1
        elapsed = time.perf_counter() - t0
        if elapsed >= seconds and steps >= 5:
            break
    return {
        "benchmark": "sim",
        "scenario": env.cfg.name,
        "batch": batch,
        "agents": n,
        "actions": actions,
        "steps": steps,
        "ms_per_step": 1e3 * elapsed / steps,
        "env_steps_per_s": batch * steps / elapsed,
        "agent_steps_per_s": batch * n * steps / elapsed,
    }

"""Run whole episodes with any policy and summarise them: one implementation for every method.

A policy here is any function from flat observations (B, N, D) to normalised actions (B, N):
the DDPG actors, the numpy inference of an exported policy file, a baseline or a heuristic.
A planner that needs the whole simulator state (the E2Coop meta-heuristic) sets the attribute
``uses_state = True`` and is called as ``act(obs, state)``.

Held-out episodes come from `evaluation_seed`, the one place that says which seeds an
evaluation uses.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from sim.config import ScenarioConfig
from sim.env import make_vector_env

ActFn = Callable[..., Any]
"""obs (B, N, D) → actions (B, N); with ``uses_state`` set on it, (obs, state) → actions; either
may return (actions, speeds (B, N) m/s) where it also chooses speeds."""

EvaluationSuite = Literal["run", "training", "zoo", "ablation", "encounters"]

EVALUATION_SEED_BASES: Mapping[EvaluationSuite, int] = {
    "training": 1_000_003,
    "run": 2_000_000,
    "zoo": 5_000_000,
    "ablation": 7_000_000,
    "encounters": 9_000_000,
}
"""First evaluation seed of each suite of evaluations (see `evaluation_seed`)."""

RUN_SEED_STRIDE = 1_000
"""Evaluation seeds of runs whose seeds differ by one lie this far apart."""


def evaluation_seed(run_seed: int = 0, *, suite: EvaluationSuite = "run", offset: int = 0) -> int:
    """The seed of an evaluation's episodes: the suite's base + 1000·run_seed + offset.

    `run_episodes` draws every episode of an evaluation from one generator seeded with this
    number. Training seeds its environments with the run seed (plus the step count on a resumed
    run): small integers, so a run's evaluation episodes are never episodes it trained on. Each
    suite starts its own range, so its published figures never share episodes with another's:

    * ``"run"``: the evaluation of a finished run — `remarl-fc eval` (run seed 0),
      `remarl-fc compare` and every method's final evaluation (the run's own seed);
    * ``"training"``: the evaluations during DDPG training that choose ``best.safetensors``
      (``offset``: the vectorised step; the same episodes whatever the run seed);
    * ``"zoo"``: the zoo's published ``.eval.json`` (`tools/train_zoo.py`);
    * ``"ablation"``: `tools/ablation.py`;
    * ``"encounters"``: the benchmark suites' episodes (`sim.suite`; each episode then has its
      own generator, `sim.encounters.episode_rng`).

    >>> evaluation_seed()  # remarl-fc eval
    2000000
    >>> evaluation_seed(2)  # a compare cell with seed 2
    2002000
    >>> evaluation_seed(suite="training", offset=4_000)
    1004003
    >>> evaluation_seed(suite="zoo")
    5000000
    """
    return EVALUATION_SEED_BASES[suite] + RUN_SEED_STRIDE * run_seed + offset


def run_episodes(
    act: ActFn,
    scenario: str | Path | ScenarioConfig,
    episodes: int,
    seed: int,
    num_envs: int = 50,
) -> list[dict[str, Any]]:
    """Exactly ``episodes`` complete episodes, their metrics in the order they ended.

    Environments run in parallel; each starts new episodes until enough have begun, so no
    episode is cut short and none is counted twice.
    """
    env = make_vector_env(scenario, min(num_envs, episodes))
    obs, _ = env.reset(seed=seed)
    started = env.num_envs
    counted = np.ones(env.num_envs, dtype=bool)  # whether each env's current episode counts
    rows: list[dict[str, Any]] = []
    uses_state = bool(getattr(act, "uses_state", False))
    while len(rows) < episodes:
        decided = act(obs, env.state) if uses_state else act(obs)
        actions, speeds = decided if isinstance(decided, tuple) else (decided, None)
        obs, _, _, _, info = env.step(actions, speeds)
        if "episode" not in info:
            continue
        ep = info["episode"]
        for k, e in enumerate(np.flatnonzero(info["_final_obs"])):
            if counted[e]:
                rows.append({key: ep[key][k] for key in ep})
            counted[e] = started < episodes
            started += int(counted[e])
    return rows[:episodes]


def summarize(rows: list[dict[str, Any]]) -> dict[str, float]:
    """Aggregate metrics (SPEC §9) over episodes from `run_episodes`.

    Distances are metres; energy is Σ|a| in radians per UAV; returns are sums over agents.
    ``min_d_*_m`` is the smallest over all episodes, ``mean_min_d_*_m`` the mean of each
    episode's smallest (episodes with no such pair within sight count as +inf and are skipped).
    """
    if not rows:
        raise ValueError("no episodes to summarise")

    def col(key: str) -> NDArray[np.float64]:
        return np.concatenate([np.ravel(np.asarray(r[key], dtype=np.float64)) for r in rows])

    u2o, u2u = col("min_d_u2o_m"), col("min_d_u2u_m")
    ratio = col("path_length_ratio")
    return {
        "episodes": float(len(rows)),
        "success_rate": float(col("success").mean()),
        "collision_rate": float(np.maximum(col("collision_u2o"), col("collision_u2u")).mean()),
        "collision_rate_u2o": float(col("collision_u2o").mean()),
        "collision_rate_u2u": float(col("collision_u2u").mean()),
        "min_d_u2o_m": float(u2o.min()),
        "min_d_u2u_m": float(u2u.min()),
        "mean_min_d_u2o_m": _finite_mean(u2o),
        "mean_min_d_u2u_m": _finite_mean(u2u),
        "energy_rad": float(col("energy_rad").mean()),
        "path_length_ratio": float(np.nanmean(ratio)) if np.isfinite(ratio).any() else np.nan,
        "swarming_return": float(col("swarming_return").mean()),
        "total_return": float(col("total_return").mean()),
        "episode_length": float(col("length").mean()),
    }


def _finite_mean(values: NDArray[np.float64]) -> float:
    finite = values[np.isfinite(values)]
    return float(finite.mean()) if finite.size else float("inf")

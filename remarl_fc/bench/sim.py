"""Micro-benchmarks behind ``remarl-fc bench`` (figures, not pass/fail tests)."""

from __future__ import annotations

import cProfile
import pstats
import statistics
import sys
import time
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np

from sim.config import PSOConfig
from sim.pso import pso_separate
from sim.scenarios import REAL_WORLD

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


PARTS = (
    "reset",
    "flight",
    "dynamics",
    "swept",
    "outcome",
    "sensors",
    "score",
    "avoidance",
    "observation",
    "other",
)
"""The parts of a step ``bench sim`` reports a share for, in order of the step:

reset: new episodes (spawn, merge, PSO of their levels); flight: the arcs (`fly`); dynamics:
the fitted vehicle dynamics (`sim.dynamics`, where it exists); swept: the swept closest
approaches; outcome: collisions, arrivals, the episode accumulators; sensors: the sensor model
(`sim.sensors`, where it exists); score: contour windows and the reward; avoidance: PSO where
avoidance begins; observation: the observation builder; other: everything else (the step's own
glue, the vector env's bookkeeping)."""

PART_OF_MODULE: Mapping[str, str] = {
    "sim.spawn": "reset",
    "sim.dynamics": "dynamics",
    "sim.sensors": "sensors",
    "sim.observation": "observation",
}
"""Every function of these modules counts in the part (unless a nearer caller part owns it)."""

PART_OF_FUNCTION: Mapping[tuple[str, str], str] = {
    ("sim.swarm", "SwarmSim.reset_where"): "reset",
    ("sim.swarm", "SwarmSim.restart_where"): "reset",
    ("sim.swarm", "SwarmSim.initial_state"): "reset",
    ("sim.swarm", "SwarmSim.start"): "reset",
    ("sim.swarm", "SwarmSim.observe"): "observation",
    ("sim.transition", "fly"): "flight",
    ("sim.transition", "closest_approaches"): "swept",
    ("sim.metrics", "swept_min_distance_xy"): "swept",
    ("sim.transition", "outcome"): "outcome",
    ("sim.transition", "accumulate"): "outcome",
    ("sim.vector_env", "episode_metrics"): "outcome",
    ("sim.transition", "score"): "score",
    ("sim.reward", "reward"): "score",
    ("sim.contour", "arc_external_xy"): "score",
    ("sim.transition", "begin_avoidance"): "avoidance",
}
"""(module, qualified name) of the functions that root a part. A function that is in neither
table takes the part of its callers (split by the time spent under each), so a helper counts
where it is called from; time with no part above it is "other"."""

PROFILED_STEPS = 40
"""Steps run under the profiler for the part shares (after the timed run, separately)."""

_Key = tuple[str, int, str]  # pstats' (file, line, function name)


def _module_of(filename: str) -> str:
    """The dotted module of a source file under a package root, e.g. ``sim.swarm``."""
    parts = filename.replace("\\", "/").removesuffix(".py").split("/")
    for root in ("sim", "remarl_fc"):
        if root in parts:
            k = len(parts) - 1 - parts[::-1].index(root)
            return ".".join(parts[k:])
    return ""


def _own_part(key: _Key, qualname: Callable[[_Key], str]) -> str | None:
    module = _module_of(key[0])
    part = PART_OF_FUNCTION.get((module, qualname(key)))
    return part if part is not None else PART_OF_MODULE.get(module)


def part_shares(stats: pstats.Stats) -> dict[str, float]:
    """Each part's share of the profiled time (`PARTS`, summing to 1) from cProfile statistics.

    See `shares_of_profile`.
    """
    raw: Mapping[_Key, Any] = stats.stats  # type: ignore[attr-defined]
    return shares_of_profile(raw, _qualnames())


def shares_of_profile(
    raw: Mapping[_Key, Any], qualname: Callable[[_Key], str] = lambda key: key[2]
) -> dict[str, float]:
    """Each part's share of the time in ``raw``, a cProfile table.

    ``raw`` is pstats' table: function → (calls, primitive calls, own time, cumulative time,
    callers → the same four). Every function's own time goes to its part (`PART_OF_FUNCTION`,
    `PART_OF_MODULE`), or is split over its callers in proportion to the time spent under
    each, up to the nearest caller that has a part; what reaches no part is "other".
    ``qualname`` names a function's key (``Class.method``).
    """
    memo: dict[_Key, dict[str, float]] = {}

    def shares_of(key: _Key, visiting: frozenset[_Key]) -> dict[str, float]:
        if key in memo:
            return memo[key]
        part = _own_part(key, qualname)
        if part is not None:
            return {part: 1.0}
        callers = {
            c: edge[3]
            for c, edge in raw[key][4].items()
            if c != key and c not in visiting and c in raw
        }
        total = sum(callers.values())
        result: dict[str, float] = {}
        if total <= 0.0:
            result["other"] = 1.0
        for caller, t in callers.items() if total > 0.0 else ():
            for p, f in shares_of(caller, visiting | {key}).items():
                result[p] = result.get(p, 0.0) + f * t / total
        memo[key] = result
        return result

    seconds = dict.fromkeys(PARTS, 0.0)
    for key, entry in raw.items():
        for p, f in shares_of(key, frozenset()).items():
            seconds[p] += f * entry[2]
    total = sum(seconds.values()) or 1.0
    return {p: t / total for p, t in seconds.items()}


def _qualnames() -> Callable[[_Key], str]:
    """A function's qualified name (``Class.method``) from its pstats key.

    pstats keeps only the bare name, so methods are matched through their code objects' first
    line in the loaded modules.
    """
    lines: dict[tuple[str, int], str] = {}
    for name, module in list(sys.modules.items()):
        if not name.startswith(("sim.", "remarl_fc.")):
            continue
        for obj in vars(module).values():
            if isinstance(obj, type) and obj.__module__ == name:
                for attr in vars(obj).values():
                    code = getattr(attr, "__code__", None)
                    if code is not None:
                        lines[(code.co_filename, code.co_firstlineno)] = attr.__qualname__

    def qualname(key: _Key) -> str:
        return lines.get((key[0], key[1]), key[2])

    return qualname


REAL_NEIGHBOURS = 6
"""Neighbour rows (k) of the "real" world's version-2 observation: the generalist's."""

REAL_INTRUDERS = 8
"""Intruder rows (m) of the "real" world's version-2 observation: the generalist's."""

WORLDS: dict[str, dict[str, Any]] = {
    "paper": {},
    "real": {
        **REAL_WORLD,
        "sensing": {
            "observation": 2,
            "max_neighbours": REAL_NEIGHBOURS,
            "max_obstacles": REAL_INTRUDERS,
        },
    },
}
"""``bench sim`` worlds, as scenario overrides: "paper" (ideal vehicles, exact sensing: the
scenario as shipped) and "real" (each UAV ArduCopter's or PX4's fitted response, randomised
per UAV, intruders through ADS-B, GPS noise, and the neighbours in the observation: version 2
with the generalist's k = 6 neighbour and m = 8 intruder rows, `sim.observation`; the
vehicles and sensors are what the robust policies train on, ``policies/zoo/robust/3u2o.toml``,
the observation what the generalist reads)."""


def _vector_env(
    scenario: str, batch: int, actions: str, seed: int, world: str = "paper"
) -> tuple[Any, np.ndarray]:
    """A reset vector env of the scenario and 16 pre-drawn joint actions, (16, B, N) float32."""
    from sim.env import make_vector_env

    if actions not in ACTION_MODES:
        raise ValueError(f"actions must be one of {', '.join(ACTION_MODES)}, got {actions!r}")
    if world not in WORLDS:
        raise ValueError(f"world must be one of {', '.join(WORLDS)}, got {world!r}")
    env = make_vector_env(scenario, batch, **WORLDS[world])
    env.reset(seed=seed)
    rng = np.random.default_rng(seed)
    shape = (16, batch, env.num_agents)
    if actions == "uniform":
        drawn = rng.uniform(-1.0, 1.0, shape)
    else:
        drawn = np.clip(rng.normal(0.0, NOISE_SIGMA, shape), -1.0, 1.0)
    return env, drawn.astype(np.float32)


def bench_sim(
    scenario: str,
    batch: int,
    actions: str = "uniform",
    seconds: float = 2.0,
    seed: int = 0,
    *,
    parts: bool = True,
    world: str = "paper",
) -> dict[str, Any]:
    """Agent-steps per second of the batched simulator with the full reMARL reward.

    Times `sim.env.SwarmVectorEnv.step` (autoreset, observations, rewards, PSO where it runs)
    on pre-drawn actions for about ``seconds``. With ``parts``, a second, separate run of
    `PROFILED_STEPS` steps under cProfile gives each part's share of a step (`PARTS`,
    `part_shares`); the throughput comes from the first run only, without the profiler.
    ``world`` (`WORLDS`): the paper's, or vehicles and sensors as in flight.
    """
    env, drawn = _vector_env(scenario, batch, actions, seed, world)
    n = env.num_agents
    for k in range(3):  # warm-up
        env.step(drawn[k])
    steps, t0 = 0, time.perf_counter()
    while True:
        env.step(drawn[steps % len(drawn)])
        steps += 1
        elapsed = time.perf_counter() - t0
        if elapsed >= seconds and steps >= 5:
            break
    result: dict[str, Any] = {
        "benchmark": "sim",
        "scenario": env.cfg.name,
        "world": world,
        "batch": batch,
        "agents": n,
        "actions": actions,
        "steps": steps,
        "ms_per_step": 1e3 * elapsed / steps,
        "env_steps_per_s": batch * steps / elapsed,
        "agent_steps_per_s": batch * n * steps / elapsed,
    }
    if parts:
        profiler = cProfile.Profile(builtins=False)  # C calls count in their Python caller
        profiler.enable()
        for k in range(PROFILED_STEPS):
            env.step(drawn[(steps + k) % len(drawn)])
        profiler.disable()
        result["parts"] = part_shares(pstats.Stats(profiler))
    return result


def format_parts(shares: Mapping[str, float]) -> str:
    """``reset 12% · flight 5% · …`` for the parts that have any share, in step order."""
    return " · ".join(f"{p} {shares[p]:.0%}" for p in PARTS if shares.get(p, 0.0) >= 0.005)

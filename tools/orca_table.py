"""The classical baselines on the paper's eight scenarios: straight, potential field and ORCA.

    python tools/orca_table.py                 # the Markdown table and ORCA's decision time
    python tools/orca_table.py --episodes 50   # quicker
    python tools/orca_table.py --scenarios 20u4o,50u8o   # beyond the paper
    python tools/orca_table.py --sweep         # the sweep behind sim.orca's constants (~11 min)

Every figure comes from `sim.evaluation` (`run_episodes`, `summarize`) on the evaluation seeds
of `remarl-fc eval` (`evaluation_seed()`); the sweep uses its own seeds (the "ablation" suite,
run seed 1), so the constants were not chosen on the table's episodes.
"""

from __future__ import annotations

import argparse
import itertools
import statistics
import time
from collections.abc import Callable
from typing import Any

import numpy as np
from numpy.typing import NDArray

from sim.config import ScenarioConfig
from sim.evaluation import evaluation_seed, run_episodes, summarize
from sim.heuristics import potential_field_actions, straight_actions
from sim.orca import orca_actions
from sim.scenarios import load_scenario
from sim.state import SwarmState
from sim.swarm import SwarmSim

PAPER_SCENARIOS = ("2u1o", "3u1o", "5u1o", "7u1o", "10u1o", "3u2o", "5u2o", "7u2o")
POLICIES = ("straight", "potential-field", "orca")
TIMING_SCENARIO = "50u8o"
"""Where the decision time is measured: 50 UAVs and 8 obstacles, batch 1."""
TIMING_CALLS = 200
SWEEP_SEED = evaluation_seed(1, suite="ablation")
SWEEP = {
    "horizon_s": (6.0, 10.0, 14.0),
    "neighbour_horizon_s": (4.0, 6.0, 8.0),
    "margin_m": (0.0, 1.0, 2.5, 5.0),
    "priority": (0.0, 0.25, 0.5),
}


def policy(name: str, cfg: ScenarioConfig, **orca: Any) -> Callable[..., NDArray[np.float32]]:
    """A `run_episodes` policy; ORCA reads the simulator state (``uses_state``)."""
    if name == "straight":
        return straight_actions
    if name == "potential-field":
        return lambda obs: potential_field_actions(
            obs, cfg.sensing.max_obstacles, cfg.uav.max_turn_rad
        )

    def act(obs: NDArray[np.float32], state: SwarmState) -> NDArray[np.float32]:
        return orca_actions(state, cfg, **orca)

    act.uses_state = True  # type: ignore[attr-defined]
    return act


def evaluate(name: str, scenario: str, episodes: int, seed: int, **orca: Any) -> dict[str, float]:
    cfg = load_scenario(scenario)
    rows = run_episodes(policy(name, cfg, **orca), cfg, episodes, seed, num_envs=episodes)
    return summarize(rows)


def decision_time_ms(scenario: str = TIMING_SCENARIO, calls: int = TIMING_CALLS) -> float:
    """Median wall time of one ORCA decision for a whole swarm (batch 1), over ``calls`` calls
    on the states of one ORCA episode (obstacles in and out of sight)."""
    cfg = load_scenario(scenario)
    sim = SwarmSim(cfg)
    rng = np.random.default_rng(evaluation_seed())
    state = sim.initial_state(rng, 1)
    states = [state]
    for _ in range(cfg.max_steps):
        state, result = sim.step(state, orca_actions(state, cfg), rng)
        if (result.terminated | result.truncated)[0]:
            break
        states.append(state)
    times = []
    for k in range(calls):
        s = states[k % len(states)]
        t0 = time.perf_counter()
        orca_actions(s, cfg)
        times.append(time.perf_counter() - t0)
    return statistics.median(times) * 1e3


def table(episodes: int, scenarios: tuple[str, ...] = PAPER_SCENARIOS) -> None:
    seed = evaluation_seed()
    print(f"{episodes} episodes per cell, seed {seed}; success / collisions U2O / U2U\n")
    print("| scenario | " + " | ".join(POLICIES) + " |")
    print("|---|" + "---|" * len(POLICIES))
    for scenario in scenarios:
        cells = []
        for name in POLICIES:
            r = evaluate(name, scenario, episodes, seed)
            cells.append(
                f"{r['success_rate']:.1%} / {r['collision_rate_u2o']:.1%} / "
                f"{r['collision_rate_u2u']:.1%}"
            )
        print(f"| {scenario} | " + " | ".join(cells) + " |", flush=True)
    ms = decision_time_ms()
    print(f"\nORCA decision, {TIMING_SCENARIO} (batch 1), median of {TIMING_CALLS}: {ms:.2f} ms")


def sweep(episodes: int) -> None:
    print(f"{episodes} episodes per scenario, seed {SWEEP_SEED}; success (mean over the eight)\n")
    names = list(SWEEP)
    print("| " + " | ".join(names) + " | " + " | ".join(PAPER_SCENARIOS) + " | mean |")
    print("|---" * (len(names) + len(PAPER_SCENARIOS) + 1) + "|")
    for values in itertools.product(*SWEEP.values()):
        orca = dict(zip(names, values, strict=True))
        rates = [
            evaluate("orca", s, episodes, SWEEP_SEED, **orca)["success_rate"]
            for s in PAPER_SCENARIOS
        ]
        cells = " | ".join(f"{r:.1%}" for r in rates)
        print(f"| {' | '.join(map(str, values))} | {cells} | {np.mean(rates):.1%} |", flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=200)
    parser.add_argument("--scenarios", default=",".join(PAPER_SCENARIOS), help="comma-separated")
    parser.add_argument("--sweep", action="store_true", help="sweep sim.orca's constants")
    args = parser.parse_args()
    if args.sweep:
        sweep(args.episodes)
    else:
        table(args.episodes, tuple(args.scenarios.split(",")))


if __name__ == "__main__":
    main()

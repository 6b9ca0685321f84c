"""How fast the oracle planner (`sim.oracle`) labels episodes, and how many it proves solvable.

    OMP_NUM_THREADS=1 python tools/oracle_bench.py         # 200 episodes of each scenario
    python tools/oracle_bench.py --episodes 50 --scenarios 3u2o,20u4o
    python tools/oracle_bench.py --hard                    # also the hand-built 1-UAV cases

Episodes come from `sim.spawn.spawn_episodes` with seed 0, as the brief of the suite asks. Each
row: the planning time (the whole `plan_episodes` call, verification flights included), that
time per 100 episodes, the fraction planned and the fraction the simulator flew to success.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from sim.oracle import OracleConfig, fly_plans, plan_episodes
from sim.scenarios import load_scenario
from sim.spawn import EpisodeStart, spawn_episodes

SCENARIOS = ("3u2o", "7u2o", "10u1o", "20u4o", "50u8o")
START_M, TARGET_M = (55.0, 150.0), (270.0, 150.0)
HARD = {
    # name: (obstacle position, velocity, solvable expected)
    "static obstacle on the target": ((270.0, 150.0), (0.0, 0.0), False),
    "head-on intruder at 10 m/s": ((200.0, 150.0), (-10.0, 0.0), True),
    "static obstacle mid-path": ((160.0, 150.0), (0.0, 0.0), True),
    "crossing from the right at 10 m/s": ((160.0, 45.0), (0.0, 10.0), True),
}


def bench(name: str, episodes: int, oracle: OracleConfig) -> None:
    cfg = load_scenario(name)
    starts = spawn_episodes(cfg, np.random.default_rng(0), episodes)
    t0 = time.perf_counter()
    plans = plan_episodes(cfg, starts, oracle)
    seconds = time.perf_counter() - t0
    print(
        f"| {name:6s} | {episodes:5d} | {seconds:8.1f} | {100 * seconds / episodes:9.2f} | "
        f"{plans.planned.mean():7.3f} | {plans.solvable.mean():8.3f} |",
        flush=True,
    )


def hard_cases(oracle: OracleConfig) -> None:
    cfg = load_scenario("3u1o", uav={"count": 1}, obstacles={"count": 1})
    print("\n| case | straight flight succeeds | solvable | expected |\n|---|---|---|---|")
    for case, (pos, vel, expected) in HARD.items():
        episodes = EpisodeStart.of_swarm(
            np.array([[START_M]]),
            np.array([[TARGET_M]]),
            np.array([[pos]]),
            np.array([[vel]]),
            np.zeros((1, 1), dtype=np.int64),
            cfg.uav.speed_m_s,
            cfg.field.swarm_lead_m,
        )
        straight = fly_plans(cfg, episodes, np.zeros((1, cfg.max_steps, 1), dtype=np.float32))
        solvable = plan_episodes(cfg, episodes, oracle).solvable[0]
        print(f"| {case} | {straight[0]} | {solvable} | {expected} |")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--episodes", type=int, default=200, help="episodes per scenario")
    parser.add_argument("--scenarios", default=",".join(SCENARIOS), help="comma-separated names")
    parser.add_argument("--beam", type=int, default=OracleConfig.beam, help="beam width W")
    parser.add_argument("--orders", type=int, default=OracleConfig.orders, help="attempts")
    parser.add_argument("--hard", action="store_true", help="also the hand-built 1-UAV cases")
    args = parser.parse_args()
    oracle = OracleConfig(beam=args.beam, orders=args.orders)
    print("| scenario | episodes | seconds | s per 100 | planned | solvable |")
    print("|---|---|---|---|---|---|")
    for name in args.scenarios.split(","):
        bench(name.strip(), args.episodes, oracle)
    if args.hard:
        hard_cases(oracle)


if __name__ == "__main__":
    main()

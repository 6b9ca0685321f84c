"""Simulator throughput sweep, with reference simulators measured in the same run if installed.

    python tools/bench_sim.py [--scenario 5u1o] [--batches 1 64 1024 4096] [--seconds 2]
        [--worlds paper real] [--json]

Measures remarl-fc (full reMARL reward, autoreset) in each world (`remarl_fc.bench.sim.WORLDS`:
"paper", ideal vehicles and exact sensing; "real", the fitted ArduCopter/PX4 response randomised
per UAV, ADS-B intruders, GPS noise and the neighbours in the observation, version 2 with k = 6
and m = 8) with uniform random actions and with
N(0, 0.1) exploration around straight flight, and each part's share of a step with uniform
actions (a separate profiled run, `remarl_fc.bench.sim.part_shares`; the throughput is timed
without the profiler). If `vmas` is importable, VMAS "navigation" with
the same number of agents and uniform random actions is timed at the same batch sizes; if
`mpe2` is importable, MPE2 `simple_spread_v3` (parallel API, batch 1). Neither is a dependency
of remarl-fc: `pip install vmas mpe2` in the benchmark environment to get the comparison.
"""

from __future__ import annotations

import argparse
import json
import time
from typing import Any

from remarl_fc.bench.sim import WORLDS, bench_sim, format_parts
from sim.heap import keep_freed_memory


def vmas_agent_steps(agents: int, batch: int, seconds: float) -> float | None:
    try:
        import torch
        import vmas
    except ImportError:
        return None
    env = vmas.make_env(
        "navigation", num_envs=batch, device="cpu", continuous_actions=True, n_agents=agents
    )
    env.reset()
    actions = [torch.rand(batch, 2) * 2 - 1 for _ in range(agents)]
    for _ in range(3):
        env.step(actions)
    steps, t0 = 0, time.perf_counter()
    while time.perf_counter() - t0 < seconds or steps < 5:
        env.step([torch.rand(batch, 2) * 2 - 1 for _ in range(agents)])
        steps += 1
    return batch * agents * steps / (time.perf_counter() - t0)


def mpe2_agent_steps(seconds: float) -> float | None:
    try:
        from mpe2 import simple_spread_v3
    except ImportError:
        return None
    env = simple_spread_v3.parallel_env(continuous_actions=True)
    env.reset(seed=0)
    agent_steps, t0 = 0, time.perf_counter()
    while time.perf_counter() - t0 < seconds:
        actions = {a: env.action_space(a).sample() for a in env.agents}
        _, _, term, trunc, _ = env.step(actions)
        agent_steps += len(actions)
        if not env.agents or any(term.values()) or any(trunc.values()):
            env.reset()
    return agent_steps / (time.perf_counter() - t0)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", default="5u1o")
    parser.add_argument("--batches", type=int, nargs="+", default=[1, 64, 1024, 4096])
    parser.add_argument("--seconds", type=float, default=2.0)
    parser.add_argument("--worlds", nargs="+", default=["paper", "real"], choices=list(WORLDS))
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    keep_freed_memory()  # the simulator's steps reuse their temporaries
    rows: list[dict[str, Any]] = []
    mpe2 = mpe2_agent_steps(args.seconds)
    for batch in args.batches:
        vmas: float | None = None
        for world in args.worlds:
            uniform = bench_sim(args.scenario, batch, "uniform", args.seconds, world=world)
            noise = bench_sim(args.scenario, batch, "noise", args.seconds, parts=False, world=world)
            if vmas is None:
                vmas = vmas_agent_steps(uniform["agents"], batch, args.seconds)
            row = {
                "batch": batch,
                "world": world,
                "remarl_uniform": uniform["agent_steps_per_s"],
                "remarl_noise": noise["agent_steps_per_s"],
                "vmas_navigation": vmas,
                "ratio_vs_vmas": None if vmas is None else uniform["agent_steps_per_s"] / vmas,
                "parts": uniform["parts"],
            }
            if batch == 1:
                row["mpe2_simple_spread"] = mpe2
                rate = uniform["agent_steps_per_s"]
                row["ratio_vs_mpe2"] = None if mpe2 is None else rate / mpe2
            rows.append(row)
    if args.json:
        print(json.dumps({"benchmark": "sim_sweep", "scenario": args.scenario, "rows": rows}))
        return

    def fmt(x: float | None) -> str:
        return "—" if x is None else f"{x:,.0f}"

    print(f"scenario {args.scenario}: agent-steps/s")
    print(f"{'batch':>6} {'world':>6} {'uniform':>10} {'noise':>10} {'VMAS nav':>10} {'ratio':>6}")
    for r in rows:
        ratio = "—" if r["ratio_vs_vmas"] is None else f"{r['ratio_vs_vmas']:.1f}x"
        print(
            f"{r['batch']:>6} {r['world']:>6} {fmt(r['remarl_uniform']):>10} "
            f"{fmt(r['remarl_noise']):>10} {fmt(r['vmas_navigation']):>10} {ratio:>6}"
        )
    print("share of a step (uniform actions, profiled separately):")
    for r in rows:
        print(f"{r['batch']:>6} {r['world']:>6} {format_parts(r['parts'])}")
    if mpe2 is not None:
        first = rows[0]
        print(f"MPE2 simple_spread_v3, batch 1: {mpe2:,.0f} agent-steps/s", end="")
        if first["batch"] == 1:
            print(f" (remarl-fc batch 1: {first['remarl_uniform'] / mpe2:.1f}x)")
        else:
            print()


if __name__ == "__main__":
    main()

"""Ablation: the full reMARL reward against its Swarming part alone, same training budget.

    python tools/ablation.py [--scenarios 5u2o 10u1o] [--steps 4000] [--episodes 500] [--json]

Trains per-agent DDPG twice per scenario (same seed, same number of environment steps), once
on r = −f + r_form·r_collide and once on r_form·r_collide, then evaluates both deterministic
policies on the same held-out seeds. Reports success rate and Swarming return (the quantity
the paper's learning curves plot) for each.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from policies.config import TrainConfig
from policies.train import train
from remarl_fc.offline.evaluate import evaluate_policy
from sim.evaluation import evaluation_seed

EVAL_SEED = evaluation_seed(suite="ablation")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenarios", nargs="+", default=["5u2o", "10u1o"])
    parser.add_argument("--steps", type=int, default=4000)
    parser.add_argument("--episodes", type=int, default=500)
    parser.add_argument("--runs", default="runs/ablation")
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    rows = []
    for name in args.scenarios:
        for reward in ("remarl", "swarming"):
            from policies.export import export_policy

            run = Path(args.runs) / f"{name}-{reward}"
            cfg = TrainConfig(
                scenario=name,
                total_steps=args.steps,
                eval_every=max(args.steps // 4, 1),
                eval_episodes=100,
                reward=reward,
            )
            summary = train(cfg, run)
            policy_file = run / "policy.safetensors"
            export_policy(run, policy_file)
            _, result = evaluate_policy(str(policy_file), name, args.episodes, EVAL_SEED)
            rows.append(
                {
                    "scenario": name,
                    "reward": reward,
                    "env_steps": summary["env_steps"],
                    "train_wall_s": summary["elapsed_s"],
                    "success_rate": result["success_rate"],
                    "collision_rate": result["collision_rate"],
                    "swarming_return": result["swarming_return"],
                    "min_d_u2o_m": result["min_d_u2o_m"],
                    "min_d_u2u_m": result["min_d_u2u_m"],
                }
            )
            print(json.dumps(rows[-1]), flush=True)
    if args.json:
        print(json.dumps({"ablation": rows}))
        return
    print("| scenario | reward | env steps | success | collisions | Swarming return |")
    print("|---|---|---|---|---|---|")
    for r in rows:
        print(
            f"| {r['scenario']} | {r['reward']} | {r['env_steps']:,} | {r['success_rate']:.1%} | "
            f"{r['collision_rate']:.1%} | {r['swarming_return']:.1f} |"
        )


if __name__ == "__main__":
    main()

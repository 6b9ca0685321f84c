"""Train, evaluate and export the policy zoo (``policies/zoo/<scenario>.safetensors``).

    python tools/train_zoo.py [--scenarios 2u1o 3u2o ...] [--minutes 10] [--episodes 1000]

For each scenario: ``remarl-fc train`` with a wall-clock budget, ``remarl-fc eval`` of the best
checkpoint on 1,000 episodes with seeds never used in training, then export with the metrics
embedded, and the eval JSON beside the policy file. Prints one line per scenario. A scenario
may be a file: the policy is named after it and evaluated on it, e.g. the robust 3u2o policy::

    python tools/train_zoo.py --scenarios policies/zoo/robust/3u2o.toml --minutes 35 \
        --zoo policies/zoo/robust --runs runs/robust
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path
from typing import Any

from policies.config import DDPGConfig, TrainConfig
from policies.export import export_policy
from policies.train import train
from remarl_fc.offline.evaluate import evaluate_policy
from sim.evaluation import evaluation_seed
from sim.heap import keep_freed_memory

ZOO = Path(__file__).resolve().parents[1] / "policies" / "zoo"
PAPER = ["2u1o", "3u1o", "5u1o", "7u1o", "10u1o", "3u2o", "5u2o", "7u2o"]
EVAL_SEED = evaluation_seed(suite="zoo")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenarios", nargs="+", default=PAPER)
    parser.add_argument("--minutes", type=float, default=10.0)
    parser.add_argument("--episodes", type=int, default=1000)
    parser.add_argument("--runs", default="runs/zoo")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--shared", action="store_true", help="parameter sharing across agents")
    parser.add_argument("--zoo", default=str(ZOO), help="where to write the policies")
    parser.add_argument(
        "--from-run", default=None, help="publish this existing run folder instead of training"
    )
    args = parser.parse_args()
    keep_freed_memory()  # the simulator's steps reuse their temporaries
    zoo = Path(args.zoo)
    zoo.mkdir(parents=True, exist_ok=True)
    for scenario in args.scenarios:
        name = Path(scenario).stem
        t0 = time.monotonic()
        if args.from_run:
            run = Path(args.from_run)
            last = [json.loads(x) for x in (run / "evals.jsonl").read_text().splitlines()][-1]
            summary = {"elapsed_s": last["elapsed_s"], "env_steps": None}
        else:
            run = Path(args.runs) / name
            cfg = TrainConfig(
                scenario=scenario,
                total_steps=10_000_000,
                minutes=args.minutes,
                seed=args.seed,
                eval_every=1_000,
                eval_episodes=100,
                ddpg=DDPGConfig(shared=args.shared),
            )
            summary = train(cfg, run)
        result = publish(run, scenario, args.episodes, zoo, summary)
        print(
            f"{name}: success {result['success_rate']:.1%}, collisions "
            f"{result['collision_rate']:.1%}, min d_U2O {result['min_d_u2o_m']:.1f} m, "
            f"trained {summary['elapsed_s'] / 60:.1f} min, "
            f"total {(time.monotonic() - t0) / 60:.1f} min",
            flush=True,
        )


def publish(
    run: Path, scenario: str, episodes: int, zoo: Path, summary: dict[str, Any]
) -> dict[str, Any]:
    """Evaluate a run's best networks on held-out seeds and write the zoo file and its JSON."""
    name = Path(scenario).stem
    staging = run / "policy.safetensors"
    export_policy(run, staging)
    _, result = evaluate_policy(str(staging), scenario, episodes, EVAL_SEED)
    result["train_wall_s"] = summary["elapsed_s"]
    result["train_env_steps"] = summary["env_steps"]
    export_policy(run, zoo / f"{name}.safetensors", metrics=result)
    where = (
        zoo.resolve().relative_to(ZOO.parents[1])
        if zoo.resolve().is_relative_to(ZOO.parents[1])
        else zoo
    )
    result["policy"] = f"{name} ({where / f'{name}.safetensors'})"
    (zoo / f"{name}.eval.json").write_text(json.dumps(result, indent=2) + "\n")
    return result


if __name__ == "__main__":
    main()

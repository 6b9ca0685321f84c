"""The recipe's round with its rollouts in other processes against one process: speed.

Runs the recipe's round (``remarl-fc train --generalist --init POLICY --teacher self-shield
--dagger-fraction 1 --dagger-lr 3e-4``, the same seed) once per ``--rollout-processes`` value,
one after the other, each for the same budget and with the machine to itself; per run it prints
the DAgger iterations, UAV transitions and gradient steps per minute of the run's budget (what
the recipe's ``--minutes`` counts; the final validation excluded), the share of it spent
flying (one process) or waiting for the rollouts (more), and each figure's ratio to the first
value's run, measured in the same invocation.

    python tools/bench_rollouts.py [--processes 0,1] [--minutes 3] [--policy generalist]
        [--seed 14] [--json]

On a 2-core machine ``--processes 0,1`` is the comparison that matters: one process flies
and learns in turn; with one rollout process the flying overlaps the learning.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

from generalist_recipe import ROUND, remarl


def run_command(policy: str, processes: int, minutes: float, seed: int, out: Path) -> list[str]:
    """The ``train --generalist`` command of one round: the recipe's (`generalist_recipe`)."""
    fleet = ("--rollout-processes", str(processes)) if processes else ()
    return remarl(
        "train",
        "--generalist",
        *("--init", policy, *ROUND),
        *("--minutes", f"{minutes:g}", "--seed", str(seed)),
        *fleet,
        *("--out", str(out), "--json"),
    )


def figures(summary: dict[str, Any], minutes: float) -> dict[str, float]:
    """One round's throughput per minute of its budget."""
    return {
        "iterations": summary["iterations"],
        "iterations_per_min": summary["iterations"] / minutes,
        "transitions_per_min": summary["transitions"] / minutes,
        "updates_per_min": summary["updates"] / minutes,
        "wait_share": summary["simulator_s"] / (60 * minutes),
    }


def bench_rollouts(
    policy: str, processes: list[int], minutes: float, seed: int, out: Path
) -> dict[str, dict[str, float]]:
    """One round per processes value, in turn; their figures with ratios to the first's."""
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    results: dict[str, dict[str, float]] = {}
    for count in processes:
        name = f"processes-{count}"
        done = subprocess.run(
            run_command(policy, count, minutes, seed, out / name),
            capture_output=True,
            text=True,
            env=env,
            check=False,
        )
        if done.returncode != 0:
            sys.exit(
                f"bench_rollouts: {name} failed (exit {done.returncode}): {done.stderr[-400:]}"
            )
        results[name] = figures(json.loads(done.stdout), minutes)
    first = results[f"processes-{processes[0]}"]
    for row in results.values():
        for key in ("iterations_per_min", "transitions_per_min", "updates_per_min"):
            row[f"{key}_ratio"] = row[key] / first[key]
    return results


def main() -> None:
    """Run the benchmark and print its figures."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--processes", default="0,1", help="comma-separated rollout processes")
    parser.add_argument("--minutes", type=float, default=3.0, help="budget of every round")
    parser.add_argument("--policy", default="generalist", help="the round's start (zoo name/path)")
    parser.add_argument("--seed", type=int, default=14)
    parser.add_argument("--out", default=None, help="folder of the run folders (default: temp)")
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    args = parser.parse_args()
    try:
        processes = [int(p) for p in args.processes.split(",")]
    except ValueError:
        parser.error(f"--processes: comma-separated integers, got {args.processes!r}")
    if any(p < 0 for p in processes):
        parser.error("--processes: every value must be >= 0")
    with tempfile.TemporaryDirectory() as temp:
        out = Path(args.out or temp)
        results = bench_rollouts(args.policy, processes, args.minutes, args.seed, out)
    if args.json:
        print(json.dumps(results, indent=2))
        return
    print(
        f"{'run':14} {'iterations':>10} {'it/min':>7} {'ratio':>6} {'transitions/min':>16} "
        f"{'updates/min':>12} {'waiting':>8}"
    )
    for name, row in results.items():
        print(
            f"{name:14} {row['iterations']:10.0f} {row['iterations_per_min']:7.2f} "
            f"{row['iterations_per_min_ratio']:6.2f} {row['transitions_per_min']:16,.0f} "
            f"{row['updates_per_min']:12,.0f} {row['wait_share']:8.0%}"
        )


if __name__ == "__main__":
    main()

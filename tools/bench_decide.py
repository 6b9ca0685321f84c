"""Time one decision of a generalist for a whole swarm: observations, actor, shield; numpy only.

50 UAVs and 8 intruders (the 50u8o scenario) against a generalist of the shipped size (hidden
64, k = 6 neighbour rows, m = 8 intruder rows); see `remarl_fc.bench.decide`. Prints the median
and p99 of a decision and of each part, in milliseconds, and of a fixed numpy reference
workload timed beside it (`remarl_fc.bench.decide.reference_workload`): the decision's ratio
to it moves less across days than the milliseconds, on a machine whose speed varies from one
session to the next (it moves too: docs/RESULTS.md).

    OMP_NUM_THREADS=1 python tools/bench_decide.py [--scenario 50u8o] [--samples 2000] [--json]
        [--pooling max-attention] [--shield-passes 1] [--dynamics arducopter]
"""

from __future__ import annotations

import argparse
import json

from remarl_fc.bench.decide import (
    SHIPPED_HIDDEN,
    SHIPPED_INTRUDERS,
    SHIPPED_NEIGHBOURS,
    bench_decide,
)
from sim.shield import ShieldConfig


def main() -> None:
    """Run the benchmark and print its figures."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", default="50u8o", help="the swarm and its intruders")
    parser.add_argument("--samples", type=int, default=2000, help="timed decisions")
    parser.add_argument("--hidden", type=int, default=SHIPPED_HIDDEN)
    parser.add_argument("--neighbours", type=int, default=SHIPPED_NEIGHBOURS, help="k")
    parser.add_argument("--intruders", type=int, default=SHIPPED_INTRUDERS, help="m")
    parser.add_argument(
        "--policy", default=None, help="a generalist (zoo name or file) instead of random weights"
    )
    parser.add_argument(
        "--pooling",
        default="max-mean",
        choices=("max-mean", "max-attention"),
        help="the random generalist's pooling (a --policy file says its own)",
    )
    parser.add_argument(
        "--shield-passes", type=int, default=ShieldConfig().passes, help="the shield's passes"
    )
    parser.add_argument(
        "--dynamics",
        default="ideal",
        help="the vehicles' profile: with a fitted one the shield predicts their response",
    )
    parser.add_argument("--json", action="store_true", help="print the result as JSON")
    args = parser.parse_args()
    result = bench_decide(
        args.scenario,
        samples=args.samples,
        hidden=args.hidden,
        neighbours=args.neighbours,
        intruders=args.intruders,
        policy_name=args.policy,
        pooling=args.pooling,
        shield_passes=args.shield_passes,
        dynamics=args.dynamics,
    )
    if args.json:
        print(json.dumps(result, indent=2))
        return
    print(
        f"{result['scenario']}: {result['uavs']} UAVs, {result['intruders']} intruders; "
        f"generalist hidden {result['hidden']} ({result['pooling']} pooling), "
        f"k = {result['max_neighbours']}, "
        f"m = {result['max_obstacles']} (observation {result['observation_size']} entries); "
        f"{result['samples']} decisions over {result['states']} states; "
        f"{result['dynamics']} vehicles"
    )
    for part, label in (
        ("decision", "decision (observe + act)"),
        ("observe", "  observations"),
        ("act", "  actor"),
        ("shield", "shield (on)"),
        ("shielded_decision", "decision + shield"),
        ("reference", "reference workload"),
    ):
        print(
            f"{label:<26} median {result[f'{part}_median_ms']:7.3f} ms   "
            f"p99 {result[f'{part}_p99_ms']:7.3f} ms"
        )
    print(
        f"decision / reference workload (medians): {result['decision_per_reference']:.2f} "
        "(moves less across machines and days than the milliseconds)"
    )


if __name__ == "__main__":
    main()

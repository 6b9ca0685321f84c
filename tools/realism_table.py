"""Every zoo policy on its own scenario in the worlds of real flight: the table in RESULTS.md.

    python tools/realism_table.py [--episodes 1000] [--policies 3u2o ...] [--json out.json]

Each policy flies its own scenario (held-out evaluation seeds, as the zoo's own evaluation) in
these worlds, one `remarl-fc eval --policy NAME --dynamics D --sensors S --arrival A` each:

* paper: ideal vehicles, exact sensing, arrived UAVs leave (the paper's world);
* ideal: the same, arrived UAVs hover in the way (as ``fly`` holds them);
* arducopter, px4: the fitted response of each autopilot, exact sensing, hovering;
* arducopter + adsb, px4 + adsb: the same, intruders seen through ADS-B, GPS noise.

Extra policy files (e.g. the robust 3u2o policy) are given by path. Prints a markdown table
of success rates (collision rates in brackets) and, with --json, writes every result.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from remarl_fc.offline.evaluate import REAL_WORLD_FLOWN, evaluate_policy, world_overrides
from remarl_fc.policy_io import zoo_names
from sim.evaluation import evaluation_seed
from sim.heap import keep_freed_memory

WORLDS: dict[str, tuple[str, str, str]] = {
    "paper": ("ideal", "exact", "leave"),
    "ideal": ("ideal", "exact", "hover"),
    "arducopter": ("arducopter", "exact", "hover"),
    "px4": ("px4", "exact", "hover"),
    "arducopter + adsb": REAL_WORLD_FLOWN,
    "px4 + adsb": ("px4", "adsb", "hover"),
}
"""Column name → (dynamics, sensors, arrival)."""

EVAL_SEED = evaluation_seed(suite="zoo")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--policies", nargs="+", default=None, help="zoo names or files")
    parser.add_argument("--episodes", type=int, default=1000)
    parser.add_argument("--json", default=None, help="write every result to this file")
    args = parser.parse_args()
    keep_freed_memory()  # the simulator's steps reuse their temporaries
    policies = args.policies or zoo_names()
    rows: list[dict[str, object]] = []
    print("| policy | " + " | ".join(WORLDS) + " |")
    print("|---|" + "---:|" * len(WORLDS))
    for name in policies:
        cells = []
        for world, (dynamics, sensors, arrival) in WORLDS.items():
            overrides = world_overrides(dynamics, sensors, arrival)
            _, result = evaluate_policy(name, None, args.episodes, EVAL_SEED, overrides)
            rows.append({"policy": name, "world": world, **result})
            cells.append(f"{result['success_rate']:.1%} ({result['collision_rate']:.1%})")
        label = Path(name).stem if name.endswith(".safetensors") else name
        print(f"| {label} | " + " | ".join(cells) + " |", flush=True)
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=2) + "\n")


if __name__ == "__main__":
    main()

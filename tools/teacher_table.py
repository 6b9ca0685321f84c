"""The generalist's teacher on the encounter suite, at several horizons: how good is it?

    OMP_NUM_THREADS=1 python tools/teacher_table.py                  # 10 and 20 s, every family
    OMP_NUM_THREADS=1 python tools/teacher_table.py --horizons 10,14,20,30,40 \\
        --families beyond-20u4o,beyond-50u8o,crossing-50u --episodes 50 [--json out.json]

Flies `policies.generalist_train.orca_shield_actions` — ORCA through the shield, turning only,
exactly what `remarl-fc train --generalist --teacher orca-shield` labels the student's states
with — over the suite's own episodes, sensing as the run does (``--sensing-range`` and
``--sensing-aperture``, the run's defaults: 200 m all around), once per horizon τ_o
(``--teacher-horizon``). Prints one row per family: the success over the episodes the oracle
proves solvable at each horizon, and the mean over the families that have any. The teacher
reads the simulator's true state (it is privileged); the student copies what it can.

It is what chose the run's ``teacher_horizon_s`` (docs/MODEL.md §20).
"""

from __future__ import annotations

import argparse
import json
import math
import time
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from policies.config import GeneralistConfig
from policies.generalist_train import generalist_layout, orca_shield_actions, with_layout
from remarl_fc.offline.suite import fly_episodes, success_summary
from sim.config import ScenarioConfig
from sim.encounters import Family, sample_family
from sim.state import SwarmState
from sim.suite import Suite, family_labels, load_suite


def teacher_cell(
    suite: Suite, family: Family, count: int, horizon_s: float, run: GeneralistConfig
) -> dict[str, float]:
    """The teacher on a family's first ``count`` episodes at τ_o = ``horizon_s``."""
    cfg, batch = sample_family(family, suite.seed, range(count))
    cfg = with_layout(cfg, generalist_layout(run, cfg))

    def act(obs: Any, state: SwarmState, scenario: ScenarioConfig) -> NDArray[np.float32]:
        return orca_shield_actions(state, scenario, horizon_s)

    rows = fly_episodes(cfg, batch, act).rows
    return success_summary(rows, family_labels(suite, family, count))


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--horizons", default="10,20", help="τ_o values, seconds, comma-separated")
    p.add_argument("--suite", default="standard")
    p.add_argument("--families", default="", help="comma-separated names (default: all)")
    p.add_argument("--episodes", type=int, default=100, help="first K episodes of each family")
    p.add_argument("--sensing-range", type=float, default=GeneralistConfig.sensing_range_m)
    p.add_argument("--sensing-aperture", type=float, default=GeneralistConfig.sensing_aperture_deg)
    p.add_argument("--json", type=Path, help="also write the table here")
    args = p.parse_args(argv)
    horizons = [float(h) for h in args.horizons.split(",")]
    suite = load_suite(args.suite)
    names = args.families.split(",") if args.families else [f.name for f in suite.families]
    run = GeneralistConfig(
        sensing_range_m=args.sensing_range, sensing_aperture_deg=args.sensing_aperture
    )
    count = min(args.episodes, suite.episodes)
    table: dict[str, dict[str, Any]] = {}
    t0 = time.perf_counter()
    print("| family | " + " | ".join(f"τ_o = {h:g} s" for h in horizons) + " |")
    print("|---|" + "---:|" * len(horizons))
    for name in names:
        family = suite.family(name)
        cells = {f"{h:g}": teacher_cell(suite, family, count, h, run) for h in horizons}
        table[name] = cells
        print(
            f"| {name} | "
            + " | ".join(f"{100 * c['success_rate_solvable']:.1f} %" for c in cells.values())
            + " |",
            flush=True,
        )
    means = {}
    for horizon in (f"{h:g}" for h in horizons):
        values = [c[horizon]["success_rate_solvable"] for c in table.values()]
        means[horizon] = float(np.nanmean(values)) if values else math.nan
    print("| mean | " + " | ".join(f"{100 * m:.1f} %" for m in means.values()) + " |")
    print(
        f"horizons {', '.join(means)} s; {count} episodes per family; range "
        f"{args.sensing_range:g} m, aperture {args.sensing_aperture:g}°; "
        f"{time.perf_counter() - t0:.0f} s"
    )
    if args.json:
        report = {"args": {**vars(args), "json": str(args.json)}, "means": means}
        args.json.write_text(json.dumps({**report, "families": table}, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""The generalist's teacher on the encounter suite, at several horizons: how good is it?

    OMP_NUM_THREADS=1 python tools/teacher_table.py                  # 10 and 20 s, every family
    OMP_NUM_THREADS=1 python tools/teacher_table.py --horizons 10,14,20,30,40 \\
        --families beyond-20u4o,beyond-50u8o,crossing-50u --episodes 50 [--json out.json]
    OMP_NUM_THREADS=1 python tools/teacher_table.py --teacher oracle --horizons 20 \\
        --families beyond-50u8o --episodes 5 --from-episode 5

Flies `policies.generalist_train.teacher_plan` — ORCA through the shield, turning only,
exactly what `remarl-fc train --generalist --teacher orca-shield` labels the student's states
with, or (``--teacher oracle``) the oracle replanned at every step, ORCA through the shield
where it finds no plan — over the suite's own episodes, sensing as the run does
(``--sensing-range`` and ``--sensing-aperture``, the run's defaults: 200 m all around), once
per horizon τ_o (``--teacher-horizon``). Prints one row per family: the success over the
episodes the oracle proves solvable at each horizon, and the mean over the families that have
any. The teacher reads the simulator's true state (it is privileged); the student copies what
it can.

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
from policies.generalist_train import generalist_layout, teacher_plan, with_layout
from remarl_fc.offline.suite import fly_episodes, success_summary
from sim.config import STATE_TEACHERS, ScenarioConfig
from sim.encounters import Family, sample_family
from sim.state import SwarmState
from sim.suite import Suite, family_labels, load_suite


def teacher_cell(
    suite: Suite,
    family: Family,
    count: int,
    horizon_s: float,
    run: GeneralistConfig,
    teacher: str = "orca-shield",
    first: int = 0,
) -> dict[str, float]:
    """The teacher on a family's episodes ``first`` … ``first + count − 1`` at τ_o =
    ``horizon_s`` (the oracle's fallback where it finds no plan, with ``teacher`` "oracle")."""
    cfg, batch = sample_family(family, suite.seed, range(first, first + count))
    cfg = with_layout(cfg, generalist_layout(run, cfg))

    def act(obs: Any, state: SwarmState, scenario: ScenarioConfig) -> NDArray[np.float32]:
        return teacher_plan(state, scenario, teacher, horizon_s)

    rows = fly_episodes(cfg, batch, act).rows
    return success_summary(rows, family_labels(suite, family, first + count)[first:])


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--horizons", default="10,20", help="τ_o values, seconds, comma-separated")
    p.add_argument("--suite", default="standard")
    p.add_argument("--families", default="", help="comma-separated names (default: all)")
    p.add_argument("--episodes", type=int, default=100, help="K episodes of each family")
    p.add_argument("--from-episode", type=int, default=0, help="the first of them (default 0)")
    p.add_argument(
        "--teacher",
        default="orca-shield",
        choices=list(STATE_TEACHERS),
        help="ORCA through the shield, or the oracle replanned at every step (~100 times slower)",
    )
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
    count = min(args.episodes, suite.episodes - args.from_episode)
    table: dict[str, dict[str, Any]] = {}
    t0 = time.perf_counter()
    print("| family | " + " | ".join(f"τ_o = {h:g} s" for h in horizons) + " |")
    print("|---|" + "---:|" * len(horizons))
    for name in names:
        family = suite.family(name)
        cells = {
            f"{h:g}": teacher_cell(suite, family, count, h, run, args.teacher, args.from_episode)
            for h in horizons
        }
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
        f"{args.teacher}; horizons {', '.join(means)} s; episodes {args.from_episode} to "
        f"{args.from_episode + count - 1} of each family; range "
        f"{args.sensing_range:g} m, aperture {args.sensing_aperture:g}°; "
        f"{time.perf_counter() - t0:.0f} s"
    )
    if args.json:
        report = {"args": {**vars(args), "json": str(args.json)}, "means": means}
        args.json.write_text(json.dumps({**report, "families": table}, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

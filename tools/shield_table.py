"""The safety-shield table of docs/RESULTS.md: every method on every family, without and with it.

    python tools/shield_table.py                                  # zoo, potential field, ORCA
    python tools/shield_table.py --methods zoo --policy generalist
    python tools/shield_table.py --from results.json             # arrange a saved run
    python tools/shield_table.py --json results.json             # keep the raw figures
    python tools/shield_table.py --plan-steps 0                  # the shield without its planner

The figures are those of ``remarl-fc eval --suite standard --method ... --shield on``: each
family flown twice on the same episodes, without the shield and with it (defaults of
`sim.shield.ShieldConfig`, ``--plan-steps`` its swarm planner's). A cell reads "success
without → with (intervention rate)", the success over the episodes the oracle proved
solvable; the last rows give the means and the families where the shield lost anything.
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path
from typing import Any

from remarl_fc.offline.suite import MethodSpec, evaluate_suite
from sim.heap import keep_freed_memory
from sim.shield import ShieldConfig
from sim.suite import load_suite


def _pct(value: float | None) -> str:
    return "–" if value is None or math.isnan(value) else f"{value:.0%}"


def markdown(results: list[dict[str, Any]]) -> str:
    """Families (rows) × methods: solvable success without → with the shield (interventions)."""
    methods = list(dict.fromkeys(r["method"] for r in results))
    families = list(dict.fromkeys(r["family"] for r in results))
    cell = {(r["family"], r["method"]): r for r in results}
    lines = [
        "| family | N | M | " + " | ".join(methods) + " |",
        "|---|---|---|" + "---|" * len(methods),
    ]
    sums: dict[str, list[tuple[float, float]]] = {m: [] for m in methods}
    lost: list[str] = []
    for f in families:
        any_row = next(cell[(f, m)] for m in methods if (f, m) in cell)
        row = [f, str(any_row["uavs"]), str(any_row.get("obstacles", "–"))]
        for m in methods:
            r = cell.get((f, m))
            if r is None or not r["applicable"]:
                row.append("n/a")
                continue
            off = _nan(r["success_rate_solvable_unshielded"])
            on = _nan(r["success_rate_solvable"])
            row.append(f"{_pct(off)} → {_pct(on)} ({r['intervention_rate']:.0%})")
            if not (math.isnan(off) or math.isnan(on)):
                sums[m].append((off, on))
                if on < off:
                    lost.append(f"{f} / {m}: {_pct(off)} → {_pct(on)}")
        lines.append("| " + " | ".join(row) + " |")
    means = ["**mean**", "", ""]
    for m in methods:
        pairs = sums[m]
        if pairs:
            off = sum(p[0] for p in pairs) / len(pairs)
            on = sum(p[1] for p in pairs) / len(pairs)
            means.append(f"**{off:.0%} → {on:.0%}** ({len(pairs)} families)")
        else:
            means.append("–")
    lines.append("| " + " | ".join(means) + " |")
    lines.append("")
    lines.append("Families where the shield lost success: " + ("; ".join(lost) or "none"))
    return "\n".join(lines)


def _nan(value: float | None) -> float:
    return math.nan if value is None else float(value)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--suite", default="standard")
    parser.add_argument("--methods", default="zoo,potential-field,orca")
    parser.add_argument("--policy", default=None, help="also a policy file (zoo name or path)")
    parser.add_argument("--episodes", type=int, default=None)
    parser.add_argument("--workers", type=int, default=1)
    parser.add_argument("--from", dest="source", default=None, help="a saved --json of eval")
    parser.add_argument("--json", default=None, help="write the raw results here")
    parser.add_argument(
        "--plan-steps",
        type=int,
        default=ShieldConfig().plan_steps,
        help="the shield's swarm planner, steps (ShieldConfig.plan_steps; 0: never)",
    )
    args = parser.parse_args()
    keep_freed_memory()
    if args.source:
        results = json.loads(Path(args.source).read_text())["results"]
    else:
        specs = [MethodSpec("method", m) for m in args.methods.split(",") if m]
        if args.policy:
            specs.append(MethodSpec("policy", args.policy))
        results = evaluate_suite(
            load_suite(args.suite),
            specs,
            episodes=args.episodes,
            workers=args.workers,
            shield=ShieldConfig(mode="on", plan_steps=args.plan_steps),
        )
    if args.json:
        Path(args.json).write_text(json.dumps({"results": results}, indent=1, default=float))
    print(markdown(results))


if __name__ == "__main__":
    main()

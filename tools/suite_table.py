"""The encounter-suite table of docs/RESULTS.md: every method on every family, in Markdown.

    python tools/suite_table.py                        # standard suite, the four methods (~2 min)
    python tools/suite_table.py --suite smoke          # a first look in seconds
    python tools/suite_table.py --plot docs/img/suite  # also the heatmap and worst episodes
    python tools/suite_table.py --json results.json    # keep the raw figures
    python tools/suite_table.py --policy generalist    # a policy file beside the methods
    python tools/suite_table.py --from results.json    # arrange a saved run

The figures are those of ``remarl-fc eval --suite NAME --method zoo,orca,potential-field,
straight``; this script only arranges them: one row per family, per method the success over all
episodes and over the episodes the oracle proved solvable, then the mean and the seconds taken.
"""

from __future__ import annotations

import argparse
import json
import math
import time
from pathlib import Path
from typing import Any

from remarl_fc.offline.suite import MethodSpec, evaluate_suite
from remarl_fc.offline.suite_report import draw_suite
from sim.heap import keep_freed_memory
from sim.suite import load_suite

METHODS = ("zoo", "orca", "potential-field", "straight")


def _pct(value: float) -> str:
    return "–" if math.isnan(value) else f"{value:.0%}"


def markdown(results: list[dict[str, Any]], suite: str, version: int) -> str:
    """The table: families (rows) × methods (success all / solvable)."""
    methods = list(dict.fromkeys(r["method"] for r in results))
    families = list(dict.fromkeys(r["family"] for r in results))
    cell = {(r["family"], r["method"]): r for r in results}
    head = "| family | N | M | solvable | " + " | ".join(methods) + " |"
    rule = "|---|---|---|---|" + "---|" * len(methods)
    lines = [
        f"Suite `{suite}` v{version} (success: all episodes / solvable episodes)",
        "",
        head,
        rule,
    ]
    for f in families:
        rows = [cell[(f, m)] for m in methods if (f, m) in cell]
        ran = [r for r in rows if r.get("applicable")]
        ref = ran[0] if ran else rows[0]
        solv = _pct(ref["solvable_episodes"] / ref["episodes"]) if ran else "–"
        texts = []
        for m in methods:
            r = cell.get((f, m))
            if r is None or not r.get("applicable"):
                texts.append("n/a")
            else:
                texts.append(f"{_pct(r['success_rate'])} / {_pct(r['success_rate_solvable'])}")
        m_count = ref.get("obstacles", "")
        lines.append(f"| {f} | {ref['uavs']} | {m_count} | {solv} | " + " | ".join(texts) + " |")
    means = []
    for m in methods:
        ran = [cell[(f, m)] for f in families if cell.get((f, m), {}).get("applicable")]
        if ran:
            all_ = sum(r["success_rate"] for r in ran) / len(ran)
            sol = [
                r["success_rate_solvable"]
                for r in ran
                if not math.isnan(r["success_rate_solvable"])
            ]
            means.append(f"{all_:.0%} / {sum(sol) / len(sol):.0%} ({len(ran)} families)")
        else:
            means.append("n/a")
    lines.append("| **mean over the families it runs** | | | | " + " | ".join(means) + " |")
    u2u = []
    for m in methods:
        ran = [cell[(f, m)] for f in families if cell.get((f, m), {}).get("applicable")]
        episodes = sum(r["episodes"] for r in ran)
        hits = sum(r["collision_rate_u2u"] * r["episodes"] for r in ran)
        u2u.append(f"{hits / episodes:.1%}" if episodes else "n/a")
    lines.append("| UAV–UAV collisions (share of episodes) | | | | " + " | ".join(u2u) + " |")
    seconds = [
        sum(cell[(f, m)].get("seconds", 0.0) for f in families if (f, m) in cell) for m in methods
    ]
    lines.append("| seconds (one core) | | | | " + " | ".join(f"{s:.0f}" for s in seconds) + " |")
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--suite", default="standard")
    parser.add_argument("--methods", default=",".join(METHODS))
    parser.add_argument("--policy", default=None, help="also a policy file (zoo name or path)")
    parser.add_argument("--from", dest="source", default=None, help="a saved --json to arrange")
    parser.add_argument("--workers", type=int, default=1)
    parser.add_argument("--plot", default=None, help="folder for the heatmap and worst episodes")
    parser.add_argument("--json", default=None, help="also write the raw results here")
    args = parser.parse_args()
    keep_freed_memory()  # the simulator's steps reuse their temporaries
    suite = load_suite(args.suite)
    specs = [MethodSpec("method", m) for m in args.methods.split(",") if m]
    if args.policy:
        specs.append(MethodSpec("policy", args.policy))
    t0 = time.perf_counter()
    if args.source:
        results = json.loads(Path(args.source).read_text())
    else:
        results = evaluate_suite(suite, specs, workers=args.workers)
    print(markdown(results, suite.name, suite.version))
    print(f"\n{time.perf_counter() - t0:.0f} s in all")
    if args.json:
        Path(args.json).write_text(json.dumps(results, indent=1, default=str))
    if args.plot:
        draw_suite(suite, results, specs, Path(args.plot))


if __name__ == "__main__":
    main()

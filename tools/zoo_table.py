"""Print the Markdown table of the shipped zoo from its eval JSON files (for the README).

The per-scenario policies' evaluations only: the generalist's (a suite evaluation, with
another schema) has its table in docs/RESULTS.md (`tools/suite_table.py`).
"""

from __future__ import annotations

import json
from pathlib import Path

ZOO = Path(__file__).resolve().parents[1] / "policies" / "zoo"


def main() -> None:
    print(
        "| scenario | success | collisions (U2O / U2U) | min d_U2O | min d_U2U | energy "
        "| path ratio | reaction time | training |"
    )
    print("|---|---|---|---|---|---|---|---|---|")
    reports = [json.loads(p.read_text()) for p in sorted(ZOO.glob("*.eval.json"))]
    reports = [r for r in reports if "scenario" in r]  # not the generalist's suite evaluation
    reports.sort(key=lambda r: (r["uavs"], r["scenario"]))
    for r in reports:
        print(
            f"| {r['scenario']} | {r['success_rate']:.1%} | {r['collision_rate_u2o']:.1%} / "
            f"{r['collision_rate_u2u']:.1%} | {r['min_d_u2o_m']:.1f} m | {r['min_d_u2u_m']:.1f} m "
            f"| {r['energy_rad']:.2f} rad | {r['path_length_ratio']:.3f} "
            f"| {r['reaction_time_median_ms'] * 1e3:.0f} µs | {r['train_wall_s'] / 60:.0f} min |"
        )


if __name__ == "__main__":
    main()

"""Validation success of generalist runs side by side, at equal wall time.

    python tools/learner_table.py runs/generalist-s1 runs/generalist-ppo-s1 [--families] [--json]

Reads each run folder's ``evals.jsonl`` (one line per validation, `policies.generalist_train`)
and prints the mean validation success of every run at each validation, by elapsed minutes
(validations come every ``eval_minutes``, 15 by default, so the rows line up); with
``--families``, each family's success at the last validation every run reached.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any


def validations(run: Path) -> list[dict[str, Any]]:
    """The run's validation records, in order."""
    path = run / "evals.jsonl"
    if not path.is_file():
        raise SystemExit(f"{run}: no evals.jsonl (not a generalist run folder, or no validation)")
    return [json.loads(line) for line in path.read_text().splitlines() if line.strip()]


def learner_of(run: Path) -> str:
    """The run's learner (td3 for runs from before the choice existed)."""
    config = json.loads((run / "config.json").read_text())
    return str(config["generalist"].get("learner", "td3"))


def main() -> None:
    """Print the table."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("runs", nargs="+", type=Path, help="generalist run folders")
    parser.add_argument("--families", action="store_true", help="per family, last common row")
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    records = {run: validations(run) for run in args.runs}
    names = [f"{run.name} ({learner_of(run)})" for run in args.runs]
    rows = max(len(r) for r in records.values())
    table = []
    for i in range(rows):
        row: dict[str, Any] = {}
        for run, name in zip(args.runs, names, strict=True):
            rec = records[run][i] if i < len(records[run]) else None
            row[name] = None if rec is None else round(rec["success_mean"], 4)
            row[f"{name} min"] = None if rec is None else round(rec["elapsed_s"] / 60, 1)
        table.append(row)
    common = min(len(r) for r in records.values()) - 1
    families = {}
    if args.families and common >= 0:
        for fam in records[args.runs[0]][common]["families"]:
            families[fam] = [records[run][common]["families"].get(fam) for run in args.runs]
    if args.json:
        print(json.dumps({"runs": names, "validations": table, "families": families}, indent=2))
        return
    print("validation  " + "  ".join(f"{n:>28}" for n in names))
    for i, row in enumerate(table):
        cells = []
        for name in names:
            value, minutes = row[name], row[f"{name} min"]
            cells.append(f"{'':>28}" if value is None else f"{value:>19.1%} @{minutes:5.0f} min")
        print(f"{i + 1:>10}  " + "  ".join(cells))
    if families:
        print(f"\nper family at validation {common + 1}:")
        for fam, values in families.items():
            print(f"{fam:<26}" + "".join(f"{v:>8.0%}" for v in values))


if __name__ == "__main__":
    main()

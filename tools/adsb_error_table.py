"""Which part of ADS-B costs a policy in the real world: the table in RESULTS.md.

    python tools/adsb_error_table.py [--policy generalist] [--scenarios 3u2o 10u1o ...]
        [--episodes 300] [--shield off|on] [--json out.json]

The real world of `remarl-fc eval --dynamics arducopter --sensors adsb --arrival hover` (fitted
ArduCopter response, intruders through ADS-B, GPS noise, arrived UAVs hover), flown with one
part of the simulated ADS-B report taken away at a time (`sim.config.SensorConfig`):

* as flown: the defaults (position error of EPU 10–30 m, velocity error of NACv 3 m/s, both
  drawn afresh for every report; 0.2–1.5 s latency; 10 % of the reports lost);
* no position error, no velocity error, neither: EPU, NACv or both 0;
* half the errors: EPU 5–15 m, NACv 1.5 m/s;
* the errors correlated over 10 s or 60 s (`SensorConfig.adsb_error_tau_s`: the same σ,
  successive reports sharing most of their error, as a real GNSS error does);
* no latency; no loss;
* the tracks filtered (`SensorConfig.adsb_filter`, `fly --track-filter on`), with the errors
  as flown and correlated over 10 s and 60 s.

Each row flies the same episodes (`remarl-fc eval`'s evaluation seeds). Prints a markdown table
of success rates, with the UAV–intruder and UAV–UAV collision rates in brackets.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

from remarl_fc.offline.evaluate import REAL_WORLD_FLOWN, evaluate_policy, world_overrides
from remarl_fc.policy_io import load_policy
from sim.evaluation import evaluation_seed
from sim.heap import keep_freed_memory
from sim.shield import ShieldConfig, track_growth_behind

VARIANTS: dict[str, dict[str, Any]] = {
    "as flown": {},
    "no position error": {"adsb_epu_m": [0.0, 0.0]},
    "no velocity error": {"adsb_nacv_m_s": 0.0},
    "neither error": {"adsb_epu_m": [0.0, 0.0], "adsb_nacv_m_s": 0.0},
    "half the errors": {"adsb_epu_m": [5.0, 15.0], "adsb_nacv_m_s": 1.5},
    "errors correlated over 10 s": {"adsb_error_tau_s": [10.0, 10.0]},
    "errors correlated over 60 s": {"adsb_error_tau_s": [60.0, 60.0]},
    "no latency": {"adsb_latency_s": [0.0, 0.0]},
    "no loss": {"adsb_drop_probability": 0.0},
    "tracks filtered": {"adsb_filter": True},
    "tracks filtered, errors correlated over 10 s": {
        "adsb_filter": True,
        "adsb_error_tau_s": [10.0, 10.0],
    },
    "tracks filtered, errors correlated over 60 s": {
        "adsb_filter": True,
        "adsb_error_tau_s": [60.0, 60.0],
    },
}
"""Row name → the ADS-B settings that differ from the defaults."""

DEFAULT_SCENARIOS = ("3u2o", "5u2o", "7u2o", "10u1o")
"""The paper scenarios the generalist flies worst in the real world (RESULTS.md)."""


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--policy", default="generalist", help="zoo name or policy file")
    parser.add_argument("--scenarios", nargs="+", default=list(DEFAULT_SCENARIOS))
    parser.add_argument("--episodes", type=int, default=300)
    parser.add_argument("--shield", choices=["off", "on"], default="off")
    parser.add_argument("--json", default=None, help="write every result to this file")
    args = parser.parse_args()
    keep_freed_memory()  # the simulator's steps reuse their temporaries
    growth = track_growth_behind(load_policy(args.policy).sees_neighbours)
    shield = ShieldConfig(mode="on", track_growth_m_s=growth) if args.shield == "on" else None
    rows: list[dict[str, Any]] = []
    print("| ADS-B | " + " | ".join(args.scenarios) + " | mean |")
    print("|---|" + "---:|" * (len(args.scenarios) + 1))
    for variant, sensors in VARIANTS.items():
        overrides = world_overrides(*REAL_WORLD_FLOWN)
        overrides["sensors"] = {"model": "adsb", **sensors}
        cells, total = [], 0.0
        for scenario in args.scenarios:
            _, result = evaluate_policy(
                args.policy, scenario, args.episodes, evaluation_seed(), overrides, shield
            )
            rows.append({"variant": variant, "adsb": sensors, **result})
            total += result["success_rate"]
            cells.append(
                f"{result['success_rate']:.1%} ({result['collision_rate_u2o']:.0%} / "
                f"{result['collision_rate_u2u']:.0%})"
            )
        mean = total / len(args.scenarios)
        print(f"| {variant} | " + " | ".join(cells) + f" | {mean:.1%} |", flush=True)
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=2))


if __name__ == "__main__":
    main()

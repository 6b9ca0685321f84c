"""The link-security figures of docs/FLYING.md: the same 3u2o flight on the mock, clean and
under the attack table (remarl_fc.sitl.attacker) from another address, unsigned and signed.

    python tools/attack_flights.py [--scenario 3u2o] [--speedup 4] [--json]

Prints one row per flight: what fly concluded (exit status, vehicles reached on trusted
telemetry) against the mock's ground truth (reached, collisions, closest approaches), and what
the link dropped.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
from typing import Any

from remarl_fc.cli.fly import fly_exit_status
from remarl_fc.demo import attacker_for, fly_on_mock


async def one(scenario: str, speedup: float, *, attack: bool, signed: bool) -> dict[str, Any]:
    box: dict[str, Any] = {}

    async def during(fleet: Any, runtime: Any) -> None:
        box["attacker"] = attacker_for(runtime)
        await box["attacker"].run()

    flight = await fly_on_mock(
        scenario,
        speedup=speedup,
        during=during if attack else None,
        signing_key=os.urandom(32) if signed else None,
    )
    truth, rt = flight.ground_truth, flight.runtime
    link = rt["link"]
    return {
        "flight": ("attacked" if attack else "clean") + (", signed" if signed else ""),
        "exit": fly_exit_status(rt),
        "reached (fly)": len(rt["reached"]),
        "reached (truth)": truth["reached_targets"],
        "collisions": truth["collisions_vehicle_intruder"] + truth["collisions_vehicle_vehicle"],
        "min to intruder m": truth["min_vehicle_intruder_m"],
        "min between vehicles m": truth["min_vehicle_vehicle_m"],
        "forged frames sent": box["attacker"].sent if attack else 0,
        "dropped by the gate": sum(link["dropped"].values()),
        "rejected unsigned": sum(v["link"]["rejected_unsigned"] for v in truth["vehicles"]),
        "spoofing alarms": len(link["alarms"]),
        "anomalies touching belief": sum(a["affected"] for a in rt["anomalies"]),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", default="3u2o")
    parser.add_argument("--speedup", type=float, default=4.0)
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    rows = [
        asyncio.run(one(args.scenario, args.speedup, attack=a, signed=s))
        for a, s in ((False, False), (True, False), (True, True))
    ]
    if args.json:
        print(json.dumps(rows))
        return
    keys = list(rows[0])
    print("| " + " | ".join(keys) + " |")
    print("|" + "---|" * len(keys))
    for r in rows:
        print("| " + " | ".join(str(r[k]) for k in keys) + " |")


if __name__ == "__main__":
    main()

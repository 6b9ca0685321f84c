"""The link-security figures of docs/FLYING.md: the same 3u2o flight on the mock, clean and
under the attack table (remarl_fc.sitl.attacker) from another address, unsigned and signed.

    python tools/attack_flights.py [--scenario 3u2o] [--speedup 4] [--json]

Prints one row per flight: what fly concluded (exit status, vehicles reached on trusted
telemetry) against the mock's ground truth (reached, collisions, closest approaches), and what
the link dropped. The last row forges from the victim's own address (a radio link): there
binding cannot help and fly must only never claim more than trusted telemetry shows.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
from typing import Any

from remarl_fc.cli.common import EXIT_USAGE
from remarl_fc.cli.fly import fly_exit_status
from remarl_fc.demo import attacker_for, fly_on_mock
from remarl_fc.errors import RemarlError


async def one(
    scenario: str,
    speedup: float,
    *,
    attack: bool,
    signed: bool,
    radio: bool = False,
    from_start: bool = True,
) -> dict[str, Any]:
    box: dict[str, Any] = {}

    async def during(fleet: Any, runtime: Any) -> None:
        box["fleet"], box["runtime"] = fleet, runtime
        if attack:
            box["attacker"] = attacker_for(runtime, radio=radio, from_start=from_start)
            await box["attacker"].run()
        await asyncio.Event().wait()

    error = ""
    try:
        flight = await fly_on_mock(
            scenario, speedup=speedup, during=during,
            signing_key=os.urandom(32) if signed else None,
        )  # fmt: skip
        truth, rt = flight.ground_truth, flight.runtime
        status = fly_exit_status(rt)
    except* RemarlError as group:  # the flight stopped: what the mock saw, fly's own account
        first = group.exceptions[0]
        error = str(first).split(": ", 1)[-1][:90]
        truth, rt, status = box["fleet"].summary(), box["runtime"].summary(), EXIT_USAGE
    link = rt["link"]
    return {
        "flight": ("attacked" if attack else "clean")
        + (" at the vehicle's own address" if radio else "")
        + ("" if from_start else ", in flight only")
        + (", signed" if signed else ""),
        "exit": status,
        "reached (fly)": len(rt["reached"]),
        "reached (truth)": truth["reached_targets"],
        "armed on the ground (truth)": sum(v["armed"] and v["landed"] for v in truth["vehicles"]),
        "collisions": truth["collisions_vehicle_intruder"] + truth["collisions_vehicle_vehicle"],
        "min to intruder m": truth["min_vehicle_intruder_m"],
        "min between vehicles m": truth["min_vehicle_vehicle_m"],
        "forged frames sent": box["attacker"].sent if attack else 0,
        "dropped by the gate": sum(link["dropped"].values()),
        "rejected unsigned (fly)": link["rejected_unsigned"],
        "spoofing alarms": len(link["alarms"]),
        "anomalies touching belief": sum(a["affected"] for a in rt["anomalies"]),
        "error": error,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", default="3u2o")
    parser.add_argument("--speedup", type=float, default=4.0)
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    cases = [  # attack, signed, radio, from the start
        (False, False, False, True), (True, False, False, True), (True, True, False, True),
        (True, False, True, True), (True, False, True, False),
    ]  # fmt: skip
    rows = [
        asyncio.run(one(args.scenario, args.speedup, attack=a, signed=s, radio=r, from_start=f))
        for a, s, r, f in cases
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

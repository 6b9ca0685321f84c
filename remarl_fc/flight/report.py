"""What a flight tells: the console's status lines, the decision log's rows, the summary.

The summary never claims more than trusted telemetry shows: a vehicle counts as reached only
when its status is ``reached`` and its telemetry was never found untrusted, and every anomaly
of the link is listed (`anomalies`), each saying whether it touched what we believed.

Pure functions of the vehicles' rows and statuses; the runtime calls them.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from remarl_fc.flight.config import Member
from remarl_fc.flight.control import Decision, SwarmController
from remarl_fc.flight.shielding import Check
from remarl_fc.flight.status import Status
from remarl_fc.flight.tracking import NO_FIX
from remarl_fc.flight.traffic import ROUTINE_REJECTIONS

Rows = Sequence[tuple[Member, Status]]
"""Every vehicle of the flight with its status, in slot order."""


def status_lines(rows: Rows, targets_ne_m: NDArray[np.float64], now: float) -> str:
    """One line per vehicle: status, position, height, distance to target."""
    lines = []
    for m, status in rows:
        t = m.track
        gap = (
            float(np.hypot(*(t.ne_m - targets_ne_m[m.slot])))
            if math.isfinite(t.t_position)
            else math.nan
        )
        lines.append(
            f"t={now:6.1f}s vehicle {m.system_id}: {status.value:10} "
            f"N {t.ne_m[0]:7.1f} E {t.ne_m[1]:7.1f} up {t.height_m:5.1f} m, "
            f"{gap:6.1f} m to target"
        )
    return "\n".join(lines)


def decision_rows(
    rows: Rows,
    controller: SwarmController,
    d: Decision,
    decide_s: Sequence[float],
    checks: Mapping[int, Check] | None = None,
) -> list[dict[str, Any]]:
    """The decision log's rows for one decision: one per vehicle.

    A vehicle the shield checked (``checks``, by system id) gets its ``shield`` field
    (`Check.fields`); with the shield off there are none.
    """
    out = []
    for m, status in rows:
        k = m.slot
        vn, ve, yaw = controller.setpoint(k, d.t)
        row: dict[str, Any] = {
            "t": round(d.t, 3),
            "system_id": m.system_id,
            "slot": k,
            "status": status.value,
            "ne_m": [round(float(v), 2) for v in d.positions_ne_m[k]],
            "height_m": round(m.track.height_m, 2),
            "obs": [round(float(v), 4) for v in d.obs[k]],
            "action": round(float(d.action[k]), 4),
            "turn_rad": round(float(d.turn_rad[k]), 4),
            "speed_m_s": round(float(d.speed_m_s[k]), 3),
            "heading_rad": round(float(d.heading_rad[k]), 4),
            "setpoint": {"vn": round(vn, 3), "ve": round(ve, 3), "yaw": round(yaw, 4)},
            "obstacles_ne_m": [[round(float(v), 2) for v in p] for p in d.obstacles_ne_m],
            "decide_ms": round(decide_s[-1] * 1000, 3) if decide_s else None,
        }
        check = (checks or {}).get(m.system_id)
        if check is not None:
            row["shield"] = check.fields()
        out.append(row)
    return out


def vehicle_summaries(rows: Rows) -> list[dict[str, Any]]:
    """What happened to each vehicle (the ``vehicles`` list of `SwarmRuntime.summary`)."""
    return [
        {
            "system_id": m.system_id,
            "slot": m.slot,
            "local": m.local,
            "status": status.value,
            "setpoints_sent": m.sent,
            "telemetry_rejected": dict(m.track.rejected),
            "trusted": m.track.untrusted is None,
            "untrusted": m.track.untrusted,
            "events": [[round(t, 2), e] for t, e in m.events],
        }
        for m, status in rows
    ]


def reached_on_trusted_telemetry(vehicle: dict[str, Any]) -> bool:
    """A vehicle of `vehicle_summaries` reached its target and its telemetry is believed."""
    return bool(vehicle["status"] == "reached" and vehicle["trusted"])


def anomalies(rows: Rows, link: dict[str, Any], traffic: dict[str, Any]) -> list[dict[str, Any]]:
    """Every anomaly of the flight's link.

    Each says whether it ``affected`` what we believed (False: contained — the frames were
    dropped and nothing they said was used).
    """
    out: list[dict[str, Any]] = []

    def add(kind: str, text: str, affected: bool, system_id: int | None = None) -> None:
        out.append({"kind": kind, "system_id": system_id, "text": text, "affected": affected})

    for alarm in link["alarms"]:
        same_source = "autopilot type" in alarm["what"]
        add("spoofing alarm", f"{alarm['what']} ({alarm['source']})", same_source,
            alarm["system_id"])  # fmt: skip
    if link["alarms_not_kept"]:
        add("spoofing alarm", f"{link['alarms_not_kept']} more foreign sources", False)
    for sysid, n in link["foreign_frames"].items():
        add("foreign frames", f"{n} frames with its id from other sources dropped", False,
            int(sysid))  # fmt: skip
    for reason, n in link["dropped"].items():
        if not reason.startswith("spoofing"):
            add("dropped frames", f"{n} frames dropped: {reason}", False)
    for m, _ in rows:
        if not m.local:
            continue
        if m.track.untrusted is not None:
            add("untrusted telemetry", m.track.untrusted, True, m.system_id)
        odd = {k: v for k, v in m.track.rejected.items() if k != NO_FIX}
        rejected = sum(odd.values())
        if rejected:
            reasons = ", ".join(f"{k} {v}" for k, v in sorted(odd.items()))
            add("rejected telemetry", f"{rejected} messages rejected ({reasons})", True,
                m.system_id)  # fmt: skip
    odd_adsb = {k: v for k, v in traffic.get("rejected", {}).items() if k not in ROUTINE_REJECTIONS}
    if odd_adsb:
        reasons = ", ".join(f"{k} {v}" for k, v in sorted(odd_adsb.items()))
        add("rejected ADS-B", f"impossible reports from trusted sources ({reasons})", True)
    if traffic.get("conflicts"):
        add("ADS-B conflict", f"{traffic['conflicts']} ICAOs reported at two places", True)
    return out

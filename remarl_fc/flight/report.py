"""What a flight tells: the console's status lines, the decision log's rows, the summary.

Pure functions of the vehicles' rows and statuses; the runtime calls them.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from remarl_fc.flight.config import Member
from remarl_fc.flight.control import Decision, SwarmController
from remarl_fc.flight.status import Status

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
    rows: Rows, controller: SwarmController, d: Decision, decide_s: Sequence[float]
) -> list[dict[str, Any]]:
    """The decision log's rows for one decision: one per vehicle."""
    out = []
    for m, status in rows:
        k = m.slot
        vn, ve, yaw = controller.setpoint(k, d.t)
        out.append(
            {
                "t": round(d.t, 3),
                "system_id": m.system_id,
                "slot": k,
                "status": status.value,
                "ne_m": [round(float(v), 2) for v in d.positions_ne_m[k]],
                "height_m": round(m.track.height_m, 2),
                "obs": [round(float(v), 4) for v in d.obs[k]],
                "action": round(float(d.action[k]), 4),
                "turn_rad": round(float(d.turn_rad[k]), 4),
                "heading_rad": round(float(d.heading_rad[k]), 4),
                "setpoint": {"vn": round(vn, 3), "ve": round(ve, 3), "yaw": round(yaw, 4)},
                "obstacles_ne_m": [[round(float(v), 2) for v in p] for p in d.obstacles_ne_m],
                "decide_ms": round(decide_s[-1] * 1000, 3) if decide_s else None,
            }
        )
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
            "events": [[round(t, 2), e] for t, e in m.events],
        }
        for m, status in rows
    ]

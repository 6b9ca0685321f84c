"""What the safety shield did in a flight: the log's fields, the tlog's STATUSTEXT, the tally.

The check itself is the controller's: `remarl_fc.flight.control.SwarmController.decide` passes
the policy's heading changes through `sim.shield.shield` (the one implementation, shared with
the simulator and the offline evaluation). This module turns one decision's outcome into what
the flight records, for each vehicle the decision flew (`Check`):

* the decision log's ``shield`` field (`Check.fields`): whether the shield intervened (in
  monitor mode: would have), the proposed and the flown heading (NED yaw, degrees, at the end
  of the coming arc), the flown speed, and the predicted closest approach of the proposal and
  of the decision flown;
* one STATUSTEXT per intervention (`Check.text`, `Check.severity`), which the runtime writes to
  the tlog;
* the counts of the summary (`ShieldTally`): vehicle decisions checked, interventions (per
  vehicle), decisions where no candidate kept clear, and the mode.

In monitor mode the same records say "would": the flown heading is the proposal, and the
``shield_*`` fields say what the shield would have flown. Pure, no I/O; the runtime calls it.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from remarl_fc.flight.control import Decision
from remarl_fc.flight.tracking import STATUSTEXT_MAX_CHARS
from remarl_fc.frames import heading_to_yaw, yaw_to_cdeg
from remarl_fc.mavlink.consts import Severity
from sim.shield import ShieldMode

CPA_SHOWN_MAX_M = 9999
"""Closest approaches above this are shown as this in a STATUSTEXT (four digits fit)."""


def yaw_deg(heading_rad: float) -> float:
    """A simulator heading (CCW from east) as NED yaw in degrees, 0 to 360 (north 0, east 90).

    >>> yaw_deg(0.0), yaw_deg(math.pi / 2)
    (90.0, 0.0)
    """
    return float(yaw_to_cdeg(heading_to_yaw(heading_rad))) / 100.0


def _metres(value: float) -> float | None:
    """A closest approach for JSON: None where nothing was in reach (+inf)."""
    return round(value, 2) if math.isfinite(value) else None


@dataclass(frozen=True)
class Check:
    """The shield's check of one vehicle at one decision.

    Attributes:
        t: decision time (flight clock, s). system_id: the vehicle. mode: "monitor" or "on".
        intervened: the proposal did not keep clear: the shield replaced it ("on") or would
            have ("monitor"). safe_exists: some candidate kept clear (else the shield flies,
            or would fly, the least dangerous: `sim.shield`'s fallback).
        proposed_deg, flown_deg, shield_deg: NED yaw (degrees) at the end of the coming arc of
            the policy's proposal, of the decision flown, and of the shield's choice.
        flown_speed_m_s, shield_speed_m_s: the speed flown, and the shield's.
        proposed_cpa_m, flown_cpa_m, shield_cpa_m: predicted closest approach (m, over the
            shield's horizon; +inf: nothing within reach) of the same three.
        proposed_action: the policy's action in [−1, 1].
    """

    t: float
    system_id: int
    mode: ShieldMode
    intervened: bool
    safe_exists: bool
    proposed_deg: float
    flown_deg: float
    shield_deg: float
    flown_speed_m_s: float
    shield_speed_m_s: float
    proposed_cpa_m: float
    flown_cpa_m: float
    shield_cpa_m: float
    proposed_action: float

    def fields(self) -> dict[str, Any]:
        """The decision log's ``shield`` field (closest approaches None where +inf)."""
        return {
            "mode": self.mode,
            "intervened": self.intervened,
            "safe_exists": self.safe_exists,
            "proposed_action": round(self.proposed_action, 4),
            "proposed_heading_deg": round(self.proposed_deg, 1),
            "flown_heading_deg": round(self.flown_deg, 1),
            "flown_speed_m_s": round(self.flown_speed_m_s, 3),
            "proposed_cpa_m": _metres(self.proposed_cpa_m),
            "flown_cpa_m": _metres(self.flown_cpa_m),
            "shield_heading_deg": round(self.shield_deg, 1),
            "shield_speed_m_s": round(self.shield_speed_m_s, 3),
            "shield_cpa_m": _metres(self.shield_cpa_m),
        }

    def text(self, cruise_m_s: float) -> str:
        """The STATUSTEXT of an intervention, at most 50 characters.

        ``SHIELD v3 hdg 090->135 cpa 12->25m`` (on) or ``SHIELD would v3 hdg 090->135 cpa
        12->25m`` (monitor): the vehicle's system id, proposed → shield's heading, the shield's
        speed where it slows down, proposed → shield's predicted closest approach; ``!`` at the
        end when no candidate kept clear.
        """
        who = "SHIELD would" if self.mode == "monitor" else "SHIELD"
        speed = ""
        if self.shield_speed_m_s < cruise_m_s:
            speed = f" {self.shield_speed_m_s:.0f}m/s"
        text = (
            f"{who} v{self.system_id} hdg {self.proposed_deg:03.0f}->{self.shield_deg:03.0f}"
            f"{speed} cpa {_shown(self.proposed_cpa_m)}->{_shown(self.shield_cpa_m)}m"
            f"{'' if self.safe_exists else '!'}"
        )
        return text[:STATUSTEXT_MAX_CHARS]

    def severity(self) -> Severity:
        """WARNING when no candidate kept clear, else NOTICE."""
        return Severity.NOTICE if self.safe_exists else Severity.WARNING

    def console(self) -> str:
        """The live console's words for an intervention (after ``vehicle N: ``)."""
        would = "would turn" if self.mode == "monitor" else "turned"
        speed = f" at {self.shield_speed_m_s:.1f} m/s"
        unsafe = "" if self.safe_exists else " (no candidate kept clear: the least dangerous)"
        return (
            f"shield {would} heading {self.proposed_deg:05.1f} -> {self.shield_deg:05.1f} deg"
            f"{speed}: predicted closest approach {_shown(self.proposed_cpa_m)} -> "
            f"{_shown(self.shield_cpa_m)} m{unsafe}"
        )


def _shown(cpa_m: float) -> str:
    return str(min(round(cpa_m), CPA_SHOWN_MAX_M)) if math.isfinite(cpa_m) else "-"


def checks_of(
    decision: Decision, system_ids: Sequence[int], max_turn_rad: float, mode: ShieldMode
) -> list[Check]:
    """The shield's check of every vehicle the decision flew (``system_ids`` in slot order).

    Empty when the shield is off (nothing was computed).
    """
    sd = decision.shield
    if sd is None:
        return []
    out = []
    for k in np.flatnonzero(decision.flown).tolist():
        h = float(decision.heading_rad[k])
        proposed = float(decision.proposed_action[k])
        shield_turn = float(sd.shield_action[0, k]) * max_turn_rad
        proposed_cpa = float(sd.proposed_cpa_m[0, k])
        shield_cpa = float(sd.flown_cpa_m[0, k])
        out.append(
            Check(
                t=decision.t,
                system_id=int(system_ids[k]),
                mode=mode,
                intervened=bool(sd.intervened[0, k]),
                safe_exists=bool(sd.safe_exists[0, k]),
                proposed_deg=yaw_deg(h + proposed * max_turn_rad),
                flown_deg=yaw_deg(h + float(decision.turn_rad[k])),
                shield_deg=yaw_deg(h + shield_turn),
                flown_speed_m_s=float(decision.speed_m_s[k]),
                shield_speed_m_s=float(sd.shield_speed_m_s[0, k]),
                proposed_cpa_m=proposed_cpa,
                flown_cpa_m=shield_cpa if mode == "on" else proposed_cpa,
                shield_cpa_m=shield_cpa,
                proposed_action=proposed,
            )
        )
    return out


@dataclass
class ShieldTally:
    """The summary's count of the shield's work over a flight (one per runtime).

    Attributes:
        mode: the shield's mode. decisions: vehicle decisions checked (one per vehicle flown,
        per decision). interventions: per system id, the decisions the shield changed (in
        monitor mode: would have changed). no_safe_option: of those, the ones where no
        candidate kept clear.
    """

    mode: ShieldMode
    decisions: int = 0
    interventions: Counter[int] = field(default_factory=Counter)
    no_safe_option: int = 0

    def add(self, checks: Sequence[Check]) -> None:
        """Count one decision's checks."""
        self.decisions += len(checks)
        for c in checks:
            if c.intervened:
                self.interventions[c.system_id] += 1
                self.no_safe_option += int(not c.safe_exists)

    def summary(self, system_ids: Sequence[int]) -> dict[str, Any]:
        """The summary's ``shield`` object: the mode, and unless off, the counts.

        ``interventions`` and ``by_vehicle`` (every vehicle of ``system_ids``) count what the
        shield changed, or in monitor mode would have changed; the rate is per vehicle
        decision, as the offline evaluation counts it.
        """
        if self.mode == "off":
            return {"mode": "off"}
        total = sum(self.interventions.values())
        return {
            "mode": self.mode,
            "decisions": self.decisions,
            "interventions": total,
            "intervention_rate": round(total / self.decisions, 4) if self.decisions else 0.0,
            "no_safe_option": self.no_safe_option,
            "by_vehicle": {str(i): self.interventions.get(i, 0) for i in system_ids},
        }


def summary_line(shield: dict[str, Any]) -> str:
    """One line for people of the summary's ``shield`` object.

    >>> summary_line({"mode": "off"})
    'shield off'
    >>> summary_line({"mode": "monitor", "decisions": 40, "interventions": 2,
    ...               "intervention_rate": 0.05, "no_safe_option": 0, "by_vehicle": {"1": 2}})
    'shield monitor: would have intervened in 2 of 40 vehicle decisions (vehicle 1: 2)'
    """
    if shield["mode"] == "off":
        return "shield off"
    verb = "would have intervened" if shield["mode"] == "monitor" else "intervened"
    who = ", ".join(f"vehicle {k}: {n}" for k, n in shield["by_vehicle"].items() if n)
    text = (
        f"shield {shield['mode']}: {verb} in {shield['interventions']} of "
        f"{shield['decisions']} vehicle decisions"
    )
    if who:
        text += f" ({who})"
    if shield["no_safe_option"]:
        text += f"; {shield['no_safe_option']} with no candidate clear"
    return text

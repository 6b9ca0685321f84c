"""Who may speak for a vehicle: per-vehicle source binding, without I/O.

The link is hostile until proven otherwise. A vehicle is the autopilot component that answered
the handshake — its first HEARTBEAT with an autopilot type (ArduPilot or PX4), from component
MAV_COMP_ID_AUTOPILOT1 — on one link, from one address. `SourceGate.admit` judges every
decoded frame:

* from a bound vehicle's own source (same link, address and component): accepted;
* claiming a bound vehicle's system id from any other link, address or component: dropped and
  counted, and the first frame from each such source raises a spoofing alarm (an event, and a
  row in the summary). Nothing it says changes what we believe about the vehicle; replies keep
  going to the bound address only. A HEARTBEAT from such a source claims the vehicle's
  identity: before take-off the runtime then refuses to fly (`SpoofingDetected`: without
  signing nothing tells which source is the vehicle); in flight it stays a contained alarm (the
  bound source answered the handshake; holding the vehicle would let any sender ground it);
* a HEARTBEAT from the bound source with another autopilot type: dropped, alarm (the
  autopilot type cannot change in flight);
* COMMAND_ACK addressed to another system or component than ours: dropped;
* ADSB_VEHICLE: accepted from a bound vehicle's source — its autopilot, or its ADS-B receiver
  (MAV_COMP_ID_ADSB) routed through it on the same link and address — or from a source the
  mission names (``[traffic] adsb_sources``), dropped from anyone else;
* anything else from a system that is not in the mission: dropped and counted.

Where the forger shares the vehicle's address (a radio link), binding cannot tell them apart:
only MAVLink signing can (docs/FLYING.md, security). Then `remarl_fc.flight.tracking` flags a
position stream that disagrees with itself, and the vehicle becomes untrusted and is held.
"""

from __future__ import annotations

import enum
from collections import Counter
from dataclasses import dataclass, replace
from typing import Any

from remarl_fc.mavlink.consts import MavAutopilot, MavComponent, MsgId

AUTOPILOTS = frozenset({MavAutopilot.ARDUPILOTMEGA, MavAutopilot.PX4})
"""HEARTBEAT.autopilot values a vehicle may bind with."""

MAX_ALARMS = 32
"""Spoofing alarms kept in full (the rest are counted): a flood of sources keeps memory flat."""


@dataclass(frozen=True)
class Source:
    """Where a frame came from: the link (index), the address on it, the MAVLink component."""

    link: int
    address: str
    component: int

    def __str__(self) -> str:
        return f"link {self.link} {self.address} component {self.component}"


class Verdict(enum.Enum):
    """What to do with a frame."""

    VEHICLE = "vehicle"  # telemetry of a bound vehicle, from its own source
    TRAFFIC = "traffic"  # an ADSB_VEHICLE from a trusted source
    DROP = "drop"


@dataclass(frozen=True)
class Admission:
    """`SourceGate.admit`'s answer for one frame."""

    verdict: Verdict
    system_id: int
    reason: str | None = None
    """Why a dropped frame was dropped."""
    bound: bool = False
    """This frame bound the vehicle: reply to its address from now on."""
    alarm: str | None = None
    """A spoofing alarm to tell the operator (the first frame of a new foreign source)."""
    identity_claim: bool = False
    """A HEARTBEAT from another source than the bound one: someone else claims to be the
    vehicle (before take-off `fly` then refuses to fly: `SpoofingDetected`)."""


@dataclass(frozen=True)
class Alarm:
    """A second source for a bound vehicle."""

    system_id: int
    source: Source
    bound: Source
    what: str


class SourceGate:
    """The binding of each vehicle to its source, and the verdict on every frame.

    Args:
        vehicles: the mission's system ids.
        own: this controller's (system id, component id): what COMMAND_ACKs must target.
        adsb_sources: (system id, component id) of ADS-B receivers the mission trusts, beside
            the bound vehicles' autopilots.
    """

    def __init__(
        self,
        vehicles: frozenset[int],
        own: tuple[int, int],
        adsb_sources: frozenset[tuple[int, int]] = frozenset(),
    ) -> None:
        self.vehicles, self.own, self.adsb_sources = vehicles, own, adsb_sources
        self.bound: dict[int, Source] = {}
        self.autopilot: dict[int, int] = {}
        self.dropped: Counter[str] = Counter()
        """Frames dropped, by reason."""
        self.foreign: Counter[int] = Counter()
        """Frames claiming a bound vehicle's id from another source, by vehicle."""
        self.alarms: list[Alarm] = []
        self.alarms_not_kept = 0
        self._alarmed: set[tuple[int, Source]] = set()

    def admit(self, link: int, address: Any, msg: Any) -> Admission:
        """The verdict on one decoded frame received on ``link`` from ``address``."""
        sysid, comp = int(msg.get_srcSystem()), int(msg.get_srcComponent())
        mid = msg.get_msgId()
        src = Source(link, _address_text(address), comp)
        if sysid not in self.vehicles:
            if mid == MsgId.ADSB_VEHICLE and (sysid, comp) in self.adsb_sources:
                return Admission(Verdict.TRAFFIC, sysid)
            return self._drop(sysid, "sender not in the mission")
        bound = self.bound.get(sysid)
        if bound is None:
            if (
                mid == MsgId.HEARTBEAT
                and comp == MavComponent.AUTOPILOT1
                and int(msg.autopilot) in AUTOPILOTS
            ):
                self.bound[sysid], self.autopilot[sysid] = src, int(msg.autopilot)
                return Admission(Verdict.VEHICLE, sysid, bound=True)
            return self._drop(sysid, "before the vehicle's handshake")
        if (
            mid == MsgId.ADSB_VEHICLE
            and comp == MavComponent.ADSB
            and (src.link, src.address) == (bound.link, bound.address)
        ):
            return Admission(Verdict.TRAFFIC, sysid)  # its ADS-B receiver, routed through it
        if src != bound:
            self.foreign[sysid] += 1
            got = self._alarm(sysid, src, bound, "its system id from another source")
            return replace(got, identity_claim=mid == MsgId.HEARTBEAT)
        if mid == MsgId.HEARTBEAT and int(msg.autopilot) != self.autopilot[sysid]:
            if int(msg.autopilot) == MavAutopilot.INVALID:
                return self._drop(sysid, "heartbeat of a non-autopilot on the vehicle's source")
            return self._alarm(sysid, src, bound, f"autopilot type changed to {msg.autopilot}")
        if mid == MsgId.COMMAND_ACK and not self._for_us(msg):
            return self._drop(sysid, "COMMAND_ACK addressed to someone else")
        if mid == MsgId.ADSB_VEHICLE:
            return Admission(Verdict.TRAFFIC, sysid)
        return Admission(Verdict.VEHICLE, sysid)

    def _for_us(self, ack: Any) -> bool:
        target_system = int(getattr(ack, "target_system", 0))
        target_component = int(getattr(ack, "target_component", 0))
        return target_system in (0, self.own[0]) and target_component in (0, self.own[1])

    def _drop(self, sysid: int, reason: str) -> Admission:
        self.dropped[reason] += 1
        return Admission(Verdict.DROP, sysid, reason=reason)

    def _alarm(self, sysid: int, src: Source, bound: Source, what: str) -> Admission:
        reason = f"spoofing: {what}"
        self.dropped[reason] += 1
        key = (sysid, src)
        if key in self._alarmed:
            return Admission(Verdict.DROP, sysid, reason=reason)
        if len(self.alarms) >= MAX_ALARMS:
            self.alarms_not_kept += 1
            return Admission(Verdict.DROP, sysid, reason=reason)
        self._alarmed.add(key)
        self.alarms.append(Alarm(sysid, src, bound, what))
        text = f"spoofing alarm: {what} ({src}; bound to {bound}): dropped, not believed"
        return Admission(Verdict.DROP, sysid, alarm=text, reason=reason)

    def summary(self) -> dict[str, Any]:
        """Bindings, drops and alarms, for the flight summary."""
        return {
            "bound": {str(k): str(v) for k, v in sorted(self.bound.items())},
            "dropped": dict(self.dropped),
            "foreign_frames": {str(k): n for k, n in sorted(self.foreign.items())},
            "alarms": [
                {"system_id": a.system_id, "source": str(a.source), "what": a.what}
                for a in self.alarms
            ],
            "alarms_not_kept": self.alarms_not_kept,
        }


def _address_text(address: Any) -> str:
    """An address as text: "HOST:PORT" for UDP, the transport's name otherwise."""
    if isinstance(address, tuple) and len(address) >= 2:
        return f"{address[0]}:{address[1]}"
    return str(address)

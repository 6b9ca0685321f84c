"""The receiving side of a flight: every decoded frame through the source gate to its track.

`Receiver.on_message` is called by the links (in the event loop, never blocking) with each
frame, its flight-clock time and its source address. The source gate (`remarl_fc.flight.trust`)
judges it; accepted telemetry goes to the vehicle's track, COMMAND_ACK and PARAM_VALUE to the
waiting command or parameter read, ADS-B to the traffic picture. A second source claiming a
vehicle's identity before take-off is recorded; `Receiver.refuse_spoofed_start` raises it as
`SpoofingDetected` in the flight's task group.
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable
from typing import Any

from remarl_fc.errors import SpoofingDetected
from remarl_fc.flight.commands import Commander
from remarl_fc.flight.config import Member
from remarl_fc.flight.paramcheck import ParamReader
from remarl_fc.flight.status import BEFORE_CONTROL, Status
from remarl_fc.flight.traffic import TrafficPicture
from remarl_fc.flight.trust import SourceGate, Verdict
from remarl_fc.mavlink.consts import MsgId
from remarl_fc.mavlink.link import MavlinkLink


class Receiver:
    """Dispatches one flight's incoming frames.

    Args:
        gate: the source gate.
        by_sysid: every vehicle's I/O row.
        links: the open links (index = the link number the gate sees).
        traffic: the ADS-B picture.
        commands: completes commands waiting for their ACK.
        params: completes parameter reads.
        status: a vehicle's status, by system id.
        event: tells the operator something about a vehicle.
        connections: the connection URLs (named in errors).
    """

    def __init__(
        self,
        gate: SourceGate,
        by_sysid: dict[int, Member],
        links: list[MavlinkLink],
        traffic: TrafficPicture,
        commands: Commander,
        params: ParamReader,
        status: Callable[[int], Status],
        event: Callable[[Member, str], None],
        connections: tuple[str, ...],
    ) -> None:
        self.gate, self.by_sysid, self.links, self.traffic = gate, by_sysid, links, traffic
        self.commands, self.params, self.status, self.event = commands, params, status, event
        self.connections = connections
        self._spoofed = asyncio.Event()
        self._spoof_error: SpoofingDetected | None = None

    def on_message(self, k: int, msg: Any, now: float, address: Any) -> bool:
        """One frame from link ``k``; returns whether it was accepted."""
        got = self.gate.admit(k, address, msg)
        member = self.by_sysid.get(got.system_id)
        if got.alarm is not None and member is not None:
            self.event(member, got.alarm)
        if got.identity_claim and self.status(got.system_id) in BEFORE_CONTROL:
            self._identity_conflict(got.system_id)
        if got.verdict == Verdict.DROP:
            return False
        if got.verdict == Verdict.TRAFFIC:
            self.traffic.update(msg, now, source=(msg.get_srcSystem(), msg.get_srcComponent()))
            return True
        assert member is not None  # the gate passes only the mission's vehicles
        if got.bound:
            member.link = self.links[k]
            member.link.bind(member.system_id, address)
            self.event(member, f"bound to {self.gate.bound[member.system_id]}")
        if not member.local:
            return True  # another process flies it: its state comes over the bus
        member.track.update(msg, now)
        mid = msg.get_msgId()
        if mid == MsgId.COMMAND_ACK:
            self.commands.on_ack(member.system_id, msg)
        elif mid == MsgId.PARAM_VALUE:
            self.params.on_value(member.system_id, msg, bytewise=member.track.is_px4)
        return True

    def _identity_conflict(self, system_id: int) -> None:
        if self._spoofed.is_set():
            return
        sources = (str(self.gate.bound[system_id]), *(
            str(a.source) for a in self.gate.alarms if a.system_id == system_id
        ))  # fmt: skip
        self._spoof_error = SpoofingDetected(
            link=", ".join(self.connections), system_id=system_id, sources=sources
        )
        self._spoofed.set()

    async def refuse_spoofed_start(self) -> None:
        """Raise `SpoofingDetected` once a second source claims a vehicle before take-off."""
        await self._spoofed.wait()
        assert self._spoof_error is not None
        raise self._spoof_error

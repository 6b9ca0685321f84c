"""What every swarm bus shares: the `SwarmBus` protocol and the receive-side bookkeeping.

`BusCore.accept` takes one (topic, payload) as it came off the wire and decides whether it is
used: the topic must be this swarm's, the sender must be a vehicle of the mission and not one
of ours, the payload must validate (`remarl_fc.bus.schema`), it must be newer than what that
sender sent before (sequence numbers; a restarted sender is recognised by its timestamp), and
a sender may not flood (a token bucket per sender and kind). Everything refused is counted by
reason in `BusStats.rejected`; nothing raises.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from types import TracebackType
from typing import Protocol, Self

from remarl_fc.bus.schema import (
    BusStats,
    Detections,
    PayloadError,
    VehicleState,
    decode_detections,
    decode_state,
    parse_topic,
)

RESTART_GAP_S = 2.0
"""A lower sequence number is a restarted sender (not a replay) if its time is this much later."""

BUCKET_SIZE = 40.0
"""Messages a sender may burst per kind before rate limiting (4 s of 10 Hz states)."""

BUCKET_RATE_HZ = 25.0
"""Sustained messages per second and kind a sender may send."""


@dataclass
class Received:
    """A validated message and its monotonic receive time."""

    value: VehicleState | Detections
    t_mono: float


@dataclass
class _Bucket:
    rate_hz: float
    tokens: float = BUCKET_SIZE
    t: float = field(default_factory=time.monotonic)

    def take(self, now: float) -> bool:
        self.tokens = min(BUCKET_SIZE, self.tokens + (now - self.t) * self.rate_hz)
        self.t = now
        if self.tokens < 1.0:
            return False
        self.tokens -= 1.0
        return True


class BusCore:
    """Receive-side state of one bus endpoint.

    Args:
        prefix, swarm: the topic root (``PREFIX/SWARM/uav/...``).
        own_ids: the vehicles this process flies (their messages come back: ignored).
        mission_ids: every vehicle of the mission (anything else is ignored and counted).
        clock: monotonic seconds.
        speedup: peers run this much faster than real time (a mock flown faster): the flood
            limit scales with it.
    """

    def __init__(
        self,
        prefix: str,
        swarm: str,
        own_ids: frozenset[int],
        mission_ids: frozenset[int],
        clock: Callable[[], float] = time.monotonic,
        speedup: float = 1.0,
    ) -> None:
        self.rate_hz = BUCKET_RATE_HZ * speedup
        self.prefix, self.swarm = prefix, swarm
        self.own_ids, self.mission_ids = own_ids, mission_ids
        self.clock = clock
        self.stats = BusStats()
        self.states: dict[int, Received] = {}
        self.detections: dict[int, Received] = {}
        self.online: dict[int, bool] = {}
        self._buckets: dict[tuple[int, str], _Bucket] = {}

    def accept(self, topic_name: str, payload: bytes) -> bool:
        """Take one message off the wire; True if it was used."""
        self.stats.received += 1
        now = self.clock()
        try:
            sender, kind = parse_topic(topic_name, self.prefix, self.swarm)
        except PayloadError:
            return self._reject("topic outside the schema")
        if sender not in self.mission_ids:
            return self._reject("sender not in the mission")
        if sender in self.own_ids:
            return False  # our own messages, echoed by the broker
        bucket = self._buckets.setdefault((sender, kind), _Bucket(self.rate_hz, t=now))
        if not bucket.take(now):
            return self._reject("rate limited (flood)")
        if kind == "status":
            if payload not in (b"online", b"offline"):
                return self._reject("status neither online nor offline")
            self.online[sender] = payload == b"online"
            self.stats.accepted += 1
            return True
        try:
            value: VehicleState | Detections = (
                decode_state(payload, sender)
                if kind == "state"
                else decode_detections(payload, sender)
            )
        except PayloadError as exc:
            return self._reject(f"{kind}: {exc}")
        table = self.states if kind == "state" else self.detections
        old = table.get(sender)
        if old is not None and value.seq <= old.value.seq and value.t < old.value.t + RESTART_GAP_S:
            return self._reject("out of order or repeated")
        table[sender] = Received(value, now)
        self.stats.accepted += 1
        return True

    def _reject(self, reason: str) -> bool:
        self.stats.rejected[reason] += 1
        return False

    def fresh_states(self, max_age_s: float) -> dict[int, Received]:
        """Peers' latest states received within ``max_age_s``."""
        now = self.clock()
        return {k: r for k, r in self.states.items() if now - r.t_mono <= max_age_s}


class SwarmBus(Protocol):
    """A swarm bus endpoint: publish our vehicles' states, learn the others'.

    Use as ``async with bus:``; run `run` in the flight's TaskGroup (it receives, and
    reconnects where that applies, until cancelled). Publishing never blocks for long and never
    raises for a missing connection: QoS-0 messages are dropped and counted meanwhile.
    """

    core: BusCore

    async def __aenter__(self) -> Self: ...

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None: ...

    async def run(self) -> None:
        """Receive until cancelled."""
        ...

    async def publish_state(self, state: VehicleState) -> None:
        """Publish one of our vehicles' state (QoS 0)."""
        ...

    async def publish_detections(self, detections: Detections) -> None:
        """Publish what one of our vehicles sees (QoS 0)."""
        ...

"""The in-process swarm bus: the embedded default when one process flies the whole swarm.

Messages go through the same encoding and validation as over MQTT (`BusCore.accept`), so a
flight on the memory bus exercises the exact code a distributed flight does — only the
transport differs. Retained status messages are replayed to endpoints that join later.
"""

from __future__ import annotations

import asyncio
from typing import Self

from remarl_fc.bus.core import BusCore
from remarl_fc.bus.schema import (
    Detections,
    VehicleState,
    encode_detections,
    encode_state,
    topic,
)
from remarl_fc.resource import Resource


class MemoryBroker:
    """Delivers every message to every joined endpoint (and keeps retained ones)."""

    def __init__(self) -> None:
        self.endpoints: list[MemoryBus] = []
        self.retained: dict[str, bytes] = {}

    def publish(self, topic_name: str, payload: bytes, *, retain: bool = False) -> None:
        """Deliver now to every endpoint."""
        if retain:
            self.retained[topic_name] = payload
        for ep in list(self.endpoints):
            ep.core.accept(topic_name, payload)


class MemoryBus(Resource):
    """One endpoint of a `MemoryBroker` (implements `SwarmBus`).

    Args:
        broker: the shared broker (one per swarm and process).
        core: receive-side bookkeeping (topic root, ids).
    """

    def __init__(self, broker: MemoryBroker, core: BusCore) -> None:
        self.broker, self.core = broker, core

    def _topic(self, uav: int, kind: str) -> str:
        return topic(self.core.prefix, self.core.swarm, uav, kind)

    async def __aenter__(self) -> Self:
        self.broker.endpoints.append(self)
        for name, payload in self.broker.retained.items():
            self.core.accept(name, payload)
        for uav in self.core.own_ids:
            self.broker.publish(self._topic(uav, "status"), b"online", retain=True)
        return self

    async def aclose(self, exc_type: type[BaseException] | None = None) -> None:
        """Say our vehicles are offline and leave the broker."""
        for uav in self.core.own_ids:
            self.broker.publish(self._topic(uav, "status"), b"offline", retain=True)
        self.broker.endpoints.remove(self)

    async def run(self) -> None:
        """Nothing to receive actively: delivery is synchronous. Waits until cancelled."""
        await asyncio.Event().wait()

    async def publish_state(self, state: VehicleState) -> None:
        """Deliver a state to every other endpoint."""
        self.core.stats.published += 1
        self.broker.publish(self._topic(state.id, "state"), encode_state(state))

    async def publish_detections(self, detections: Detections) -> None:
        """Deliver detections to every other endpoint."""
        self.core.stats.published += 1
        self.broker.publish(self._topic(detections.id, "detections"), encode_detections(detections))

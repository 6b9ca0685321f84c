"""The runtime's side of the swarm bus: our vehicles out, the others' in.

`Peers.tx_loop` publishes each local vehicle's state (10 Hz) and what its own ADS-B sees
(2 Hz). `Peers.sync` mirrors the other processes' vehicles into their `Member` rows: position,
velocity, status — a peer silent for longer than the peer timeout is marked lost, so the
controller treats it as an obstacle at its last known track — and merges their detections into
the local traffic picture. `Peers.start_plan` gives every process the same swarm start (the
ready positions and the latest ready time of all vehicles), so that each computes the same
virtual centre without further coordination; this assumes the companions' clocks agree to a
fraction of a second (GPS or NTP time).
"""

from __future__ import annotations

import asyncio
import math
import time
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Protocol

import numpy as np

from remarl_fc.bus.core import SwarmBus
from remarl_fc.bus.schema import STATUSES, Detection, Detections, VehicleState
from remarl_fc.flight.traffic import TrafficPicture
from remarl_fc.frames import yaw_to_heading

if TYPE_CHECKING:
    from remarl_fc.flight.config import Member

STATE_HZ = 10.0
"""State publication rate per local vehicle."""

DETECTIONS_EVERY = 5
"""Detections go out with every 5th state (2 Hz)."""


class ClockLike(Protocol):
    """The runtime's clock (`remarl_fc.flight.config.Clock`)."""

    speedup: float

    def now(self) -> float: ...  # noqa: D102

    def at(self, t_mono: float) -> float: ...  # noqa: D102

    async def sleep(self, seconds: float) -> None: ...  # noqa: D102


class Peers:
    """Bus glue for one runtime.

    Args:
        bus: the swarm bus endpoint.
        members: every vehicle of the mission (local and remote).
        traffic: the local traffic picture (ADS-B).
        clock: the runtime's clock.
        peer_timeout_s: a remote vehicle silent this long is lost.
        status_of: the status name to publish for a local member.
        arc_of: the arc its controller commands a local member now (``VehicleState.arc``:
            course and turn clockwise from north, speed, seconds since its start), None
            when it flies none.
    """

    def __init__(
        self,
        bus: SwarmBus,
        members: Sequence[Member],
        traffic: TrafficPicture,
        clock: ClockLike,
        peer_timeout_s: float,
        status_of: Callable[[Member], str],
        arc_of: Callable[[Member], tuple[float, float, float, float] | None] = lambda m: None,
    ) -> None:
        self.bus, self.members, self.traffic, self.clock = bus, members, traffic, clock
        self.peer_timeout_s = peer_timeout_s
        self.status_of, self.arc_of = status_of, arc_of
        self._seq = 0
        self._merged: dict[int, tuple[int, float]] = {}  # sender → (seq, t_mono) merged last

    # -- out ----------------------------------------------------------------------------

    def _state(self, m: Member) -> VehicleState | None:
        t = m.track
        if not math.isfinite(t.t_position):
            return None
        ready = m.ready_ne_m is not None and m.ready_t is not None
        return VehicleState(
            id=m.system_id,
            seq=self._seq,
            t=time.time(),
            ne_m=(float(t.ne_m[0]), float(t.ne_m[1])),
            height_m=float(t.height_m),
            vel_ned_m_s=tuple(float(v) for v in t.vel_ned_m_s),  # type: ignore[arg-type]
            yaw_rad=float(t.yaw_rad) if math.isfinite(t.yaw_rad) else 0.0,
            status=self.status_of(m),
            ready_ne_m=(float(m.ready_ne_m[0]), float(m.ready_ne_m[1])) if ready else None,  # type: ignore[index]
            ready_t=m.ready_t if ready else None,
            arc=self.arc_of(m),
        )

    def _detections(self, m: Member, now: float) -> Detections:
        """Our own fresh tracks, not shared ones; nearest first (the codec keeps the first 64)."""
        items = tuple(
            Detection(
                icao,
                (float(x.ne_m[0]), float(x.ne_m[1])),
                None if math.isnan(x.height_m) else float(x.height_m),
                (float(x.vel_ne_m_s[0]), float(x.vel_ne_m_s[1])),
            )
            for icao, x in self.traffic.own_tracks(now)
        )
        return Detections(m.system_id, self._seq, time.time(), items)

    async def tx_loop(self, done: asyncio.Event) -> None:
        """Publish until ``done``."""
        while not done.is_set():
            self._seq += 1
            now = self.clock.now()
            for m in self.members:
                if not m.local:
                    continue
                state = self._state(m)
                if state is not None:
                    await self.bus.publish_state(state)
                if self._seq % DETECTIONS_EVERY == 0:
                    await self.bus.publish_detections(self._detections(m, now))
            await self.clock.sleep(1.0 / STATE_HZ)

    # -- in -----------------------------------------------------------------------------

    def sync(self, now: float) -> None:
        """Mirror the remote vehicles and merge their detections (call before using them)."""
        core = self.bus.core
        for m in self.members:
            if m.local:
                continue
            got = core.states.get(m.system_id)
            if got is None:
                continue
            s = got.value
            assert isinstance(s, VehicleState)
            t = m.track
            t.ne_m = np.array(s.ne_m)
            t.height_m = s.height_m
            t.vel_ned_m_s = np.array(s.vel_ned_m_s)
            t.yaw_rad = s.yaw_rad
            t.t_position = self.clock.at(got.t_mono)
            if s.ready_ne_m is not None and m.ready_ne_m is None:
                m.ready_ne_m, m.ready_t = np.array(s.ready_ne_m), s.ready_t
            m.remote_status = m.remote_said = s.status if s.status in STATUSES else None
            m.remote_arc = None
            if s.arc is not None and s.status == "controlled":
                course, turn, speed, age = s.arc
                heading = float(yaw_to_heading(course))
                m.remote_arc = (heading, -turn, speed, t.t_position - age)
            if now - t.t_position > self.peer_timeout_s * self.clock.speedup:
                m.remote_status = "lost"
                m.remote_arc = None
        for sender, got in core.detections.items():
            batch = got.value
            assert isinstance(batch, Detections)
            mark = (batch.seq, got.t_mono)
            if self._merged.get(sender) == mark:
                continue  # merged on an earlier call: counted once, not at every tick
            self._merged[sender] = mark
            t_local = self.clock.at(got.t_mono)
            for d in batch.items:  # checked, capped; our own fresh report of an ICAO wins
                self.traffic.merge_shared(
                    sender, d.icao, d.ne_m, d.height_m, d.vel_ne_m_s, t_local, now
                )

    def start_plan(self) -> tuple[np.ndarray, float] | None:
        """(ready positions (N, 2) in slot order, latest ready UNIX time), once all are ready."""
        if any(m.ready_ne_m is None or m.ready_t is None for m in self.members):
            return None
        positions = np.array([m.ready_ne_m for m in sorted(self.members, key=lambda m: m.slot)])
        return positions, max(float(m.ready_t) for m in self.members)  # type: ignore[arg-type]

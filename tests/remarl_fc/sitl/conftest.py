"""A small ground station over real UDP, for walking the mock's handshakes in tests."""

from __future__ import annotations

import contextlib
import time
from collections.abc import AsyncIterator, Callable
from typing import Any

import pytest_asyncio

from remarl_fc.errors import LinkError
from remarl_fc.mavlink.codec import Codec, SigningConfig
from remarl_fc.mavlink.udp import Address, UdpEndpoint
from remarl_fc.sitl.config import SitlConfig
from remarl_fc.sitl.fleet import SitlFleet

WAIT_S = 10.0
"""Wall-clock limit of one wait in these tests (generous: CI machines are slow)."""


class Gcs:
    """A ground station: sends to one vehicle, records everything it hears."""

    def __init__(self, endpoint: UdpEndpoint, vehicle: Address, fleet: SitlFleet, codec: Codec):
        self.ep, self.vehicle, self.fleet, self.codec = endpoint, vehicle, fleet, codec
        self.f = codec.factory
        self.heard: list[tuple[float, Any]] = []  # (simulated time, message)
        self.cursor = 0

    def send(self, msg: Any) -> None:
        self.ep.send(self.codec.encode(msg), self.vehicle)

    def hello(self) -> None:
        """A GCS heartbeat: the vehicle learns where to send."""
        self.send(self.f.heartbeat_encode(6, 8, 0, 0, 4))

    async def pump(self, seconds: float = 0.05) -> None:
        """Read whatever arrives for ``seconds`` (wall)."""
        end = time.monotonic() + seconds
        while (left := end - time.monotonic()) > 0:
            try:
                data, addr = await self.ep.recv(left)
            except LinkError:  # a quiet link is fine here
                return
            for m in self.codec.decode(data, addr):
                self.heard.append((self.fleet.now_s(), m))

    async def wait_for(
        self, mtype: str, pred: Callable[[Any], bool] = lambda m: True, limit_s: float = WAIT_S
    ) -> Any:
        """The next message of type ``mtype`` satisfying ``pred`` after the last one returned
        (or after the last command sent); raises after ``limit_s``."""
        end = time.monotonic() + limit_s
        while True:
            for k in range(self.cursor, len(self.heard)):
                m = self.heard[k][1]
                if m.get_type() == mtype and pred(m):
                    self.cursor = k + 1
                    return m
            if time.monotonic() > end:
                raise AssertionError(f"no {mtype} matching within {limit_s} s")
            await self.pump(0.02)

    async def wait_sim(self, sim_s: float) -> None:
        """Keep listening until the mock's clock has advanced ``sim_s``."""
        target = self.fleet.now_s() + sim_s
        end = time.monotonic() + WAIT_S + sim_s
        while self.fleet.now_s() < target:
            if time.monotonic() > end:
                raise AssertionError("the mock's clock stalled")
            await self.pump(0.02)

    async def command(self, cmd: int, *params: float, sysid: int = 1) -> Any:
        """COMMAND_LONG → its COMMAND_ACK."""
        p = [*params, *([0.0] * (7 - len(params)))]
        self.cursor = len(self.heard)
        self.send(self.f.command_long_encode(sysid, 1, cmd, 0, *p))
        return await self.wait_for("COMMAND_ACK", lambda m: m.command == cmd)

    def fresh(self) -> None:
        """Make `wait_for` skip everything heard so far."""
        self.cursor = len(self.heard)

    def count(self, mtype: str, since_s: float = 0.0) -> int:
        return sum(1 for t, m in self.heard if t >= since_s and m.get_type() == mtype)

    async def heartbeat_after(self, sim_s: float) -> Any:
        """The first HEARTBEAT stamped after simulated time ``sim_s``."""
        while True:
            for t, m in self.heard:
                if t > sim_s and m.get_type() == "HEARTBEAT":
                    return m
            await self.pump(0.05)

    async def wait_ready(self) -> None:
        """Until the vehicle has left boot and has a position (system time only)."""
        ap = self.fleet.vehicles[0]
        await self.wait_sim(max(0.0, ap.position_estimate_s() - self.fleet.now_s()) + 0.2)


@pytest_asyncio.fixture
async def sitl() -> AsyncIterator[Callable[..., Any]]:
    """Factory: ``async with sitl(vehicles=1, flavour=...) as (fleet, gcs)``."""
    stack = contextlib.AsyncExitStack()

    @contextlib.asynccontextmanager
    async def make(
        *,
        signing_key: bytes | None = None,
        gcs_signing: bytes | None = None,
        scenario: Any = None,
        faults: Any = None,
        **kw: Any,
    ) -> AsyncIterator[tuple[SitlFleet, Gcs]]:
        kw.setdefault("base_port", 0)
        kw.setdefault("speedup", 10.0)
        cfg = SitlConfig(**kw)
        fleet = SitlFleet(cfg, scenario=scenario, faults=faults, signing_key=signing_key)
        signing = SigningConfig(gcs_signing) if gcs_signing else None
        codec = Codec(255, 190, signing=signing)
        async with fleet, UdpEndpoint(("127.0.0.1", 0)) as ep:
            gcs = Gcs(ep, fleet.addresses[0], fleet, codec)
            yield fleet, gcs

    async with stack:
        yield make

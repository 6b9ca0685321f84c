"""A small ground station over real UDP, for walking the mock's handshakes in tests.

Every wait here is on the mock's simulated clock or on a message arriving, with a wall-clock
deadline; none sleeps a fixed time. A message is stamped with the simulated time at which its
datagram reached the ground station's socket (within a physics tick of its sending, however
late the test reads it); messages that carry time_boot_ms carry the exact sending time.
"""

from __future__ import annotations

import asyncio
import contextlib
import time
from collections.abc import AsyncIterator, Callable
from typing import Any

import pytest_asyncio

from remarl_fc.mavlink.codec import Codec, SigningConfig
from remarl_fc.mavlink.udp import Address, UdpEndpoint
from remarl_fc.sitl.config import ARDUPILOT_QUICK_START, SitlConfig
from remarl_fc.sitl.fleet import SitlFleet

WAIT_S = 10.0
"""Wall-clock limit of one wait in these tests (generous: CI machines are slow)."""

POLL_S = 0.005
"""Wall seconds between two looks at the mock's clock."""


class Gcs:
    """A ground station: sends to one vehicle, records everything it hears."""

    def __init__(self, fleet: SitlFleet, codec: Codec) -> None:
        self.fleet, self.codec, self.f = fleet, codec, codec.factory
        self.ep: UdpEndpoint | None = None
        self.vehicle: Address = fleet.addresses[0]
        self.heard: list[tuple[float, Any]] = []  # (simulated time of arrival, message)
        self.cursor = 0
        self._arrived = asyncio.Event()

    def on_datagram(self, data: bytes, addr: Address) -> None:
        """The endpoint's callback: decode and stamp at once, in the event loop."""
        now = self.fleet.now_s()
        self.heard += [(now, m) for m in self.codec.decode(data, addr)]
        self._arrived.set()

    def send(self, msg: Any) -> None:
        assert self.ep is not None
        self.ep.send(self.codec.encode(msg), self.vehicle)

    def hello(self) -> None:
        """A GCS heartbeat: the vehicle learns where to send."""
        self.send(self.f.heartbeat_encode(6, 8, 0, 0, 4))

    async def _arrival(self, end: float) -> None:
        """Until the next datagram arrives, or the wall-clock deadline ``end``."""
        self._arrived.clear()
        with contextlib.suppress(TimeoutError):
            async with asyncio.timeout(max(0.0, end - time.monotonic())):
                await self._arrived.wait()

    async def wait_for_stamped(
        self, mtype: str, pred: Callable[[Any], bool] = lambda m: True, limit_s: float = WAIT_S
    ) -> tuple[float, Any]:
        """(arrival time, message) of the next ``mtype`` satisfying ``pred`` after the last one
        returned (or after the last command sent); raises after ``limit_s``."""
        end = time.monotonic() + limit_s
        while True:
            for k in range(self.cursor, len(self.heard)):
                t, m = self.heard[k]
                if m.get_type() == mtype and pred(m):
                    self.cursor = k + 1
                    return t, m
            if time.monotonic() > end:
                raise AssertionError(f"no {mtype} matching within {limit_s} s")
            await self._arrival(end)

    async def wait_for(
        self, mtype: str, pred: Callable[[Any], bool] = lambda m: True, limit_s: float = WAIT_S
    ) -> Any:
        """The next message of type ``mtype`` satisfying ``pred`` (see `wait_for_stamped`)."""
        return (await self.wait_for_stamped(mtype, pred, limit_s))[1]

    async def until(self, what: str, pred: Callable[[], bool], limit_s: float = WAIT_S) -> None:
        """Until ``pred()`` holds, looking every `POLL_S`; fails naming ``what`` after
        ``limit_s`` wall seconds."""
        end = time.monotonic() + limit_s
        while not pred():
            if time.monotonic() > end:
                raise AssertionError(f"timed out waiting for {what}")
            await asyncio.sleep(POLL_S)

    async def until_sim(self, target_s: float) -> None:
        """Until the mock's clock reaches ``target_s`` (simulated seconds since start)."""
        left_s = max(0.0, target_s - self.fleet.now_s())
        await self.until(
            "the mock's clock", lambda: self.fleet.now_s() >= target_s, WAIT_S + left_s
        )

    async def wait_sim(self, sim_s: float) -> None:
        """Keep listening until the mock's clock has advanced ``sim_s``."""
        await self.until_sim(self.fleet.now_s() + sim_s)

    async def stream(self, make: Callable[[], Any], seconds: float, hz: float = 10.0) -> None:
        """Send ``make()`` at ``hz`` (simulated) for ``seconds`` simulated seconds."""
        start = self.fleet.now_s()
        for k in range(round(seconds * hz)):
            self.send(make())
            await self.until_sim(start + (k + 1) / hz)

    async def command(self, cmd: int, *params: float, sysid: int = 1) -> Any:
        """COMMAND_LONG → its COMMAND_ACK."""
        p = [*params, *([0.0] * (7 - len(params)))]
        self.cursor = len(self.heard)
        self.send(self.f.command_long_encode(sysid, 1, cmd, 0, *p))
        return await self.wait_for("COMMAND_ACK", lambda m: m.command == cmd)

    def fresh(self) -> None:
        """Make `wait_for` skip everything heard so far."""
        self.cursor = len(self.heard)

    def sent_between(self, mtype: str, start_s: float, end_s: float) -> list[Any]:
        """``mtype`` messages heard whose time_boot_ms is in [start_s, end_s) (simulated s):
        when the vehicle sent them, however late they arrived."""
        return [
            m
            for _, m in self.heard
            if m.get_type() == mtype and start_s * 1000 <= m.time_boot_ms < end_s * 1000
        ]

    async def sent_after(self, mtype: str, t_s: float) -> Any:
        """The first ``mtype`` heard (ever) whose time_boot_ms is at or after ``t_s``."""
        self.cursor = 0
        return await self.wait_for(mtype, lambda m: m.time_boot_ms >= t_s * 1000)

    def count(self, mtype: str, since_s: float = 0.0) -> int:
        return sum(1 for t, m in self.heard if t >= since_s and m.get_type() == mtype)

    def texts(self) -> list[str]:
        """Every STATUSTEXT heard so far."""
        return [m.text for _, m in self.heard if m.get_type() == "STATUSTEXT"]

    async def heartbeat_after(self, sim_s: float) -> Any:
        """The first HEARTBEAT that arrived after simulated time ``sim_s``."""
        end = time.monotonic() + WAIT_S
        while True:
            for t, m in self.heard:
                if t > sim_s and m.get_type() == "HEARTBEAT":
                    return m
            if time.monotonic() > end:
                raise AssertionError(f"no HEARTBEAT after {sim_s} s within {WAIT_S} s")
            await self._arrival(end)

    async def wait_ready(self) -> None:
        """Until the vehicle has left boot and has a position (system time only)."""
        ap = self.fleet.vehicles[0]
        ready_s = max(self.fleet.now_s(), ap.boot_s(), ap.position_estimate_s())
        await self.until_sim(ready_s + 0.2)


@pytest_asyncio.fixture
async def sitl() -> Callable[..., Any]:
    """Factory: ``async with sitl(vehicles=1, flavour=...) as (fleet, gcs)``."""

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
        kw.setdefault("ardupilot", ARDUPILOT_QUICK_START)  # tests of the slow start opt out
        cfg = SitlConfig(**kw)
        fleet = SitlFleet(cfg, scenario=scenario, faults=faults, signing_key=signing_key)
        signing = SigningConfig(gcs_signing) if gcs_signing else None
        async with fleet:
            gcs = Gcs(fleet, Codec(255, 190, signing=signing))
            async with UdpEndpoint(("127.0.0.1", 0), on_datagram=gcs.on_datagram) as ep:
                gcs.ep = ep
                yield fleet, gcs

    return make

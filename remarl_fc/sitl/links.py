"""The mock fleet's MAVLink links: one UDP endpoint or TCP server per vehicle, with the faults.

`FleetLinks` owns every vehicle's codec, transport and peer. Outgoing messages are encoded and
sent to the vehicle's peer (the address it last heard a valid frame from) and its ``--out``
address; incoming datagrams — or, over TCP, byte-stream pieces — are decoded and handed to
the fleet, stamped with the simulated time. Loss, latency and cut links act on frames the
same way on both transports, in both directions; the counters go into the summary.
"""

from __future__ import annotations

import asyncio
import contextlib
import functools
from collections.abc import Callable
from typing import Any

import numpy as np

from remarl_fc.errors import LinkLost
from remarl_fc.mavlink.codec import Codec, SigningConfig
from remarl_fc.mavlink.consts import MavComponent
from remarl_fc.mavlink.udp import Address, UdpEndpoint
from remarl_fc.sitl.config import SitlConfig
from remarl_fc.sitl.faults import Faults

OnMessage = Callable[[int, Any], None]
"""Takes one decoded message for vehicle ``i``."""


class _TcpVehicle(asyncio.Protocol):
    """One TCP connection to vehicle ``index``: bytes in go to the links as a stream."""

    def __init__(self, links: FleetLinks, index: int) -> None:
        self.links, self.index = links, index
        self.transport: asyncio.Transport | None = None
        self.peer: Address = ("", 0)

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        assert isinstance(transport, asyncio.Transport)
        self.transport = transport
        host, port = transport.get_extra_info("peername")[:2]
        self.peer = (str(host), int(port))
        self.links._tcp_connected(self.index, self)

    def data_received(self, data: bytes) -> None:
        self.links._on_datagram(self.index, data, self.peer, stream=True)

    def connection_lost(self, exc: Exception | None) -> None:
        self.links._tcp_disconnected(self.index, self)


class FleetLinks:
    """Every vehicle's link.

    Args:
        cfg: the fleet's configuration (transport, host, ports, ``--out``, speedup).
        n: number of vehicles.
        faults: the faults acting on frames (replace or mutate them while running).
        rng: the mock's random generator (loss and jitter draws).
        now_s: the simulated clock.
        on_message: takes each decoded message, with the vehicle's index.
        signing: signing of every vehicle's link, or None.
    """

    def __init__(
        self,
        cfg: SitlConfig,
        n: int,
        faults: Faults,
        rng: np.random.Generator,
        now_s: Callable[[], float],
        on_message: OnMessage,
        signing: SigningConfig | None = None,
    ) -> None:
        self.cfg, self.n, self.faults, self.rng = cfg, n, faults, rng
        self.now_s, self.on_message = now_s, on_message
        self.codecs = [Codec(i + 1, MavComponent.AUTOPILOT1, signing=signing) for i in range(n)]
        self.peers: list[Address | None] = [None] * n
        self.outs = [cfg.out_address(i) for i in range(n)]
        self.stats = [
            {"datagrams_in": 0, "datagrams_out": 0, "dropped_in": 0, "dropped_out": 0}
            for _ in range(n)
        ]
        self.endpoints: list[UdpEndpoint] = []
        self.tcp_clients: list[_TcpVehicle | None] = [None] * n
        """The client connected to each vehicle (TCP transport)."""
        self.ports: list[int] = []
        """The port each vehicle listens on, once open."""
        self.loop: asyncio.AbstractEventLoop | None = None
        """Schedules delayed frames; None (no latency) until the fleet runs."""
        self.failure: BaseException | None = None
        """An error raised while handling a frame (a bug in the mock), for the fleet to raise."""

    def listening(self, i: int) -> bool:
        """Whether vehicle ``i`` has anyone to send to (a peer or an ``--out`` address)."""
        return self.peers[i] is not None or self.outs[i] is not None

    # -- opening --------------------------------------------------------------------------

    async def open(self, stack: contextlib.AsyncExitStack) -> None:
        """Bind every vehicle's endpoint or TCP server; ``stack`` closes them."""
        for i in range(self.n):
            if self.cfg.transport == "tcp":
                self.ports.append(await self._serve_tcp(i, stack))
                continue
            ep = UdpEndpoint(
                (self.cfg.host, self.cfg.port(i)),
                on_datagram=functools.partial(self._on_datagram, i),
                name=f"sitl vehicle {i + 1} udp:{self.cfg.host}:{self.cfg.port(i)}",
            )
            self.endpoints.append(await stack.enter_async_context(ep))
            self.ports.append(ep.local_address[1])

    async def _serve_tcp(self, i: int, stack: contextlib.AsyncExitStack) -> int:
        """Listen for vehicle ``i``'s TCP client; returns the port."""
        loop = asyncio.get_running_loop()
        host, port = self.cfg.host, self.cfg.port(i)
        try:
            server = await loop.create_server(lambda: _TcpVehicle(self, i), host, port)
        except OSError as exc:
            raise LinkLost(
                f"cannot listen ({exc.strerror or exc}); is another program using the port?",
                link=f"sitl vehicle {i + 1} tcp:{host}:{port}",
            ) from exc

        async def close() -> None:
            server.close()
            client = self.tcp_clients[i]
            if client is not None and client.transport is not None:
                client.transport.close()
            await server.wait_closed()

        stack.push_async_callback(close)
        bound: int = server.sockets[0].getsockname()[1]
        return bound

    def _tcp_connected(self, i: int, client: _TcpVehicle) -> None:
        old = self.tcp_clients[i]
        if old is not None and old.transport is not None:
            old.transport.close()  # one client at a time, as a serial port over TCP
        self.tcp_clients[i] = client
        self.peers[i] = client.peer

    def _tcp_disconnected(self, i: int, client: _TcpVehicle) -> None:
        if self.tcp_clients[i] is client:
            self.tcp_clients[i] = None
            self.peers[i] = None

    # -- out ------------------------------------------------------------------------------

    def send(self, i: int, msg: Any, *, component: int | None = None) -> None:
        """Send ``msg`` from vehicle ``i`` (from ``component``, else its autopilot)."""
        frame = self.codecs[i].encode(msg, source_component=component)
        now = self.now_s()
        dests = {d for d in (self.peers[i], self.outs[i]) if d is not None}
        for dest in dests:
            if self.faults.link_down(i, now) or self.faults.drop(self.rng):
                self.stats[i]["dropped_out"] += 1
                continue
            self.stats[i]["datagrams_out"] += 1
            delay = self.faults.delay_s(self.rng) / self.cfg.speedup
            if delay > 0 and self.loop is not None:
                self.loop.call_later(delay, self._raw_send, i, frame, dest)
            else:
                self._raw_send(i, frame, dest)

    def _raw_send(self, i: int, frame: bytes, dest: Address) -> None:
        if self.cfg.transport == "tcp":
            client = self.tcp_clients[i]
            transport = client.transport if client is not None and client.peer == dest else None
            if transport is not None and not transport.is_closing():
                transport.write(frame)
            return
        ep = self.endpoints[i] if i < len(self.endpoints) else None
        if ep is not None and ep.is_open:
            ep.send(frame, dest)

    # -- in -------------------------------------------------------------------------------

    def _on_datagram(self, i: int, data: bytes, addr: Address, *, stream: bool = False) -> None:
        now = self.now_s()
        if self.faults.link_down(i, now) or self.faults.drop(self.rng):
            self.stats[i]["dropped_in"] += 1  # over TCP: a cut frame, as on a noisy serial line
            return
        delay = self.faults.delay_s(self.rng) / self.cfg.speedup
        if delay > 0 and self.loop is not None:
            self.loop.call_later(delay, self._deliver, i, data, addr, stream)
        else:
            self._deliver(i, data, addr, stream)

    def _deliver(self, i: int, data: bytes, addr: Address, stream: bool = False) -> None:
        self.stats[i]["datagrams_in"] += 1
        try:
            msgs = self.codecs[i].decode(data, addr, datagram=not stream)
            if msgs:
                self.peers[i] = addr
            for msg in msgs:
                self.on_message(i, msg)
        except Exception as exc:  # a bug in the mock: stop the fleet loudly, not in a log
            self.failure = exc

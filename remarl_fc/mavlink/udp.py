"""An asyncio UDP endpoint: datagrams in and out, without blocking and without threads.

`UdpEndpoint` is an async context manager around `loop.create_datagram_endpoint`. Received
datagrams either go to a callback (``on_datagram``, called in the event loop — the SITL mock
handles them synchronously) or wait in a bounded queue for `UdpEndpoint.recv`, which raises
`LinkTimeout` after its deadline and `LinkLost` when the socket has failed.
"""

from __future__ import annotations

import asyncio
import collections
import socket
from collections.abc import Callable
from typing import Self

from remarl_fc.errors import LinkLost, LinkTimeout
from remarl_fc.resource import SyncResource

Address = tuple[str, int]
DatagramHandler = Callable[[bytes, Address], None]

QUEUE_DATAGRAMS = 4096
"""Datagrams buffered for `UdpEndpoint.recv`; when full the oldest is dropped (and counted)."""


def parse_host_port(text: str, *, what: str = "address") -> Address:
    """``HOST:PORT`` → (host, port).

    >>> parse_host_port("127.0.0.1:14550")
    ('127.0.0.1', 14550)
    """
    host, sep, port = text.rpartition(":")
    if not sep or not host:
        raise ValueError(f"{what} {text!r} is not HOST:PORT (e.g. 127.0.0.1:14550)")
    try:
        number = int(port)
    except ValueError as exc:
        raise ValueError(f"{what} {text!r}: port {port!r} is not a number") from exc
    if not 0 <= number <= 65535:
        raise ValueError(f"{what} {text!r}: port {number} is outside 0..65535")
    return host, number


class _Protocol(asyncio.DatagramProtocol):
    def __init__(self, owner: UdpEndpoint) -> None:
        self.owner = owner

    def datagram_received(self, data: bytes, addr: tuple[str | object, ...]) -> None:
        host, port = addr[0], addr[1]
        self.owner._received(data, (str(host), port if isinstance(port, int) else 0))

    def error_received(self, exc: Exception) -> None:
        self.owner.errors += 1  # ICMP port unreachable and the like: UDP carries on

    def connection_lost(self, exc: Exception | None) -> None:
        self.owner._lost(exc)


class UdpEndpoint(SyncResource):
    """A bound UDP socket in the event loop.

    Args:
        local: (host, port) to bind; port 0 picks a free one (see `local_address`).
        on_datagram: called with (data, sender) for every datagram; None queues them for
            `recv` instead.
        name: how errors name this endpoint (``udp:127.0.0.1:14550``).
        receive_buffer_bytes: ask the OS for this receive buffer (it may grant less: Linux caps
            it at net.core.rmem_max); a ground station hearing a whole fleet needs more than
            the default to ride out bursts.

    Not reentrant: one ``async with`` at a time.
    """

    def __init__(
        self,
        local: Address,
        *,
        on_datagram: DatagramHandler | None = None,
        name: str | None = None,
        receive_buffer_bytes: int | None = None,
    ) -> None:
        self.local = local
        self.name = name or f"udp:{local[0]}:{local[1]}"
        self.on_datagram = on_datagram
        self.receive_buffer_bytes = receive_buffer_bytes
        self.errors = 0
        self.dropped = 0
        self.sent = 0
        self._transport: asyncio.DatagramTransport | None = None
        self._queue: collections.deque[tuple[bytes, Address]] = collections.deque()
        self._waiter: asyncio.Future[None] | None = None
        self._failure: BaseException | None = None

    async def __aenter__(self) -> Self:
        if self._transport is not None:
            raise RuntimeError(f"{self.name} is already open; use one `async with` at a time")
        loop = asyncio.get_running_loop()
        try:
            transport, _ = await loop.create_datagram_endpoint(
                lambda: _Protocol(self), local_addr=self.local
            )
        except OSError as exc:
            raise LinkLost(
                f"cannot bind ({exc.strerror}); is another program using this port?",
                link=self.name,
            ) from exc
        self._transport = transport
        self._failure = None
        if self.receive_buffer_bytes is not None:
            sock = transport.get_extra_info("socket")
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, self.receive_buffer_bytes)
        return self

    def close(self) -> None:
        """Close the socket (idempotent)."""
        if self._transport is not None:
            self._transport.close()
            self._transport = None

    @property
    def is_open(self) -> bool:
        """Whether the socket is open."""
        return self._transport is not None

    @property
    def local_address(self) -> Address:
        """The bound (host, port), with the real port when 0 was asked for."""
        if self._transport is None:
            raise RuntimeError(f"{self.name} is not open")
        host, port = self._transport.get_extra_info("sockname")[:2]
        return str(host), int(port)

    def send(self, data: bytes, address: Address) -> None:
        """Send one datagram (never blocks; the OS drops it if its buffer is full)."""
        if self._transport is None:
            raise LinkLost("the socket is closed", link=self.name)
        self._transport.sendto(data, address)
        self.sent += 1

    async def recv(self, timeout_s: float) -> tuple[bytes, Address]:
        """The next queued datagram and its sender.

        Raises:
            LinkTimeout: none arrived within ``timeout_s`` (monotonic event-loop clock).
            LinkLost: the socket failed or was closed.
        """
        try:
            async with asyncio.timeout(timeout_s):
                while not self._queue:
                    self._check_open()
                    self._waiter = asyncio.get_running_loop().create_future()
                    try:
                        await self._waiter
                    finally:
                        self._waiter = None
        except TimeoutError as exc:
            raise LinkTimeout(link=self.name, waited_for="datagram", timeout_s=timeout_s) from exc
        return self._queue.popleft()

    def _check_open(self) -> None:
        if self._failure is not None:
            raise LinkLost(f"the socket failed: {self._failure}", link=self.name)
        if self._transport is None:
            raise LinkLost("the socket is closed", link=self.name)

    def _received(self, data: bytes, addr: Address) -> None:
        if self.on_datagram is not None:
            self.on_datagram(data, addr)
            return
        if len(self._queue) >= QUEUE_DATAGRAMS:
            self._queue.popleft()
            self.dropped += 1
        self._queue.append((data, addr))
        if self._waiter is not None and not self._waiter.done():
            self._waiter.set_result(None)

    def _lost(self, exc: BaseException | None) -> None:
        self._failure = exc or ConnectionError("closed")
        if self._waiter is not None and not self._waiter.done():
            self._waiter.set_result(None)

"""A MAVLink connection for the runtime: URL in, decoded messages out, by system id.

URLs take pymavlink's forms:

* ``udpin:HOST:PORT``, ``udp:HOST:PORT``, ``HOST:PORT``: bind and listen; reply to wherever
  each system was heard;
* ``udpout:HOST:PORT``: send to a fixed address (and listen on the socket it sends from);
* ``tcp:HOST:PORT``: connect to a TCP server (an autopilot's or SITL's serial-over-TCP port);
* ``serial:DEVICE[:BAUD]``, ``/dev/ttyX[,BAUD]``: a serial port (default 57600 baud).

Several vehicles may share one link: messages are dispatched by their source system id, and
`MavlinkLink.send` addresses a vehicle by its system id. On UDP a system is sent to the address
it is bound to (`MavlinkLink.bind`, done by the runtime once the vehicle answered the
handshake); an address heard later never moves it. Before binding, a system is sent to where it
was last heard. Everything is callback-driven in the event loop — the datagram protocol, a
stream protocol for TCP, a file-descriptor reader for serial — so the link owns no task and
nothing blocks. Every frame in and out can be written to a ``.tlog`` (`TlogWriter`): frames the
receiver refused (foreign sources) at most `REFUSED_TLOG_PER_S` a second, so that a flood cannot
fill the disk; the log is flushed at least every `TLOG_FLUSH_S`.
"""

from __future__ import annotations

import asyncio
import os
import struct
import termios
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any, Self

from remarl_fc.errors import LinkLost
from remarl_fc.mavlink.codec import Codec, Message
from remarl_fc.mavlink.udp import Address, UdpEndpoint, parse_host_port
from remarl_fc.resource import SyncResource

MessageHandler = Callable[[Message, float, Any], bool]
"""Called with (message, monotonic receive time s, source address) for every valid message;
returns whether the message was accepted (False: refused, e.g. from a foreign source)."""

REFUSED_TLOG_PER_S = 20
"""Refused frames written to the tlog per second at most (the rest are only counted)."""

TLOG_FLUSH_S = 1.0
"""The tlog is handed to the OS at least this often, s: a crash loses at most this much."""

DEFAULT_BAUD = 57600
"""Serial baud rate when the URL gives none (the usual telemetry radio rate)."""

BAUD_CONSTANTS = {
    9600: termios.B9600,
    19200: termios.B19200,
    38400: termios.B38400,
    57600: termios.B57600,
    115200: termios.B115200,
    230400: termios.B230400,
    460800: getattr(termios, "B460800", termios.B230400),
    921600: getattr(termios, "B921600", termios.B230400),
}


@dataclass(frozen=True)
class LinkAddress:
    """A parsed connection URL."""

    kind: str  # "udpin", "udpout", "tcp", "serial"
    host: str = ""
    port: int = 0
    device: str = ""
    baud: int = DEFAULT_BAUD

    @classmethod
    def parse(cls, url: str) -> LinkAddress:
        """Parse a pymavlink-style URL (see the module docstring).

        >>> LinkAddress.parse("udpin:0.0.0.0:14550")
        LinkAddress(kind='udpin', host='0.0.0.0', port=14550, device='', baud=57600)
        >>> LinkAddress.parse("/dev/ttyUSB0,921600").baud
        921600
        """
        head, sep, rest = url.partition(":")
        if head in ("udpin", "udp", "udpout", "tcp") and sep:
            host, port = parse_host_port(rest, what=f"connection {url!r}")
            return cls(
                "udpout" if head == "udpout" else "tcp" if head == "tcp" else "udpin", host, port
            )
        if head == "serial" and sep and rest.partition(":")[0]:
            device, _, baud = rest.partition(":")
            return cls("serial", device=device, baud=_baud(baud or str(DEFAULT_BAUD), url))
        # COM1, COM3,57600 — but not a host whose name starts with "com" (companion:14550)
        if url.startswith("/dev/") or (url.upper().startswith("COM") and url[3:4].isdigit()):
            device, _, baud = url.partition(",")
            return cls("serial", device=device, baud=_baud(baud or str(DEFAULT_BAUD), url))
        if sep and rest.isdigit():
            host, port = parse_host_port(url, what=f"connection {url!r}")
            return cls("udpin", host, port)
        raise ValueError(
            f"connection {url!r} is not one of udpin:HOST:PORT, udpout:HOST:PORT, "
            "tcp:HOST:PORT, serial:DEVICE[:BAUD] or /dev/ttyX[,BAUD]"
        )


def _baud(text: str, url: str) -> int:
    try:
        baud = int(text)
    except ValueError as exc:
        raise ValueError(f"connection {url!r}: baud {text!r} is not a number") from exc
    if baud not in BAUD_CONSTANTS:
        raise ValueError(f"connection {url!r}: baud {baud} is not one of {sorted(BAUD_CONSTANTS)}")
    return baud


class TlogWriter:
    """Appends frames to a ``.tlog``: each an 8-byte big-endian µs wall-clock stamp + the frame.

    The format pymavlink's tools (mavlogdump, MAVExplorer) read.
    """

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self._fh: IO[bytes] | None = None
        self._flushed = time.monotonic()

    def open(self) -> None:
        """Open for appending (creating folders)."""
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._fh = self.path.open("ab")

    def write(self, frame: bytes) -> None:
        """Log one frame now (flushed when the last flush is `TLOG_FLUSH_S` old)."""
        if self._fh is not None:
            self._fh.write(struct.pack(">Q", int(time.time() * 1e6)) + frame)
            now = time.monotonic()
            if now - self._flushed >= TLOG_FLUSH_S:
                self._fh.flush()
                self._flushed = now

    def close(self) -> None:
        """Flush and close (idempotent)."""
        if self._fh is not None:
            self._fh.close()
            self._fh = None


class _Stream(asyncio.Protocol):
    def __init__(self, link: MavlinkLink) -> None:
        self.link = link

    def data_received(self, data: bytes) -> None:
        self.link._received(data, "stream")

    def connection_lost(self, exc: Exception | None) -> None:
        self.link._lost(exc or ConnectionError("closed by the peer"))


class MavlinkLink(SyncResource):
    """One connection to one or more vehicles (an async context manager).

    Args:
        url: a connection URL (module docstring).
        codec: this side's MAVLink identity (system id, component id, signing).
        on_message: called for every valid message with its monotonic receive time.
        tlog: where to log every frame in and out, or None.
    """

    def __init__(
        self,
        url: str,
        codec: Codec,
        on_message: MessageHandler,
        *,
        tlog: TlogWriter | None = None,
    ) -> None:
        self.url, self.codec, self.on_message, self.tlog = url, codec, on_message, tlog
        self.address = LinkAddress.parse(url)
        self.where: dict[int, Any] = {}  # system id → address to send to
        self.bound: set[int] = set()  # systems whose address is fixed (`bind`)
        self.refused = 0  # frames the receiver refused
        self.refused_not_logged = 0  # of those, not written to the tlog (rate limit)
        self._refused_window = (0.0, 0)  # (start of the current second, refused logged in it)
        self.failure: BaseException | None = None
        self._udp: UdpEndpoint | None = None
        self._transport: asyncio.Transport | None = None
        self._fd: int | None = None
        self._pending = bytearray()  # serial bytes the port could not take yet
        self._loop: asyncio.AbstractEventLoop | None = None

    async def __aenter__(self) -> Self:
        a = self.address
        self._loop = loop = asyncio.get_running_loop()
        if self.tlog is not None:
            self.tlog.open()
        try:
            if a.kind == "udpin":
                self._udp = UdpEndpoint((a.host, a.port), on_datagram=self._received, name=self.url)
                await self._udp.__aenter__()
            elif a.kind == "udpout":
                self._udp = UdpEndpoint(("0.0.0.0", 0), on_datagram=self._received, name=self.url)
                await self._udp.__aenter__()
            elif a.kind == "tcp":
                try:
                    transport, _ = await loop.create_connection(
                        lambda: _Stream(self), a.host, a.port
                    )
                except OSError as exc:
                    raise LinkLost(
                        f"cannot connect ({exc.strerror or exc})", link=self.url
                    ) from exc
                self._transport = transport
            else:
                self._fd = _open_serial(a.device, a.baud, self.url)
                loop.add_reader(self._fd, self._read_serial)
        except BaseException:
            if self.tlog is not None:
                self.tlog.close()
            raise
        return self

    def close(self) -> None:
        """Close the connection and the log (idempotent)."""
        if self._udp is not None:
            self._udp.close()
            self._udp = None
        if self._transport is not None:
            self._transport.close()
            self._transport = None
        if self._fd is not None:
            if self._loop is not None:
                self._loop.remove_reader(self._fd)
                self._loop.remove_writer(self._fd)
            os.close(self._fd)
            self._fd = None
        if self.tlog is not None:
            self.tlog.close()

    @property
    def local_address(self) -> Address | None:
        """The bound UDP address (for udpin/udpout), else None."""
        return self._udp.local_address if self._udp is not None else None

    def send(self, msg: Message, system_id: int | None = None) -> bool:
        """Encode and send ``msg`` toward ``system_id`` (None: every system heard / the peer).

        Returns:
            False when a udpin link has not heard that system yet (nowhere to send).

        Raises:
            LinkLost: the connection has failed.
        """
        if self.failure is not None:
            raise LinkLost(f"the connection failed: {self.failure}", link=self.url)
        a = self.address
        dests: set[Any] = set()
        if a.kind == "udpin" and self._udp is not None:  # first: nowhere to go, nothing logged
            heard = self.where.values() if system_id is None else [self.where.get(system_id)]
            dests = {d for d in heard if d is not None}
            if not dests:
                return False
        frame = self.codec.encode(msg)
        if self.tlog is not None:
            self.tlog.write(frame)
        if self._udp is not None:
            if a.kind == "udpout":
                self._udp.send(frame, (a.host, a.port))
                return True
            for dest in dests:
                self._udp.send(frame, dest)
            return True
        if self._transport is not None:
            self._transport.write(frame)
            return True
        if self._fd is not None:
            if self._pending:  # earlier bytes wait: keep frames whole and in order
                self._pending += frame
                return True
            try:
                written = os.write(self._fd, frame)
            except BlockingIOError:
                return False  # the UART buffer is full: drop whole frames, as a radio would
            except OSError as exc:
                self._lost(exc)
                raise LinkLost(f"serial write failed ({exc.strerror})", link=self.url) from exc
            if written < len(frame):  # finish the frame when the port can take more
                self._pending += frame[written:]
                if self._loop is not None:
                    self._loop.add_writer(self._fd, self._flush_serial)
            return True
        raise LinkLost("the connection is closed", link=self.url)

    def bind(self, system_id: int, address: Any) -> None:
        """Send to ``system_id`` only at ``address`` from now on (it answered the handshake)."""
        self.where[system_id] = address
        self.bound.add(system_id)

    def _received(self, data: bytes, addr: Any) -> None:
        now = time.monotonic()
        datagram = self._udp is not None
        for msg in self.codec.decode(data, addr, datagram=datagram):
            sysid = msg.get_srcSystem()
            accepted = self.on_message(msg, now, addr)
            if accepted and sysid not in self.bound:
                self.where[sysid] = addr
            if not accepted:
                self.refused += 1
            if self.tlog is not None and (accepted or self._log_refused(now)):
                self.tlog.write(msg.get_msgbuf())

    def _log_refused(self, now: float) -> bool:
        start, n = self._refused_window
        if now - start >= 1.0:
            start, n = now, 0
        if n >= REFUSED_TLOG_PER_S:
            self.refused_not_logged += 1
            return False
        self._refused_window = (start, n + 1)
        return True

    def _flush_serial(self) -> None:
        assert self._fd is not None
        try:
            written = os.write(self._fd, self._pending)
        except BlockingIOError:
            return
        except OSError as exc:
            self._lost(exc)
            return
        del self._pending[:written]
        if not self._pending and self._loop is not None:
            self._loop.remove_writer(self._fd)

    def _read_serial(self) -> None:
        assert self._fd is not None
        try:
            data = os.read(self._fd, 4096)
        except BlockingIOError:
            return
        except OSError as exc:
            self._lost(exc)
            return
        if not data:  # readable but empty: the device went away (a USB adapter unplugged)
            self._lost(ConnectionError("the serial device disconnected"))
            return
        self._received(data, "serial")

    def _lost(self, exc: BaseException) -> None:
        self.failure = exc
        if self._fd is not None and self._loop is not None:
            self._loop.remove_reader(self._fd)
            self._loop.remove_writer(self._fd)


def _open_serial(device: str, baud: int, url: str) -> int:
    try:
        fd = os.open(device, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
    except OSError as exc:
        raise LinkLost(f"cannot open {device} ({exc.strerror})", link=url) from exc
    try:
        attrs = termios.tcgetattr(fd)
        speed = BAUD_CONSTANTS[baud]
        attrs[0] = 0  # iflag: raw
        attrs[1] = 0  # oflag
        attrs[2] = termios.CS8 | termios.CREAD | termios.CLOCAL  # cflag
        attrs[3] = 0  # lflag
        attrs[4] = attrs[5] = speed
        # VMIN 1, VTIME 0: with O_NONBLOCK an idle port reads EAGAIN, so an empty read means
        # hang-up (a previous program, e.g. pyserial, may have left VMIN 0: empty reads when idle)
        attrs[6][termios.VMIN], attrs[6][termios.VTIME] = 1, 0
        termios.tcsetattr(fd, termios.TCSANOW, attrs)
    except termios.error as exc:
        os.close(fd)
        raise LinkLost(f"{device} is not a serial port ({exc})", link=url) from exc
    return fd

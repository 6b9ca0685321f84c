"""The MAVLink link: URL parsing, UDP in/out, TCP, serial over a pty, and .tlog files."""

from __future__ import annotations

import asyncio
import contextlib
import os
import socket
import struct
import time
from collections.abc import AsyncIterator, Callable
from pathlib import Path
from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from remarl_fc.errors import LinkLost
from remarl_fc.mavlink.codec import Codec
from remarl_fc.mavlink.link import (
    DEFAULT_BAUD,
    LinkAddress,
    MavlinkLink,
    TlogWriter,
)

WAIT_S = 5.0
"""Wall-clock limit of one wait (generous for slow CI machines)."""


async def until(pred: Callable[[], bool], what: str, limit_s: float = WAIT_S) -> None:
    end = time.monotonic() + limit_s
    while not pred():
        if time.monotonic() > end:
            raise AssertionError(f"timed out waiting for {what}")
        await asyncio.sleep(0.005)


class Inbox:
    """A link's `on_message`: records (message, receive time), accepts everything."""

    def __init__(self) -> None:
        self.got: list[tuple[Any, float]] = []

    def __call__(self, msg: Any, now: float, address: Any = None) -> bool:
        self.got.append((msg, now))
        return True

    def types(self) -> list[str]:
        return [m.get_type() for m, _ in self.got]

    def from_system(self, sysid: int) -> list[Any]:
        return [m for m, _ in self.got if m.get_srcSystem() == sysid]


def heartbeat(codec: Codec, custom_mode: int = 4) -> Any:
    return codec.factory.heartbeat_encode(2, 3, 81, custom_mode, 4)


def statustext(codec: Codec, text: bytes) -> Any:
    return codec.factory.statustext_encode(6, text)


def free_tcp_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


# -- LinkAddress.parse ----------------------------------------------------------------------


@pytest.mark.parametrize(
    ("url", "expected"),
    [
        ("udpin:0.0.0.0:14550", LinkAddress("udpin", "0.0.0.0", 14550)),
        ("udp:127.0.0.1:14550", LinkAddress("udpin", "127.0.0.1", 14550)),
        ("127.0.0.1:14540", LinkAddress("udpin", "127.0.0.1", 14540)),
        ("localhost:14540", LinkAddress("udpin", "localhost", 14540)),
        ("udpin:127.0.0.1:0", LinkAddress("udpin", "127.0.0.1", 0)),
        # a host whose name starts with "com" is a host, not a Windows COM port
        ("companion:14550", LinkAddress("udpin", "companion", 14550)),
        ("udpout:10.0.0.2:14550", LinkAddress("udpout", "10.0.0.2", 14550)),
        ("udpout:vehicle.local:14555", LinkAddress("udpout", "vehicle.local", 14555)),
        ("tcp:127.0.0.1:5760", LinkAddress("tcp", "127.0.0.1", 5760)),
        ("tcp:sitl:5762", LinkAddress("tcp", "sitl", 5762)),
        ("serial:/dev/ttyUSB0", LinkAddress("serial", device="/dev/ttyUSB0", baud=DEFAULT_BAUD)),
        ("serial:/dev/ttyACM0:115200", LinkAddress("serial", device="/dev/ttyACM0", baud=115200)),
        ("serial:COM5:921600", LinkAddress("serial", device="COM5", baud=921600)),
        ("/dev/ttyUSB0", LinkAddress("serial", device="/dev/ttyUSB0", baud=57600)),
        ("/dev/ttyAMA0,921600", LinkAddress("serial", device="/dev/ttyAMA0", baud=921600)),
        (
            "/dev/serial/by-id/usb-x,9600",
            LinkAddress("serial", device="/dev/serial/by-id/usb-x", baud=9600),
        ),
        ("COM3", LinkAddress("serial", device="COM3", baud=57600)),
        ("com12,115200", LinkAddress("serial", device="com12", baud=115200)),
    ],
)
def test_parse(url, expected):
    assert LinkAddress.parse(url) == expected


def test_default_baud_is_the_radio_rate():
    assert DEFAULT_BAUD == 57600


@pytest.mark.parametrize(
    ("url", "words"),
    [
        ("", "is not one of"),
        ("vehicle", "is not one of"),
        ("udpin", "is not one of"),
        ("http://example.com", "is not one of"),
        ("serial:", "is not one of"),  # no device
        ("serial::57600", "is not one of"),
        ("companion", "is not one of"),
        ("udpin:14550", "is not HOST:PORT"),
        ("udpin:", "is not HOST:PORT"),
        ("udpout:127.0.0.1", "is not HOST:PORT"),
        ("tcp:", "is not HOST:PORT"),
        ("udpin:127.0.0.1:abc", "is not a number"),
        ("tcp:127.0.0.1:70000", "outside 0..65535"),
        ("udpout:127.0.0.1:-1", "outside 0..65535"),
        ("serial:/dev/ttyUSB0:fast", "baud 'fast' is not a number"),
        ("serial:/dev/ttyUSB0:1234", "baud 1234 is not one of"),
        ("/dev/ttyUSB0,abc", "is not a number"),
        ("/dev/ttyUSB0,100", "is not one of"),
        ("COM3,12", "is not one of"),
    ],
)
def test_parse_refuses_bad_forms_clearly(url, words):
    with pytest.raises(ValueError, match="connection") as info:
        LinkAddress.parse(url)
    assert repr(url) in str(info.value)
    assert words in str(info.value)


def test_a_bad_url_fails_at_construction():
    with pytest.raises(ValueError, match="is not one of"):
        MavlinkLink("nowhere", Codec(255, 190), Inbox())


# -- UDP ------------------------------------------------------------------------------------


@contextlib.asynccontextmanager
async def udp_pair(
    *sysids: int, tlog: TlogWriter | None = None
) -> AsyncIterator[tuple[MavlinkLink, Inbox, list[tuple[MavlinkLink, Inbox, Codec]]]]:
    """A udpin "ground station" (system 255) and one udpout "vehicle" per system id."""
    gcs_inbox = Inbox()
    async with contextlib.AsyncExitStack() as stack:
        gcs = await stack.enter_async_context(
            MavlinkLink("udpin:127.0.0.1:0", Codec(255, 190), gcs_inbox, tlog=tlog)
        )
        assert gcs.local_address is not None
        host, port = gcs.local_address
        vehicles = []
        for sysid in sysids:
            inbox, codec = Inbox(), Codec(sysid, 1)
            link = await stack.enter_async_context(
                MavlinkLink(f"udpout:{host}:{port}", codec, inbox)
            )
            vehicles.append((link, inbox, codec))
        yield gcs, gcs_inbox, vehicles


@pytest.mark.asyncio
@pytest.mark.network
async def test_udpin_and_udpout_talk_and_dispatch_by_system_id():
    async with udp_pair(1, 2) as (gcs, gcs_inbox, vehicles):
        (v1, in1, c1), (v2, in2, c2) = vehicles
        assert gcs.address.kind == "udpin" and v1.address.kind == "udpout"
        gcs_codec_ = gcs.codec
        # nothing heard yet: a udpin link has nowhere to send
        assert gcs.send(heartbeat(gcs_codec_), 1) is False
        assert gcs.send(heartbeat(gcs_codec_)) is False
        # a udpout link always has its peer
        t0 = time.monotonic()
        assert v1.send(heartbeat(c1, custom_mode=4)) is True
        assert v2.send(heartbeat(c2, custom_mode=5), 255) is True
        await until(lambda: len(gcs_inbox.got) == 2, "both heartbeats")
        assert sorted(m.get_srcSystem() for m, _ in gcs_inbox.got) == [1, 2]
        assert gcs_inbox.from_system(1)[0].custom_mode == 4
        assert gcs_inbox.from_system(2)[0].custom_mode == 5
        assert all(t0 <= now <= time.monotonic() for _, now in gcs_inbox.got)
        assert set(gcs.where) == {1, 2}
        assert gcs.where[1] == ("127.0.0.1", v1.local_address[1])
        assert gcs.where[2] == ("127.0.0.1", v2.local_address[1])
        # addressed to system 2: only vehicle 2 hears it
        assert gcs.send(statustext(gcs_codec_, b"for two"), 2) is True
        await until(lambda: len(in2.got) == 1, "vehicle 2's text")
        await asyncio.sleep(0.05)
        assert in1.got == []
        (msg, _) = in2.got[0]
        assert msg.get_type() == "STATUSTEXT" and msg.text == "for two"
        assert msg.get_srcSystem() == 255 and msg.get_srcComponent() == 190
        assert msg.get_seq() == 0  # the sends that went nowhere used no sequence number
        assert v2.where == {255: gcs.local_address}
        # an unknown system: nowhere to send
        assert gcs.send(statustext(gcs_codec_, b"nobody"), 9) is False
        # no system id: everyone heard
        assert gcs.send(statustext(gcs_codec_, b"all")) is True
        await until(lambda: len(in1.got) == 1 and len(in2.got) == 2, "the broadcast")
        assert in1.got[0][0].text == "all" and in2.got[1][0].text == "all"


@pytest.mark.asyncio
@pytest.mark.network
@pytest.mark.parametrize("bound", [False, True], ids=["last-heard", "bound"])
async def test_udpin_replies_to_where_a_system_was_last_heard_unless_it_is_bound(bound):
    """System 3 is heard from one port, then from another (a reconnect, or a forger): replies
    follow it to the new port, unless the first address was bound; then they all go there."""
    async with udp_pair(3, 3) as (gcs, gcs_inbox, vehicles):
        (first, in_first, c_first), (second, in_second, c_second) = vehicles
        first.send(heartbeat(c_first))
        await until(lambda: len(gcs_inbox.got) == 1, "the first heartbeat")
        if bound:
            gcs.bind(3, gcs.where[3])
        second.send(heartbeat(c_second))  # system 3's id from another port
        await until(lambda: len(gcs_inbox.got) == 2, "the second heartbeat")
        to, heard, unheard = (
            (first, in_first, in_second) if bound else (second, in_second, in_first)
        )
        assert gcs.where[3][1] == to.local_address[1]
        assert gcs.send(statustext(gcs.codec, b"here"), 3)
        assert gcs.send(statustext(gcs.codec, b"again"), 3)
        await until(lambda: len(heard.got) == 2, "both replies")
        await asyncio.sleep(0.05)
        assert [m.text for m, _ in heard.got] == ["here", "again"]
        assert unheard.got == []


class Refuser(Inbox):
    """Accepts only system 1."""

    def __call__(self, msg: Any, now: float, address: Any = None) -> bool:
        super().__call__(msg, now, address)
        return bool(msg.get_srcSystem() == 1)


@pytest.mark.asyncio
@pytest.mark.network
async def test_refused_frames_are_rate_limited_in_the_tlog(tmp_path, monkeypatch):
    from remarl_fc.mavlink.link import REFUSED_TLOG_PER_S

    tlog = TlogWriter(tmp_path / "flight.tlog")
    inbox = Refuser()
    async with MavlinkLink("udpin:127.0.0.1:0", Codec(255, 190), inbox, tlog=tlog) as gcs:
        stranger, friend = Codec(9, 1), Codec(1, 1)
        flood = b"".join(stranger.encode(heartbeat(stranger)) for _ in range(500))
        gcs._received(flood, ("10.0.0.9", 5))  # 500 refused frames within one second
        gcs._received(friend.encode(heartbeat(friend)), ("10.0.0.1", 5))
        assert gcs.refused == 500
        assert gcs.refused_not_logged == 500 - REFUSED_TLOG_PER_S
    logged = read_tlog(tmp_path / "flight.tlog", monkeypatch)
    assert len(logged) == REFUSED_TLOG_PER_S + 1
    assert logged[-1].get_srcSystem() == 1  # what was accepted is always logged


def test_the_tlog_is_flushed_at_least_every_second(tmp_path, monkeypatch):
    import remarl_fc.mavlink.link as link_module

    clock = [100.0]
    monkeypatch.setattr(link_module.time, "monotonic", lambda: clock[0])
    tlog = TlogWriter(tmp_path / "flight.tlog")
    tlog.open()
    codec = Codec(1, 1)
    frame = codec.encode(heartbeat(codec))
    tlog.write(frame)
    size = (tmp_path / "flight.tlog").stat().st_size
    assert size == 0  # buffered
    clock[0] += link_module.TLOG_FLUSH_S
    tlog.write(frame)
    assert (tmp_path / "flight.tlog").stat().st_size == 2 * (8 + len(frame))  # on disk
    tlog.close()


@pytest.mark.asyncio
@pytest.mark.network
async def test_garbage_and_two_frames_in_one_datagram():
    async with udp_pair() as (gcs, gcs_inbox, _):
        host, port = gcs.local_address
        vehicle = Codec(4, 1)
        frame = vehicle.encode(heartbeat(vehicle))
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as raw:
            raw.sendto(b"\x00not mavlink", (host, port))
            raw.sendto(frame + frame, (host, port))  # two frames in one datagram
            await until(lambda: len(gcs_inbox.got) == 2, "two heartbeats")
        assert [m.get_srcSystem() for m, _ in gcs_inbox.got] == [4, 4]
        assert [m.get_seq() for m, _ in gcs_inbox.got] == [0, 0]
        assert gcs.codec.stats.bad_frames == 1


@pytest.mark.asyncio
@pytest.mark.network
async def test_a_closed_link_refuses_to_send():
    inbox = Inbox()
    link = MavlinkLink("udpin:127.0.0.1:0", Codec(255, 190), inbox)
    async with link:
        assert link.local_address is not None
    assert link.local_address is None
    with pytest.raises(LinkLost, match="closed"):
        link.send(heartbeat(link.codec))
    link.close()  # idempotent


@pytest.mark.asyncio
@pytest.mark.network
async def test_binding_a_port_in_use_is_link_lost():
    async with udp_pair() as (gcs, _, _):
        host, port = gcs.local_address
        with pytest.raises(LinkLost, match="cannot bind"):
            async with MavlinkLink(f"udpin:{host}:{port}", Codec(255, 190), Inbox()):
                pass


# -- TCP ------------------------------------------------------------------------------------


class TcpVehicle:
    """An asyncio TCP server playing an autopilot's serial-over-TCP port (system 1)."""

    def __init__(self, *, close_at_once: bool = False) -> None:
        self.codec = Codec(1, 1)
        self.parser = Codec(200, 1)  # decodes what the link sends
        self.heard: list[Any] = []
        self.writers: list[asyncio.StreamWriter] = []
        self.close_at_once = close_at_once
        self.server: asyncio.Server | None = None
        self.port = 0

    async def handle(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        self.writers.append(writer)
        if self.close_at_once:
            writer.close()
            await writer.wait_closed()
            return
        try:
            while data := await reader.read(4096):
                self.heard.extend(self.parser.decode(data, "link"))
        finally:
            writer.close()

    async def send(self, *frames: bytes) -> None:
        (writer,) = self.writers
        for frame in frames:
            writer.write(frame)
            await writer.drain()
            await asyncio.sleep(0.01)

    async def __aenter__(self) -> TcpVehicle:
        self.server = await asyncio.start_server(self.handle, "127.0.0.1", 0)
        self.port = self.server.sockets[0].getsockname()[1]
        return self

    async def __aexit__(self, *exc: object) -> None:
        assert self.server is not None
        for writer in self.writers:
            writer.close()
        self.server.close()
        await self.server.wait_closed()


@pytest.mark.asyncio
@pytest.mark.network
async def test_tcp_link_receives_and_sends():
    inbox = Inbox()
    async with (
        TcpVehicle() as vehicle,
        MavlinkLink(f"tcp:127.0.0.1:{vehicle.port}", Codec(255, 190), inbox) as link,
    ):
        assert link.address.kind == "tcp" and link.local_address is None
        await until(lambda: len(vehicle.writers) == 1, "the connection")
        frame = vehicle.codec.encode(heartbeat(vehicle.codec, custom_mode=4))
        text = vehicle.codec.encode(statustext(vehicle.codec, b"EKF3 IMU0 is using GPS"))
        # a stream: frames split anywhere, several in one read
        await vehicle.send(frame[:3], frame[3:] + text[:10], text[10:])
        await until(lambda: len(inbox.got) == 2, "two messages over TCP")
        assert inbox.types() == ["HEARTBEAT", "STATUSTEXT"]
        assert [m.get_srcSystem() for m, _ in inbox.got] == [1, 1]
        assert inbox.got[1][0].text == "EKF3 IMU0 is using GPS"
        assert link.where == {1: "stream"}
        # sending: the stream goes to its one peer, whatever the system id
        assert link.send(heartbeat(link.codec)) is True
        assert link.send(statustext(link.codec, b"hello"), 1) is True
        await until(lambda: len(vehicle.heard) == 2, "the link's two messages")
        assert [m.get_type() for m in vehicle.heard] == ["HEARTBEAT", "STATUSTEXT"]
        assert [m.get_srcSystem() for m in vehicle.heard] == [255, 255]
        assert [m.get_seq() for m in vehicle.heard] == [0, 1]


@pytest.mark.asyncio
@pytest.mark.network
async def test_tcp_server_closing_makes_send_raise_link_lost():
    async with (
        TcpVehicle(close_at_once=True) as vehicle,
        MavlinkLink(f"tcp:127.0.0.1:{vehicle.port}", Codec(255, 190), Inbox()) as link,
    ):
        await until(lambda: link.failure is not None, "the link to notice the close")
        with pytest.raises(LinkLost) as info:
            link.send(heartbeat(link.codec))
        assert info.value.link == f"tcp:127.0.0.1:{vehicle.port}"
        assert "the connection failed" in str(info.value)


@pytest.mark.asyncio
@pytest.mark.network
async def test_connecting_to_a_closed_tcp_port_is_link_lost(tmp_path):
    port = free_tcp_port()
    tlog = TlogWriter(tmp_path / "flight.tlog")
    with pytest.raises(LinkLost, match="cannot connect") as info:
        async with MavlinkLink(f"tcp:127.0.0.1:{port}", Codec(255, 190), Inbox(), tlog=tlog):
            pass
    assert info.value.link == f"tcp:127.0.0.1:{port}"
    assert tlog._fh is None  # the log is closed again


# -- serial ---------------------------------------------------------------------------------


@pytest.fixture
def pty() -> Any:
    """(master fd, slave path): the link opens the slave as its serial port."""
    master, slave = os.openpty()
    os.set_blocking(master, False)
    try:
        yield master, os.ttyname(slave)
    finally:
        for fd in (master, slave):
            with contextlib.suppress(OSError):
                os.close(fd)


async def read_master(master: int, parser: Codec, count: int) -> list[Any]:
    got: list[Any] = []

    def more() -> bool:
        with contextlib.suppress(BlockingIOError):
            got.extend(parser.decode(os.read(master, 4096), "master"))
        return len(got) >= count

    await until(more, f"{count} messages on the pty master")
    return got


# Bytes a cooked tty would eat or translate: CR, LF, ^C (VINTR), ^Q/^S (XON/XOFF), ^D (VEOF).
CONTROL_TEXT = b"a\rb\nc\x03d\x11e\x13f\x04g\x7f"


@pytest.mark.asyncio
async def test_serial_link_over_a_pty(pty):
    master, path = pty
    inbox = Inbox()
    vehicle = Codec(1, 1)
    async with MavlinkLink(f"serial:{path}:57600", Codec(255, 190), inbox) as link:
        assert link.address == LinkAddress("serial", device=path, baud=57600)
        frames = [
            vehicle.encode(heartbeat(vehicle)),
            vehicle.encode(statustext(vehicle, CONTROL_TEXT)),
            vehicle.encode(vehicle.factory.attitude_encode(0, 0.1, 0.2, 0.3, 0, 0, 0)),
        ]
        os.write(master, frames[0][:7])
        await asyncio.sleep(0.02)
        os.write(master, frames[0][7:] + frames[1] + frames[2])
        await until(lambda: len(inbox.got) == 3, "three messages over the pty")
        assert inbox.types() == ["HEARTBEAT", "STATUSTEXT", "ATTITUDE"]
        assert inbox.got[1][0].text == CONTROL_TEXT.decode()  # raw mode: bytes unchanged
        assert inbox.got[2][0].yaw == pytest.approx(0.3)
        assert link.where == {1: "serial"}
        # sent frames come out of the master unchanged
        assert link.send(statustext(link.codec, CONTROL_TEXT), 1) is True
        assert link.send(heartbeat(link.codec)) is True
        got = await read_master(master, Codec(1, 1), 2)
        assert [m.get_type() for m in got] == ["STATUSTEXT", "HEARTBEAT"]
        assert got[0].text == CONTROL_TEXT.decode() and got[0].get_srcSystem() == 255
    with pytest.raises(LinkLost, match="closed"):
        link.send(heartbeat(link.codec))


@pytest.mark.asyncio
@pytest.mark.parametrize("form", ["serial:{path}", "{path},115200"])
async def test_serial_url_forms_open_the_device(pty, form):
    master, path = pty
    inbox = Inbox()
    vehicle = Codec(7, 1)
    async with MavlinkLink(form.format(path=path), Codec(255, 190), inbox):
        os.write(master, vehicle.encode(heartbeat(vehicle)))
        await until(lambda: len(inbox.got) == 1, "a heartbeat")
    assert inbox.got[0][0].get_srcSystem() == 7


@pytest.mark.asyncio
async def test_serial_device_gone_is_noticed(pty):
    """The other end hangs up (a USB adapter unplugged): reads return nothing, forever.

    The link must mark itself failed (and stop reading) instead of spinning on the empty reads.
    """
    master, path = pty
    async with MavlinkLink(f"serial:{path}", Codec(255, 190), Inbox()) as link:
        os.close(master)
        await until(lambda: link.failure is not None, "the hang-up to be noticed")
        with pytest.raises(LinkLost, match="the connection failed"):
            link.send(heartbeat(link.codec))


@pytest.mark.asyncio
async def test_opening_a_missing_device_is_link_lost(tmp_path):
    path = tmp_path / "ttyNOPE"
    with pytest.raises(LinkLost, match="cannot open") as info:
        async with MavlinkLink(f"serial:{path}", Codec(255, 190), Inbox()):
            pass
    assert str(path) in str(info.value)


@pytest.mark.asyncio
async def test_opening_a_file_that_is_not_a_tty_is_link_lost(tmp_path):
    path = tmp_path / "not-a-tty"
    path.write_bytes(b"")
    with pytest.raises(LinkLost, match="is not a serial port"):
        async with MavlinkLink(f"serial:{path}", Codec(255, 190), Inbox()):
            pass


# -- .tlog ----------------------------------------------------------------------------------


def read_tlog(path: Path, monkeypatch: pytest.MonkeyPatch) -> list[Any]:
    """Every message of a .tlog, read by pymavlink's own log reader."""
    # mavutil switches itself to MAVLink 2 by setting MAVLINK20 in the environment: contain it
    monkeypatch.setenv("MAVLINK20", "1")
    from pymavlink import mavutil

    log = mavutil.mavlink_connection(str(path))
    out = []
    try:
        while (m := log.recv_match()) is not None:
            out.append(m)
    finally:
        log.close()
    return out


def test_tlog_writer_format(tmp_path, monkeypatch):
    path = tmp_path / "logs" / "deep" / "a.tlog"  # folders are created
    writer = TlogWriter(path)
    vehicle = Codec(1, 1)
    writer.write(vehicle.encode(heartbeat(vehicle)))  # not open yet: dropped
    writer.open()
    before = time.time()
    frames = [vehicle.encode(heartbeat(vehicle, custom_mode=k)) for k in range(3)] + [
        vehicle.encode(statustext(vehicle, b"logged"))
    ]
    for frame in frames:
        writer.write(frame)
    after = time.time()
    writer.close()
    writer.close()  # idempotent
    data = path.read_bytes()
    assert len(data) == sum(8 + len(f) for f in frames)
    (stamp_us,) = struct.unpack(">Q", data[:8])
    assert before - 1e-3 <= stamp_us / 1e6 <= after + 1e-3
    assert data[8 : 8 + len(frames[0])] == frames[0]
    msgs = read_tlog(path, monkeypatch)
    assert [m.get_type() for m in msgs] == ["HEARTBEAT"] * 3 + ["STATUSTEXT"]
    assert [m.custom_mode for m in msgs[:3]] == [0, 1, 2]
    assert msgs[3].text == "logged"
    assert all(before - 1e-3 <= m._timestamp <= after + 1e-3 for m in msgs)
    # opened again: appended, not truncated
    writer.open()
    writer.write(frames[0])
    writer.close()
    assert len(read_tlog(path, monkeypatch)) == 5


@pytest.mark.asyncio
@pytest.mark.network
async def test_link_logs_every_frame_in_and_out(tmp_path, monkeypatch):
    path = tmp_path / "flight.tlog"
    async with udp_pair(1, 2, tlog=TlogWriter(path)) as (gcs, gcs_inbox, vehicles):
        (v1, in1, c1), (v2, _, c2) = vehicles
        v1.send(heartbeat(c1, custom_mode=4))
        await until(lambda: len(gcs_inbox.got) == 1, "heartbeat 1")
        v2.send(c2.factory.attitude_encode(10, 0.0, 0.0, 1.5, 0, 0, 0))
        await until(lambda: len(gcs_inbox.got) == 2, "attitude 2")
        gcs.send(statustext(gcs.codec, b"to one"), 1)
        await until(lambda: len(in1.got) == 1, "the text")
        gcs.send(statustext(gcs.codec, b"to nobody"), 9)  # not sent, not logged
    msgs = read_tlog(path, monkeypatch)
    assert [(m.get_type(), m.get_srcSystem()) for m in msgs] == [
        ("HEARTBEAT", 1),
        ("ATTITUDE", 2),
        ("STATUSTEXT", 255),
    ]
    assert msgs[0].custom_mode == 4
    assert msgs[1].yaw == pytest.approx(1.5)
    assert msgs[2].text == "to one"
    # the logged frames are the ones on the wire
    assert msgs[0].get_msgbuf() == gcs_inbox.got[0][0].get_msgbuf()
    assert msgs[2].get_msgbuf() == in1.got[0][0].get_msgbuf()


@settings(max_examples=150, deadline=None)
@given(data=st.lists(st.binary(max_size=300), max_size=8))
def test_random_datagrams_into_a_link_never_raise_and_deliver_only_valid_messages(data):
    inbox = Inbox()
    link = MavlinkLink("udpin:127.0.0.1:0", Codec(255, 190), inbox)
    link._udp = object()  # type: ignore[assignment]  # as if open: datagram rules apply
    for k, datagram in enumerate(data):
        link._received(datagram, ("10.0.0.1", 1000 + k % 3))
    assert all(m.get_type() != "BAD_DATA" for m, _ in inbox.got)
    assert set(link.where) <= {m.get_srcSystem() for m, _ in inbox.got}

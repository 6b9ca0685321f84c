"""The mock's TCP transport: each vehicle a serial-over-TCP server, as ArduPilot SITL's 5760."""

from __future__ import annotations

import asyncio
import time

import pytest

from remarl_fc.mavlink.codec import Codec
from remarl_fc.mavlink.consts import MavCmd, MavResult, MsgId
from remarl_fc.sitl.config import SitlConfig
from remarl_fc.sitl.fleet import SitlFleet

pytestmark = [pytest.mark.network, pytest.mark.timeout(60)]

WAIT_S = 10.0


class TcpGcs:
    """A ground station on one TCP connection: sends frames, collects what comes back."""

    def __init__(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        self.reader, self.writer = reader, writer
        self.codec = Codec(255, 190)
        self.heard: list = []

    def send(self, msg, *, chunk: int | None = None) -> bytes:
        frame = self.codec.encode(msg)
        step = chunk or len(frame)
        for k in range(0, len(frame), step):
            self.writer.write(frame[k : k + step])
        return frame

    async def wait_for(self, mtype: str, pred=lambda m: True):
        end = time.monotonic() + WAIT_S
        while True:
            for m in self.heard:
                if m.get_type() == mtype and pred(m):
                    self.heard.remove(m)
                    return m
            left = end - time.monotonic()
            if left <= 0:
                raise AssertionError(f"no {mtype} within {WAIT_S} s")
            async with asyncio.timeout(left):
                data = await self.reader.read(4096)
            if not data:
                raise AssertionError("the vehicle closed the connection")
            self.heard += self.codec.decode(data, "vehicle")

    async def until_closed(self) -> None:
        """Read whatever is in flight until the vehicle closes the stream."""
        async with asyncio.timeout(WAIT_S):
            while await self.reader.read(4096):
                pass

    async def close(self) -> None:
        self.writer.close()
        await self.writer.wait_closed()


async def connect(fleet: SitlFleet, i: int) -> TcpGcs:
    reader, writer = await asyncio.open_connection(*fleet.addresses[i])
    return TcpGcs(reader, writer)


def test_tcp_ports_follow_ardupilot_sitl_and_refuse_out():
    assert SitlConfig(transport="tcp").port(1) == 5770
    assert SitlConfig(transport="tcp", flavour="px4", vehicles=3).port(2) == 5780
    assert SitlConfig(transport="tcp", base_port=6000, port_step=1, vehicles=2).port(1) == 6001
    with pytest.raises(ValueError, match="--out is for UDP"):
        SitlConfig(transport="tcp", out=("127.0.0.1", 14540))


@pytest.mark.asyncio
async def test_a_vehicle_answers_over_a_byte_stream():
    cfg = SitlConfig(vehicles=2, transport="tcp", base_port=0, speedup=10.0)
    async with SitlFleet(cfg) as fleet:
        gcs = await connect(fleet, 1)
        f = gcs.codec.factory
        gcs.send(f.heartbeat_encode(6, 8, 0, 0, 4))
        hb = await gcs.wait_for("HEARTBEAT")
        assert hb.get_srcSystem() == 2 and hb.autopilot == 3
        # one command cut into 3-byte pieces: the vehicle reassembles the stream
        cmd = f.command_long_encode(
            2, 1, MavCmd.REQUEST_MESSAGE, 0, MsgId.AUTOPILOT_VERSION, *[0] * 6
        )
        gcs.send(cmd, chunk=3)
        ack = await gcs.wait_for("COMMAND_ACK")
        assert ack.command == MavCmd.REQUEST_MESSAGE and ack.result == MavResult.ACCEPTED
        await gcs.wait_for("AUTOPILOT_VERSION")
        v = fleet.summary()["vehicles"][1]
        assert v["link"]["bad_frames"] == 0 and v["commands"] == {"REQUEST_MESSAGE": 1}
        assert fleet.summary()["vehicles"][0]["link"]["datagrams_in"] == 0  # its own port
        await gcs.close()


@pytest.mark.asyncio
async def test_a_second_client_replaces_the_first():
    cfg = SitlConfig(vehicles=1, transport="tcp", base_port=0, speedup=10.0)
    async with SitlFleet(cfg) as fleet:
        first = await connect(fleet, 0)
        first.send(first.codec.factory.heartbeat_encode(6, 8, 0, 0, 4))
        await first.wait_for("HEARTBEAT")
        second = await connect(fleet, 0)
        second.send(second.codec.factory.heartbeat_encode(6, 8, 0, 0, 4))
        await second.wait_for("HEARTBEAT")
        await first.until_closed()  # one client at a time: the first was dropped
        await first.close()
    # the fleet closed its side on exit: the client sees the end of the stream
    await second.until_closed()
    await second.close()

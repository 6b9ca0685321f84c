"""``remarl-fc bench sitl``: how much telemetry the mock fleet delivers, and at what CPU cost.

One client socket (in the same process) greets every vehicle, asks each for the same messages
at the same rate with MAV_CMD_SET_MESSAGE_INTERVAL — the ArduPilot flavour sends nothing
until asked — then counts, for a measured window, the frames each vehicle delivers. The client
reads only the 10-byte MAVLink 2 header of each datagram (message id and sender), so nearly all
the CPU time measured is the mock's. Figures: achieved rate per vehicle and message (mean and
worst vehicle) against the requested rate, HEARTBEAT rate, and CPU seconds per simulated
second for the whole process.
"""

from __future__ import annotations

import asyncio
import collections
import time
from typing import Any

from remarl_fc.mavlink.codec import Codec
from remarl_fc.mavlink.consts import MavCmd, MavType, MsgId
from remarl_fc.mavlink.udp import Address, UdpEndpoint
from remarl_fc.sitl.config import SitlConfig
from remarl_fc.sitl.fleet import SitlFleet

BENCH_MESSAGES = (MsgId.GLOBAL_POSITION_INT, MsgId.ATTITUDE)
"""Messages the benchmark client asks every vehicle for."""

MAVLINK2_MAGIC = 0xFD
"""First byte of a MAVLink 2 frame."""

CLIENT_BUFFER_BYTES = 8 * 1024 * 1024
"""Receive buffer the client asks for: one socket hears the whole fleet."""

GCS_SYSTEM_ID, GCS_COMPONENT_ID = 255, 190
"""The benchmark client's MAVLink identity (a ground station)."""


def frame_header(data: bytes) -> tuple[int, int] | None:
    """(system id, message id) of a MAVLink 2 frame, from its header only; None otherwise.

    >>> c = Codec(7, 1)
    >>> frame_header(c.encode(c.factory.heartbeat_encode(2, 3, 0, 0, 3)))
    (7, 0)
    """
    if len(data) < 10 or data[0] != MAVLINK2_MAGIC:
        return None
    return data[5], data[7] | data[8] << 8 | data[9] << 16


async def bench_sitl(
    vehicles: int = 100,
    rate_hz: float = 10.0,
    seconds: float = 5.0,
    warmup_s: float = 2.0,
    flavour: str = "ardupilot",
    speedup: float = 1.0,
) -> dict[str, Any]:
    """Run the benchmark (see the module docstring); ``seconds`` is simulated time."""
    cfg = SitlConfig(vehicles=vehicles, flavour=flavour, base_port=0, speedup=speedup)  # type: ignore[arg-type]
    counts: collections.Counter[tuple[int, int]] = collections.Counter()
    counting = False

    def on_datagram(data: bytes, addr: Address) -> None:
        if counting:
            head = frame_header(data)
            if head is not None:
                counts[head] += 1

    gcs = Codec(GCS_SYSTEM_ID, GCS_COMPONENT_ID)
    f = gcs.factory
    async with (
        SitlFleet(cfg) as fleet,
        UdpEndpoint(
            ("127.0.0.1", 0), on_datagram=on_datagram, receive_buffer_bytes=CLIENT_BUFFER_BYTES
        ) as client,
    ):
        for sysid, addr in enumerate(fleet.addresses, start=1):
            client.send(gcs.encode(f.heartbeat_encode(MavType.GCS, 8, 0, 0, 4)), addr)
            for mid in BENCH_MESSAGES:
                interval_us = 1e6 / rate_hz
                cmd = f.command_long_encode(
                    sysid, 1, MavCmd.SET_MESSAGE_INTERVAL, 0, int(mid), interval_us, 0, 0, 0, 0, 0
                )
                client.send(gcs.encode(cmd), addr)
        await asyncio.sleep(warmup_s / speedup)
        counting = True
        sim0, cpu0, wall0 = fleet.now_s(), time.process_time(), time.monotonic()
        await asyncio.sleep(seconds / speedup)
        counting = False
        sim_s = fleet.now_s() - sim0
        cpu_s, wall_s = time.process_time() - cpu0, time.monotonic() - wall0
    per_message: dict[str, Any] = {}
    for mid in (*BENCH_MESSAGES, MsgId.HEARTBEAT):
        rates = [counts[(s, int(mid))] / sim_s for s in range(1, vehicles + 1)]
        per_message[mid.name] = {
            "requested_hz": cfg.heartbeat_hz if mid == MsgId.HEARTBEAT else rate_hz,
            "mean_hz": round(sum(rates) / len(rates), 3),
            "worst_vehicle_hz": round(min(rates), 3),
        }
    return {
        "vehicles": vehicles,
        "flavour": flavour,
        "requested_speedup": speedup,
        "achieved_speedup": round(sim_s / wall_s, 3),
        "simulated_s": round(sim_s, 3),
        "cpu_s_per_simulated_s": round(cpu_s / sim_s, 4),
        "messages": per_message,
    }

"""``remarl-fc bench bus``: end-to-end state latency through an MQTT broker.

N vehicles publish their state at 10 Hz (the runtime's rate), each over its own MQTT
connection, in the bus's wire format; a few observers subscribe to the whole swarm, as every
vehicle's process does, validate every payload with the bus's schema, and measure the latency
from the moment a state was stamped to the moment it was decoded (one machine: one clock).
Without ``--bus`` the benchmark starts its own mosquitto on a free loopback port. Publishers
and observers share this process, so at large N the figures include the client side's own CPU
contention — an upper bound for a real deployment with one process per companion computer.
"""

from __future__ import annotations

import asyncio
import contextlib
import shutil
import socket
import subprocess
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import aiomqtt
import numpy as np

from remarl_fc.bus.schema import VehicleState, decode_state, encode_state, parse_topic, topic
from remarl_fc.errors import ConfigError

RATE_HZ = 10.0
"""State rate per vehicle (the runtime's)."""

OBSERVERS = 3
"""Subscribers that measure latency (each hears every vehicle)."""


@contextlib.contextmanager
def local_mosquitto() -> Iterator[int]:
    """Start mosquitto on a free loopback port; yields the port."""
    exe = shutil.which("mosquitto") or (
        "/usr/sbin/mosquitto" if Path("/usr/sbin/mosquitto").exists() else None
    )
    if exe is None:
        raise ConfigError(
            "mosquitto is not installed: apt-get install mosquitto, or give --bus mqtt://HOST:PORT"
        )
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = int(s.getsockname()[1])
    with tempfile.TemporaryDirectory() as tmp:
        conf = Path(tmp) / "mosquitto.conf"
        conf.write_text(f"listener {port} 127.0.0.1\nallow_anonymous true\nuser root\n")
        proc = subprocess.Popen(
            [exe, "-c", str(conf)], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL
        )
        try:
            for _ in range(200):
                with socket.socket() as s:
                    if s.connect_ex(("127.0.0.1", port)) == 0:
                        break
                time.sleep(0.05)
            yield port
        finally:
            proc.terminate()
            proc.wait(timeout=10)


async def _publisher(host: str, port: int, uav: int, seconds: float, counts: list[int]) -> None:
    async with aiomqtt.Client(host, port, identifier=f"bench-pub-{uav}") as client:
        name = topic("remarl", "bench", uav, "state")
        period = 1.0 / RATE_HZ
        t_next = time.monotonic() + uav * period / 50  # spread the vehicles over the period
        end = time.monotonic() + seconds
        seq = 0
        while time.monotonic() < end:
            seq += 1
            state = VehicleState(
                uav, seq, time.time(), (0.0, 0.0), 20.0, (10.0, 0.0, 0.0), 0.0, "controlled"
            )
            await client.publish(name, encode_state(state), qos=0)
            counts[uav - 1] += 1
            t_next += period
            await asyncio.sleep(max(0.0, t_next - time.monotonic()))


async def _observer(
    host: str, port: int, k: int, latencies: list[float], ready: asyncio.Event
) -> None:
    async with aiomqtt.Client(host, port, identifier=f"bench-obs-{k}") as client:
        await client.subscribe("remarl/bench/uav/+/state", qos=0)
        ready.set()
        async for message in client.messages:
            payload = message.payload
            if not isinstance(payload, bytes):
                continue
            uav, _ = parse_topic(str(message.topic), "remarl", "bench")
            state = decode_state(payload, uav)
            latencies.append(time.time() - state.t)


async def bench_bus(
    vehicles: int = 50, seconds: float = 5.0, port: int | None = None, host: str = "127.0.0.1"
) -> dict[str, Any]:
    """Run the benchmark against ``host:port`` (see the module docstring)."""
    if port is None:
        with local_mosquitto() as own_port:
            return await bench_bus(vehicles, seconds, own_port, "127.0.0.1")
    latencies: list[float] = []
    counts = [0] * vehicles
    cpu0 = time.process_time()
    async with asyncio.TaskGroup() as tg:
        readies = [asyncio.Event() for _ in range(OBSERVERS)]
        observers = [
            tg.create_task(_observer(host, port, k, latencies, readies[k]), name=f"bench.obs{k}")
            for k in range(OBSERVERS)
        ]
        for r in readies:
            await asyncio.wait_for(r.wait(), 10)
        async with asyncio.TaskGroup() as pubs:
            for uav in range(1, vehicles + 1):
                pubs.create_task(
                    _publisher(host, port, uav, seconds, counts), name=f"bench.pub{uav}"
                )
        await asyncio.sleep(0.5)  # the last messages arrive
        for t in observers:
            t.cancel()
    cpu = time.process_time() - cpu0
    lat = np.array(latencies) * 1000
    sent = sum(counts)
    return {
        "vehicles": vehicles,
        "observers": OBSERVERS,
        "rate_hz": RATE_HZ,
        "seconds": seconds,
        "published": sent,
        "delivered_fraction": round(len(lat) / (sent * OBSERVERS), 4) if sent else None,
        "latency_ms_p50": round(float(np.percentile(lat, 50)), 3) if lat.size else None,
        "latency_ms_p99": round(float(np.percentile(lat, 99)), 3) if lat.size else None,
        "client_cpu_s_per_s": round(cpu / seconds, 3),
    }

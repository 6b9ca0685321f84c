"""The swarm bus: schema, validation, the in-process bus, and MQTT against a real mosquitto."""

from __future__ import annotations

import asyncio
import json
import math
import subprocess
import sys
import time

import aiomqtt
import pytest
from hypothesis import given
from hypothesis import strategies as st

from remarl_fc.bus.core import BUCKET_SIZE, BusCore
from remarl_fc.bus.memory import MemoryBroker, MemoryBus
from remarl_fc.bus.mqtt import MqttBus, MqttSettings
from remarl_fc.bus.schema import (
    MAX_PAYLOAD_BYTES,
    Detection,
    Detections,
    PayloadError,
    VehicleState,
    decode_detections,
    decode_state,
    encode_detections,
    encode_state,
    parse_topic,
    topic,
)
from remarl_fc.errors import ConfigError

IDS = frozenset({1, 2, 3})


def state(uav: int = 2, seq: int = 1, t: float | None = None, **kw) -> VehicleState:
    base = {
        "id": uav,
        "seq": seq,
        "t": time.time() if t is None else t,
        "ne_m": (10.0, -5.0),
        "height_m": 20.0,
        "vel_ned_m_s": (1.0, 2.0, 0.0),
        "yaw_rad": 0.5,
        "status": "controlled",
    }
    base.update(kw)
    return VehicleState(**base)


def core(own: int = 1) -> BusCore:
    return BusCore("remarl", "s", frozenset({own}), IDS)


finite = st.floats(-1e4, 1e4, allow_nan=False)


@given(finite, finite, finite, st.floats(-3, 3), st.integers(0, 2**31))
def test_state_round_trip(n, e, h, yaw, seq):
    arc = (yaw, -0.5, 10.0, 1.25)
    s = state(
        seq=seq, ne_m=(n, e), height_m=h, yaw_rad=yaw, ready_ne_m=(n, e), ready_t=1.5, arc=arc
    )
    back = decode_state(encode_state(s), 2)
    assert back.arc is not None and all(
        math.isclose(a, b, abs_tol=1e-3) for a, b in zip(back.arc, arc, strict=True)
    )
    assert decode_state(encode_state(state()), 2).arc is None  # optional: none, none back
    assert back.seq == seq and back.status == "controlled"
    assert math.isclose(back.ne_m[0], n, abs_tol=0.01) and math.isclose(
        back.height_m, h, abs_tol=0.01
    )
    assert back.ready_ne_m is not None and back.ready_t == 1.5
    assert len(encode_state(s)) < 300


def test_detections_round_trip():
    d = Detections(2, 7, 1.0, (Detection(0xC00001, (1.0, 2.0), None, (3.0, 4.0)),))
    back = decode_detections(encode_detections(d), 2)
    assert back.items[0].icao == 0xC00001 and back.items[0].height_m is None


@pytest.mark.parametrize(
    ("payload", "reason"),
    [
        (b"{", "not JSON"),
        (b"[1, 2]", "not a JSON object"),
        (b"x" * (MAX_PAYLOAD_BYTES + 1), "oversized"),
        (json.dumps({"v": 9, "id": 2}).encode(), "schema version"),
        (json.dumps({"v": 1, "id": 3}).encode(), "spoofed"),
    ],
)
def test_malformed_payloads_are_refused(payload, reason):
    with pytest.raises(PayloadError, match=reason):
        decode_state(payload, 2)


@pytest.mark.parametrize(
    ("change", "reason"),
    [
        ({"ne": [1, "x"]}, "ne"),
        ({"ne": [1]}, "ne"),
        ({"h": float("nan")}, "h"),
        ({"st": "flying"}, "status"),
        ({"seq": -1}, "seq"),
        ({"seq": True}, "seq"),
        ({"vel": [500, 0, 0]}, "200"),
        ({"rt": 1.0}, "rne and rt"),
        ({"arc": [0.0, 0.5, 10.0]}, "arc"),
        ({"arc": [0.0, 4.0, 10.0, 1.0]}, "arc turn"),
        ({"arc": [0.0, 0.5, -1.0, 1.0]}, "arc turn"),
        ({"arc": [0.0, 0.5, 10.0, 3600.0]}, "arc turn"),
        ({"arc": [0.0, 0.5, 10.0, None]}, "arc"),
    ],
)
def test_bad_fields_are_refused(change, reason):
    body = json.loads(encode_state(state()))
    body.update(change)
    with pytest.raises(PayloadError, match=reason):
        decode_state(json.dumps(body).encode(), 2)


def test_topics():
    assert parse_topic(topic("a/b", "s", 7, "state"), "a/b", "s") == (7, "state")
    for bad in ["remarl/s/uav/x/state", "remarl/s/uav/7/cmd", "remarl/t/uav/7/state", "x"]:
        with pytest.raises(PayloadError):
            parse_topic(bad, "remarl", "s")


def test_core_filters_order_senders_and_floods():
    c = core()
    t = topic("remarl", "s", 2, "state")
    assert c.accept(t, encode_state(state(seq=5)))
    assert not c.accept(t, encode_state(state(seq=5)))  # repeated
    assert not c.accept(t, encode_state(state(seq=4)))  # out of order
    assert c.accept(t, encode_state(state(seq=1, t=time.time() + 10)))  # a restarted sender
    assert not c.accept(topic("remarl", "s", 9, "state"), encode_state(state(uav=9)))
    assert not c.accept(topic("remarl", "s", 1, "state"), encode_state(state(uav=1)))  # own echo
    assert not c.accept(t, b"garbage")
    rejected = c.stats.rejected
    assert rejected["out of order or repeated"] == 2
    assert rejected["sender not in the mission"] == 1
    assert rejected["state: not JSON"] == 1
    assert c.stats.rejected.total() == 4  # the own echo is not an error
    flood = [c.accept(t, encode_state(state(seq=100 + k, t=time.time() + 20))) for k in range(200)]
    assert sum(flood) <= BUCKET_SIZE + 5
    assert c.stats.rejected["rate limited (flood)"] >= 150


@pytest.mark.asyncio
async def test_memory_bus_delivers_and_replays_retained_status():
    broker = MemoryBroker()
    async with MemoryBus(broker, core(1)) as a:
        await a.publish_state(state(uav=1))
        async with MemoryBus(broker, core(2)) as b:
            assert b.core.online[1] is True  # retained "online" replayed on join
            await a.publish_state(state(uav=1, seq=2))
            assert b.core.states[1].value.seq == 2
            await b.publish_state(state(uav=2))
            assert a.core.states[2].value.id == 2
        assert a.core.online[2] is False  # b said offline on leaving


def test_mqtt_settings():
    s = MqttSettings.from_url("mqtts://alice@broker.example")
    assert (s.port, s.tls, s.username) == (8883, True, "alice")
    with pytest.raises(ConfigError, match="password"):
        MqttSettings.from_url("mqtt://alice:secret@host")
    with pytest.raises(ConfigError, match="mqtt://HOST"):
        MqttSettings.from_url("http://host")


async def running(bus) -> asyncio.Task:
    task = asyncio.create_task(bus.run())
    await asyncio.wait_for(bus.connected.wait(), 10)
    return task


async def eventually(pred, limit_s=10.0):
    end = time.monotonic() + limit_s
    while not pred():
        if time.monotonic() > end:
            raise AssertionError("condition not met in time")
        await asyncio.sleep(0.02)


@pytest.mark.asyncio
@pytest.mark.network
@pytest.mark.timeout(60)
async def test_mqtt_exchange_restart_and_hostile_publisher(mosquitto):
    settings = MqttSettings.from_url(mosquitto.url)
    a, b = MqttBus(settings, core(1)), MqttBus(settings, core(2))
    async with a, b:
        ta, tb = await running(a), await running(b)
        await eventually(lambda: b.core.online.get(1) is True)
        for k in range(5):
            await a.publish_state(state(uav=1, seq=k + 1))
        await eventually(lambda: 1 in b.core.states and b.core.states[1].value.seq == 5)

        # a hostile publisher: garbage, spoofed ids, an id outside the mission, a flood
        before = b.core.states[1].value
        async with aiomqtt.Client("127.0.0.1", mosquitto.port) as evil:
            t1 = topic("remarl", "s", 1, "state")
            await evil.publish(t1, b"\x00\xff garbage")
            await evil.publish(t1, encode_state(state(uav=3, seq=999)))  # payload id != topic id
            await evil.publish(topic("remarl", "s", 77, "state"), encode_state(state(uav=77)))
            await evil.publish(t1, b"{" + b" " * (MAX_PAYLOAD_BYTES + 10) + b"}")
            for k in range(300):
                await evil.publish(
                    topic("remarl", "s", 3, "state"), encode_state(state(uav=3, seq=k + 1))
                )
        await eventually(lambda: b.core.stats.rejected["rate limited (flood)"] > 0)
        rejected = b.core.stats.rejected
        assert rejected["state: not JSON"] >= 1
        assert rejected["state: id differs from the topic's (spoofed)"] >= 1
        assert rejected["sender not in the mission"] >= 1
        assert rejected["state: oversized"] >= 1
        assert b.core.states[1].value == before  # nothing the hostile publisher sent was used

        # the broker goes away for a while and comes back: both reconnect
        mosquitto.stop()
        await eventually(lambda: not b.connected.is_set())
        await a.publish_state(state(uav=1, seq=50))  # dropped, counted, no exception
        assert a.core.stats.publish_dropped >= 1
        await eventually(lambda: not a.connected.is_set())  # both saw the outage
        mosquitto.start()
        await asyncio.wait_for(a.connected.wait(), 15)
        await asyncio.wait_for(b.connected.wait(), 15)
        await a.publish_state(state(uav=1, seq=60))
        await eventually(lambda: b.core.states[1].value.seq == 60)
        assert a.core.stats.reconnects >= 1 and b.core.stats.reconnects >= 1
        ta.cancel()
        tb.cancel()
        await asyncio.gather(ta, tb, return_exceptions=True)


WILL_SCRIPT = """
import asyncio, sys, os
from remarl_fc.bus.core import BusCore
from remarl_fc.bus.mqtt import MqttBus, MqttSettings
async def main():
    core = BusCore("remarl", "s", frozenset({3}), frozenset({1, 2, 3}))
    bus = MqttBus(MqttSettings.from_url(sys.argv[1]), core)
    task = asyncio.create_task(bus.run())
    await bus.connected.wait()
    print("up", flush=True)
    await asyncio.sleep(60)
asyncio.run(main())
"""


@pytest.mark.asyncio
@pytest.mark.network
@pytest.mark.timeout(60)
async def test_last_will_marks_a_dead_process_offline(mosquitto):
    b = MqttBus(MqttSettings.from_url(mosquitto.url), core(2))
    async with b:
        tb = await running(b)
        proc = await asyncio.create_subprocess_exec(
            sys.executable, "-c", WILL_SCRIPT, mosquitto.url, stdout=subprocess.PIPE
        )
        try:
            assert proc.stdout is not None
            assert (await asyncio.wait_for(proc.stdout.readline(), 20)).strip() == b"up"
            await eventually(lambda: b.core.online.get(3) is True)
            proc.kill()  # no clean goodbye: the broker publishes the will after the keepalive
            await eventually(lambda: b.core.online.get(3) is False, limit_s=20)
        finally:
            if proc.returncode is None:
                proc.kill()
            await proc.communicate()
        tb.cancel()
        await asyncio.gather(tb, return_exceptions=True)


@pytest.mark.asyncio
@pytest.mark.network
@pytest.mark.timeout(60)
async def test_acls_let_a_vehicle_publish_only_as_itself(secured_mosquitto):
    url = secured_mosquitto.url

    def settings(user: int, password: str) -> MqttSettings:
        return MqttSettings(
            host="127.0.0.1", port=secured_mosquitto.port, username=str(user), password=password
        )

    a = MqttBus(settings(1, "pw-1"), core(1))
    b = MqttBus(settings(2, "pw-2"), core(2))
    wrong = MqttBus(settings(3, "not-the-password"), core(3))
    async with a, b, wrong:
        ta, tb = await running(a), await running(b)
        tw = asyncio.create_task(wrong.run())
        await a.publish_state(state(uav=1, seq=1))
        await eventually(lambda: 1 in b.core.states)
        # vehicle 1's credentials cannot publish as vehicle 3: the broker drops it
        forged = topic("remarl", "s", 3, "state")
        assert a._client is not None
        await a._client.publish(forged, encode_state(state(uav=3, seq=1)))
        # a's own next state goes out after the forged one on the same connection: once b
        # has it, the broker has dealt with the forged one too
        await a.publish_state(state(uav=1, seq=2))
        await eventually(lambda: b.core.states[1].value.seq == 2)
        assert 3 not in b.core.states
        assert not wrong.connected.is_set()  # a wrong password never connects
        for t in (ta, tb, tw):
            t.cancel()
        await asyncio.gather(ta, tb, tw, return_exceptions=True)
    assert url.startswith("mqtt://")


@pytest.mark.network
@pytest.mark.timeout(60)
def test_bench_bus_command(mosquitto, capsys):
    from remarl_fc.cli import main

    assert (
        main(
            ["bench", "bus", "--vehicles", "5", "--seconds", "1", "--bus", mosquitto.url, "--json"]
        )
        == 0
    )
    result = json.loads(capsys.readouterr().out)
    assert result["published"] >= 40 and result["delivered_fraction"] > 0.9
    assert result["latency_ms_p50"] < 100

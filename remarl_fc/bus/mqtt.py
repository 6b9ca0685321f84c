"""The swarm bus over MQTT (aiomqtt 2.x on paho-mqtt): one process per vehicle, one broker.

Each endpoint connects as ``PREFIX-SWARM-ID``, sets ``PREFIX/SWARM/uav/ID/status`` =
"offline" (retained, QoS 1) as its last will, publishes "online" (retained) once connected,
subscribes to ``PREFIX/SWARM/uav/+/+`` and feeds everything it hears to `BusCore.accept`.
States and detections go out at QoS 0 (stale beats late). When the broker goes away `run`
reconnects with exponential backoff and jitter; meanwhile publishing drops (counted) and the
peers' states age until the runtime treats them as stale. Credentials and TLS come from
`MqttSettings` (a password never goes on the command line: use a file or the environment).
"""

from __future__ import annotations

import asyncio
import os
import random
import ssl
from dataclasses import dataclass
from pathlib import Path
from typing import Self
from urllib.parse import urlsplit

import aiomqtt

from remarl_fc.bus.core import BusCore
from remarl_fc.bus.schema import (
    Detections,
    VehicleState,
    encode_detections,
    encode_state,
    topic,
)
from remarl_fc.errors import ConfigError
from remarl_fc.resource import Resource

KEEPALIVE_S = 5
"""MQTT keepalive: the broker publishes our will ≈ 1.5 × this after we vanish."""

BACKOFF_FIRST_S, BACKOFF_MAX_S = 0.25, 4.0
"""Reconnection backoff: doubling from the first to the max, each with ±50 % jitter."""

PUBLISH_TIMEOUT_S = 0.5
"""A publish that takes longer is dropped (the client's queue is full or the link is gone)."""

INCOMING_QUEUE = 2000
"""Messages queued for `run` at most (a flood cannot eat the memory)."""

PASSWORD_ENV = "REMARL_BUS_PASSWORD"
"""Environment variable holding the broker password (instead of a file)."""


@dataclass(frozen=True)
class MqttSettings:
    """Where and how to connect.

    Attributes:
        host, port: the broker. tls: connect with TLS (``mqtts://``).
        username, password: credentials, or None.
        ca_file, cert_file, key_file: TLS trust anchor and client certificate, or None.
    """

    host: str
    port: int = 1883
    tls: bool = False
    username: str | None = None
    password: str | None = None
    ca_file: str | None = None
    cert_file: str | None = None
    key_file: str | None = None

    @classmethod
    def from_url(
        cls,
        url: str,
        *,
        username: str | None = None,
        password_file: str | None = None,
        ca_file: str | None = None,
        cert_file: str | None = None,
        key_file: str | None = None,
    ) -> MqttSettings:
        """``mqtt://[USER@]HOST[:PORT]`` or ``mqtts://...`` (default ports 1883 / 8883).

        >>> MqttSettings.from_url("mqtt://127.0.0.1:18830").port
        18830
        """
        parts = urlsplit(url)
        if parts.scheme not in ("mqtt", "mqtts") or not parts.hostname:
            raise ConfigError(
                f"bus {url!r} is not mqtt://HOST[:PORT] or mqtts://HOST[:PORT] (or 'memory')"
            )
        if parts.password:
            raise ConfigError(
                "do not put a password in the bus URL (it shows in process lists); "
                f"use --bus-password-file or the {PASSWORD_ENV} environment variable"
            )
        tls = parts.scheme == "mqtts"
        password = os.environ.get(PASSWORD_ENV)
        if password_file:
            try:
                password = Path(password_file).read_text().strip()
            except OSError as exc:
                raise ConfigError(f"{password_file}: cannot read ({exc.strerror})") from exc
        return cls(
            host=parts.hostname,
            port=parts.port or (8883 if tls else 1883),
            tls=tls or ca_file is not None,
            username=username or parts.username,
            password=password,
            ca_file=ca_file,
            cert_file=cert_file,
            key_file=key_file,
        )

    def tls_context(self) -> ssl.SSLContext | None:
        """The TLS context (certificate checks on), or None without TLS."""
        if not self.tls:
            return None
        try:
            ctx = ssl.create_default_context(cafile=self.ca_file)
            if self.cert_file:
                ctx.load_cert_chain(self.cert_file, self.key_file)
        except (OSError, ssl.SSLError) as exc:
            raise ConfigError(f"bus TLS files cannot be used: {exc}") from exc
        return ctx


class MqttBus(Resource):
    """One MQTT endpoint (implements `SwarmBus`).

    Args:
        settings: broker address, credentials, TLS.
        core: receive-side bookkeeping; its ``own_ids`` are the vehicles this process flies.
        rng: jitter of the reconnection backoff.
    """

    def __init__(self, settings: MqttSettings, core: BusCore, rng: random.Random | None = None):
        self.settings, self.core = settings, core
        self.rng = rng or random.Random()
        self._client: aiomqtt.Client | None = None
        self._tls = settings.tls_context()
        self.connected = asyncio.Event()

    def _topic(self, uav: int, kind: str) -> str:
        return topic(self.core.prefix, self.core.swarm, uav, kind)

    def _new_client(self) -> aiomqtt.Client:
        s, core = self.settings, self.core
        ids = "-".join(str(i) for i in sorted(core.own_ids)) or "observer"
        will_uav = min(core.own_ids) if core.own_ids else None
        will = (
            aiomqtt.Will(self._topic(will_uav, "status"), b"offline", qos=1, retain=True)
            if will_uav is not None
            else None
        )
        return aiomqtt.Client(
            s.host,
            s.port,
            username=s.username,
            password=s.password,
            identifier=f"{core.prefix}-{core.swarm}-{ids}",
            will=will,
            keepalive=KEEPALIVE_S,
            timeout=2.0,
            tls_context=self._tls,
            max_queued_incoming_messages=INCOMING_QUEUE,
            clean_session=True,
        )

    async def __aenter__(self) -> Self:
        return self

    async def aclose(self, exc_type: type[BaseException] | None = None) -> None:
        """Forget the client (the receive task owns the connection and closes it)."""
        self._client = None

    async def run(self) -> None:
        """Connect, subscribe, receive; reconnect with backoff and jitter; until cancelled."""
        delay = BACKOFF_FIRST_S
        first = True
        while True:
            try:
                async with self._new_client() as client:
                    for uav in self.core.own_ids:
                        await client.publish(
                            self._topic(uav, "status"), b"online", qos=1, retain=True
                        )
                    await client.subscribe(f"{self.core.prefix}/{self.core.swarm}/uav/+/+", qos=0)
                    self._client = client
                    self.connected.set()
                    if not first:
                        self.core.stats.reconnects += 1
                    first, delay = False, BACKOFF_FIRST_S
                    try:
                        async for message in client.messages:
                            payload = message.payload
                            data = payload if isinstance(payload, bytes) else str(payload).encode()
                            self.core.accept(str(message.topic), data)
                    finally:
                        self._client = None
                        self.connected.clear()
                        await self._say_offline(client)
            except aiomqtt.MqttError:
                self._client = None
                self.connected.clear()
            await asyncio.sleep(delay * self.rng.uniform(0.5, 1.5))
            delay = min(BACKOFF_MAX_S, delay * 2)

    async def _say_offline(self, client: aiomqtt.Client) -> None:
        """A clean goodbye (the will covers the unclean ones)."""
        for uav in self.core.own_ids:
            try:
                await client.publish(
                    self._topic(uav, "status"), b"offline", qos=1, retain=True, timeout=0.5
                )
            except aiomqtt.MqttError:
                return

    async def _publish(self, name: str, payload: bytes) -> None:
        client = self._client
        if client is None:
            self.core.stats.publish_dropped += 1
            return
        try:
            await client.publish(name, payload, qos=0, timeout=PUBLISH_TIMEOUT_S)
        except aiomqtt.MqttError:
            self.core.stats.publish_dropped += 1
            return
        self.core.stats.published += 1

    async def publish_state(self, state: VehicleState) -> None:
        """Publish a state at QoS 0 (dropped and counted while disconnected)."""
        await self._publish(self._topic(state.id, "state"), encode_state(state))

    async def publish_detections(self, detections: Detections) -> None:
        """Publish detections at QoS 0."""
        await self._publish(self._topic(detections.id, "detections"), encode_detections(detections))

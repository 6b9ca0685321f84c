"""The swarm bus's messages: topics, a versioned payload schema, and strict validation.

Topics (``PREFIX`` defaults to ``remarl``)::

    PREFIX/SWARM/uav/ID/status       retained, QoS 1, "online"/"offline" (the MQTT last will)
    PREFIX/SWARM/uav/ID/state        QoS 0, 10 Hz: where the vehicle is and what it is doing
    PREFIX/SWARM/uav/ID/detections   QoS 0, 2 Hz: the ADS-B traffic it sees

Payloads are compact JSON objects with a schema version ``v``: readable with ``mosquitto_sub``
and any language's standard library, no extra dependency, about 200 bytes a state. msgpack
would save about a third, which does not matter at 10 Hz × tens of vehicles, and would make
every broker-side debugging session need a decoder. Every payload is checked against the
schema before it is used: size, JSON, version, types, finite numbers, the sender id in the
topic equal to the one in the payload and part of the mission. Anything else is rejected
with a counted reason (`BusStats`) — the receive loop never raises on input.
"""

from __future__ import annotations

import json
import math
from collections import Counter
from dataclasses import dataclass, field
from typing import Any

SCHEMA_VERSION = 1
"""Payload schema version (``v`` in every payload)."""

MAX_PAYLOAD_BYTES = 8192
"""Larger payloads are rejected unread (a state is ~200 bytes; 40 detections ~4 kB)."""

MAX_DETECTIONS = 64
"""Detections per message at most."""

STATUSES = frozenset(
    {"waiting", "taking-off", "ready", "controlled", "lost", "held", "reached", "pilot"}
)
"""Vehicle statuses a state may carry (`remarl_fc.flight.config.Status` values)."""


class PayloadError(ValueError):
    """A payload that does not follow the schema (the reason is the message)."""


def topic(prefix: str, swarm: str, uav: int | str, kind: str) -> str:
    """``PREFIX/SWARM/uav/ID/KIND``.

    >>> topic("remarl", "alpha", 3, "state")
    'remarl/alpha/uav/3/state'
    """
    return f"{prefix}/{swarm}/uav/{uav}/{kind}"


def parse_topic(name: str, prefix: str, swarm: str) -> tuple[int, str]:
    """(sender id, kind) of a topic under ``PREFIX/SWARM/uav/``; PayloadError otherwise."""
    parts = name.split("/")
    head = [*prefix.split("/"), swarm, "uav"]
    if len(parts) != len(head) + 2 or parts[: len(head)] != head:
        raise PayloadError(f"topic {name!r} is not {'/'.join(head)}/ID/KIND")
    uav, kind = parts[-2], parts[-1]
    if not uav.isdigit() or not 1 <= int(uav) <= 255:
        raise PayloadError(f"topic {name!r}: id {uav!r} is not a system id 1..255")
    if kind not in ("status", "state", "detections"):
        raise PayloadError(f"topic {name!r}: unknown kind {kind!r}")
    return int(uav), kind


@dataclass(frozen=True)
class VehicleState:
    """One vehicle's state on the bus (mission frame: north/east m from the origin).

    Attributes:
        id: system id. seq: sender's sequence number. t: sender's UNIX time, s.
        ne_m: (north, east); height_m above the origin; vel_ned_m_s: (vn, ve, vd).
        yaw_rad; status: a `STATUSES` value.
        ready_ne_m, ready_t: where and when (UNIX s) it became ready to start the swarm
            (None before): every process computes the same swarm start from these.
        arc: the arc its process commands it now, while it is under control (None
            otherwise): (course at the arc's start, rad clockwise from north; turn over the
            arc, rad, clockwise positive; speed, m/s; seconds since the arc started).
    """

    id: int
    seq: int
    t: float
    ne_m: tuple[float, float]
    height_m: float
    vel_ned_m_s: tuple[float, float, float]
    yaw_rad: float
    status: str
    ready_ne_m: tuple[float, float] | None = None
    ready_t: float | None = None
    arc: tuple[float, float, float, float] | None = None


MAX_ARC_TURN_RAD = math.pi
"""An arc turns by at most this much (a policy's turn is a fraction of it)."""

MAX_ARC_AGE_S = 60.0
"""An arc is at most this old (one decision step: a few seconds)."""


@dataclass(frozen=True)
class Detection:
    """An obstacle one vehicle sees: ICAO address, position, height (None unknown), velocity."""

    icao: int
    ne_m: tuple[float, float]
    height_m: float | None
    vel_ne_m_s: tuple[float, float]


@dataclass(frozen=True)
class Detections:
    """A batch of detections from one vehicle."""

    id: int
    seq: int
    t: float
    items: tuple[Detection, ...]


@dataclass
class BusStats:
    """Counters of one bus endpoint (monotonic)."""

    published: int = 0
    publish_dropped: int = 0
    received: int = 0
    accepted: int = 0
    rejected: Counter[str] = field(default_factory=Counter)
    reconnects: int = 0

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        return {
            "published": self.published,
            "publish_dropped": self.publish_dropped,
            "received": self.received,
            "accepted": self.accepted,
            "rejected": dict(self.rejected),
            "reconnects": self.reconnects,
        }


def _r(x: float, digits: int = 3) -> float:
    return round(float(x), digits)


def encode_state(s: VehicleState) -> bytes:
    """Compact JSON of a state."""
    body: dict[str, Any] = {
        "v": SCHEMA_VERSION,
        "id": s.id,
        "seq": s.seq,
        "t": round(s.t, 4),
        "ne": [_r(s.ne_m[0], 2), _r(s.ne_m[1], 2)],
        "h": _r(s.height_m, 2),
        "vel": [_r(v) for v in s.vel_ned_m_s],
        "yaw": _r(s.yaw_rad, 4),
        "st": s.status,
    }
    if s.ready_ne_m is not None and s.ready_t is not None:
        body["rne"] = [_r(s.ready_ne_m[0], 2), _r(s.ready_ne_m[1], 2)]
        body["rt"] = round(s.ready_t, 4)
    if s.arc is not None:
        course, turn, speed, age = s.arc
        body["arc"] = [_r(course, 4), _r(turn, 4), _r(speed), _r(age)]
    return json.dumps(body, separators=(",", ":")).encode()


def encode_detections(d: Detections) -> bytes:
    """Compact JSON of a detection batch."""
    body = {
        "v": SCHEMA_VERSION,
        "id": d.id,
        "seq": d.seq,
        "t": round(d.t, 4),
        "obs": [
            {
                "icao": x.icao,
                "ne": [_r(x.ne_m[0], 2), _r(x.ne_m[1], 2)],
                "h": None if x.height_m is None else _r(x.height_m, 2),
                "vel": [_r(x.vel_ne_m_s[0]), _r(x.vel_ne_m_s[1])],
            }
            for x in d.items[:MAX_DETECTIONS]
        ],
    }
    return json.dumps(body, separators=(",", ":")).encode()


def _load(payload: bytes, sender: int) -> dict[str, Any]:
    if len(payload) > MAX_PAYLOAD_BYTES:
        raise PayloadError("oversized")
    try:
        body = json.loads(payload)
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise PayloadError("not JSON") from exc
    if not isinstance(body, dict):
        raise PayloadError("not a JSON object")
    if body.get("v") != SCHEMA_VERSION:
        raise PayloadError(f"schema version {body.get('v')!r}, expected {SCHEMA_VERSION}")
    if body.get("id") != sender:
        raise PayloadError("id differs from the topic's (spoofed)")
    return body


def _int(body: dict[str, Any], key: str) -> int:
    v = body.get(key)
    if isinstance(v, bool) or not isinstance(v, int) or v < 0:
        raise PayloadError(f"{key} is not a non-negative integer")
    return v


def _num(v: Any, key: str) -> float:
    if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
        raise PayloadError(f"{key} is not a finite number")
    return float(v)


def _vec(body: dict[str, Any], key: str, n: int) -> tuple[float, ...]:
    v = body.get(key)
    if not isinstance(v, list) or len(v) != n:
        raise PayloadError(f"{key} is not a list of {n} numbers")
    return tuple(_num(x, key) for x in v)


def decode_state(payload: bytes, sender: int) -> VehicleState:
    """Validate a state payload from ``sender`` (the id in its topic)."""
    body = _load(payload, sender)
    status = body.get("st")
    if status not in STATUSES:
        raise PayloadError(f"status {status!r} unknown")
    ne = _vec(body, "ne", 2)
    ready_ne = _vec(body, "rne", 2) if "rne" in body else None
    ready_t = _num(body["rt"], "rt") if "rt" in body else None
    if (ready_ne is None) != (ready_t is None):
        raise PayloadError("rne and rt come together")
    vel = _vec(body, "vel", 3)
    if math.hypot(*vel) > 200.0:
        raise PayloadError("velocity above 200 m/s")
    arc = _vec(body, "arc", 4) if "arc" in body else None
    if arc is not None and not (
        abs(arc[1]) <= MAX_ARC_TURN_RAD
        and 0.0 <= arc[2] <= 200.0
        and 0.0 <= arc[3] <= MAX_ARC_AGE_S
    ):
        raise PayloadError(
            f"arc turn beyond ±π, speed outside 0..200 m/s or age outside 0..{MAX_ARC_AGE_S:g} s"
        )
    return VehicleState(
        id=sender,
        seq=_int(body, "seq"),
        t=_num(body.get("t"), "t"),
        ne_m=(ne[0], ne[1]),
        height_m=_num(body.get("h"), "h"),
        vel_ned_m_s=(vel[0], vel[1], vel[2]),
        yaw_rad=_num(body.get("yaw"), "yaw"),
        status=str(status),
        ready_ne_m=None if ready_ne is None else (ready_ne[0], ready_ne[1]),
        ready_t=ready_t,
        arc=None if arc is None else (arc[0], arc[1], arc[2], arc[3]),
    )


def decode_detections(payload: bytes, sender: int) -> Detections:
    """Validate a detections payload from ``sender``."""
    body = _load(payload, sender)
    raw = body.get("obs")
    if not isinstance(raw, list) or len(raw) > MAX_DETECTIONS:
        raise PayloadError(f"obs is not a list of at most {MAX_DETECTIONS}")
    items = []
    for x in raw:
        if not isinstance(x, dict):
            raise PayloadError("a detection is not an object")
        icao = _int(x, "icao")
        ne = _vec(x, "ne", 2)
        vel = _vec(x, "vel", 2)
        h = x.get("h")
        height = None if h is None else _num(h, "h")
        items.append(Detection(icao, (ne[0], ne[1]), height, (vel[0], vel[1])))
    return Detections(sender, _int(body, "seq"), _num(body.get("t"), "t"), tuple(items))

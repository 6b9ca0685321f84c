"""Sans-IO MAVLink 2 codec: bytes in → messages out, messages in → bytes out.

It wraps the parser and encoder pymavlink generates for the ardupilotmega dialect (which
includes common.xml and minimal.xml), chosen explicitly here — nothing reads or writes
environment variables, nothing is global. One `Codec` is one MAVLink identity (system id,
component id, sequence counter, signing state); it keeps one parser per remote address so that
interleaved datagrams from several peers never corrupt each other's framing.

Malformed input never raises: bad bytes, CRC failures and unsigned or badly signed frames (when
signing is on) are counted in `Codec.stats` and dropped, as an autopilot does.
"""

from __future__ import annotations

import base64
import binascii
import time
from collections import Counter
from collections.abc import Callable, Hashable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from pymavlink.dialects.v20 import ardupilotmega as dialect

from remarl_fc.errors import SigningKeyError

Message = Any
"""A decoded or to-be-encoded MAVLink message (pymavlink's generated `MAVLink_message`)."""

SIGNING_KEY_BYTES = 32
"""MAVLink 2 signing secret key length, bytes (SETUP_SIGNING.secret_key)."""

SIGNING_EPOCH_UNIX_S = 1_420_070_400
"""MAVLink 2 signing timestamps count from 2015-01-01T00:00:00Z ..."""

SIGNING_TICK_S = 1e-5
"""... in units of 10 µs (MAVLink 2 message signing specification)."""

MAX_ADDRESSES = 1024
"""Parsers kept per codec (one per remote address); the least recently created is dropped."""


def load_signing_key(path: str | Path) -> bytes:
    """Read a 32-byte signing key: raw bytes, 64 hex digits, or base64, in a file.

    A PX4 key file (32 key bytes + 8 timestamp bytes) is accepted too; its key is used.

    Raises:
        SigningKeyError: the file is missing or holds no 32-byte key.
    """
    p = Path(path)
    try:
        raw = p.read_bytes()
    except OSError as exc:
        raise SigningKeyError(f"cannot read the key file ({exc.strerror})", path=str(p)) from exc
    if len(raw) in (SIGNING_KEY_BYTES, SIGNING_KEY_BYTES + 8):
        return raw[:SIGNING_KEY_BYTES]
    text = raw.strip()
    for decode in (binascii.unhexlify, base64.b64decode):
        try:
            key = decode(text)
        except (ValueError, binascii.Error):
            continue
        if len(key) == SIGNING_KEY_BYTES:
            return key
    raise SigningKeyError(
        f"holds {len(raw)} bytes, not a {SIGNING_KEY_BYTES}-byte key as raw bytes, 64 hex "
        'digits or base64; make one with: python -c "import os;print(os.urandom(32).hex())"',
        path=str(p),
    )


def signing_timestamp_now() -> int:
    """The current MAVLink signing timestamp (10 µs units since 2015-01-01, wall clock)."""
    return int((time.time() - SIGNING_EPOCH_UNIX_S) / SIGNING_TICK_S)


@dataclass(frozen=True)
class SigningConfig:
    """MAVLink 2 signing of one codec.

    Attributes:
        key: the 32-byte secret key.
        link_id: this side's link id in the signature.
        sign_outgoing: sign every frame this codec encodes.
        allow_unsigned: message ids accepted without a valid signature; everything else
            unsigned or badly signed is rejected (counted, dropped).
    """

    key: bytes
    link_id: int = 0
    sign_outgoing: bool = True
    allow_unsigned: frozenset[int] = frozenset()

    def __post_init__(self) -> None:
        if len(self.key) != SIGNING_KEY_BYTES:
            raise ValueError(f"a signing key has {SIGNING_KEY_BYTES} bytes, not {len(self.key)}")
        if not 0 <= self.link_id <= 255:
            raise ValueError(f"link_id {self.link_id} is outside 0..255")


@dataclass
class CodecStats:
    """Counters of one codec (monotonic, never reset).

    The incoming ones in the order a frame meets them: parsed, signature checked, delivered.
    """

    sent: int = 0
    """Frames encoded."""
    reasons: Counter[str] = field(default_factory=Counter)
    """Invalid frames skipped, by reason."""
    rejected_unsigned: int = 0
    """Valid frames dropped for a missing or bad signature."""
    received: int = 0
    """Messages delivered."""

    @property
    def bad_frames(self) -> int:
        """Invalid frames skipped, for any reason."""
        return self.reasons.total()


class _Sink:
    """The `file` pymavlink's MAVLink object writes to; we take bytes from `pack` instead."""

    def write(self, data: bytes) -> None:  # pragma: no cover - never called: we use pack()
        raise RuntimeError("Codec encodes with pack(); nothing writes to the sink")


class Codec:
    """One MAVLink 2 identity: encodes its messages, decodes what its peers send.

    Args:
        system_id: this side's system id (1–255).
        component_id: this side's component id (0–255).
        signing: signing settings, or None for unsigned MAVLink 2.

    >>> a, b = Codec(1, 1), Codec(255, 190)
    >>> frame = a.encode(a.factory.heartbeat_encode(2, 3, 81, 4, 3))
    >>> [m.get_type() for m in b.decode(frame, "vehicle")]
    ['HEARTBEAT']
    """

    def __init__(
        self, system_id: int, component_id: int, *, signing: SigningConfig | None = None
    ) -> None:
        if not 1 <= system_id <= 255:
            raise ValueError(f"system id {system_id} is outside 1..255")
        if not 0 <= component_id <= 255:
            raise ValueError(f"component id {component_id} is outside 0..255")
        self.system_id, self.component_id = system_id, component_id
        self.signing = signing
        self.stats = CodecStats()
        self._encoder = self._new_mavlink()
        if signing is not None:
            self._encoder.signing.sign_outgoing = signing.sign_outgoing
        self._parsers: dict[Hashable, Any] = {}

    @property
    def factory(self) -> Any:
        """Pymavlink's message constructors (``factory.heartbeat_encode(...)``), never sending."""
        return self._encoder

    def _new_mavlink(self) -> Any:
        mav = dialect.MAVLink(_Sink(), srcSystem=self.system_id, srcComponent=self.component_id)
        mav.robust_parsing = True
        if self.signing is not None:
            allowed = self.signing.allow_unsigned
            mav.signing.secret_key = self.signing.key
            mav.signing.link_id = self.signing.link_id
            mav.signing.timestamp = signing_timestamp_now()
            mav.signing.allow_unsigned_callback = _allow(allowed)
        return mav

    def encode(self, message: Message, *, source_component: int | None = None) -> bytes:
        """Frame a message: next sequence number, CRC, signature when signing is on.

        Args:
            message: a message from `factory` (``codec.factory.heartbeat_encode(...)``).
            source_component: send as another component of this system (the mock's ADS-B
                receiver is component 156); default this codec's.
        """
        mav = self._encoder
        if source_component is not None:
            mav.srcComponent = source_component
        try:
            frame: bytes = message.pack(mav)
        finally:
            mav.srcComponent = self.component_id
        mav.seq = (mav.seq + 1) % 256
        self.stats.sent += 1
        return frame

    def decode(
        self, data: bytes, address: Hashable = None, *, datagram: bool = False
    ) -> list[Message]:
        """Every whole, valid message in ``data`` from the peer at ``address``.

        On a byte stream (TCP, serial) the bytes of an incomplete frame wait in that peer's
        parser for the next call. A ``datagram`` (UDP) holds whole frames only: what is left
        over is dropped, so a stray start byte cannot swallow the peer's next datagrams.
        Invalid frames are counted and skipped.
        """
        parser = self._parsers.get(address)
        if parser is None:
            if len(self._parsers) >= MAX_ADDRESSES:
                self._parsers.pop(next(iter(self._parsers)))
            parser = self._parsers[address] = self._new_mavlink()
        rejected_before = parser.signing.reject_count
        try:
            found = parser.parse_buffer(data) or []
        except dialect.MAVError as exc:  # robust parsing returns BAD_DATA; this is a backstop
            self._count_bad(str(exc))
            return []
        out = []
        for msg in found:
            if msg.get_type() == "BAD_DATA":
                self._count_bad(str(getattr(msg, "reason", "bad data")))
            else:
                out.append(msg)
        if datagram and parser.buf_len() > 0:
            self._count_bad("incomplete frame at the end of a datagram")
            parser.buf, parser.buf_index = bytearray(), 0
            parser.expected_length = dialect.HEADER_LEN_V1 + 2
        self.stats.rejected_unsigned += parser.signing.reject_count - rejected_before
        self.stats.received += len(out)
        return out

    def _count_bad(self, reason: str) -> None:
        self.stats.reasons[reason] += 1


def _allow(allowed: frozenset[int]) -> Callable[[Any, int], bool]:
    def callback(_mav: Any, msg_id: int) -> bool:
        return msg_id in allowed

    return callback

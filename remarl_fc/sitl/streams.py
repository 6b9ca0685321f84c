"""Which telemetry messages a mock vehicle sends, and when.

A `StreamSchedule` keeps one vehicle's message intervals — the flavour's defaults, changed by
MAV_CMD_SET_MESSAGE_INTERVAL and REQUEST_DATA_STREAM — and the one-shot messages asked for
with MAV_CMD_REQUEST_MESSAGE or MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES; it answers those
commands and requests, and the fleet asks it every physics tick which messages are due.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from typing import Any

from remarl_fc.mavlink.consts import MavResult, MsgId
from remarl_fc.sitl.commands import Command
from remarl_fc.sitl.flavour import Result

MAX_INTERVAL_HZ = 50.0
"""Highest message rate a stream can be set to (the physics rate caps it anyway)."""

SUPPORTED_STREAMS = frozenset(
    {
        MsgId.SYS_STATUS,
        MsgId.GPS_RAW_INT,
        MsgId.ATTITUDE,
        MsgId.LOCAL_POSITION_NED,
        MsgId.GLOBAL_POSITION_INT,
        MsgId.POSITION_TARGET_LOCAL_NED,
        MsgId.HOME_POSITION,
        MsgId.EXTENDED_SYS_STATE,
        MsgId.ADSB_VEHICLE,
    }
)
"""Messages both flavours stream on request (a flavour may add its own).

ADSB_VEHICLE is the traffic the vehicle relays: ArduCopter SITL ACKs SET_MESSAGE_INTERVAL for
it (0, ACCEPTED) and then sends its ADS-B list at that interval; PX4 streams it as any of its
MAVLink streams."""


class StreamSchedule:
    """One vehicle's streams: message id → interval, the next due times, one-shot requests.

    Args:
        defaults: message id → interval s streamed before anyone asks (the flavour's).
        supported: messages a GCS may ask to stream.
        groups: REQUEST_DATA_STREAM ids → messages (empty: such requests change nothing).
    """

    def __init__(
        self,
        defaults: Mapping[int, float],
        supported: frozenset[int] = SUPPORTED_STREAMS,
        groups: Mapping[int, tuple[int, ...]] | None = None,
    ) -> None:
        self.defaults, self.supported, self.groups = defaults, supported, groups or {}
        self.interval_s: dict[int, float] = dict(defaults)
        self.due_s: dict[int, float] = {}
        self.requested: list[int] = []
        """One-shot messages to send with the next telemetry (after the command's ACK)."""

    def set_interval(self, msg_id: int, interval_s: float | None, now_s: float) -> None:
        """Stream ``msg_id`` every ``interval_s`` from now (None: stop)."""
        if interval_s is None:
            self.interval_s.pop(msg_id, None)
            self.due_s.pop(msg_id, None)
            return
        self.interval_s[msg_id] = max(interval_s, 1.0 / MAX_INTERVAL_HZ)
        self.due_s[msg_id] = now_s

    def first_due(self, msg_id: int, at_s: float) -> None:
        """Send the next ``msg_id`` at ``at_s`` (simulated s), then at its interval."""
        self.due_s[msg_id] = at_s

    def set_default(self, msg_id: int, now_s: float) -> None:
        """Back to the flavour's default for ``msg_id`` (off where it streams none)."""
        self.set_interval(msg_id, self.defaults.get(msg_id), now_s)

    def set_rate(self, msg_ids: Iterable[int], rate_hz: int, start: bool, now_s: float) -> None:
        """REQUEST_DATA_STREAM's effect: every message at ``rate_hz``, or off."""
        for msg_id in msg_ids:
            if start and rate_hz > 0:
                self.set_interval(msg_id, 1.0 / rate_hz, now_s)
            else:
                self.set_interval(msg_id, None, now_s)

    def due(self, now_s: float) -> list[int]:
        """Message ids due now, in the order they were turned on (their next time advances)."""
        due = []
        for mid, interval in self.interval_s.items():
            t = self.due_s.get(mid, now_s)
            if now_s + 1e-9 >= t:
                due.append(mid)
                nxt = t + interval
                self.due_s[mid] = nxt if nxt > now_s else now_s + interval
        return due

    def take_requested(self) -> list[int]:
        """The one-shot messages asked for since the last call (and forget them)."""
        requested, self.requested = self.requested, []
        return requested

    # -- the requests that change it ------------------------------------------------------

    def cmd_set_message_interval(self, cmd: Command, now_s: float) -> Result:
        """MAV_CMD_SET_MESSAGE_INTERVAL: p1 message id, p2 µs (−1 off, 0 default)."""
        msg_id, interval_us = cmd.int_param(0, 0, 2**24 - 1), cmd.params[1]
        if msg_id not in self.supported:
            return MavResult.FAILED, ""
        if interval_us < 0:
            self.set_interval(msg_id, None, now_s)
        elif interval_us == 0:
            self.set_default(msg_id, now_s)
        else:
            self.set_interval(msg_id, interval_us * 1e-6, now_s)
        return MavResult.ACCEPTED, ""

    def cmd_request_message(self, cmd: Command, now_s: float) -> Result:
        """MAV_CMD_REQUEST_MESSAGE: p1 message id, sent once after the ACK."""
        msg_id = cmd.int_param(0, 0, 2**24 - 1)
        if msg_id not in self.supported | {MsgId.AUTOPILOT_VERSION}:
            return MavResult.UNSUPPORTED, ""
        self.requested.append(msg_id)
        return MavResult.ACCEPTED, ""

    def cmd_request_capabilities(self, cmd: Command, now_s: float) -> Result:
        """MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES: AUTOPILOT_VERSION follows the ACK."""
        self.requested.append(MsgId.AUTOPILOT_VERSION)
        return MavResult.ACCEPTED, ""

    def on_request_data_stream(self, msg: Any, now_s: float) -> None:
        """REQUEST_DATA_STREAM: every message of the group(s) to req_message_rate Hz.

        Group 0 is every group; a group without messages changes nothing.
        """
        stream = int(msg.req_stream_id)
        ids = self.groups.keys() if stream == 0 else [stream]
        messages = [mid for g in ids for mid in self.groups.get(g, ())]
        self.set_rate(messages, int(msg.req_message_rate), msg.start_stop, now_s)

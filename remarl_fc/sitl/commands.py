"""The command protocol of a mock vehicle: COMMAND_LONG and COMMAND_INT in one form, one ACK.

`Command.from_message` normalises either message (COMMAND_INT's x/y become params 5/6, z
param 7, and its frame is kept); a handler takes a `Command` and the simulated time and
returns a `remarl_fc.sitl.flavour.Result`. `CommandServer` is one vehicle's end of the
protocol: every command addressed to it gets exactly one COMMAND_ACK, back to its sender.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

from remarl_fc.mavlink.consts import ARM_FORCE_MAGIC, MavCmd, MavResult, MsgId, Severity
from remarl_fc.sitl.channel import Channel
from remarl_fc.sitl.flavour import Result

Params7 = tuple[float, float, float, float, float, float, float]


@dataclass(frozen=True)
class Command:
    """A COMMAND_LONG or COMMAND_INT, normalised (COMMAND_INT x/y → params 5/6, z → 7)."""

    command: int
    params: Params7
    frame: int | None  # None for COMMAND_LONG
    source: tuple[int, int]

    @classmethod
    def from_message(cls, msg: Any) -> Command:
        """Normalise a decoded COMMAND_LONG or COMMAND_INT."""
        src = (msg.get_srcSystem(), msg.get_srcComponent())
        if msg.get_msgId() == MsgId.COMMAND_LONG:
            p = (msg.param1, msg.param2, msg.param3, msg.param4, msg.param5, msg.param6)
            return cls(int(msg.command), (*p, msg.param7), None, src)
        p = (msg.param1, msg.param2, msg.param3, msg.param4, float(msg.x), float(msg.y))
        return cls(int(msg.command), (*p, msg.z), int(msg.frame), src)

    @property
    def name(self) -> str:
        """MAV_CMD name, or the number of a command MAVLink's common set does not name."""
        try:
            return MavCmd(self.command).name
        except ValueError:
            return str(self.command)

    def int_param(self, k: int, low: int = 0, high: int = 2**32 - 1) -> int:
        """Parameter ``k`` (0-based) truncated to an integer (a C cast), within ``[low, high]``.

        Raises:
            BadParameter: it is NaN, infinite or out of range (the command is then answered
                DENIED, as an autopilot refuses a malformed command, instead of the mock
                failing).
        """
        value = self.params[k]
        if not math.isfinite(value) or not low <= value <= high:
            raise BadParameter(f"param{k + 1} {value:g} invalid (not in {low}..{high})")
        return int(value)

    def frame_in(self, allowed: tuple[int, ...]) -> bool:
        """COMMAND_INT frame check (COMMAND_LONG has no frame and passes)."""
        return self.frame is None or self.frame in allowed


class BadParameter(ValueError):
    """A command parameter that cannot be what the command needs (see `Command.int_param`)."""


Handler = Callable[[Command, float], Result]
"""A command handler: (command, simulated time) → (MAV_RESULT, STATUSTEXT or "")."""


def forced(param2: float) -> bool:
    """Whether COMPONENT_ARM_DISARM p2 is the force magic (21196).

    NaN (an unset parameter, as MAVSDK and PX4's own commands send it) is not: ArduPilot
    compares floats and PX4 rounds p2; neither converts NaN to a number.

    >>> forced(21196.0), forced(float("nan")), forced(0.0)
    (True, False, False)
    """
    return abs(param2 - ARM_FORCE_MAGIC) < 0.5


class CommandServer:
    """One vehicle's end of the command protocol.

    Args:
        channel: how the vehicle answers; it counts commands and results by name.
    """

    def __init__(self, channel: Channel) -> None:
        self.channel = channel

    def handle(self, msg: Any, handlers: Mapping[int, Handler], now_s: float) -> None:
        """Run the command's handler: one COMMAND_ACK, then its STATUSTEXT if it has one.

        A command without a handler is UNSUPPORTED. The STATUSTEXT is INFO after an
        ACCEPTED, CRITICAL after a refusal.
        """
        cmd = Command.from_message(msg)
        ch = self.channel
        ch.counters.commands[cmd.name] += 1
        handler = handlers.get(cmd.command)
        if handler is None:
            result, text = int(MavResult.UNSUPPORTED), ""
        else:
            try:
                result, text = handler(cmd, now_s)
            except BadParameter as exc:
                result, text = int(MavResult.DENIED), f"{cmd.name}: {exc}"
        ch.counters.results[MavResult(result).name] += 1
        ch.emit(
            ch.factory.command_ack_encode(
                cmd.command, int(result), 0, 0, cmd.source[0], cmd.source[1]
            )
        )
        if text:
            severity = Severity.INFO if result == MavResult.ACCEPTED else Severity.CRITICAL
            ch.say(severity, text)

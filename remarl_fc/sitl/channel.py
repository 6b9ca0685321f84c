"""One mock vehicle's side of its MAVLink conversation: how it answers, what it counted.

`Channel` bundles what the vehicle's protocol handlers (`remarl_fc.sitl.autopilot`,
`remarl_fc.sitl.commands.CommandServer`, `remarl_fc.sitl.params.ParamServer`) share: the
message factory that builds replies, the callback that sends them to the vehicle's peers, and
the `Counters` of what the vehicle received and did with it (which go into the ground-truth
summary). A leaf module: the fleet wires the sending, the handlers only use it.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

Emit = Callable[[Any], None]
"""Sends one message to the vehicle's peers."""


@dataclass
class Counters:
    """What one vehicle received and did with it (goes into the ground-truth summary)."""

    setpoints_received: int = 0
    setpoints_applied: int = 0
    ignored_reasons: Counter[str] = field(default_factory=Counter)
    """Setpoints ignored, by reason."""
    commands: Counter[str] = field(default_factory=Counter)
    results: Counter[str] = field(default_factory=Counter)
    params_set: Counter[str] = field(default_factory=Counter)
    params_refused: Counter[str] = field(default_factory=Counter)
    params_unknown: Counter[str] = field(default_factory=Counter)

    @property
    def setpoints_ignored(self) -> int:
        """Setpoints ignored, for any reason."""
        return self.ignored_reasons.total()

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        return {
            "setpoints_received": self.setpoints_received,
            "setpoints_applied": self.setpoints_applied,
            "setpoints_ignored": self.setpoints_ignored,
            "setpoints_ignored_by_reason": dict(self.ignored_reasons),
            "commands": dict(self.commands),
            "command_results": dict(self.results),
            "params_set": dict(self.params_set),
            "params_refused": dict(self.params_refused),
            "params_unknown": dict(self.params_unknown),
        }


def statustext(factory: Any, severity: int, text: str) -> Any:
    """STATUSTEXT (253): at most 50 characters, as the autopilots send single chunks."""
    return factory.statustext_encode(severity, text[:50].encode("ascii", "replace"))


@dataclass
class Channel:
    """How one vehicle answers, and what it counts.

    Attributes:
        factory: the vehicle's MAVLink message factory (its system and component ids).
        emit: sends one message to the vehicle's peers.
        counters: what the vehicle received and did with it.
    """

    factory: Any
    emit: Emit
    counters: Counters = field(default_factory=Counters)

    def say(self, severity: int, text: str) -> None:
        """Send a STATUSTEXT."""
        self.emit(statustext(self.factory, severity, text))

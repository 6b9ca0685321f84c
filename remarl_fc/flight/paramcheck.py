"""Pre-flight check of the autopilot parameters that decide what happens when `fly` fails.

Before anything is armed, `fly` reads a handful of parameters from every vehicle
(PARAM_REQUEST_READ → PARAM_VALUE; harmless, so also in a dry run) and judges them against the
flight it is about to make:

- **errors** stop the flight: a setpoint timeout shorter than two setpoint periods would drop
  the vehicle out of external control between two setpoints (PX4 ``COM_OF_LOSS_T``) or stop it
  between them (ArduPilot ``GUID_TIMEOUT``);
- **warnings** are events in the status and the log: a failsafe that needs the pilot on the
  sticks, or none at all, where FLYING.md §4.1 asks for one.

A parameter the vehicle does not answer for (a renamed one in another firmware, or the mock,
which serves only those it models) is reported as not read, never guessed.
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any, Literal

from remarl_fc.mavlink.consts import MavComponent
from remarl_fc.mavlink.params import from_wire, param_name

PARAM_READ_TIMEOUT_S = 1.0
"""Wait this long (flight clock) for the PARAM_VALUEs of one round of requests."""

PARAM_READ_ATTEMPTS = 3
"""Rounds of PARAM_REQUEST_READ for the parameters still unanswered."""

SETPOINT_PERIODS_MIN = 2.0
"""A setpoint timeout must cover at least this many setpoint periods (one lost setpoint must
not end external control)."""

GUID_TIMEOUT_MAX_S = 3.0
"""Longest GUID_TIMEOUT without a warning: ArduCopter's default, s."""

ARDUPILOT_CHECKED = ("GUID_TIMEOUT", "FS_GCS_ENABLE", "AVD_ENABLE", "AVD_F_ACTION", "FENCE_ENABLE")
"""ArduCopter parameters read before a flight."""

PX4_CHECKED = ("COM_OF_LOSS_T", "COM_OBL_RC_ACT", "NAV_DLL_ACT", "COM_RC_IN_MODE", "GF_ACTION")
"""PX4 parameters read before a flight."""

PX4_OFFBOARD_LOSS_ACTIONS = {0: "Position", 1: "Altitude", 2: "Manual", 3: "Return", 4: "Land"}
"""COM_OBL_RC_ACT options (PX4 v1.14+) that the checks name; 5 is Hold."""

PILOT_ACTIONS = frozenset({0, 1, 2})
"""COM_OBL_RC_ACT options that hand the vehicle to the sticks."""

Level = Literal["error", "warning"]


@dataclass(frozen=True)
class Finding:
    """One judged parameter: ``error`` stops the flight, ``warning`` is logged."""

    level: Level
    text: str


@dataclass(frozen=True)
class Readout:
    """What one vehicle answered: values by name, and the names it did not answer for."""

    values: Mapping[str, float]
    unread: tuple[str, ...]


Rule = Callable[[Mapping[str, float], float], Finding | None]
"""Judges one aspect of a vehicle's parameters, given the setpoint period (s)."""


def checked_names(px4: bool) -> tuple[str, ...]:
    """The parameters read from a vehicle of this autopilot."""
    return PX4_CHECKED if px4 else ARDUPILOT_CHECKED


def check_params(
    values: Mapping[str, float], *, px4: bool, setpoint_period_s: float
) -> list[Finding]:
    """Judge the parameters read from one vehicle (missing ones are not judged)."""
    rules = _px4_rules if px4 else _ardupilot_rules
    found = (rule(values, setpoint_period_s) for rule in rules)
    return [f for f in found if f is not None]


def _timeout_rule(name: str, default_s: float, what: str) -> Rule:
    def rule(values: Mapping[str, float], period_s: float) -> Finding | None:
        timeout_s = values.get(name)
        least = SETPOINT_PERIODS_MIN * period_s
        if timeout_s is None or timeout_s >= least:
            return None
        return Finding(
            "error",
            f"{name} {timeout_s:g} s is under two setpoint periods ({least:g} s): {what}; "
            f"raise it (default {default_s:g} s)",
        )

    return rule


def _guid_timeout_long(values: Mapping[str, float], period_s: float) -> Finding | None:
    timeout_s = values.get("GUID_TIMEOUT")
    if timeout_s is None or timeout_s <= GUID_TIMEOUT_MAX_S:
        return None
    return Finding(
        "warning",
        f"GUID_TIMEOUT {timeout_s:g} s: a vehicle keeps its last velocity that long after fly "
        f"stops; {GUID_TIMEOUT_MAX_S:g} s or less",
    )


def _equals(name: str, bad: float, text: str) -> Rule:
    def rule(values: Mapping[str, float], period_s: float) -> Finding | None:
        value = values.get(name)
        if value is None or value != bad:
            return None
        return Finding("warning", f"{name} {value:g}: {text}")

    return rule


def _avoidance_action(values: Mapping[str, float], period_s: float) -> Finding | None:
    action = values.get("AVD_F_ACTION")
    if values.get("AVD_ENABLE") != 1 or action is None or action < 2:
        return None
    return Finding(
        "warning",
        f"AVD_F_ACTION {action:g}: ADS-B avoidance would switch the vehicle to AVOID_ADSB, "
        "out of GUIDED, releasing it mid-flight; use 0 or 1 (report only)",
    )


def _offboard_loss_action(values: Mapping[str, float], period_s: float) -> Finding | None:
    action = values.get("COM_OBL_RC_ACT")
    if action is None or int(action) not in PILOT_ACTIONS:
        return None
    name = PX4_OFFBOARD_LOSS_ACTIONS[int(action)]
    return Finding(
        "warning",
        f"COM_OBL_RC_ACT {action:g} ({name}): after an offboard loss the vehicle needs the "
        "pilot on the sticks; without one use 5 (Hold) or 4 (Land)",
    )


_ardupilot_rules: tuple[Rule, ...] = (
    _timeout_rule("GUID_TIMEOUT", 3.0, "the vehicle would stop between setpoints"),
    _guid_timeout_long,
    _equals(
        "FS_GCS_ENABLE",
        0,
        "no GCS failsafe: a vehicle that hears neither fly nor a ground station keeps going",
    ),
    _avoidance_action,
    _equals("FENCE_ENABLE", 0, "no fence: nothing stops a vehicle if fly misbehaves"),
)

_px4_rules: tuple[Rule, ...] = (
    _timeout_rule("COM_OF_LOSS_T", 1.0, "OFFBOARD would be lost between setpoints"),
    _offboard_loss_action,
    _equals("NAV_DLL_ACT", 0, "losing the data link does nothing; use Hold, Return or Land"),
    _equals("COM_RC_IN_MODE", 4, "stick input disabled: the pilot could not take over"),
    _equals("GF_ACTION", 0, "the geofence does nothing when breached"),
)


class ParamReader:
    """Reads parameters by name from the flight's vehicles.

    Args:
        send: sends a message to a vehicle (`remarl_fc.flight.commands.Commander.send` with
            ``harmless=True``: a read changes nothing).
        factory: the MAVLink message factory of the flight's codec.
        timeout: the flight clock's ``timeout`` (`remarl_fc.flight.config.Clock.timeout`).
    """

    def __init__(
        self,
        send: Callable[[int, Any], object],
        factory: Any,
        timeout: Callable[[float], asyncio.Timeout],
    ) -> None:
        self.send, self.factory, self.timeout = send, factory, timeout
        self._waiting: dict[tuple[int, str], asyncio.Future[float]] = {}

    def on_value(self, system_id: int, msg: Any, *, bytewise: bool) -> None:
        """A PARAM_VALUE from ``system_id`` (PX4 encodes integers byte-wise)."""
        name = param_name(msg.param_id)
        fut = self._waiting.get((system_id, name))
        if fut is not None and not fut.done():
            fut.set_result(
                from_wire(float(msg.param_value), int(msg.param_type), bytewise=bytewise)
            )

    async def read(self, system_id: int, names: tuple[str, ...]) -> Readout:
        """Ask ``system_id`` for ``names``.

        Up to `PARAM_READ_ATTEMPTS` rounds of `PARAM_READ_TIMEOUT_S` each, re-asking only for
        what is still missing.
        """
        values: dict[str, float] = {}
        loop = asyncio.get_running_loop()
        for _ in range(PARAM_READ_ATTEMPTS):
            missing = [n for n in names if n not in values]
            if not missing:
                break
            futs: dict[str, asyncio.Future[float]] = {}
            for name in missing:
                futs[name] = self._waiting[(system_id, name)] = loop.create_future()
                self.send(
                    system_id,
                    self.factory.param_request_read_encode(
                        system_id, MavComponent.AUTOPILOT1, name.encode("ascii"), -1
                    ),
                )
            try:
                async with self.timeout(PARAM_READ_TIMEOUT_S):
                    await asyncio.wait(futs.values())
            except TimeoutError:
                pass  # the ones that came are kept; the rest are asked for again
            finally:
                for name in futs:
                    self._waiting.pop((system_id, name), None)
            values.update({n: f.result() for n, f in futs.items() if f.done()})
        return Readout(values, tuple(n for n in names if n not in values))

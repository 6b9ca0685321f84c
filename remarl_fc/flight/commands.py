"""Commands to the vehicles: COMMAND_LONG with retries, mode changes, deadline-bound waits.

A command is retried until its COMMAND_ACK; a mode change is sent in each autopilot's encoding
and confirmed by the next HEARTBEAT.

Every wait runs on the flight's `Clock` (monotonic) and raises: `LinkTimeout` when no answer
comes, `CommandRejected` (with the vehicle's STATUSTEXT reason) when the answer is a refusal.
In a dry run only the read-only commands (`READ_ONLY_COMMANDS`) are sent.
"""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import Callable
from typing import Any

from remarl_fc.errors import CommandRejected, LinkTimeout
from remarl_fc.flight.config import Clock, FlyConfig, Member
from remarl_fc.mavlink.codec import Codec
from remarl_fc.mavlink.consts import (
    CopterMode,
    LandedState,
    MavCmd,
    MavComponent,
    MavModeFlag,
    MavResult,
    Px4AutoSubMode,
    Px4MainMode,
    px4_mode_parts,
)
from remarl_fc.mavlink.link import MavlinkLink

READ_ONLY_COMMANDS = frozenset({MavCmd.SET_MESSAGE_INTERVAL, MavCmd.REQUEST_MESSAGE})
"""Commands that change nothing on the vehicle: sent even in a dry run (telemetry is needed)."""

ACK_TIMEOUT_S = 1.0
"""Wait for one COMMAND_ACK before retrying, s."""

ACK_RETRIES = 5
"""Attempts per command (COMMAND_LONG.confirmation counts them): at 10 % loss each way an
attempt fails 19 % of the time, five in a row 0.02 %."""

REASON_WAIT_S = 0.2
"""After a refusal, wait this long for the STATUSTEXT that explains it (it may follow the ACK)."""

EFFECT_WAIT_S = 1.5
"""After every ACK was lost, wait this long for the command's effect to show."""

MODE_CONFIRM_S = 3.0
"""Wait this long for a HEARTBEAT in the mode just set."""

POLL_S = 0.05
"""`Commander.wait_until` checks its condition this often (clock seconds)."""


class Commander:
    """The flight's command channel to its vehicles.

    Args:
        cfg: the flight's settings (dry run, hold mode, connections named in errors).
        codec: encodes the commands (the controller's ids, signing).
        clock: the flight's clock: every deadline is on it.
        links: the open links, filled by the runtime as it opens them (a vehicle whose link is
            not known yet is sent the command on every link).
    """

    def __init__(
        self, cfg: FlyConfig, codec: Codec, clock: Clock, links: list[MavlinkLink]
    ) -> None:
        self.cfg, self.codec, self.clock, self.links = cfg, codec, clock, links
        self._acks: dict[tuple[int, int], asyncio.Future[Any]] = {}

    def on_ack(self, system_id: int, msg: Any) -> None:
        """A COMMAND_ACK from ``system_id``: completes the command waiting for it."""
        fut = self._acks.get((system_id, int(msg.command)))
        if fut is not None and not fut.done():
            fut.set_result(msg)

    def send(self, member: Member, msg: Any, *, harmless: bool = False) -> bool:
        """Send ``msg`` to ``member`` (not in a dry run unless ``harmless``); True if sent."""
        if self.cfg.dry_run and not harmless:
            return False
        links = [member.link] if member.link is not None else self.links
        return any(link.send(msg, member.system_id) for link in links)

    async def command(
        self,
        member: Member,
        cmd: int,
        *params: float,
        done: Callable[[], bool] | None = None,
    ) -> None:
        """COMMAND_LONG with retries; returns on ACCEPTED.

        ``done`` tells whether the command's effect is already visible: a retry refused
        because the first attempt worked (its ACK was lost) — e.g. NAV_TAKEOFF while already
        climbing — then counts as accepted.

        Raises:
            CommandRejected: any other result (with the vehicle's STATUSTEXT reason).
            LinkTimeout: no ACK after `ACK_RETRIES` attempts.
        """
        harmless = cmd in READ_ONLY_COMMANDS
        if self.cfg.dry_run and not harmless:
            return
        p = [*params, *([0.0] * (7 - len(params)))]
        key = (member.system_id, cmd)
        sent_at = self.clock.now()
        for attempt in range(ACK_RETRIES):
            fut: asyncio.Future[Any] = asyncio.get_running_loop().create_future()
            self._acks[key] = fut
            msg = self.codec.factory.command_long_encode(
                member.system_id, MavComponent.AUTOPILOT1, cmd, attempt, *p
            )
            self.send(member, msg, harmless=harmless)
            try:
                async with self.clock.timeout(ACK_TIMEOUT_S):
                    ack = await fut
            except TimeoutError:
                continue
            finally:
                self._acks.pop(key, None)
            if ack.result == MavResult.ACCEPTED or (attempt > 0 and done is not None and done()):
                return
            await self.clock.sleep(REASON_WAIT_S)
            raise CommandRejected(
                command=cmd,
                command_name=enum_name(MavCmd, cmd),
                result=int(ack.result),
                result_name=enum_name(MavResult, int(ack.result)),
                system_id=member.system_id,
                reason=member.track.last_text(sent_at),
            )
        if done is not None:  # every ACK lost: the effect may still be there
            with contextlib.suppress(LinkTimeout):
                await self.wait_until("the command's effect", done, EFFECT_WAIT_S)
                return
        raise LinkTimeout(
            link=self.cfg.connections[0],
            waited_for=f"COMMAND_ACK of {enum_name(MavCmd, cmd)} from vehicle {member.system_id}",
            timeout_s=ACK_TIMEOUT_S * ACK_RETRIES,
        )

    async def wait_until(self, what: str, pred: Callable[[], bool], timeout_s: float) -> None:
        """Poll ``pred`` until true; raise `LinkTimeout` naming ``what`` after ``timeout_s``."""
        try:
            async with self.clock.timeout(timeout_s):
                while not pred():
                    await self.clock.sleep(POLL_S)
        except TimeoutError as exc:
            raise LinkTimeout(
                link=", ".join(self.cfg.connections), waited_for=what, timeout_s=timeout_s
            ) from exc

    async def set_mode(self, member: Member, mode: str) -> None:
        """DO_SET_MODE in the vehicle's encoding, confirmed by the next HEARTBEAT.

        ``mode``: "external" (GUIDED / OFFBOARD) or "hold" (`FlyConfig.hold` on ArduPilot,
        AUTO.LOITER on PX4).
        """
        t = member.track
        if mode == "hold" and not t.is_px4:
            mode = self.cfg.hold
        params, check = mode_command(t.is_px4, mode)
        await self.command(member, MavCmd.DO_SET_MODE, *params, done=lambda: check(t.custom_mode))
        if not self.cfg.dry_run:
            await self.wait_until(
                f"vehicle {member.system_id} HEARTBEAT in {mode}",
                lambda: check(t.custom_mode),
                MODE_CONFIRM_S,
            )

    async def hold(self, member: Member) -> str:
        """The hold mode; a vehicle still armed on the ground is disarmed instead.

        Returns:
            What was done, for the event log.
        """
        t = member.track
        if t.armed and t.landed_state == LandedState.ON_GROUND:
            disarm = MavCmd.COMPONENT_ARM_DISARM
            await self.command(member, disarm, 0, done=lambda: not t.armed)
            return "on the ground: disarmed"
        await self.set_mode(member, "hold")
        return "holding"


def enum_name(enum_cls: Any, value: int) -> str:
    """The member name of ``value`` in ``enum_cls``, else the number."""
    try:
        return str(enum_cls(value).name)
    except ValueError:
        return str(value)


def mode_command(px4: bool, mode: str) -> tuple[tuple[float, ...], Callable[[int], bool]]:
    """(DO_SET_MODE params, HEARTBEAT.custom_mode check) for a mode.

    ``mode``: "external" or "hold" (PX4); "external", "brake" or "loiter" (ArduPilot).
    """
    if px4:
        main, sub = {
            "external": (Px4MainMode.OFFBOARD, 0),
            "hold": (Px4MainMode.AUTO, Px4AutoSubMode.LOITER),
        }[mode]
        return (float(MavModeFlag.CUSTOM_MODE_ENABLED), float(main), float(sub)), (
            lambda cm: px4_mode_parts(cm) == (main, sub)
        )
    number = {
        "external": CopterMode.GUIDED,
        "brake": CopterMode.BRAKE,
        "loiter": CopterMode.LOITER,
    }[mode]
    return (float(MavModeFlag.CUSTOM_MODE_ENABLED), float(number)), (lambda cm: cm == number)

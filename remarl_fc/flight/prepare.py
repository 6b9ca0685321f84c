"""Getting a vehicle ready for the policy: streams, failsafe parameters, position, take-off.

`Preparation.prepare_one` runs once per vehicle this process flies, concurrently:

0. (`Preparation.prepare_swarm`) wait for a HEARTBEAT of every vehicle, prepare them all
   concurrently, then wait for the whole swarm to be ready (over the bus: one start for all);
1. ask for the telemetry streams (`TELEMETRY`; ADS-B relay best effort);
2. read and judge the failsafe parameters (`remarl_fc.flight.paramcheck`): an error finding
   raises `UnsafeParameters` before anything is armed;
3. wait for a position and attitude (and, on ArduPilot, the EKF's position flags);
4. take off (ArduPilot: GUIDED, arm, NAV_TAKEOFF; PX4: zero-velocity stream, OFFBOARD, arm,
   climb by velocity setpoints), or check it is already flying and switch to the external mode;
5. ``ready``.

Every wait has a deadline on the flight clock and raises `LinkTimeout`; every status change
goes through `remarl_fc.flight.core.transition` (via the ``apply`` callback).
"""

from __future__ import annotations

import asyncio
import math
import time
from collections.abc import Callable
from dataclasses import replace

import numpy as np
from numpy.typing import NDArray

from remarl_fc.errors import CommandRejected, RemarlError, UnsafeParameters
from remarl_fc.flight.commands import Commander, enum_name
from remarl_fc.flight.config import PX4_TELEMETRY, TELEMETRY, Clock, FlyConfig, Member
from remarl_fc.flight.core import TAKEOFF_DONE_FRACTION, Vehicle
from remarl_fc.flight.mission import VehiclePlan
from remarl_fc.flight.paramcheck import ParamReader, check_params, checked_names
from remarl_fc.flight.peers import Peers
from remarl_fc.flight.status import Status
from remarl_fc.mavlink.consts import LandedState, MavCmd, MavState, MsgId

ADSB_HZ = 2.0
"""ADSB_VEHICLE rate asked for (best effort: not every autopilot takes it)."""

PRESTREAM_S = 0.5
"""PX4: stream setpoints this long before switching to OFFBOARD (it needs a stream first)."""

ARMED_WAIT_S = 3.0
"""After the ARM command's ACK, wait this long for a HEARTBEAT that says armed."""

MIN_FLYING_HEIGHT_M = 1.0
"""Without a take-off, a vehicle lower than this is on the ground: `fly` refuses it."""


class Preparation:
    """Prepares the vehicles of one flight.

    Args:
        cfg: the flight's settings.
        commands: the command channel.
        params: the parameter reader (fed PARAM_VALUE by the runtime).
        clock: the flight clock.
        plans: each vehicle's mission plan, by system id.
        vehicle: the decision state of a vehicle, by system id.
        update: replaces a vehicle's decision state (no status change).
        apply: a status change: the new state and its commands (`transition`'s result).
        event: tells the operator something about a vehicle.
    """

    def __init__(
        self,
        cfg: FlyConfig,
        commands: Commander,
        params: ParamReader,
        clock: Clock,
        plans: dict[int, VehiclePlan],
        vehicle: Callable[[int], Vehicle],
        update: Callable[[Vehicle], None],
        apply: Callable[[Vehicle, Status, str | None], None],
        event: Callable[[Member, str], None],
    ) -> None:
        self.cfg, self.commands, self.params, self.clock = cfg, commands, params, clock
        self.plans = plans
        self.vehicle, self.update, self.apply, self.event = vehicle, update, apply, event

    async def prepare_swarm(
        self, mine: list[Member], peers: Peers
    ) -> tuple[NDArray[np.float64], float]:
        """Prepare every vehicle of this process at once, then wait for the whole swarm.

        Returns:
            The swarm's start: every vehicle's ready position (N, 2) in slot order, and the
            start time on the flight clock — the same in every process of the swarm bus.
        """
        cfg = self.cfg
        await self.commands.wait_until(
            "a HEARTBEAT from every vehicle this process flies",
            lambda: all(m.track.autopilot is not None for m in mine),
            cfg.ready_timeout_s,
        )
        async with asyncio.TaskGroup() as tg:
            for m in mine:
                tg.create_task(self.prepare_one(m), name=f"remarl[{m.system_id}].prepare")
        for m in mine:
            m.ready_ne_m, m.ready_t = m.track.ne_m.copy(), time.time()
        plan: list[tuple[NDArray[np.float64], float]] = []

        def all_ready() -> bool:
            peers.sync(self.clock.now())
            got = peers.start_plan()
            if got is not None:
                plan.append(got)
            return got is not None

        await self.commands.wait_until(
            "every vehicle of the swarm ready (states on the swarm bus)",
            all_ready,
            cfg.ready_timeout_s + cfg.takeoff_timeout_s,
        )
        positions, start_unix = plan[0]
        return positions, self.clock.now() - (time.time() - start_unix) * self.clock.speedup

    def _stream(self, m: Member, *, prestream: bool, climb_target_m: float | None = None) -> None:
        v = self.vehicle(m.system_id)
        self.update(replace(v, prestream=prestream, climb_target_m=climb_target_m))

    async def prepare_one(self, m: Member) -> None:
        """Steps 1–5 of the module docstring for one vehicle."""
        t, cfg = m.track, self.cfg
        for mid, hz in TELEMETRY.items():
            if t.is_px4 and mid not in PX4_TELEMETRY:
                continue
            await self.commands.command(m, MavCmd.SET_MESSAGE_INTERVAL, int(mid), 1e6 / hz)
        try:  # ArduPilot relays its ADS-B receiver's traffic only when asked (ADSB_TYPE=1)
            await self.commands.command(
                m, MavCmd.SET_MESSAGE_INTERVAL, int(MsgId.ADSB_VEHICLE), 1e6 / ADSB_HZ
            )
        except CommandRejected as exc:
            self.event(m, f"ADSB_VEHICLE rate not set ({exc.result_name}): relying on its default")
        if cfg.check_params:
            await self.check_params(m)
        for mid in (MsgId.GLOBAL_POSITION_INT, MsgId.ATTITUDE):
            name = enum_name(MsgId, mid)
            await self.commands.wait_until(
                f"vehicle {m.system_id}: {name} after asking for it at {TELEMETRY[mid]:g} Hz",
                lambda name=name: t.seen[name] > 0,  # type: ignore[misc]
                cfg.ready_timeout_s,
            )
        if cfg.dry_run:  # nothing is sent: fly the setpoints on paper from where it is
            await self.commands.wait_until(
                f"vehicle {m.system_id}: a position",
                lambda: math.isfinite(t.t_position),
                cfg.ready_timeout_s,
            )
            self.apply(self.vehicle(m.system_id), Status.READY, None)
            return
        await self.commands.wait_until(
            f"vehicle {m.system_id}: out of boot with a position (EKF flags on ArduPilot)",
            lambda: t.system_status != MavState.BOOT and t.position_ok(),
            cfg.ready_timeout_s,
        )
        if cfg.takeoff_m is not None or cfg.takeoff_to_mission_alt:
            alt = self.takeoff_alt(m)
            self.apply(self.vehicle(m.system_id), Status.TAKING_OFF, f"taking off to {alt:g} m")
            await (self._takeoff_px4(m, alt) if t.is_px4 else self._takeoff_ardupilot(m, alt))
        else:
            if t.height_m < MIN_FLYING_HEIGHT_M or t.landed_state == LandedState.ON_GROUND:
                raise RemarlError(
                    f"vehicle {m.system_id} is on the ground; use --takeoff ALT_M to take off"
                )
            if t.is_px4:
                self._stream(m, prestream=True)
                await self.clock.sleep(PRESTREAM_S)
            await self.commands.set_mode(m, "external")
        self.apply(self.vehicle(m.system_id), Status.READY, None)
        # PX4 leaves OFFBOARD after 1 s without setpoints: keep streaming until controlled
        self._stream(m, prestream=t.is_px4)

    async def check_params(self, m: Member) -> None:
        """Read and judge the vehicle's failsafe parameters; raise on an error finding."""
        px4 = m.track.is_px4
        readout = await self.params.read(m.system_id, checked_names(px4))
        period_s = 1.0 / self.cfg.setpoint_hz
        findings = check_params(readout.values, px4=px4, setpoint_period_s=period_s)
        if readout.values:
            read = ", ".join(f"{k}={v:g}" for k, v in readout.values.items())
            self.event(m, f"parameters: {read}")
        if readout.unread:
            unread = ", ".join(readout.unread)
            self.event(m, f"parameters not read (not on this vehicle?): {unread}")
        for f in findings:
            self.event(m, f"parameter {f.level}: {f.text}")
        errors = tuple(f.text for f in findings if f.level == "error")
        if errors:
            raise UnsafeParameters(system_id=m.system_id, problems=errors)

    def takeoff_alt(self, m: Member) -> float:
        """Take-off height of ``m``: ``--takeoff ALT_M``, else its mission ``alt_m``."""
        if self.cfg.takeoff_m is not None:
            return float(self.cfg.takeoff_m)
        return self.plans[m.system_id].alt_m

    async def _arm(self, m: Member) -> None:
        await self.commands.command(m, MavCmd.COMPONENT_ARM_DISARM, 1, done=lambda: m.track.armed)
        await self.commands.wait_until(
            f"vehicle {m.system_id} armed", lambda: m.track.armed, ARMED_WAIT_S
        )

    async def _takeoff_ardupilot(self, m: Member, alt: float) -> None:
        await self.commands.set_mode(m, "external")
        await self._arm(m)
        airborne = (LandedState.IN_AIR, LandedState.TAKEOFF)
        await self.commands.command(
            m, MavCmd.NAV_TAKEOFF, 0, 0, 0, math.nan, 0, 0, alt,
            done=lambda: m.track.height_m > 0.5 or m.track.landed_state in airborne,
        )  # fmt: skip
        await self._wait_height(m, alt)

    async def _takeoff_px4(self, m: Member, alt: float) -> None:
        self._stream(m, prestream=True)  # zero-velocity setpoints: OFFBOARD needs a stream first
        await self.clock.sleep(PRESTREAM_S)
        await self.commands.set_mode(m, "external")
        await self._arm(m)
        self._stream(m, prestream=False, climb_target_m=alt)
        await self._wait_height(m, alt)
        self._stream(m, prestream=True)

    async def _wait_height(self, m: Member, alt: float) -> None:
        await self.commands.wait_until(
            f"vehicle {m.system_id} at {TAKEOFF_DONE_FRACTION:.0%} of {alt:g} m",
            lambda: m.track.height_m >= TAKEOFF_DONE_FRACTION * alt,
            self.cfg.takeoff_timeout_s,
        )

"""``remarl-fc fly``: the asyncio shell that flies a swarm policy on ArduPilot or PX4.

    async with SwarmRuntime(cfg, policy, spec) as rt:  # links open; any exit: every vehicle holds
        await rt.run()

One `asyncio.TaskGroup` owns every task, each named ``remarl.<what>``: ``heartbeat`` (1 Hz),
``mission`` (prepare every vehicle — `remarl_fc.flight.prepare` — then one policy decision
per dt, through the safety shield; `remarl_fc.flight.shielding` records what it did),
``setpoints`` (at ≥ 10 Hz one tick of the sans-I/O core `remarl_fc.flight.core`: telemetry
snapshots in; setpoints, holds and events out), ``holds`` (the hold modes the core asks for,
each waiting for its ACK), ``bus_rx``/``bus_tx`` (`remarl_fc.flight.peers`).
Frames come in through `remarl_fc.flight.receive` (the source gate); commands go out through
`remarl_fc.flight.commands`. Every wait has a deadline on the flight clock and raises; on any
exit — the end of the mission, an error, Ctrl-C — every vehicle still flown is told to hold.

This module is the one place that owns a flight's tasks, clocks and resources, so it stays
whole (about 490 lines): every decision it carries out is made elsewhere, without I/O.
"""

from __future__ import annotations

import asyncio
import contextlib
import time
from collections.abc import Callable
from dataclasses import asdict, replace
from typing import Any

import numpy as np

from remarl_fc.bus.core import SwarmBus
from remarl_fc.bus.memory import MemoryBroker, MemoryBus
from remarl_fc.errors import RemarlError
from remarl_fc.flight.commands import Commander
from remarl_fc.flight.config import (
    ARDUPILOT_PROFILE,
    PX4_PROFILE,
    Clock,
    FlyConfig,
    Member,
    bus_core,
    members_of,
)
from remarl_fc.flight.control import (
    ControlSpec,
    FlownPolicy,
    SwarmController,
    obstacle_picture,
    swarm_picture,
    whereabouts,
)
from remarl_fc.flight.core import (
    Command,
    Event,
    Hold,
    Rules,
    Setpoint,
    Telemetry,
    Vehicle,
    flight_goes_on,
    hold_all,
    next_actions,
    transition,
)
from remarl_fc.flight.flightlog import DecisionLog, mission_header
from remarl_fc.flight.paramcheck import ParamReader
from remarl_fc.flight.peers import Peers
from remarl_fc.flight.prepare import Preparation
from remarl_fc.flight.receive import Receiver
from remarl_fc.flight.report import (
    anomalies,
    decision_rows,
    reached_on_trusted_telemetry,
    status_lines,
    vehicle_summaries,
)
from remarl_fc.flight.shielding import Check, ShieldTally, checks_of
from remarl_fc.flight.status import Status
from remarl_fc.flight.traffic import TrafficPicture
from remarl_fc.flight.trust import SourceGate
from remarl_fc.mavlink.codec import Codec
from remarl_fc.mavlink.consts import (
    TYPE_MASK_VELOCITY_YAW,
    MavAutopilot,
    MavComponent,
    MavFrame,
    MavState,
    MavType,
)
from remarl_fc.mavlink.link import MavlinkLink, TlogWriter
from remarl_fc.resource import StackOwner
from sim.dynamics import response_values
from sim.sensors import TrackNoise
from sim.vehicle import VehicleProfile, load_profile

HOLD_CONFIRM_S = 6.0
"""At the end, wait at most this long for the last hold commands to be confirmed."""


class SwarmRuntime(StackOwner):
    """The flight (see the module docstring).

    Args:
        cfg: flight settings.
        policy: the policy (numpy).
        spec: control constants (from the policy file).
        on_status: called with a one-line-per-vehicle status at every decision, and with
            each vehicle's events as they happen (the console of `fly` and the demo).
    """

    def __init__(
        self,
        cfg: FlyConfig,
        policy: FlownPolicy,
        spec: ControlSpec,
        *,
        on_status: Callable[[str], None] | None = None,
        bus: SwarmBus | None = None,
    ) -> None:
        self.cfg, self.policy, self.spec = cfg, policy, spec
        self.clock = Clock(cfg.speedup)
        self.on_status = on_status
        mission = cfg.mission
        self.members = members_of(mission, cfg.vehicles)
        self.by_sysid = {m.system_id: m for m in self.members}
        self.plans = {p.system_id: p for p in mission.vehicles}
        local = frozenset(m.system_id for m in self.members if m.local)
        self.traffic = TrafficPicture(
            mission.origin, noise=TrackNoise.of(mission.sensors()) if cfg.track_filter else None
        )
        self.bus: SwarmBus = bus or MemoryBus(MemoryBroker(), bus_core(cfg, local))
        self.peers = Peers(
            self.bus, self.members, self.traffic, self.clock, cfg.peer_timeout_s,
            lambda m: self.vehicles[m.system_id].status.value, self._arc_of,
        )  # fmt: skip
        self.controller = SwarmController(
            policy, spec, mission.targets_ne_m(), shield=cfg.shield, groups=mission.groups()
        )
        given = cfg.vehicle_profile
        self.profiles: dict[bool, VehicleProfile] = {
            px4: load_profile(given or (PX4_PROFILE if px4 else ARDUPILOT_PROFILE))
            for px4 in (False, True)
        }
        """The profile the shield predicts a vehicle of this process with, by ``is_px4``."""
        self._responses = np.array([response_values(self.profiles[False])] * len(self.members))
        """(N, 3) each vehicle's fitted response (`whereabouts`: how one told to hold stops);
        set from its autopilot once the handshakes are done."""
        self.shield = ShieldTally(cfg.shield.mode)
        """What the safety shield did (`remarl_fc.flight.shielding`)."""
        self.vehicles: dict[int, Vehicle] = {
            m.system_id: Vehicle(m.system_id, m.slot) for m in self.members
        }
        """The decision state of every vehicle (immutable values, replaced on each change)."""
        self.rules = Rules(
            stale_s=cfg.stale_s, dt_s=spec.dt_s, dry_run=cfg.dry_run, geofence=mission.geofence
        )
        self.codec = Codec(cfg.system_id, cfg.component_id, signing=cfg.signing)
        self.gate = SourceGate(
            frozenset(self.by_sysid),
            (cfg.system_id, cfg.component_id),
            adsb_sources=mission.adsb_sources,
        )
        self.links: list[MavlinkLink] = []
        self.commands = Commander(cfg, self.codec, self.clock, self.links)
        self.params = ParamReader(
            lambda sysid, msg: self.commands.send(self.by_sysid[sysid], msg, harmless=True),
            self.codec.factory,
            self.clock.timeout,
        )
        self.preparation = Preparation(
            cfg, self.commands, self.params, self.clock, self.plans,
            lambda sysid: self.vehicles[sysid], self._update, self._apply, self._event,
        )  # fmt: skip
        self._log: DecisionLog | None = None
        self._done = asyncio.Event()
        self.decisions = 0
        self.setpoint_deadline_misses = 0
        self.decide_s: list[float] = []
        """Wall time of each swarm decision (observation + inference), s."""
        self.tick_s: list[float] = []
        """Wall time of each setpoint tick (checks + setpoints for every vehicle), s."""
        self._to_hold: asyncio.Queue[Member] = asyncio.Queue()
        self.receiver = Receiver(
            self.gate, self.by_sysid, self.links, self.traffic, self.commands, self.params,
            lambda sysid: self.vehicles[sysid].status, self._event, cfg.connections,
        )  # fmt: skip

    # -- lifetime -----------------------------------------------------------------------

    async def _enter(self, stack: contextlib.AsyncExitStack) -> None:
        """Open the logs, the links and the bus, on ``stack``."""
        log_dir = self.cfg.log_dir
        if log_dir is not None:
            log_dir.mkdir(parents=True, exist_ok=True)
            header = mission_header(
                self.cfg.mission,
                d_col_m=self.spec.arrival_m,
                speed_m_s=self.spec.speed_m_s,
                dt_s=self.spec.dt_s,
                speedup=self.cfg.speedup,
            )
            fh = stack.enter_context((log_dir / "decisions.jsonl").open("w"))
            self._log = DecisionLog(fh, header)
        for k, url in enumerate(self.cfg.connections):
            tlog = None
            if log_dir is not None:
                name = "flight.tlog" if len(self.cfg.connections) == 1 else f"link{k}.tlog"
                tlog = TlogWriter(log_dir / name)
            link = MavlinkLink(url, self.codec, self._receiver(k), tlog=tlog)
            self.links.append(await stack.enter_async_context(link))
        await stack.enter_async_context(self.bus)

    async def _leave(self, exc_type: type[BaseException] | None) -> None:
        """Hold every vehicle still flown, while the links are open (then they close)."""
        await self.hold_all(reason=f"exit ({exc_type.__name__})" if exc_type else "exit")

    # -- receiving ----------------------------------------------------------------------

    def _receiver(self, k: int) -> Callable[[Any, float, Any], bool]:
        def on_message(msg: Any, t_mono: float, address: Any) -> bool:
            return self.receiver.on_message(k, msg, self.clock.at(t_mono), address)

        return on_message

    # -- the flight ---------------------------------------------------------------------

    async def run(self) -> None:
        """Prepare, take control, fly until every vehicle is done; hold on the way out."""
        try:
            await self._run_group()
        except ExceptionGroup as group:  # one task failed: surface the project's error itself
            first = _first_leaf(group)
            if isinstance(first, RemarlError):
                raise first from group
            raise

    async def _run_group(self) -> None:
        try:
            async with asyncio.TaskGroup() as tg:
                tg.create_task(self._heartbeat_loop(), name="remarl.heartbeat")
                tg.create_task(self._setpoint_loop(), name="remarl.setpoints")
                tg.create_task(self._hold_loop(), name="remarl.holds")
                tg.create_task(self.bus.run(), name="remarl.bus_rx")
                tg.create_task(self.peers.tx_loop(self._done), name="remarl.bus_tx")
                tg.create_task(self._mission(), name="remarl.mission")
        except* _FlightOver:  # the mission ended normally: the group cancelled the loops
            pass

    async def _heartbeat_loop(self) -> None:
        f = self.codec.factory
        while not self._done.is_set():
            hb = f.heartbeat_encode(
                MavType.ONBOARD_CONTROLLER, MavAutopilot.INVALID, 0, 0, MavState.ACTIVE
            )
            for link in self.links:
                link.send(hb)
            await self.clock.sleep(1.0)

    async def _mission(self) -> None:
        try:
            async with asyncio.TaskGroup() as tg:
                watch = tg.create_task(
                    self.receiver.refuse_spoofed_start(), name="remarl.spoof_watch"
                )
                await self._prepare()
                watch.cancel()
            await self._fly()
            with contextlib.suppress(TimeoutError):  # let the last holds be confirmed
                async with self.clock.timeout(HOLD_CONFIRM_S):
                    await self._to_hold.join()
        finally:
            self._done.set()
        raise _FlightOver

    def local_members(self) -> list[Member]:
        """The vehicles this process flies."""
        return [m for m in self.members if m.local]

    async def _prepare(self) -> None:
        mine = self.local_members()
        start_ne_m, start = await self.preparation.prepare_swarm(mine, self.peers)
        self.controller.start(start_ne_m, start)
        # the autopilots answered: each vehicle is predicted with its own (a peer's flies on at
        # its velocity, its command, whatever its profile)
        profiles = [self.profiles[m.track.is_px4] for m in self.members]
        self.controller.use_profiles(profiles)
        self._responses = np.array([response_values(p) for p in profiles])
        fitted = self.cfg.shield.mode != "off" and self.cfg.shield.vehicle_model == "fitted"
        for m in mine:
            self._apply(self.vehicles[m.system_id], Status.CONTROLLED, "under control")
            if fitted:
                profile = profiles[m.slot].name
                self._event(m, f"the shield predicts it with the {profile} response")

    async def _fly(self) -> None:
        dt = self.spec.dt_s
        t_next = self.clock.now()
        end = t_next + self.cfg.max_flight_s
        mine = frozenset(m.system_id for m in self.local_members())
        while flight_goes_on(self.vehicles, mine, self.clock.now(), self.cfg.lost_timeout_s):
            now = self.clock.now()
            if now > end:
                await self.hold_all(reason="max flight time")
                return
            self.decide(now)
            t_next += dt
            await self.clock.sleep(t_next - self.clock.now())
        for sysid in sorted(mine):
            if self.vehicles[sysid].status == Status.LOST:
                self._event(
                    self.by_sysid[sysid],
                    f"still lost after the lost timeout ({self.cfg.lost_timeout_s:g} s) with "
                    "every other vehicle done: given up",
                )

    def decide(self, now: float) -> None:
        """One swarm decision at ``now`` (the mission task calls it every dt).

        The policy through the shield (`SwarmController.decide`), then the decision log's
        rows, the shield's records (`remarl_fc.flight.shielding`) and the status lines.
        """
        self._sync_peers(now)
        rows = self._report_rows()
        where = whereabouts(rows, self._responses, now)
        positions = where.ne_m
        obstacles = obstacle_picture(self.traffic, rows, where, now, self.cfg.adsb_band_m)
        t0 = time.perf_counter()
        decision = self.controller.decide(
            now,
            positions,
            obstacles.ne_m,
            obstacles.vel_ne_m_s,
            swarm=swarm_picture(rows),
            obstacle_age_s=obstacles.age_s,
        )
        self.decide_s.append(time.perf_counter() - t0)
        self.decisions += 1
        ids = [m.system_id for m in self.members]
        checks = checks_of(decision, ids, self.spec.max_turn_rad, self.cfg.shield.mode)
        self.shield.add(checks)
        if self._log is not None:
            by_id = {c.system_id: c for c in checks}
            for row in decision_rows(rows, self.controller, decision, self.decide_s, by_id):
                self._log.write(row)
            self._log.flush()
        for c in checks:
            if c.intervened:
                self._intervention(c)
        if self.on_status is not None:
            self.on_status(self.status_line(now))

    def _intervention(self, c: Check) -> None:
        """An intervention of the shield (in monitor mode a would-be one) to the tlog and console.

        A STATUSTEXT in the tlog of the vehicle's link, written but not sent (the vehicles and
        their ground stations get no extra traffic), and a line on the console.
        """
        m = self.by_sysid[c.system_id]
        link = m.link if m.link is not None else (self.links[0] if self.links else None)
        if link is not None and link.tlog is not None:
            text = c.text(self.spec.speed_m_s).encode("ascii", "replace")
            link.tlog.write(
                self.codec.encode(self.codec.factory.statustext_encode(c.severity(), text))
            )
        if self.on_status is not None:
            self.on_status(f"t={c.t:6.1f}s vehicle {c.system_id}: {c.console()}")

    def _report_rows(self) -> list[tuple[Member, Status]]:
        return [(m, self.vehicles[m.system_id].status) for m in self.members]

    def status_line(self, now: float) -> str:
        """One line per vehicle: status, position, height, distance to target."""
        return status_lines(self._report_rows(), self.cfg.mission.targets_ne_m(), now)

    def status(self, system_id: int) -> Status:
        """Where vehicle ``system_id`` is in the flight."""
        return self.vehicles[system_id].status

    def statuses(self) -> list[Status]:
        """Every vehicle's status, in slot order."""
        return [self.vehicles[m.system_id].status for m in self.members]

    # -- setpoints and safety -----------------------------------------------------------

    async def _setpoint_loop(self) -> None:
        period = 1.0 / self.cfg.setpoint_hz
        t_next = self.clock.now()
        while not self._done.is_set():
            now = self.clock.now()
            if now - t_next > period:
                self.setpoint_deadline_misses += 1
                t_next = now
            t0 = time.perf_counter()
            self.tick(now)
            self.tick_s.append(time.perf_counter() - t0)
            t_next += period
            await self.clock.sleep(t_next - self.clock.now())

    def tick(self, now: float) -> None:
        """One setpoint tick: snapshot every local vehicle, decide (`next_actions`), carry out."""
        self._sync_peers(now)
        telemetry = {m.system_id: Telemetry.of(m.track, now) for m in self.local_members()}
        self.vehicles, commands = next_actions(
            self.vehicles, telemetry, now, self.rules, self.controller
        )
        self._carry_out(commands)

    def _apply(self, v: Vehicle, new: Status, why: str | None) -> None:
        """A status change of one vehicle, through the status machine."""
        v, commands = transition(v, new, why)
        self.vehicles[v.system_id] = v
        self._carry_out(commands)

    def _update(self, v: Vehicle) -> None:
        self.vehicles[v.system_id] = v

    def _carry_out(self, commands: list[Command] | tuple[Command, ...]) -> None:
        for c in commands:
            m = self.by_sysid[c.system_id]
            if isinstance(c, Setpoint):
                self._stream(m, c.vn, c.ve, c.vd, c.yaw)
            elif isinstance(c, Hold):
                self._to_hold.put_nowait(m)  # the holds task sends it (it waits for the ACK)
            else:
                self._event(m, c.text)

    def _stream(self, m: Member, vn: float, ve: float, vd: float, yaw: float) -> None:
        msg = self.codec.factory.set_position_target_local_ned_encode(
            int(self.clock.now() * 1000) & 0xFFFF_FFFF, m.system_id, MavComponent.AUTOPILOT1,
            MavFrame.LOCAL_NED, TYPE_MASK_VELOCITY_YAW, 0.0, 0.0, 0.0, vn, ve, vd,
            0.0, 0.0, 0.0, yaw, 0.0,
        )  # fmt: skip
        if self.commands.send(m, msg):
            m.sent += 1

    async def _hold_loop(self) -> None:
        while True:
            m = await self._to_hold.get()
            try:
                await self._hold(m)
            finally:
                self._to_hold.task_done()

    async def _hold(self, m: Member) -> None:
        try:
            self._event(m, await self.commands.hold(m))
        except RemarlError as exc:
            self._event(m, f"hold command failed: {exc}")

    async def hold_all(self, *, reason: str) -> None:
        """Send the hold mode to every vehicle still flown by this runtime (never raises)."""
        mine = frozenset(m.system_id for m in self.local_members())
        self.vehicles, commands = hold_all(self.vehicles, mine, reason)
        flown = [self.by_sysid[c.system_id] for c in commands if isinstance(c, Hold)]
        for c in commands:
            if isinstance(c, Event):
                self._event(self.by_sysid[c.system_id], c.text)
        if self.cfg.dry_run or not flown:
            return
        results = await asyncio.gather(*(self._hold(m) for m in flown), return_exceptions=True)
        for m, r in zip(flown, results, strict=True):
            if isinstance(r, BaseException):
                self._event(m, f"hold failed: {r!r}")

    # -- logs ---------------------------------------------------------------------------

    def _arc_of(self, m: Member) -> tuple[float, float, float, float] | None:
        """The arc a vehicle of this process flies now, for the bus (None: none)."""
        if self.vehicles[m.system_id].status != Status.CONTROLLED:
            return None
        return self.controller.arc(m.slot, self.clock.now())

    def _sync_peers(self, now: float) -> None:
        """Bring the remote vehicles' rows up to date from the swarm bus.

        A remote vehicle's status is its own process's word (that process runs the status
        machine for it): it is mirrored, not checked here.
        """
        self.peers.sync(now)
        for m in self.members:
            if m.local or m.remote_status is None:
                continue
            status = Status(m.remote_status)
            v = self.vehicles[m.system_id]
            if status != v.status:
                self._event(m, f"peer: {status.value}")
                self.vehicles[m.system_id] = replace(v, status=status)
            if m.remote_arc is not None and status == Status.CONTROLLED:
                self.controller.follow(m.slot, m.remote_arc)

    def _event(self, m: Member, text: str) -> None:
        now = self.clock.now()
        m.events.append((now, text))
        if self._log is not None:
            self._log.event(now, m.system_id, text)
        if self.on_status is not None:
            self.on_status(f"t={now:6.1f}s vehicle {m.system_id}: {text}")

    def summary(self) -> dict[str, Any]:
        """What happened to each vehicle, and to the link (see `remarl_fc.flight.report`)."""
        rows = self._report_rows()
        link = {
            "signed": self.cfg.signing is not None,
            **self.gate.summary(),
            "refused_not_logged": sum(link.refused_not_logged for link in self.links),
            "rejected_unsigned": self.codec.stats.rejected_unsigned,
            "bad_frames": self.codec.stats.bad_frames,
        }
        traffic = self.traffic.stats()
        vehicles = vehicle_summaries(rows)
        return {
            "policy": self.policy.summary(),
            "decisions": self.decisions,
            "setpoint_deadline_misses": self.setpoint_deadline_misses,
            "bus": self.bus.core.stats.as_dict(),
            "link": link,
            "traffic": traffic,
            "anomalies": anomalies(rows, link, traffic),
            "shield": self.shield.summary([m.system_id for m in self.local_members()]),
            "shield_settings": asdict(self.cfg.shield),  # as eval records them
            "vehicles": vehicles,
            "reached": [v["system_id"] for v in vehicles if reached_on_trusted_telemetry(v)],
        }


class _FlightOver(Exception):
    """Raised by the mission task when the flight is over, to stop the other tasks."""


def _first_leaf(group: BaseExceptionGroup[Any]) -> BaseException:
    first = group.exceptions[0]
    return _first_leaf(first) if isinstance(first, BaseExceptionGroup) else first

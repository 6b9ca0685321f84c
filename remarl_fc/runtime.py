"""``remarl-fc fly``: the asyncio runtime that flies a swarm policy on ArduPilot or PX4.

    async with SwarmRuntime(cfg, policy) as rt:   # links open; on any exit: every vehicle holds
        await rt.run()

One `asyncio.TaskGroup` owns every task, each named ``remarl.<what>``:

* ``heartbeat`` — the controller's HEARTBEAT at 1 Hz (MAV_TYPE_ONBOARD_CONTROLLER);
* ``mission`` — prepare every vehicle (streams, failsafe parameters checked by
  `remarl_fc.paramcheck`, position, optional take-off, take control), then the decision loop:
  every dt, one policy decision for the whole swarm;
* ``setpoints`` — at ≥ 10 Hz, each controlled vehicle's point on its arc as
  SET_POSITION_TARGET_LOCAL_NED velocity + yaw (type_mask 2503), after the safety checks:
  stale telemetry (> `FlyConfig.stale_s`) → the vehicle is no longer commanded and becomes an
  obstacle at its last track, and is told to hold when it comes back; a mode the pilot chose →
  released, never fought; a geofence breach ahead → hold; target reached → hold and release.

Receiving is callback-driven (`remarl_fc.mavlink.link`); commands, mode changes and waits go
through `remarl_fc.commands.Commander`; the settings and per-vehicle rows are in
`remarl_fc.flyconfig`. Every wait has a deadline on the monotonic clock and raises
(`LinkTimeout`, `CommandRejected`); on any exit — the end of the mission, an error, Ctrl-C —
every vehicle still under control is sent the hold mode.
"""

from __future__ import annotations

import asyncio
import contextlib
import math
import time
from collections.abc import Callable
from types import TracebackType
from typing import Any, Self

import numpy as np

from remarl_fc.bus.core import SwarmBus
from remarl_fc.bus.memory import MemoryBroker, MemoryBus
from remarl_fc.commands import Commander, enum_name
from remarl_fc.control import ControlSpec, Decision, PolicyLike, SwarmController
from remarl_fc.errors import CommandRejected, ConfigError, RemarlError, UnsafeParameters
from remarl_fc.flightlog import DecisionLog, mission_header
from remarl_fc.flyconfig import (
    PX4_TELEMETRY,
    TELEMETRY,
    Clock,
    FlyConfig,
    Member,
    Status,
    bus_core,
)
from remarl_fc.mavlink.codec import Codec
from remarl_fc.mavlink.consts import (
    TYPE_MASK_VELOCITY_YAW,
    MavAutopilot,
    MavCmd,
    MavComponent,
    MavFrame,
    MavState,
    MavType,
    MsgId,
)
from remarl_fc.mavlink.link import MavlinkLink, TlogWriter
from remarl_fc.paramcheck import ParamReader, check_params, checked_names
from remarl_fc.peers import Peers
from remarl_fc.tracking import TrafficPicture, VehicleTrack

HOLD_CONFIRM_S = 6.0
"""At the end, wait at most this long for the last hold commands to be confirmed."""

ADSB_HZ = 2.0
"""ADSB_VEHICLE rate asked for (best effort: not every autopilot takes it)."""

CLIMB_RATE_M_S = 1.5
"""PX4 take-off climb in OFFBOARD (MPC_TKO_SPEED's default)."""

TAKEOFF_DONE_FRACTION = 0.95
"""A take-off is done at this fraction of its height."""


class SwarmRuntime:
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
        policy: PolicyLike,
        spec: ControlSpec,
        *,
        on_status: Callable[[str], None] | None = None,
        bus: SwarmBus | None = None,
    ) -> None:
        self.cfg, self.policy, self.spec = cfg, policy, spec
        self.clock = Clock(cfg.speedup)
        self.on_status = on_status
        mission = cfg.mission
        self.members = [
            Member(p.slot, p.system_id, VehicleTrack(p.system_id, mission.origin))
            for p in mission.by_slot()
        ]
        self.by_sysid = {m.system_id: m for m in self.members}
        self.plans = {p.system_id: p for p in mission.vehicles}
        local = cfg.vehicles if cfg.vehicles is not None else frozenset(self.by_sysid)
        unknown = sorted(local - set(self.by_sysid))
        if unknown:
            raise ConfigError(
                f"vehicle(s) {unknown} are not in the mission {mission.source} "
                f"(its system ids: {sorted(self.by_sysid)})"
            )
        for m in self.members:
            m.local = m.system_id in local
        self.traffic = TrafficPicture(mission.origin)
        self.bus: SwarmBus = bus or MemoryBus(MemoryBroker(), bus_core(cfg, local))
        self.peers = Peers(
            self.bus, self.members, self.traffic, self.clock, cfg.peer_timeout_s,
            lambda m: m.status.value,
        )  # fmt: skip
        self.controller = SwarmController(policy, spec, mission.targets_ne_m())
        self.codec = Codec(cfg.system_id, cfg.component_id, signing=cfg.signing)
        self.links: list[MavlinkLink] = []
        self.commands = Commander(cfg, self.codec, self.clock, self.links)
        self.params = ParamReader(
            lambda sysid, msg: self.commands.send(self.by_sysid[sysid], msg, harmless=True),
            self.codec.factory,
            self.clock.timeout,
        )
        self._stack: contextlib.AsyncExitStack | None = None
        self._log: DecisionLog | None = None
        self._done = asyncio.Event()
        self.decisions = 0
        self.setpoint_deadline_misses = 0
        self.decide_s: list[float] = []
        """Wall time of each swarm decision (observation + inference), s."""
        self.tick_s: list[float] = []
        """Wall time of each setpoint tick (checks + setpoints for every vehicle), s."""
        self._to_hold: asyncio.Queue[Member] = asyncio.Queue()

    # -- lifetime -----------------------------------------------------------------------

    async def __aenter__(self) -> Self:
        if self._stack is not None:
            raise RuntimeError("this SwarmRuntime is already open")
        stack = contextlib.AsyncExitStack()
        await stack.__aenter__()
        try:
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
        except BaseException:
            await stack.aclose()
            raise
        self._stack = stack
        return self

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        try:
            await self.hold_all(reason=f"exit ({exc_type.__name__})" if exc_type else "exit")
        finally:
            stack, self._stack = self._stack, None
            if stack is not None:
                await stack.aclose()

    # -- receiving ----------------------------------------------------------------------

    def _receiver(self, k: int) -> Callable[[Any, float], None]:
        def on_message(msg: Any, t_mono: float) -> None:
            self._on_message(k, msg, self.clock.at(t_mono))

        return on_message

    def _on_message(self, k: int, msg: Any, now: float) -> None:
        mid = msg.get_msgId()
        if mid == MsgId.ADSB_VEHICLE:
            self.traffic.update(msg, now)
            return
        member = self.by_sysid.get(msg.get_srcSystem())
        if member is None or not member.local or msg.get_srcComponent() != MavComponent.AUTOPILOT1:
            return
        if member.link is None:
            member.link = self.links[k]
        member.track.update(msg, now)
        if mid == MsgId.COMMAND_ACK:
            self.commands.on_ack(member.system_id, msg)
        elif mid == MsgId.PARAM_VALUE:
            self.params.on_value(member.system_id, msg, bytewise=member.track.is_px4)

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
            await self._prepare()
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
        cfg = self.cfg
        mine = self.local_members()
        await self.commands.wait_until(
            "a HEARTBEAT from every vehicle this process flies",
            lambda: all(m.track.autopilot is not None for m in mine),
            cfg.ready_timeout_s,
        )
        async with asyncio.TaskGroup() as tg:
            for m in mine:
                tg.create_task(self._prepare_one(m), name=f"remarl[{m.system_id}].prepare")
        for m in mine:
            m.ready_ne_m, m.ready_t = m.track.ne_m.copy(), time.time()
        plan: list[tuple[np.ndarray, float]] = []

        def all_ready() -> bool:
            self.peers.sync(self.clock.now())
            got = self.peers.start_plan()
            if got is not None:
                plan.append(got)
            return got is not None

        await self.commands.wait_until(
            "every vehicle of the swarm ready (states on the swarm bus)",
            all_ready,
            cfg.ready_timeout_s + cfg.takeoff_timeout_s,
        )
        positions, start_unix = plan[0]
        start = self.clock.now() - (time.time() - start_unix) * self.clock.speedup
        self.controller.start(positions, start)
        for m in mine:
            m.prestream = False
            m.status = Status.CONTROLLED
            self._event(m, "under control")

    async def _prepare_one(self, m: Member) -> None:
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
            self._event(m, f"ADSB_VEHICLE rate not set ({exc.result_name}): relying on its default")
        if cfg.check_params:
            await self._check_params(m)
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
            m.status = Status.READY
            return
        await self.commands.wait_until(
            f"vehicle {m.system_id}: out of boot with a position (EKF flags on ArduPilot)",
            lambda: t.system_status != MavState.BOOT and t.position_ok(),
            cfg.ready_timeout_s,
        )
        if cfg.takeoff_m is not None or cfg.takeoff_to_mission_alt:
            m.status = Status.TAKING_OFF
            self._event(m, f"taking off to {self._takeoff_alt(m):g} m")
            await (self._takeoff_px4(m) if t.is_px4 else self._takeoff_ardupilot(m))
        else:
            if t.height_m < 1.0 or t.landed_state == 1:
                raise RemarlError(
                    f"vehicle {m.system_id} is on the ground; use --takeoff ALT_M to take off"
                )
            if t.is_px4:
                m.prestream = True
                await self.clock.sleep(0.5)
            await self.commands.set_mode(m, "external")
        m.prestream = t.is_px4  # PX4 leaves OFFBOARD after 1 s without setpoints: keep them
        m.status = Status.READY

    async def _check_params(self, m: Member) -> None:
        """Read and judge the vehicle's failsafe parameters; raise on an error finding."""
        px4 = m.track.is_px4
        readout = await self.params.read(m.system_id, checked_names(px4))
        period_s = 1.0 / self.cfg.setpoint_hz
        findings = check_params(readout.values, px4=px4, setpoint_period_s=period_s)
        if readout.values:
            read = ", ".join(f"{k}={v:g}" for k, v in readout.values.items())
            self._event(m, f"parameters: {read}")
        if readout.unread:
            unread = ", ".join(readout.unread)
            self._event(m, f"parameters not read (not on this vehicle?): {unread}")
        for f in findings:
            self._event(m, f"parameter {f.level}: {f.text}")
        errors = tuple(f.text for f in findings if f.level == "error")
        if errors:
            raise UnsafeParameters(system_id=m.system_id, problems=errors)

    def _takeoff_alt(self, m: Member) -> float:
        """Take-off height of ``m``: ``--takeoff ALT_M``, else its mission ``alt_m``."""
        if self.cfg.takeoff_m is not None:
            return float(self.cfg.takeoff_m)
        return self.plans[m.system_id].alt_m

    async def _takeoff_ardupilot(self, m: Member) -> None:
        alt = self._takeoff_alt(m)
        await self.commands.set_mode(m, "external")
        await self.commands.command(m, MavCmd.COMPONENT_ARM_DISARM, 1, done=lambda: m.track.armed)
        await self.commands.wait_until(f"vehicle {m.system_id} armed", lambda: m.track.armed, 3.0)
        await self.commands.command(
            m, MavCmd.NAV_TAKEOFF, 0, 0, 0, math.nan, 0, 0, alt,
            done=lambda: m.track.height_m > 0.5 or m.track.landed_state in (2, 3),
        )  # fmt: skip
        await self._wait_height(m, alt)

    async def _takeoff_px4(self, m: Member) -> None:
        alt = self._takeoff_alt(m)
        m.prestream = True  # zero-velocity setpoints: OFFBOARD needs a stream first
        await self.clock.sleep(0.5)
        await self.commands.set_mode(m, "external")
        await self.commands.command(m, MavCmd.COMPONENT_ARM_DISARM, 1, done=lambda: m.track.armed)
        await self.commands.wait_until(f"vehicle {m.system_id} armed", lambda: m.track.armed, 3.0)
        m.climb_target_m = alt
        await self._wait_height(m, alt)
        m.climb_target_m = None

    async def _wait_height(self, m: Member, alt: float) -> None:
        await self.commands.wait_until(
            f"vehicle {m.system_id} at {TAKEOFF_DONE_FRACTION:.0%} of {alt:g} m",
            lambda: m.track.height_m >= TAKEOFF_DONE_FRACTION * alt,
            self.cfg.takeoff_timeout_s,
        )

    async def _fly(self) -> None:
        dt = self.spec.dt_s
        t_next = self.clock.now()
        end = t_next + self.cfg.max_flight_s
        mine = self.local_members()
        while any(m.status in (Status.CONTROLLED, Status.LOST) for m in mine):
            now = self.clock.now()
            if now > end:
                await self.hold_all(reason="max flight time")
                return
            self._decide(now)
            t_next += dt
            await self.clock.sleep(t_next - self.clock.now())

    def _obstacles(self, now: float, height_m: float) -> tuple[np.ndarray, np.ndarray]:
        pos, vel = [], []
        for intr in self.traffic.current(now, height_m, self.cfg.adsb_band_m):
            pos.append(intr.predicted_ne_m(now))
            vel.append(intr.vel_ne_m_s)
        for m in self.members:
            if m.status in (Status.LOST, Status.PILOT, Status.HELD) and math.isfinite(
                m.track.t_position
            ):
                pos.append(m.track.predicted_ne_m(now))
                vel.append(m.track.vel_ned_m_s[:2])
        if not pos:
            return np.zeros((0, 2)), np.zeros((0, 2))
        return np.array(pos), np.array(vel)

    def _decide(self, now: float) -> None:
        self._sync_peers(now)
        positions = np.array([m.track.predicted_ne_m(now) for m in self.members])
        heights = [m.track.height_m for m in self.members if math.isfinite(m.track.height_m)]
        obstacles, obstacle_vel = self._obstacles(now, float(np.mean(heights)) if heights else 0.0)
        t0 = time.perf_counter()
        decision = self.controller.decide(now, positions, obstacles, obstacle_vel)
        self.decide_s.append(time.perf_counter() - t0)
        self.decisions += 1
        self._log_decision(decision)
        if self.on_status is not None:
            self.on_status(self.status_line(now))

    def status_line(self, now: float) -> str:
        """One line per vehicle: status, position, height, distance to target."""
        lines = []
        targets = self.cfg.mission.targets_ne_m()
        for m in self.members:
            t = m.track
            gap = (
                float(np.hypot(*(t.ne_m - targets[m.slot])))
                if math.isfinite(t.t_position)
                else math.nan
            )
            lines.append(
                f"t={now:6.1f}s vehicle {m.system_id}: {m.status.value:10} "
                f"N {t.ne_m[0]:7.1f} E {t.ne_m[1]:7.1f} up {t.height_m:5.1f} m, "
                f"{gap:6.1f} m to target"
            )
        return "\n".join(lines)

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
            self._sync_peers(now)
            for m in self.members:
                if m.local:
                    self._tick_member(m, now)
            self.tick_s.append(time.perf_counter() - t0)
            t_next += period
            await self.clock.sleep(t_next - self.clock.now())

    def _tick_member(self, m: Member, now: float) -> None:
        t = m.track
        if m.prestream or m.climb_target_m is not None:
            vz = 0.0
            if (
                m.climb_target_m is not None
                and t.height_m < TAKEOFF_DONE_FRACTION * m.climb_target_m
            ):
                vz = -CLIMB_RATE_M_S
            yaw = t.yaw_rad if math.isfinite(t.yaw_rad) else 0.0
            self._stream(m, 0.0, 0.0, vz, yaw)
            return
        if m.status == Status.LOST and t.position_age_s(now) <= self.cfg.stale_s:
            self._event(m, "telemetry back: told to hold, not resumed")
            m.status = Status.HELD
            self._spawn_hold(m)
            return
        if m.status != Status.CONTROLLED:
            return
        if t.position_age_s(now) > self.cfg.stale_s:
            m.status = Status.LOST
            self._event(m, f"telemetry stale for {t.position_age_s(now):.1f} s: an obstacle now")
            return
        if not self.cfg.dry_run and not t.in_external_control_mode():
            m.status = Status.PILOT
            self._event(m, f"mode changed to {t.custom_mode} by someone else: released")
            return
        if self.controller.reached(m.slot, t.ne_m):
            m.status = Status.REACHED
            self._event(m, "target reached: hold and release")
            self._spawn_hold(m)
            return
        fence = self.cfg.mission.geofence
        if fence is not None:
            vn, ve, _ = self.controller.setpoint(m.slot, now)
            ahead = t.ne_m + np.array([vn, ve]) * self.spec.dt_s
            if not fence.inside(ahead, t.height_m):
                m.status = Status.HELD
                self._event(m, "geofence breach ahead: hold")
                self._spawn_hold(m)
                return
        vn, ve, yaw = self.controller.setpoint(m.slot, now)
        self._stream(m, vn, ve, 0.0, yaw)

    def _stream(self, m: Member, vn: float, ve: float, vd: float, yaw: float) -> None:
        msg = self.codec.factory.set_position_target_local_ned_encode(
            int(self.clock.now() * 1000) & 0xFFFF_FFFF, m.system_id, MavComponent.AUTOPILOT1,
            MavFrame.LOCAL_NED, TYPE_MASK_VELOCITY_YAW, 0.0, 0.0, 0.0, vn, ve, vd,
            0.0, 0.0, 0.0, yaw, 0.0,
        )  # fmt: skip
        if self.commands.send(m, msg):
            m.sent += 1

    def _spawn_hold(self, m: Member) -> None:
        self._to_hold.put_nowait(m)  # the holds task sends it (commands wait for their ACK)

    async def _hold_loop(self) -> None:
        while True:
            m = await self._to_hold.get()
            try:
                await self._hold(m)
            finally:
                self._to_hold.task_done()

    async def _hold(self, m: Member) -> None:
        try:
            await self.commands.set_mode(m, "hold")
            self._event(m, "holding")
        except RemarlError as exc:
            self._event(m, f"hold command failed: {exc}")

    async def hold_all(self, *, reason: str) -> None:
        """Send the hold mode to every vehicle still flown by this runtime (never raises)."""
        flown = [
            m
            for m in self.local_members()
            if m.status in (Status.CONTROLLED, Status.TAKING_OFF, Status.READY)
        ]
        for m in flown:
            m.status = Status.HELD
            self._event(m, f"{reason}: hold")
        if self.cfg.dry_run or not flown:
            return
        results = await asyncio.gather(*(self._hold(m) for m in flown), return_exceptions=True)
        for m, r in zip(flown, results, strict=True):
            if isinstance(r, BaseException):
                self._event(m, f"hold failed: {r!r}")

    # -- logs ---------------------------------------------------------------------------

    def _sync_peers(self, now: float) -> None:
        """Bring the remote vehicles' rows up to date from the swarm bus."""
        self.peers.sync(now)
        for m in self.members:
            if m.local or m.remote_status is None:
                continue
            status = Status(m.remote_status)
            if status != m.status:
                self._event(m, f"peer: {status.value}")
                m.status = status

    def _event(self, m: Member, text: str) -> None:
        now = self.clock.now()
        m.events.append((now, text))
        if self._log is not None:
            self._log.event(now, m.system_id, text)
        if self.on_status is not None:
            self.on_status(f"t={now:6.1f}s vehicle {m.system_id}: {text}")

    def _log_decision(self, d: Decision) -> None:
        if self._log is None:
            return
        for m in self.members:
            k = m.slot
            vn, ve, yaw = self.controller.setpoint(k, d.t)
            row = {
                "t": round(d.t, 3),
                "system_id": m.system_id,
                "slot": k,
                "status": m.status.value,
                "ne_m": [round(float(v), 2) for v in d.positions_ne_m[k]],
                "height_m": round(m.track.height_m, 2),
                "obs": [round(float(v), 4) for v in d.obs[k]],
                "action": round(float(d.action[k]), 4),
                "turn_rad": round(float(d.turn_rad[k]), 4),
                "heading_rad": round(float(d.heading_rad[k]), 4),
                "setpoint": {"vn": round(vn, 3), "ve": round(ve, 3), "yaw": round(yaw, 4)},
                "obstacles_ne_m": [[round(float(v), 2) for v in p] for p in d.obstacles_ne_m],
                "decide_ms": round(self.decide_s[-1] * 1000, 3) if self.decide_s else None,
            }
            self._log.write(row)

    def summary(self) -> dict[str, Any]:
        """What happened to each vehicle."""
        return {
            "decisions": self.decisions,
            "setpoint_deadline_misses": self.setpoint_deadline_misses,
            "bus": self.bus.core.stats.as_dict(),
            "vehicles": [
                {
                    "system_id": m.system_id,
                    "slot": m.slot,
                    "local": m.local,
                    "status": m.status.value,
                    "setpoints_sent": m.sent,
                    "telemetry_rejected": dict(m.track.rejected),
                    "events": [[round(t, 2), e] for t, e in m.events],
                }
                for m in self.members
            ],
        }


class _FlightOver(Exception):
    """Raised by the mission task when the flight is over, to stop the other tasks."""


def _first_leaf(group: BaseExceptionGroup[Any]) -> BaseException:
    first = group.exceptions[0]
    return _first_leaf(first) if isinstance(first, BaseExceptionGroup) else first

"""The mock fleet: N vehicles, each a MAVLink 2 endpoint on its own UDP (or TCP) port, one loop.

    async with SitlFleet(SitlConfig(vehicles=3, flavour="px4", base_port=0)) as fleet:
        print(fleet.addresses)        # where to connect
        await fleet.wait(until_done=True, timeout_s=120.0)
    print(fleet.summary())            # ground truth

One task (``sitl.physics``, owned by the fleet's TaskGroup) runs the simulated clock: each
physics tick steps every airframe at once, records the ground truth, runs the autopilot timers
and sends whatever HEARTBEAT, telemetry and ADS-B is due. Datagrams are handled as they arrive
(``datagram_received`` or, over TCP, ``data_received`` → codec → autopilot), stamped with the
simulated time; the faults act on frames the same way on both transports. The simulated
clock is the tick count × tick length, paced to ``speedup`` × wall time; when the host cannot
keep up the simulation slows down rather than skipping physics (``summary()["achieved_speedup"]``
says by how much).
"""

from __future__ import annotations

import asyncio
import contextlib
import dataclasses
import functools
import math
from types import TracebackType
from typing import Any, Self

import numpy as np
from numpy.typing import NDArray

from remarl_fc.errors import LinkLost
from remarl_fc.frames import GeoPoint, heading_to_yaw, ned_to_geodetic, sim_to_ne
from remarl_fc.mavlink.codec import Codec, SigningConfig
from remarl_fc.mavlink.consts import MavComponent, MsgId
from remarl_fc.mavlink.udp import Address, UdpEndpoint
from remarl_fc.sitl.ardupilot import ArduCopterLogic
from remarl_fc.sitl.autopilot import TICK_HZ, Autopilot, Emit
from remarl_fc.sitl.config import SitlConfig
from remarl_fc.sitl.faults import Faults
from remarl_fc.sitl.groundtruth import GroundTruth
from remarl_fc.sitl.px4 import Px4Logic
from remarl_fc.sitl.telemetry import TelemetryBuilder, heartbeat
from remarl_fc.sitl.traffic import Traffic
from remarl_fc.sitl.vehicle import Airframes, step
from sim.config import ScenarioConfig
from sim.spawn import SPAWN_SPACING_FACTOR, swarm_layout

FloatArray = NDArray[np.float64]

DEFAULT_D_COL_M = float(ScenarioConfig.__dataclass_fields__["d_col_m"].default)  # type: ignore[arg-type]
"""Collision distance of a fleet without a scenario: the scenario default (d_col, 20 m)."""

UNSIGNED_ALLOWED = {
    "ardupilot": frozenset({MsgId.RADIO_STATUS, MsgId.RADIO}),
    "px4": frozenset({MsgId.HEARTBEAT, MsgId.RADIO_STATUS, MsgId.ADSB_VEHICLE, MsgId.COLLISION}),
}
"""Messages each autopilot accepts unsigned once signing is on (GCS_Signing.cpp; PX4 docs)."""

MAX_LAG_S = 0.5
"""Wall seconds the physics loop may fall behind before it stops trying to catch up."""


class _TcpVehicle(asyncio.Protocol):
    """One TCP connection to vehicle ``index``: bytes in go to the fleet as a stream."""

    def __init__(self, fleet: SitlFleet, index: int) -> None:
        self.fleet, self.index = fleet, index
        self.transport: asyncio.Transport | None = None
        self.peer: Address = ("", 0)

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        assert isinstance(transport, asyncio.Transport)
        self.transport = transport
        host, port = transport.get_extra_info("peername")[:2]
        self.peer = (str(host), int(port))
        self.fleet._tcp_connected(self.index, self)

    def data_received(self, data: bytes) -> None:
        self.fleet._on_datagram(self.index, data, self.peer, stream=True)

    def connection_lost(self, exc: Exception | None) -> None:
        self.fleet._tcp_disconnected(self.index, self)


def make_autopilot(
    index: int, cfg: SitlConfig, frames: Airframes, origin: GeoPoint, factory: Any, emit: Emit
) -> Autopilot:
    """The flavour's logic for vehicle ``index``."""
    cls: type[Autopilot] = ArduCopterLogic if cfg.flavour == "ardupilot" else Px4Logic
    return cls(index, cfg, frames, origin, factory, emit)


def grid_layout(n: int, spacing_m: float) -> FloatArray:
    """(n, 2) north/east spawn points on a square grid, row by row, starting at (0, 0).

    >>> grid_layout(3, 30.0).tolist()
    [[0.0, 0.0], [0.0, 30.0], [30.0, 0.0]]
    """
    cols = math.ceil(math.sqrt(n))
    k = np.arange(n)
    return np.stack([k // cols * spacing_m, k % cols * spacing_m], axis=-1).astype(np.float64)


class SitlFleet:
    """A fleet of mock autopilots (see the module docstring).

    Args:
        cfg: fleet settings. With a scenario, the vehicle count is the scenario's.
        scenario: place the vehicles at the scenario's spawn points, give them its targets,
            and fly its obstacles as ADS-B intruders. None: a grid at 1.5·d_col spacing.
        faults: faults to inject (may be changed while running).
        signing_key: 32-byte MAVLink 2 signing key, or None.
        traffic_start_s: start the intruders at this simulated time instead of with the swarm.
    """

    def __init__(
        self,
        cfg: SitlConfig,
        *,
        scenario: ScenarioConfig | None = None,
        faults: Faults | None = None,
        signing_key: bytes | None = None,
        traffic_start_s: float | None = None,
    ) -> None:
        self.cfg = cfg
        self.scenario = scenario
        self.faults = faults or Faults()
        self.rng = np.random.default_rng(cfg.seed)
        n = scenario.uav.count if scenario is not None else cfg.vehicles
        self.n = n
        if scenario is not None:
            layout = swarm_layout(scenario)
            spawn_ne = sim_to_ne(layout.positions_m)
            yaw = heading_to_yaw(layout.headings_rad)
            targets: FloatArray | None = sim_to_ne(layout.targets_m)
            d_col = scenario.d_col_m
            self.traffic: Traffic | None = Traffic(
                scenario, self.rng, cfg.cruise_alt_m, traffic_start_s
            )
        else:
            d_col = DEFAULT_D_COL_M
            spawn_ne = grid_layout(n, SPAWN_SPACING_FACTOR * d_col)
            yaw = np.zeros(n)
            targets = None
            self.traffic = None
        home3 = np.concatenate([spawn_ne, np.zeros((n, 1))], axis=1)
        self.frames = Airframes.on_ground(home3, yaw)
        lat, lon, _ = ned_to_geodetic(home3[:, 0], home3[:, 1], home3[:, 2], cfg.home)
        self.homes = [
            GeoPoint(float(a), float(b), cfg.home.alt_m) for a, b in zip(lat, lon, strict=True)
        ]
        m = self.traffic.count if self.traffic is not None else 0
        self.truth = GroundTruth(n, m, d_col, targets)
        signing = None
        if signing_key is not None:
            signing = SigningConfig(signing_key, allow_unsigned=UNSIGNED_ALLOWED[cfg.flavour])
        self.codecs = [Codec(i + 1, MavComponent.AUTOPILOT1, signing=signing) for i in range(n)]
        self.vehicles: list[Autopilot] = [
            make_autopilot(
                i,
                cfg,
                self.frames,
                cfg.home,
                self.codecs[i].factory,
                functools.partial(self._send, i),
            )
            for i in range(n)
        ]
        self.telemetry = TelemetryBuilder(
            self.codecs[0].factory,
            self.frames,
            cfg.home,
            self.homes,
            cfg.flavour,
            cfg.model.gps_noise_m,
            self.rng,
        )
        self.peers: list[Address | None] = [None] * n
        self.outs = [cfg.out_address(i) for i in range(n)]
        self.link_stats = [
            {"datagrams_in": 0, "datagrams_out": 0, "dropped_in": 0, "dropped_out": 0}
            for _ in range(n)
        ]
        self.endpoints: list[UdpEndpoint] = []
        self.tcp_clients: list[_TcpVehicle | None] = [None] * n
        """The client connected to each vehicle (TCP transport)."""
        self._ports: list[int] = []
        self._ticks = 0
        self._dt = 1.0 / cfg.physics_hz
        self._failure: BaseException | None = None
        self._done = asyncio.Event()
        self._stack: contextlib.AsyncExitStack | None = None
        self._task: asyncio.Task[None] | None = None
        self._pilot_done: set[int] = set()
        self._wall_start = 0.0
        self._wall_end: float | None = None
        self._time_limit_s = math.inf
        self._until_done = False
        self._loop: asyncio.AbstractEventLoop | None = None

    # -- lifetime -----------------------------------------------------------------------

    async def __aenter__(self) -> Self:
        if self._stack is not None:
            raise RuntimeError("this SitlFleet is already running; use one `async with`")
        stack = contextlib.AsyncExitStack()
        await stack.__aenter__()
        try:
            for i in range(self.n):
                if self.cfg.transport == "tcp":
                    self._ports.append(await self._serve_tcp(i, stack))
                    continue
                ep = UdpEndpoint(
                    (self.cfg.host, self.cfg.port(i)),
                    on_datagram=functools.partial(self._on_datagram, i),
                    name=f"sitl vehicle {i + 1} udp:{self.cfg.host}:{self.cfg.port(i)}",
                )
                self.endpoints.append(await stack.enter_async_context(ep))
                self._ports.append(ep.local_address[1])
            group = await stack.enter_async_context(asyncio.TaskGroup())
            self._loop = asyncio.get_running_loop()
            self._wall_start = self._loop.time()
            self._task = group.create_task(self._physics(), name="sitl.physics")
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
        stack, self._stack = self._stack, None
        if self._task is not None:
            self._task.cancel()
        if self._loop is not None:
            self._wall_end = self._loop.time()
        if stack is None:
            return
        if exc_type is not None and issubclass(exc_type, asyncio.CancelledError):
            await stack.__aexit__(exc_type, exc, tb)  # let the TaskGroup see its own cancel
        else:  # the caller's own error propagates as it is, not wrapped in a group
            await stack.aclose()

    async def _serve_tcp(self, i: int, stack: contextlib.AsyncExitStack) -> int:
        """Listen for vehicle ``i``'s TCP client; returns the port."""
        loop = asyncio.get_running_loop()
        host, port = self.cfg.host, self.cfg.port(i)
        try:
            server = await loop.create_server(lambda: _TcpVehicle(self, i), host, port)
        except OSError as exc:
            raise LinkLost(
                f"cannot listen ({exc.strerror or exc}); is another program using the port?",
                link=f"sitl vehicle {i + 1} tcp:{host}:{port}",
            ) from exc

        async def close() -> None:
            server.close()
            client = self.tcp_clients[i]
            if client is not None and client.transport is not None:
                client.transport.close()
            await server.wait_closed()

        stack.push_async_callback(close)
        bound: int = server.sockets[0].getsockname()[1]
        return bound

    def _tcp_connected(self, i: int, client: _TcpVehicle) -> None:
        old = self.tcp_clients[i]
        if old is not None and old.transport is not None:
            old.transport.close()  # one client at a time, as a serial port over TCP
        self.tcp_clients[i] = client
        self.peers[i] = client.peer

    def _tcp_disconnected(self, i: int, client: _TcpVehicle) -> None:
        if self.tcp_clients[i] is client:
            self.tcp_clients[i] = None
            self.peers[i] = None

    @property
    def addresses(self) -> list[Address]:
        """(host, port) each vehicle listens on, by vehicle index."""
        return [(self.cfg.host, port) for port in self._ports]

    def now_s(self) -> float:
        """Simulated seconds since start."""
        return self._ticks * self._dt

    async def wait(self, *, until_done: bool = False, timeout_s: float | None = None) -> bool:
        """Run until every vehicle is done (``until_done``) or ``timeout_s`` simulated seconds.

        Returns:
            True if the fleet finished, False if the time ran out (or neither was asked and
            the task was cancelled).
        """
        self._until_done = until_done
        self._time_limit_s = math.inf if timeout_s is None else timeout_s
        await self._done.wait()
        return self.finished()

    def finished(self) -> bool:
        """Every vehicle has reached its target, or flown and landed."""
        reached = self.truth.reached()
        return all(
            bool(reached[i]) or (ap.flew and ap.landed) for i, ap in enumerate(self.vehicles)
        )

    # -- the clock ----------------------------------------------------------------------

    async def _physics(self) -> None:
        loop = asyncio.get_running_loop()
        start = loop.time()
        wall_per_tick = self._dt / self.cfg.speedup
        autopilot_every = max(1, round(self.cfg.physics_hz / TICK_HZ))
        heartbeat_every = max(1, round(self.cfg.physics_hz / self.cfg.heartbeat_hz))
        adsb_every = max(1, round(self.cfg.physics_hz / self.cfg.adsb_hz))
        while True:
            delay = start + (self._ticks + 1) * wall_per_tick - loop.time()
            if delay > 0:
                await asyncio.sleep(delay)
            else:
                if delay < -MAX_LAG_S:  # cannot keep up: stop owing time, run slower
                    start -= delay + MAX_LAG_S
                await asyncio.sleep(0)
            if self._failure is not None:
                raise self._failure
            self._ticks += 1
            k = self._ticks
            self._tick(
                self.now_s(),
                autopilot=k % autopilot_every == 0,
                beat_phase=k % heartbeat_every,
                beat_every=heartbeat_every,
                adsb=k % adsb_every == 0,
            )
            if self.now_s() >= self._time_limit_s or (self._until_done and self.finished()):
                self._done.set()

    def _tick(
        self, now: float, *, autopilot: bool, beat_phase: int, beat_every: int, adsb: bool
    ) -> None:
        f = self.frames
        self._apply_faults(now)
        step(f, self.cfg.model, self._dt, self.rng)
        intruders = np.zeros((0, 3))
        if self.traffic is not None:
            self.traffic.maybe_start(now, f.vel_ned_m_s)
            intruders = self.traffic.positions_ned(now)
        self.truth.record(now, f.pos_ned_m, intruders)
        for i, ap in enumerate(self.vehicles):
            if autopilot:
                ap.tick(now)
            if self.peers[i] is None and self.outs[i] is None:
                ap.due_streams(now)  # nobody listens: keep the schedule, build nothing
                continue
            # each vehicle beats at its own phase, as independent autopilots do (no bursts)
            beat = beat_phase == (i * beat_every) // self.n
            if beat and not self.faults.heartbeat_muted(i, now):
                self._send(i, heartbeat(ap.factory, ap))
            for mid in ap.due_streams(now) + ap.requested:
                msg = self.telemetry.build(mid, i, ap, now)
                if msg is not None:
                    self._send(i, msg)
            ap.requested.clear()
            if adsb and self.traffic is not None and self.traffic.count:
                for report in self.traffic.reports(ap.factory, self.cfg.home, now):
                    self._send(i, report, component=MavComponent.ADSB)

    def _apply_faults(self, now: float) -> None:
        for k, sw in enumerate(self.faults.pilot_switches):
            if k not in self._pilot_done and now >= sw.at_s:
                self._pilot_done.add(k)
                targets = range(self.n) if sw.vehicle is None else [sw.vehicle]
                for i in targets:
                    if i < self.n and not self.vehicles[i].pilot_mode(sw.mode, now):
                        raise ValueError(
                            f"pilot mode {sw.mode!r} is not a {self.cfg.flavour} mode the "
                            "mock models"
                        )
        if self.faults.gps_glitches:
            for i, state in enumerate(self.telemetry.gps):
                off = self.faults.gps_offset_m(i, now)
                state.glitching = off is not None
                state.offset_ne_m = (off or 0.0, 0.0)

    # -- datagrams ----------------------------------------------------------------------

    def _send(self, i: int, msg: Any, *, component: int | None = None) -> None:
        frame = self.codecs[i].encode(msg, source_component=component)
        now = self.now_s()
        dests = {d for d in (self.peers[i], self.outs[i]) if d is not None}
        for dest in dests:
            if self.faults.link_down(i, now) or self.faults.drop(self.rng):
                self.link_stats[i]["dropped_out"] += 1
                continue
            self.link_stats[i]["datagrams_out"] += 1
            delay = self.faults.delay_s(self.rng) / self.cfg.speedup
            if delay > 0 and self._loop is not None:
                self._loop.call_later(delay, self._raw_send, i, frame, dest)
            else:
                self._raw_send(i, frame, dest)

    def _raw_send(self, i: int, frame: bytes, dest: Address) -> None:
        if self.cfg.transport == "tcp":
            client = self.tcp_clients[i]
            transport = client.transport if client is not None and client.peer == dest else None
            if transport is not None and not transport.is_closing():
                transport.write(frame)
            return
        ep = self.endpoints[i] if i < len(self.endpoints) else None
        if ep is not None and ep.is_open:
            ep.send(frame, dest)

    def _on_datagram(self, i: int, data: bytes, addr: Address, *, stream: bool = False) -> None:
        now = self.now_s()
        if self.faults.link_down(i, now) or self.faults.drop(self.rng):
            self.link_stats[i]["dropped_in"] += 1  # over TCP: a cut frame, as on a noisy serial
            return
        delay = self.faults.delay_s(self.rng) / self.cfg.speedup
        if delay > 0 and self._loop is not None:
            self._loop.call_later(delay, self._deliver, i, data, addr, stream)
        else:
            self._deliver(i, data, addr, stream)

    def _deliver(self, i: int, data: bytes, addr: Address, stream: bool = False) -> None:
        self.link_stats[i]["datagrams_in"] += 1
        ap = self.vehicles[i]
        try:
            msgs = self.codecs[i].decode(data, addr, datagram=not stream)
            if msgs:
                self.peers[i] = addr
            now = self.now_s()
            for msg in msgs:
                if msg.get_srcSystem() != ap.system_id:
                    ap.handle(msg, now)
        except Exception as exc:  # a bug in the mock: stop the fleet loudly, not in a log
            self._failure = exc

    # -- results ------------------------------------------------------------------------

    def summary(self) -> dict[str, Any]:
        """Ground truth and counters of the flight so far (JSON-ready)."""
        wall = 0.0
        if self._loop is not None:
            end = self._wall_end if self._wall_end is not None else self._loop.time()
            wall = end - self._wall_start
        vehicles = []
        for i, ap in enumerate(self.vehicles):
            codec = self.codecs[i].stats
            entry: dict[str, Any] = {
                "system_id": ap.system_id,
                "port": self._ports[i] if i < len(self._ports) else self.cfg.port(i),
                "home": dataclasses.asdict(self.homes[i]),
                "armed": ap.armed,
                "custom_mode": ap.custom_mode,
                "flew": ap.flew,
                "landed": ap.landed,
                **self.truth.vehicle_summary(i),
                **ap.counters.as_dict(),
                "params": ap.param_table.snapshot(ap.params()),
                "link": {
                    **self.link_stats[i],
                    "bad_frames": codec.bad_frames,
                    "rejected_unsigned": codec.rejected_unsigned,
                },
            }
            vehicles.append(entry)
        sim_s = self.now_s()
        return {
            "flavour": self.cfg.flavour,
            "scenario": self.scenario.name if self.scenario is not None else None,
            "finished": self.finished(),
            "simulated_s": round(sim_s, 3),
            "wall_s": round(wall, 3),
            "achieved_speedup": round(sim_s / wall, 3) if wall > 0 else None,
            "intruders": self.traffic.count if self.traffic is not None else 0,
            **self.truth.overall(),
            "vehicles": vehicles,
        }

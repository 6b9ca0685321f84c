"""The mock fleet: N vehicles, each a MAVLink 2 endpoint on its own UDP (or TCP) port, one loop.

    async with SitlFleet(SitlConfig(vehicles=3, flavour="px4", base_port=0)) as fleet:
        print(fleet.addresses)        # where to connect
        await fleet.wait(until_done=True, timeout_s=120.0)
    print(fleet.summary())            # ground truth

One task (``sitl.physics``, owned by the fleet's TaskGroup) runs the simulated clock: each
physics tick steps every airframe at once, records the ground truth, runs the autopilot timers
and sends whatever HEARTBEAT, telemetry and ADS-B is due. Datagrams are handled as they arrive
(`remarl_fc.sitl.links`: ``datagram_received`` or, over TCP, ``data_received`` → codec →
autopilot), stamped with the simulated time; the faults act on frames the same way on both
transports. The simulated
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
from typing import Any

import numpy as np
from numpy.typing import NDArray

from remarl_fc.frames import GeoPoint, heading_to_yaw, ned_to_geodetic, sim_to_ne
from remarl_fc.mavlink.codec import Codec, SigningConfig
from remarl_fc.mavlink.consts import MavComponent, MsgId
from remarl_fc.mavlink.udp import Address
from remarl_fc.resource import StackOwner
from remarl_fc.sitl.ardupilot import ArduCopterLogic
from remarl_fc.sitl.autopilot import TICK_HZ, Autopilot
from remarl_fc.sitl.channel import Emit
from remarl_fc.sitl.config import Flavour, SitlConfig
from remarl_fc.sitl.faults import Faults
from remarl_fc.sitl.groundtruth import GroundTruth
from remarl_fc.sitl.links import FleetLinks
from remarl_fc.sitl.px4 import Px4Logic
from remarl_fc.sitl.telemetry import TelemetryBuilder, heartbeat
from remarl_fc.sitl.traffic import ReportErrors, Traffic
from remarl_fc.sitl.vehicle import Airframes, step
from sim.config import ScenarioConfig, SensorConfig
from sim.spawn import SPAWN_SPACING_FACTOR, EpisodeStart, spawn_episodes
from sim.vehicle import DelayLine, load_profile

FloatArray = NDArray[np.float64]

DEFAULT_D_COL_M = float(ScenarioConfig.__dataclass_fields__["d_col_m"].default)  # type: ignore[arg-type]
"""Collision distance of a fleet without a scenario: the scenario default (d_col, 20 m)."""

MAX_LAG_S = 0.5
"""Wall seconds the physics loop may fall behind before it stops trying to catch up."""


FLAVOURS: dict[Flavour, type[Autopilot[Any]]] = {"ardupilot": ArduCopterLogic, "px4": Px4Logic}
"""The autopilot logic of each flavour."""


def make_autopilot(
    index: int, cfg: SitlConfig, frames: Airframes, origin: GeoPoint, factory: Any, emit: Emit
) -> Autopilot[Any]:
    """The flavour's logic for vehicle ``index``."""
    return FLAVOURS[cfg.flavour](index, cfg, frames, origin, factory, emit)


def grid_layout(n: int, spacing_m: float) -> FloatArray:
    """(n, 2) north/east spawn points on a square grid, row by row, starting at (0, 0).

    >>> grid_layout(3, 30.0).tolist()
    [[0.0, 0.0], [0.0, 30.0], [30.0, 0.0]]
    """
    cols = math.ceil(math.sqrt(n))
    k = np.arange(n)
    return np.stack([k // cols * spacing_m, k % cols * spacing_m], axis=-1).astype(np.float64)


class SitlFleet(StackOwner):
    """A fleet of mock autopilots (see the module docstring).

    Args:
        cfg: fleet settings. With a scenario, the vehicle count is the scenario's.
        scenario: place the vehicles at the scenario's spawn points, give them its targets,
            and fly its obstacles as ADS-B intruders. None: a grid at 1.5·d_col spacing.
        episode: with a scenario, the episode to fly (B = 1: starts, targets, intruders; e.g.
            an encounter drawn by `sim.encounters.sample_family`); None: one drawn from the
            scenario (`sim.spawn.spawn_episodes`, from the fleet's seed).
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
        episode: EpisodeStart | None = None,
    ) -> None:
        self.cfg = cfg
        self.scenario = scenario
        self.rng = np.random.default_rng(cfg.seed)
        n = scenario.uav.count if scenario is not None else cfg.vehicles
        self.n = n
        if scenario is not None:
            if episode is None:
                episode = spawn_episodes(scenario, self.rng, 1)
            episode.check(scenario)
            if episode.num_envs != 1:
                raise ValueError(f"the mock flies one episode, got {episode.num_envs}")
            spawn_ne = sim_to_ne(episode.start_m[0])
            yaw = heading_to_yaw(episode.headings()[0])
            targets: FloatArray | None = sim_to_ne(episode.target_m[0])
            d_col = scenario.d_col_m
            errors = None
            if cfg.adsb_noise:
                count = episode.obstacle_pos_m.shape[1]
                errors = ReportErrors.drawn(count, SensorConfig(), cfg.adsb_hz, cfg.seed, self.rng)
            self.traffic: Traffic | None = Traffic(
                episode.obstacle_pos_m[0],
                episode.obstacle_vel_m_s[0],
                cfg.cruise_alt_m,
                traffic_start_s,
                errors,
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
            unsigned = FLAVOURS[cfg.flavour].spec.unsigned_allowed
            signing = SigningConfig(signing_key, allow_unsigned=unsigned)
        self._ticks = 0
        self._dt = 1.0 / cfg.physics_hz
        fitted = FLAVOURS[cfg.flavour].spec.vehicle_profile
        self.vehicle_profile = load_profile(
            fitted if cfg.model.profile == "flavour" else cfg.model.profile
        )
        self._delay = DelayLine(self.vehicle_profile.delay_s, self._dt)
        self.links = FleetLinks(
            cfg, n, faults or Faults(), self.rng, self.now_s, self._on_message, signing
        )
        self.vehicles: list[Autopilot[Any]] = [
            make_autopilot(
                i,
                cfg,
                self.frames,
                cfg.home,
                self.codecs[i].factory,
                functools.partial(self.links.send, i),
            )
            for i in range(n)
        ]
        self.telemetry = TelemetryBuilder(
            self.codecs[0].factory,
            self.frames,
            cfg.home,
            self.homes,
            cfg.model.gps_noise_m,
            self.rng,
        )
        self._done = asyncio.Event()
        self._task: asyncio.Task[None] | None = None
        self._pilot_done: set[int] = set()
        self._wall_start = 0.0
        self._wall_end: float | None = None
        self._time_limit_s = math.inf
        self._until_done = False
        self._loop: asyncio.AbstractEventLoop | None = None

    # -- lifetime -----------------------------------------------------------------------

    async def _enter(self, stack: contextlib.AsyncExitStack) -> None:
        """Open the links and start the physics task, on ``stack``."""
        await self.links.open(stack)
        group = await stack.enter_async_context(asyncio.TaskGroup())
        self._loop = self.links.loop = asyncio.get_running_loop()
        self._wall_start = self._loop.time()
        self._task = group.create_task(self._physics(), name="sitl.physics")

    async def _leave(self, exc_type: type[BaseException] | None) -> None:
        """Stop the physics before the links close."""
        if self._task is not None:
            self._task.cancel()
        if self._loop is not None:
            self._wall_end = self._loop.time()

    @property
    def faults(self) -> Faults:
        """The faults acting on the fleet (mutate or replace them while it runs)."""
        return self.links.faults

    @faults.setter
    def faults(self, faults: Faults) -> None:
        self.links.faults = faults

    @property
    def codecs(self) -> list[Codec]:
        """Each vehicle's MAVLink codec (its signing counters among its stats)."""
        return self.links.codecs

    @property
    def link_stats(self) -> list[dict[str, int]]:
        """Each vehicle's datagram counters: in, out, dropped either way."""
        return self.links.stats

    @property
    def addresses(self) -> list[Address]:
        """(host, port) each vehicle listens on, by vehicle index."""
        return [(self.cfg.host, port) for port in self.links.ports]

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
        while True:
            delay = start + (self._ticks + 1) * wall_per_tick - loop.time()
            if delay > 0:
                await asyncio.sleep(delay)
            else:
                if delay < -MAX_LAG_S:  # cannot keep up: stop owing time, run slower
                    start -= delay + MAX_LAG_S
                await asyncio.sleep(0)
            if self.links.failure is not None:
                raise self.links.failure
            self._ticks += 1
            k = self._ticks
            self._tick(
                self.now_s(),
                autopilot=k % autopilot_every == 0,
                beat_phase=k % heartbeat_every,
                beat_every=heartbeat_every,
            )
            if self.now_s() >= self._time_limit_s or (self._until_done and self.finished()):
                self._done.set()

    def _tick(self, now: float, *, autopilot: bool, beat_phase: int, beat_every: int) -> None:
        f = self.frames
        self._apply_faults(now)
        step(f, self.cfg.model, self._dt, self.rng, self.vehicle_profile, self._delay)
        intruders = np.zeros((0, 3))
        if self.traffic is not None:
            self.traffic.maybe_start(now, f.vel_ned_m_s)
            intruders = self.traffic.positions_ned(now)
        self.truth.record(now, f.pos_ned_m, intruders)
        for i, ap in enumerate(self.vehicles):
            if autopilot:
                ap.tick(now)
            if not self.links.listening(i):
                ap.streams.due(now)  # nobody listens: keep the schedule, build nothing
                continue
            send = self.links.send
            # each vehicle beats at its own phase, as independent autopilots do (no bursts)
            beat = beat_phase == (i * beat_every) // self.n
            if beat and not self.faults.heartbeat_muted(i, now):
                send(i, heartbeat(ap.factory, ap))
            for mid in ap.streams.due(now) + ap.streams.take_requested():
                if mid == MsgId.ADSB_VEHICLE:
                    self._send_traffic(i, ap, now)
                    continue
                msg = self.telemetry.build(mid, i, ap, now)
                if msg is not None:
                    send(i, msg)

    def _send_traffic(self, i: int, ap: Autopilot[Any], now: float) -> None:
        """Vehicle i's ADSB_VEHICLE stream: one report per intruder, from its ADS-B receiver."""
        if self.traffic is None or not self.traffic.count:
            return
        for report in self.traffic.reports(ap.factory, self.cfg.home, now):
            self.links.send(i, report, component=MavComponent.ADSB)

    def _apply_faults(self, now: float) -> None:
        for k, sw in enumerate(self.faults.pilot_switches):
            if k not in self._pilot_done and now >= sw.at_s:
                self._pilot_done.add(k)
                for i in range(self.n):
                    if sw.targets(i) and not self.vehicles[i].pilot_mode(sw.mode, now):
                        raise ValueError(
                            f"pilot mode {sw.mode!r} is not a {self.cfg.flavour} mode the "
                            "mock models"
                        )
        if self.faults.gps_glitches:
            for i, state in enumerate(self.telemetry.gps):
                off = self.faults.gps_offset_m(i, now)
                state.glitching = off is not None
                state.offset_ne_m = (off or 0.0, 0.0)

    def _on_message(self, i: int, msg: Any) -> None:
        """A message for vehicle ``i`` (its own echoes are not)."""
        ap = self.vehicles[i]
        if msg.get_srcSystem() != ap.system_id:
            ap.handle(msg, self.now_s())

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
                "port": self.links.ports[i] if i < len(self.links.ports) else self.cfg.port(i),
                "home": dataclasses.asdict(self.homes[i]),
                "armed": ap.armed,
                "custom_mode": ap.custom_mode,
                "flew": ap.flew,
                "landed": ap.landed,
                **self.truth.vehicle_summary(i),
                **ap.counters.as_dict(),
                "params": ap.param_snapshot(),
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
            "adsb_noise": self.cfg.adsb_noise,
            **self.truth.overall(),
            "vehicles": vehicles,
        }

"""``remarl-fc demo``: the mock fleet and the runtime in one process, flying a shipped policy.

`fly_on_mock` starts `remarl-fc sitl --scenario NAME` in-process (every vehicle sending to
one UDP port), opens the runtime on that port with the scenario's mission, takes off, flies
the policy to the targets, holds, and returns both sides' accounts: the runtime's (what it
decided and why) and the mock's ground truth (what really happened). Tests use it for the
closed-loop flights; the demo prints it.

With ``vehicles`` (``remarl-fc demo --vehicles N``) the geometry is drawn instead of read
from a scenario: N vehicles and M intruders of an encounter (`drawn_encounter`, the
benchmark's generator `sim.encounters`), the same for the same seed. Either is flown by the
zoo's generalist policy where it is shipped (`demo_policy`).
"""

from __future__ import annotations

import asyncio
import dataclasses
import math
import socket
from collections.abc import Callable, Coroutine
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from remarl_fc.errors import ConfigError
from remarl_fc.flight.config import FLY_SHIELD, FlyConfig
from remarl_fc.flight.control import ControlSpec
from remarl_fc.flight.mission import Geofence, Mission
from remarl_fc.flight.runtime import SwarmRuntime
from remarl_fc.flight.status import Status
from remarl_fc.mavlink.codec import SigningConfig
from remarl_fc.policy_io import GENERALIST_ZOO, load_policy, zoo_dir
from remarl_fc.sitl.attacker import Attacker
from remarl_fc.sitl.config import ARDUPILOT_QUICK_START, DEFAULT_HOME, Flavour, SitlConfig
from remarl_fc.sitl.faults import Faults
from remarl_fc.sitl.fleet import SitlFleet
from sim.config import ScenarioConfig
from sim.encounters import DISTRIBUTIONS, Family, Formation, sample_family
from sim.scenarios import load_scenario
from sim.shield import ShieldConfig, track_growth_behind
from sim.spawn import EpisodeStart

CRUISE_ALT_M = 20.0
"""Take-off and cruise height of the demo, above the origin (the intruders fly at it too)."""


@dataclass
class MockFlight:
    """Both accounts of a flight on the mock."""

    runtime: dict[str, Any]
    ground_truth: dict[str, Any]


def attacker_for(
    runtime: SwarmRuntime,
    victim: int = 2,
    seed: int = 0,
    *,
    radio: bool = False,
    from_start: bool = True,
) -> Attacker:
    """A hostile sender (`remarl_fc.sitl.attacker`) against ``runtime``'s first link.

    It watches ``victim``'s true track (here: the runtime's own, before any forged fix could
    touch it) and starts its in-flight attacks once every vehicle is under control. With
    ``radio`` its frames arrive from the victim's own address (a forger on the vehicle's
    radio link: binding cannot tell them apart, only signing can), once the victim is bound.
    """
    address = runtime.links[0].local_address
    if address is None:
        raise ValueError("the runtime's first link is not a UDP listener (udpin:)")
    track = runtime.by_sysid[victim].track

    def locate() -> tuple[tuple[float, float, float], tuple[float, float]] | None:
        if not math.isfinite(track.t_position):
            return None
        n, e = (float(x) for x in track.ne_m)
        vn, ve = (float(x) for x in track.vel_ned_m_s[:2])
        return (n, e, float(track.height_m)), (vn, ve)

    def centre() -> tuple[float, float] | None:
        known = [m.track.ne_m for m in runtime.members if math.isfinite(m.track.t_position)]
        if not known:
            return None
        n, e = np.mean(known, axis=0)
        return float(n), float(e)

    link = runtime.links[0]

    def inject(frame: bytes) -> None:
        if victim in link.bound:
            link._received(frame, link.where[victim])

    return Attacker(
        inject=inject if radio else None,
        from_start=from_start,
        target=address,
        victim=victim,
        origin=runtime.cfg.mission.origin,
        locate=locate,
        centre=centre,
        armed=lambda: all(s == Status.CONTROLLED for s in runtime.statuses()),
        seed=seed,
    )


def free_udp_port(host: str = "127.0.0.1") -> int:
    """A UDP port nobody holds right now."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind((host, 0))
        return int(s.getsockname()[1])


ROBUST_ZOO = "robust"
"""The zoo folder of the policies trained on fitted vehicles and ADS-B (`policies/zoo/robust`)."""

DEMO_DISTRIBUTION = "crossing"
"""The encounter distribution of ``demo --vehicles`` (`sim.encounters.DISTRIBUTIONS`): the
swarm flies its routes in formation, each intruder crosses one vehicle's route at 30–150°."""

DEMO_FORMATION: Formation = "random"
"""The swarm's formation in ``demo --vehicles``: scattered, no two closer than 1.5·d_col."""

DEFAULT_INTRUDERS = 2
"""Intruders of ``demo --vehicles`` when not given."""

MAX_DEMO_VEHICLES = 20
"""The most vehicles ``demo --vehicles`` flies (the mock runs every airframe in one process)."""

MAX_DEMO_INTRUDERS = 8
"""The most intruders ``demo --vehicles`` draws (a generalist's: 0 to 8)."""


def demo_policy(scenario: str) -> str:
    """The policy the demo flies, on ``scenario`` or on drawn vehicles.

    The zoo's generalist where it is shipped (any number of vehicles). Where it is not, the
    zoo's robust policy of the scenario where there is one (the mock's vehicles answer like
    real autopilots), else the zoo policy of the scenario.
    """
    if (zoo_dir() / f"{GENERALIST_ZOO}.safetensors").is_file():
        return GENERALIST_ZOO
    return scenario_policy(scenario)


def scenario_policy(scenario: str) -> str:
    """The zoo's own policy of ``scenario``: the robust one where there is one, else its own."""
    robust = f"{ROBUST_ZOO}/{scenario}"
    return robust if (zoo_dir() / f"{robust}.safetensors").is_file() else scenario


def drawn_encounter(
    vehicles: int, intruders: int, seed: int, spec: ControlSpec
) -> tuple[ScenarioConfig, EpisodeStart]:
    """N vehicles with targets and M intruders, drawn from ``seed``.

    One episode of a `DEMO_DISTRIBUTION` family of the encounter generator (`sim.encounters`)
    at the policy's speed, step and d_col (``spec``): the same seed, the same geometry.

    Returns:
        The family's scenario (N UAVs, M obstacles) and its episode (B = 1), which the mock
        (`SitlFleet`'s ``episode``) and the mission (`Mission.from_scenario`) both fly.

    Raises:
        ConfigError: N outside 1..`MAX_DEMO_VEHICLES` or M outside 0..`MAX_DEMO_INTRUDERS`.
    """
    if not 1 <= vehicles <= MAX_DEMO_VEHICLES:
        raise ConfigError(f"vehicles must be 1 to {MAX_DEMO_VEHICLES}, got {vehicles}")
    if not 0 <= intruders <= MAX_DEMO_INTRUDERS:
        raise ConfigError(f"intruders must be 0 to {MAX_DEMO_INTRUDERS}, got {intruders}")
    family = Family(
        f"random {vehicles}u{intruders}o",
        DEMO_DISTRIBUTION,
        uavs=vehicles,
        formation=DEMO_FORMATION,
        encounter=dataclasses.replace(DISTRIBUTIONS[DEMO_DISTRIBUTION], intruders=intruders),
        overrides={
            "uav": {"speed_m_s": spec.speed_m_s},
            "dt_s": spec.dt_s,
            "d_col_m": spec.arrival_m,
        },
    )
    return sample_family(family, seed, [0])


async def fly_on_mock(
    scenario: str = "3u2o",
    policy: str | None = None,
    *,
    flavour: Flavour = "ardupilot",
    speedup: float = 1.0,
    faults: Faults | None = None,
    log_dir: Path | None = None,
    on_status: Callable[[str], None] | None = None,
    seed: int = 0,
    during: Callable[[SitlFleet, SwarmRuntime], Coroutine[Any, Any, None]] | None = None,
    fly_options: dict[str, Any] | None = None,
    geofence: Geofence | None = None,
    vehicles: int | None = None,
    intruders: int = DEFAULT_INTRUDERS,
    link_per_vehicle: bool = False,
    tcp: bool = False,
    signing_key: bytes | None = None,
    sitl_options: dict[str, Any] | None = None,
    quick_start: bool = False,
    shield: ShieldConfig | None = None,
) -> MockFlight:
    """Fly ``policy`` (default: `demo_policy`) on a mock of ``scenario``, or of a drawn encounter.

    Args:
        seed: the mock's noise, and the drawn encounter's geometry.
        during: a coroutine run alongside the flight (tests inject faults with it); it is
            cancelled when the flight ends.
        fly_options: extra `FlyConfig` fields.
        geofence: add this fence to the scenario's mission.
        link_per_vehicle: one ``udpout:`` connection per vehicle port (ArduPilot SITL style)
            instead of one ``udpin:`` port that every vehicle sends to.
        tcp: the vehicles are TCP servers and the runtime connects ``tcp:`` to each (ArduPilot
            SITL's serial-over-TCP ports).
        signing_key: sign both sides with this key (the mock then rejects unsigned commands).
        sitl_options: extra `SitlConfig` fields (e.g. ``px4=Px4Params(...)``).
        quick_start: skip ArduCopter's slow start (EKF ready after 5 s instead of 39 s, the
            climb at once after the take-off ACK): for tests that do not exercise the start.
        shield: the safety shield behind the policy; None: `FlyConfig`'s (on), with the track
            growth for the policy (`sim.shield.track_growth_behind`), as `remarl-fc demo`.
        vehicles: fly this many vehicles and ``intruders`` intruders drawn from ``seed``
            (`drawn_encounter`) instead of ``scenario``, for at most the drawn family's step
            limit under control (``max_flight_s`` = max_steps × dt, as the simulator's episodes
            end; ``fly_options`` may say otherwise).

    Raises:
        PolicySpecMismatch: the policy cannot fly the scenario (or N vehicles: a
            `remarl_fc.flight.mission.VehicleCountMismatch` says what to do).
    """
    pol = load_policy(policy or demo_policy(scenario))
    spec = ControlSpec.from_policy_meta(pol.meta)
    episode: EpisodeStart | None = None
    if vehicles is None:
        cfg = load_scenario(scenario)
        pol.check_scenario(cfg)
    else:
        cfg, episode = drawn_encounter(vehicles, intruders, seed, spec)
        fly_options = {"max_flight_s": cfg.max_steps * cfg.dt_s, **(fly_options or {})}
    if shield is None:  # FlyConfig's, keeping the policy's track growth
        growth = track_growth_behind(pol.sees_neighbours)
        shield = dataclasses.replace(FLY_SHIELD, track_growth_m_s=growth)
    fly_options = {"shield": shield, **(fly_options or {})}
    mission = Mission.from_scenario(cfg, DEFAULT_HOME, CRUISE_ALT_M, episode=episode)
    mission.check_policy(pol.uav_range, spec.speed_m_s, spec.dt_s, spec.arrival_m)
    # held until the runtime binds it: the fleet's own sockets take ephemeral ports, and one
    # of them could otherwise take this one between the choice and the bind
    reservation = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        reservation.bind(("127.0.0.1", 0))
        port = int(reservation.getsockname()[1])
        options: dict[str, Any] = {"ardupilot": ARDUPILOT_QUICK_START} if quick_start else {}
        options.update(sitl_options or {})
        sitl = SitlConfig(
            vehicles=cfg.uav.count,
            flavour=flavour,
            base_port=0,
            transport="tcp" if tcp else "udp",
            out=None if link_per_vehicle or tcp else ("127.0.0.1", port),
            speedup=speedup,
            cruise_alt_m=CRUISE_ALT_M,
            seed=seed,
            **options,
        )
        if geofence is not None:
            mission = dataclasses.replace(mission, geofence=geofence)
        fleet = SitlFleet(
            sitl, scenario=cfg, faults=faults, signing_key=signing_key, episode=episode
        )
        signing = SigningConfig(signing_key) if signing_key is not None else None
        # the fleet outlives the runtime: the runtime's hold commands on exit must reach it
        async with fleet:
            reservation.close()  # bound by the fleet's sockets now: the runtime's to take
            connections: tuple[str, ...] = (f"udpin:127.0.0.1:{port}",)
            if link_per_vehicle or tcp:
                kind = "tcp" if tcp else "udpout"
                connections = tuple(f"{kind}:{h}:{p}" for h, p in fleet.addresses)
            fly = FlyConfig(
                connections=connections,
                mission=mission,
                takeoff_m=CRUISE_ALT_M,
                log_dir=log_dir,
                speedup=speedup,
                signing=signing,
                **(fly_options or {}),
            )
            runtime = SwarmRuntime(fly, pol, spec, on_status=on_status)
            await _fly(fleet, runtime, during, speedup)
    finally:
        reservation.close()
    return MockFlight(runtime.summary(), fleet.summary())


async def _fly(
    fleet: SitlFleet,
    runtime: SwarmRuntime,
    during: Callable[[SitlFleet, SwarmRuntime], Coroutine[Any, Any, None]] | None,
    speedup: float,
) -> None:
    async with runtime:
        if during is None:
            await runtime.run()
        else:
            async with asyncio.TaskGroup() as tg:
                side = tg.create_task(during(fleet, runtime), name="demo.during")
                await runtime.run()
                side.cancel()
        await asyncio.sleep(1.0 / speedup)  # the last hold commands take effect

"""``remarl-fc demo``: the mock fleet and the runtime in one process, flying a shipped policy.

`fly_on_mock` starts `remarl-fc sitl --scenario NAME` in-process (every vehicle sending to
one UDP port), opens the runtime on that port with the scenario's mission, takes off, flies
the policy to the targets, holds, and returns both sides' accounts: the runtime's (what it
decided and why) and the mock's ground truth (what really happened). Tests use it for the
closed-loop flights; the demo prints it.
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

from remarl_fc.flight.config import FlyConfig
from remarl_fc.flight.control import ControlSpec
from remarl_fc.flight.mission import Geofence, Mission
from remarl_fc.flight.runtime import SwarmRuntime
from remarl_fc.flight.status import Status
from remarl_fc.mavlink.codec import SigningConfig
from remarl_fc.policy_io import load_policy, zoo_dir
from remarl_fc.sitl.attacker import Attacker
from remarl_fc.sitl.config import ARDUPILOT_QUICK_START, DEFAULT_HOME, Flavour, SitlConfig
from remarl_fc.sitl.faults import Faults
from remarl_fc.sitl.fleet import SitlFleet
from sim.scenarios import load_scenario

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


def demo_policy(scenario: str) -> str:
    """The policy the demo flies on a scenario.

    The zoo's robust one where there is one (the mock's vehicles answer like real autopilots),
    else the zoo policy of the scenario.
    """
    robust = f"{ROBUST_ZOO}/{scenario}"
    return robust if (zoo_dir() / f"{robust}.safetensors").is_file() else scenario


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
    link_per_vehicle: bool = False,
    tcp: bool = False,
    signing_key: bytes | None = None,
    sitl_options: dict[str, Any] | None = None,
    quick_start: bool = False,
) -> MockFlight:
    """Fly ``policy`` (default: `demo_policy` of ``scenario``) on a mock of ``scenario``.

    Args:
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
    """
    cfg = load_scenario(scenario)
    pol = load_policy(policy or demo_policy(scenario))
    pol.check_scenario(cfg)
    port = free_udp_port()
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
    mission = Mission.from_scenario(cfg, DEFAULT_HOME, CRUISE_ALT_M)
    if geofence is not None:
        mission = dataclasses.replace(mission, geofence=geofence)
    spec = ControlSpec.from_policy_meta(pol.meta)
    fleet = SitlFleet(sitl, scenario=cfg, faults=faults, signing_key=signing_key)
    signing = SigningConfig(signing_key) if signing_key is not None else None
    # the fleet outlives the runtime: the runtime's hold commands on exit must reach it
    async with fleet:
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

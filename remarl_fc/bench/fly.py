"""``remarl-fc bench fly``: the runtime's timings against the mock, for 10 to 100+ vehicles.

The mock fleet (ArduPilot flavour, 1× time) and the runtime share one process — the figures
include the mock's own load, so they are an upper bound for the runtime alone. The policy is
the zoo's 10u1o one with its per-agent networks repeated to N agents (the timings depend on
the network's size, not its weights). Vehicles take off from a grid and fly north; measured
while under control:

* setpoint tick: safety checks + one SET_POSITION_TARGET_LOCAL_NED per vehicle — the
  processing between the latest telemetry and the setpoints that use it (p50 / p99, and per
  vehicle);
* decision: every vehicle's observation (the shared builder) and the policy's inference;
* missed setpoint deadlines, and the setpoint rate each vehicle actually received.
"""

from __future__ import annotations

import asyncio
import dataclasses
import time
from typing import Any

import numpy as np

from remarl_fc.demo import free_udp_port
from remarl_fc.flight.config import FlyConfig
from remarl_fc.flight.control import ControlSpec
from remarl_fc.flight.mission import Mission, VehiclePlan
from remarl_fc.flight.runtime import SwarmRuntime
from remarl_fc.flight.status import Status
from remarl_fc.policy_io import Policy, load_policy
from remarl_fc.sitl.config import DEFAULT_HOME, SitlConfig
from remarl_fc.sitl.fleet import DEFAULT_D_COL_M, SitlFleet, grid_layout
from sim.spawn import SPAWN_SPACING_FACTOR

BENCH_ALT_M = 10.0
"""Take-off height of the benchmark."""

BENCH_LEG_M = 2_000.0
"""Distance to each vehicle's target (north): nobody arrives during the measurement."""


def repeated_policy(n: int, base: str = "10u1o") -> Policy:
    """A policy for ``n`` agents made of ``base``'s per-agent networks, repeated."""
    pol = load_policy(base)
    reps = -(-n // pol.agents)
    actor = {
        k: (np.tile(w, (reps, 1, 1))[:n], np.tile(b, (reps, 1, 1))[:n])
        for k, (w, b) in pol.actor.items()
    }
    meta = {**pol.meta, "agents": n}
    return dataclasses.replace(pol, source=f"{base} x{n}", meta=meta, actor=actor, critic={})


async def bench_fly(vehicles: int = 10, seconds: float = 10.0) -> dict[str, Any]:
    """Run the benchmark (module docstring)."""
    policy = repeated_policy(vehicles)
    spec = ControlSpec.from_policy_meta(policy.meta)
    spawn = grid_layout(vehicles, SPAWN_SPACING_FACTOR * DEFAULT_D_COL_M)
    plans = tuple(
        VehiclePlan(i + 1, i, (float(p[0] + BENCH_LEG_M), float(p[1])), BENCH_ALT_M)
        for i, p in enumerate(spawn)
    )
    mission = Mission(DEFAULT_HOME, spec.speed_m_s, plans, spec.dt_s, None, "bench")
    port = free_udp_port()
    sitl = SitlConfig(vehicles=vehicles, base_port=0, out=("127.0.0.1", port))
    cfg = FlyConfig(
        connections=(f"udpin:127.0.0.1:{port}",),
        mission=mission,
        takeoff_m=BENCH_ALT_M,
        max_flight_s=seconds,
    )
    runtime = SwarmRuntime(cfg, policy, spec)
    async with runtime, SitlFleet(sitl) as fleet:

        async def watch() -> None:
            await runtime.commands.wait_until(
                "every vehicle under control",
                lambda: all(s == Status.CONTROLLED for s in runtime.statuses()),
                cfg.ready_timeout_s + cfg.takeoff_timeout_s,
            )
            runtime.tick_s.clear()
            runtime.decide_s.clear()
            runtime.setpoint_deadline_misses = 0
            for m in runtime.members:
                m.sent = 0
            window.append(time.monotonic())
            await runtime.commands.wait_until(
                "the end of the measured flight",
                lambda: not any(s == Status.CONTROLLED for s in runtime.statuses()),
                seconds + 30.0,
            )
            window.append(time.monotonic())

        window: list[float] = []
        async with asyncio.TaskGroup() as tg:
            tg.create_task(watch(), name="bench.watch")
            tg.create_task(runtime.run(), name="bench.runtime")
        applied = [ap.counters.setpoints_applied for ap in fleet.vehicles]
    tick = np.array(runtime.tick_s) * 1000
    decide = np.array(runtime.decide_s) * 1000
    sent = [m.sent for m in runtime.members]
    return {
        "vehicles": vehicles,
        "seconds": seconds,
        "tick_ms_p50": float(np.percentile(tick, 50)),
        "tick_ms_p99": float(np.percentile(tick, 99)),
        "tick_us_per_vehicle_p50": float(np.percentile(tick, 50)) * 1000 / vehicles,
        "decide_ms_p50": float(np.percentile(decide, 50)) if decide.size else None,
        "decide_ms_p99": float(np.percentile(decide, 99)) if decide.size else None,
        "setpoint_deadline_misses": runtime.setpoint_deadline_misses,
        "setpoints_per_vehicle_hz": float(np.mean(sent)) / (window[-1] - window[0]),
        "setpoints_applied_by_mock_min": int(min(applied)),
    }

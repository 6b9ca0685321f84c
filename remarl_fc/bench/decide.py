"""One decision of a generalist, timed: observation building and the set network, numpy only.

The swarm is the 50u8o scenario's (50 UAVs, 8 intruders; `tools/bench_decide.py` takes others),
flown straight (zero actions) until its first collision, and each of those states again with the
intruders moved in among the UAVs (`crowded`), so every UAV sees up to all 8: decisions cycle
over both. The policy is a generalist of the
shipped size (hidden 64, k = 6 neighbour and m = 8 intruder rows) with random weights: the
timings depend on the network's size, not its weights. A decision is what the offline
evaluation and the flight runtime do for one swarm at one step: every UAV's version-2
observation (`sim.swarm.SwarmSim.observe` with the policy's layout) and the actor
(`remarl_fc.policy_io.Policy.act`, i.e. `sim.setnet.set_actor`).
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable
from typing import Any

import numpy as np
from numpy.typing import NDArray

from remarl_fc.policy_io import Policy, load_policy
from sim.config import ScenarioConfig
from sim.policy_file import build_metadata, expected_shapes, network_layers, pooling_of
from sim.scenarios import load_scenario
from sim.shield import ShieldConfig, shield_state, vehicle_of
from sim.state import SwarmState
from sim.swarm import SwarmSim

SHIPPED_HIDDEN = 64
"""Hidden units of the shipped generalist."""

SHIPPED_NEIGHBOURS = 6
"""k, neighbour rows of the shipped generalist."""

SHIPPED_INTRUDERS = 8
"""m, intruder rows of the shipped generalist."""

SHIPPED_UAVS = (1, 50)
"""Swarm sizes the shipped generalist flies."""


def random_generalist(
    cfg: ScenarioConfig,
    *,
    hidden: int = SHIPPED_HIDDEN,
    neighbours: int = SHIPPED_NEIGHBOURS,
    intruders: int = SHIPPED_INTRUDERS,
    seed: int = 0,
    pooling: str = "max-mean",
) -> Policy:
    """A generalist (actor only, weights N(0, 0.1²)) of this size and pooling for ``cfg``."""
    sensing = dataclasses.replace(
        cfg.sensing, observation=2, max_neighbours=neighbours, max_obstacles=intruders
    )
    base = dataclasses.replace(cfg, sensing=sensing)
    uavs = (min(SHIPPED_UAVS[0], cfg.uav.count), max(SHIPPED_UAVS[1], cfg.uav.count))
    meta = build_metadata(
        base,
        shared=True,
        hidden=hidden,
        reward="none",
        training={"commit": "bench", "steps": 0, "seed": seed},
        metrics={},
        network="set",
        uavs=uavs,
        pooling=pooling,
    )
    rng = np.random.default_rng(seed)
    shapes = expected_shapes(meta)

    def draw(name: str) -> NDArray[np.float32]:
        return rng.normal(0.0, 0.1, shapes[name]).astype(np.float32)

    actor_layers, _ = network_layers(meta)
    actor = {n: (draw(f"actor.{n}.weight"), draw(f"actor.{n}.bias")) for n in actor_layers}
    return Policy(source="random generalist", meta=meta, actor=actor, critic={})


def episode_states(cfg: ScenarioConfig, seed: int = 0) -> tuple[SwarmSim, list[SwarmState]]:
    """The states of one episode of ``cfg`` flown straight (zero actions), one per step."""
    sim = SwarmSim(cfg, scored=False)
    rng = np.random.default_rng(seed)
    state = sim.initial_state(rng, 1)
    states = [state]
    for _ in range(cfg.max_steps):
        state, result = sim.step(state, np.zeros((1, cfg.uav.count)), rng)
        if result.terminated[0] or result.truncated[0]:
            break
        states.append(state)
    return sim, states


def crowded(state: SwarmState, rng: np.random.Generator) -> SwarmState:
    """``state`` with each intruder moved 20–60 m from a random UAV (in everyone's midst)."""
    b, n, _ = state.pos_m.shape
    m = state.obstacle_pos_m.shape[1]
    near = state.pos_m[:, rng.integers(0, n, m)]  # (B, M, 2)
    angle = rng.uniform(0.0, 2 * np.pi, (b, m))
    radius = rng.uniform(20.0, 60.0, (b, m))[..., None]
    offset = radius * np.stack([np.cos(angle), np.sin(angle)], axis=-1)
    return dataclasses.replace(state, obstacle_pos_m=near + offset)


REFERENCE_ROWS = 400
"""Rows of the reference workload: about the encoder rows of one 50u8o decision."""

REFERENCE_LAYERS = 8
"""Dense layers (64 → 64, float64, ReLU) of the reference workload."""


def reference_workload(seed: int = 0) -> Callable[[], object]:
    """A fixed numpy workload of the decision's kind, timed beside it in the same run.

    `REFERENCE_ROWS` rows through `REFERENCE_LAYERS` dense ReLU layers of 64 units, float64:
    small matrix products and element-wise calls, as the actor's. Its time says how fast this
    machine is at such work today, so that decisions timed on different days compare by
    their ratio to it (the 2-core machines differ from one session to the next by up to 2.3×).
    """
    rng = np.random.default_rng(seed)
    x = rng.normal(size=(REFERENCE_ROWS, SHIPPED_HIDDEN))
    shape = (SHIPPED_HIDDEN, SHIPPED_HIDDEN)
    weights = [rng.normal(0, 0.1, shape) for _ in range(REFERENCE_LAYERS)]

    def run() -> object:
        y = x
        for w in weights:
            y = np.maximum(y @ w, 0.0)
        return y

    return run


def _percentiles(times: NDArray[np.float64], prefix: str) -> dict[str, float]:
    return {
        f"{prefix}_median_ms": float(np.median(times) * 1e3),
        f"{prefix}_p99_ms": float(np.percentile(times, 99) * 1e3),
    }


def bench_decide(
    scenario: str = "50u8o",
    *,
    samples: int = 2000,
    hidden: int = SHIPPED_HIDDEN,
    neighbours: int = SHIPPED_NEIGHBOURS,
    intruders: int = SHIPPED_INTRUDERS,
    seed: int = 0,
    policy_name: str | None = None,
    pooling: str = "max-mean",
    shield_passes: int = ShieldConfig().passes,
    dynamics: str = "ideal",
) -> dict[str, Any]:
    """Median and p99 (ms) of one decision (observations + actor) for one swarm.

    ``policy_name``: a generalist file (zoo name or path) instead of random weights of the
    given size and ``pooling`` — the actor's time depends on the size and pooling only, the
    shield's on the proposals (a trained policy's need fewer interventions than random ones).

    Also each part alone: ``observe_*`` (the version-2 observations of every UAV), ``act_*``
    (the actor on them), ``shield_*`` (the safety shield on the actor's proposals, mode on,
    `sim.shield.shield_state`, ``shield_passes`` passes), and ``shielded_decision_*`` (all
    three). Decisions cycle over the states of one straight episode and their crowded copies.
    ``dynamics``: the vehicles' profile (`sim.vehicle`); with a fitted one the shield predicts
    every candidate with its response (`sim.shield.ShieldConfig.vehicle_model`).
    ``reference_*``: the `reference_workload` timed after each decision, and
    ``decision_per_reference`` the ratio of the medians, which moves less across machines and
    days than the milliseconds (1.28–1.31 on a fast day, 1.46–1.62 on one twice as slow).
    """
    cfg = load_scenario(scenario, dynamics=dynamics)
    if policy_name is not None:
        policy = load_policy(policy_name)
        hidden = int(policy.meta["hidden"])
        neighbours, intruders = policy.layout.max_neighbours, policy.layout.max_obstacles
    else:
        policy = random_generalist(
            cfg,
            hidden=hidden,
            neighbours=neighbours,
            intruders=intruders,
            seed=seed,
            pooling=pooling,
        )
    layout = policy.layout
    sim, flown = episode_states(cfg, seed)
    rng = np.random.default_rng(seed)
    states = flown + [crowded(s, rng) for s in flown]
    decide, observe, act = np.empty(samples), np.empty(samples), np.empty(samples)
    guard, reference = np.empty(samples), np.empty(samples)
    workload = reference_workload(seed)
    shield_cfg = ShieldConfig(mode="on", passes=shield_passes)
    vehicle = vehicle_of(cfg)
    sensed = interventions = 0
    for k in range(samples):
        state = states[k % len(states)]
        t0 = time.perf_counter()
        obs = sim.observe(state, layout=layout).flat_shared()
        t1 = time.perf_counter()
        actions = policy.act(obs)
        t2 = time.perf_counter()
        shielded = shield_state(shield_cfg, cfg, state, actions, vehicle)
        t3 = time.perf_counter()
        workload()
        t4 = time.perf_counter()
        observe[k], act[k], decide[k], guard[k] = t1 - t0, t2 - t1, t2 - t0, t3 - t2
        reference[k] = t4 - t3
        interventions += int(shielded.intervened.sum())
        if k < len(states):
            sensed = max(sensed, int(obs[..., layout.blocks()["intruder_mask"]].sum(-1).max()))
    return {
        "scenario": cfg.name,
        "uavs": cfg.uav.count,
        "intruders": cfg.obstacles.count,
        "hidden": hidden,
        "pooling": pooling_of(policy.meta),
        "max_neighbours": neighbours,
        "max_obstacles": intruders,
        "observation_size": layout.size,
        "states": len(states),
        "most_intruders_in_one_observation": sensed,
        "samples": samples,
        "shield_passes": shield_passes,
        "dynamics": cfg.dynamics,
        **_percentiles(decide, "decision"),
        **_percentiles(observe, "observe"),
        **_percentiles(act, "act"),
        **_percentiles(guard, "shield"),
        **_percentiles(decide + guard, "shielded_decision"),
        **_percentiles(reference, "reference"),
        "decision_per_reference": float(np.median(decide) / np.median(reference)),
        "shield_intervention_rate": interventions / (samples * cfg.uav.count),
    }

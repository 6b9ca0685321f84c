"""An oracle that says which episodes can be solved: a plan for every UAV, flown by the simulator.

`plan_episodes` labels an episode *solvable* when it has a plan — heading changes within the
turn limit for every UAV, at constant speed — that `sim.swarm.SwarmSim` flies to success: every
UAV arrives, nothing comes within d_col (the simulator's own swept check). The search itself is
prioritised space-time beam search over the intruders' known futures (`sim.oracle_search`).

**What the oracle may know, and when.** Intruders fly straight at constant speed, so their
future is known the moment they are seen — but not before: a late pop-up (`obstacle_appear_step`)
is hidden from the oracle as it is from the UAVs. The oracle plans in phases: against what can
be seen, until the next intruder appears; then, from the state its plan reached (positions,
headings, who has arrived), against what can be seen from then on. A plan that exploits an
intruder before it appears would call solvable an episode no controller can save (one that
pops up 30 m ahead at 15 m/s). The intruder is there all along: flying into it while it is
hidden fails the episode, in the plan's final check as in the simulator.

**Guarantees.** ``solvable`` is True only where the simulator flew the whole plan to success, a
proof by construction. False means that no plan was found within the search's budget, not that
none exists. The result is deterministic.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from sim.arrays import BoolArray, Float32Array, FloatArray, IntArray
from sim.config import DynamicsRandomisation, ObstacleConfig, ScenarioConfig, SensorConfig
from sim.oracle_search import OracleConfig, OraclePlans, fly_plans, plan_known
from sim.spawn import EpisodeStart
from sim.state import SwarmState
from sim.swarm import SwarmSim

__all__ = [
    "ORACLE_VERSION",
    "OracleConfig",
    "OraclePlans",
    "fly_plans",
    "oracle_actions",
    "oracle_plan",
    "plan_episodes",
]

ORACLE_VERSION = 3
"""Bumped whenever a change to the oracle can change a label (the label cache checks it).
3: the random priority orders are the same for every episode of a batch (an episode's label
had depended on the episodes labelled beside it)."""

PARKED_M = 1.0e7
"""Where the phases' plans keep what the UAVs may not know, metres: hidden intruders (at rest)
and UAVs that have arrived (each on its own target, 1 km from the next), far from everything."""

PARKED_SPACING_M = 1000.0
"""Distance between two parked UAVs, metres: never within d_col of each other."""


def plan_episodes(
    cfg: ScenarioConfig, episodes: EpisodeStart, oracle: OracleConfig | None = None
) -> OraclePlans:
    """Plan every UAV of every episode, phase by phase as intruders appear; label them.

    An episode is solvable where the simulator flies its whole plan to success.

    Args:
        cfg: the scenario; episodes: B episodes of its N UAVs and M obstacles.
        oracle: the search settings (default `OracleConfig()`).

    Raises:
        ValueError: the episodes do not have the scenario's N UAVs and M obstacles.
    """
    episodes.check(cfg)
    b, s, n = episodes.num_envs, cfg.max_steps, cfg.uav.count
    oracle = oracle or OracleConfig()
    appear = episodes.obstacle_appear_step
    if not (appear > 0).any():
        return plan_known(cfg, episodes, oracle)
    actions = np.zeros((b, s, n), dtype=np.float32)
    planned = np.ones(b, dtype=bool)
    offset = np.zeros(b, dtype=np.int64)  # the step at which each episode's phase starts
    current = _hide(episodes, appear > 0)
    todo = np.arange(b)
    while todo.size:
        first = int(offset[todo].min())
        phase = plan_known(dataclasses.replace(cfg, max_steps=s - first), current, oracle)
        later = np.where(appear[todo] > offset[todo, None], appear[todo], s)
        reveal = np.minimum(later.min(axis=-1, initial=s), s)  # the next appearance
        for k, ep in enumerate(todo):  # the phase's actions up to the next appearance
            span = reveal[k] - offset[ep]
            actions[ep, offset[ep] : reveal[k]] = phase.actions[k, :span]
        planned[todo[~phase.solvable]] = False
        go_on = phase.solvable & (reveal < s)
        todo, reveal = todo[go_on], reveal[go_on]
        if todo.size == 0:
            break
        current = _restart(cfg, episodes.take(todo), actions[todo], reveal)
        offset[todo] = reveal
        planned[todo] &= np.isfinite(current.start_m).all(axis=(1, 2))  # no crash before
        keep = planned[todo]
        todo, current = todo[keep], current.take(keep)
    solvable = np.zeros(b, dtype=bool)
    solvable[planned] = fly_plans(cfg, episodes.take(planned), actions[planned])
    return OraclePlans(actions=actions, planned=planned, solvable=solvable)


def _parked_spots(count: int, first: int = 0, side: float = 1.0) -> FloatArray:
    """(count, 2) spots far from everything, one per vehicle set aside.

    ``PARKED_SPACING_M`` apart on the diagonal: spots ``first`` … ``first + count − 1``, on the
    + (UAVs) or the − (obstacles) ``side``.
    """
    far = side * (PARKED_M + PARKED_SPACING_M * np.arange(first, first + count, dtype=np.float64))
    return np.stack([far, far], axis=-1)


def _parked_uavs(n: int) -> FloatArray:
    """(N, 2) where UAVs that may be ignored wait: each on its own spot, far from everything."""
    return _parked_spots(n)


def _hide(episodes: EpisodeStart, hidden: BoolArray) -> EpisodeStart:
    """The episodes with the ``hidden`` (B, M) obstacles parked at rest, far away."""
    far = _parked_spots(hidden.shape[1], side=-1.0)
    pos = np.where(hidden[..., None], far, episodes.obstacle_pos_m)
    vel = np.where(hidden[..., None], 0.0, episodes.obstacle_vel_m_s)
    return dataclasses.replace(
        episodes,
        obstacle_pos_m=pos,
        obstacle_vel_m_s=vel,
        obstacle_appear_step=np.zeros_like(episodes.obstacle_appear_step),
    )


def _restart(
    cfg: ScenarioConfig, episodes: EpisodeStart, actions: Float32Array, at: IntArray
) -> EpisodeStart:
    """Where the plans so far leave each episode at its step ``at`` (E,), as new episodes.

    Flown in the simulator with every obstacle present (a hidden one collides). Arrived UAVs are
    parked on their targets; obstacles still hidden at ``at`` are parked. An episode whose plan
    collided before ``at`` comes back with NaN positions.
    """
    sim, rng = SwarmSim(cfg, scored=False), np.random.default_rng(0)
    state = sim.start(episodes, rng)
    snap: list[tuple[FloatArray, ...]] = [()] * episodes.num_envs
    failed = np.zeros(episodes.num_envs, dtype=bool)
    for t in range(int(at.max()) + 1):
        for e in np.flatnonzero(at == t):
            snap[e] = (
                state.pos_m[e].copy(),
                state.heading_rad[e].copy(),
                state.reached[e].copy(),
                state.obstacle_pos_m[e].copy(),
            )
        if t == int(at.max()):
            break
        state, result = sim.step(state, actions[:, t], rng)
        crashed = result.collided_u2o.any(axis=-1) | result.collided_u2u.any(axis=-1)
        failed |= crashed & (t < at)  # before its snapshot; later steps are not its plan
    pos, heading, reached, obstacles = (np.stack(parts) for parts in zip(*snap, strict=True))
    n = pos.shape[1]
    park = _parked_uavs(n)
    start = np.where(reached[..., None], park, pos)
    target = np.where(reached[..., None], park, episodes.target_m)
    start[failed] = np.nan
    hidden = episodes.obstacle_appear_step > at[:, None]
    moved = dataclasses.replace(
        episodes,
        start_m=start,
        target_m=target,
        heading_rad=heading,
        obstacle_pos_m=obstacles,
        obstacle_appear_step=np.maximum(episodes.obstacle_appear_step - at[:, None], 0),
    )
    return _hide(moved, hidden)


def oracle_actions(
    state: SwarmState,
    cfg: ScenarioConfig,
    oracle: OracleConfig | None = None,
    envs: IntArray | None = None,
) -> tuple[Float32Array, BoolArray]:
    """The oracle as a controller: plan from this state, fly the plan's first step.

    `oracle_plan`'s first step: (E, N) normalised actions (0 where no plan was found) and (E,)
    whether a plan was found.
    """
    plans, found = oracle_plan(state, cfg, oracle, envs)
    return np.ascontiguousarray(plans[:, 0, :]), found


def oracle_plan(
    state: SwarmState,
    cfg: ScenarioConfig,
    oracle: OracleConfig | None = None,
    envs: IntArray | None = None,
) -> tuple[Float32Array, BoolArray]:
    """The oracle's whole plan from this state, for the steps the episodes have left.

    Replanned at every decision (receding horizon), it is a centralised controller that knows
    every UAV's state and the future of every intruder seen so far (they fly straight): the
    strongest teacher a policy can imitate (`policies.config.GeneralistConfig.teacher`,
    "oracle"). Each episode is planned from where it stands — positions, headings, the UAVs
    that arrived parked on their targets — against the intruders that can be sensed now (the
    hidden ones parked), for the steps it has left, in the ideal world: the plan is checked by
    a flight of the ideal vehicle with exact sensing, whatever the world's vehicle and sensors
    (a privileged teacher reads the true state; its first step is a heading change like any
    other). Where arrived UAVs hover on their targets (``arrival = "hover"``) they are
    obstacles at rest to the others.

    ``envs``: plan these environments alone (indices, E of them; None: all B).

    Returns:
        (E, S, N) the plans' normalised actions, step by step from this one (S: the steps the
        least advanced of the episodes has left; 0 after a UAV's planned arrival and where no
        plan was found), and (E,) whether a plan was found.
    """
    oracle = oracle or OracleConfig()
    pick = np.arange(state.num_envs) if envs is None else np.asarray(envs, dtype=np.intp)
    pos, active, reached = state.pos_m[pick], state.active[pick], state.reached[pick]
    park = _parked_uavs(pos.shape[1])
    gone = ~active[..., None]  # arrived, or the episode is over
    steps = state.steps[pick].astype(np.int64)
    appear = state.obstacle_appear_step[pick]
    episodes = EpisodeStart(
        start_m=np.where(gone, park, pos),
        target_m=np.where(gone, park, state.target_m[pick]),
        centre_m=state.centre_m[pick],
        swarm_vel_m_s=state.swarm_vel_m_s[pick],
        obstacle_pos_m=state.obstacle_pos_m[pick],
        obstacle_vel_m_s=state.obstacle_vel_m_s[pick],
        obstacle_appear_step=np.zeros_like(appear),
        heading_rad=state.heading_rad[pick].copy(),
    )
    episodes = _hide(episodes, appear > steps[:, None])
    obstacles = cfg.obstacles
    if cfg.arrival == "hover":  # arrived UAVs hover on their targets: in the way, at rest
        episodes, obstacles = _hovering(episodes, pos, reached, cfg)
    left = cfg.max_steps - int(steps[active.any(axis=-1)].min(initial=cfg.max_steps))
    ideal = dataclasses.replace(
        cfg,
        max_steps=max(left, 1),
        obstacles=obstacles,
        dynamics="ideal",
        dynamics_randomisation=DynamicsRandomisation(),
        sensors=SensorConfig(),
    )
    plans = plan_known(ideal, episodes, oracle)
    actions = np.where(plans.planned[:, None, None], plans.actions, 0.0)
    return actions.astype(np.float32), plans.planned


def _hovering(
    episodes: EpisodeStart, pos_m: FloatArray, reached: BoolArray, cfg: ScenarioConfig
) -> tuple[EpisodeStart, ObstacleConfig]:
    """``episodes`` with every UAV that arrived added as an obstacle at rest where it hovers.

    ``pos_m`` (B, N, 2), ``reached`` (B, N): the UAVs now. One obstacle slot per UAV (the
    flying ones' parked far away), after the intruders; and the obstacle settings for M + N of
    them.
    """
    b, n = pos_m.shape[:2]
    spots = _parked_spots(n, first=episodes.obstacle_pos_m.shape[1] + 1, side=-1.0)
    parked = np.broadcast_to(spots, (b, n, 2))
    hover = np.where(reached[..., None], pos_m, parked)
    moved = dataclasses.replace(
        episodes,
        obstacle_pos_m=np.concatenate([episodes.obstacle_pos_m, hover], axis=1),
        obstacle_vel_m_s=np.concatenate([episodes.obstacle_vel_m_s, np.zeros((b, n, 2))], axis=1),
        obstacle_appear_step=np.concatenate(
            [episodes.obstacle_appear_step, np.zeros((b, n), np.int64)], axis=1
        ),
    )
    count = cfg.obstacles.count + n
    return moved, dataclasses.replace(cfg.obstacles, count=count)

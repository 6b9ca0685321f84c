"""Training the generalist: one shared set-encoder policy on a mixture of encounter families.

Read it top to bottom. Every family of the configured suites (`GeneralistConfig.suites`) is a
*world*: its scenario with the version-2 observation (k neighbours, m intruders), flown by
ceil(w · agents_per_family / N) environments (w: its ``family_weights``, 1 by default) in the
scored simulator (the reMARL reward), a share of them (``real_share``) in the real world
(`sim.scenarios.REAL_WORLD`). One iteration steps every world once with the current actor plus
exploration noise, stores every UAV's transition in one replay buffer, and takes TD3 steps
(`policies.generalist`); with ``learner = "ppo"``, `policies.generalist_ppo` flies rollouts
and takes PPO steps instead. A world's finished episodes
restart at once with new episodes of its family, drawn from the run's own seed: the suites'
evaluation episodes are never drawn in training.

Reward: the reMARL reward (contour + Swarming, as every policy of the zoo) minus a separation
term between UAVs of the swarm (`separation_penalty`), with ``separation_horizon_s`` also on
the closest approach predicted to every other vehicle (`predicted_closest_approach`).
Terminal values as in `policies.train`: an arrival is the absorbing goal, a collision ends
with 0.

Run folder (``out``)::

    config.json        the resolved GeneralistConfig and the worlds
    last.safetensors   networks, optimiser moments, counters (resumable; written at every
                       validation and on Ctrl-C)
    best.safetensors   the networks of the best validation so far
    evals.jsonl        one line per validation: success per family on validation episodes
                       (every ``eval_minutes``, and of the final networks at the run's end)
    events.*           TensorBoard scalars (when tensorboard is installed)

The replay buffer is not saved; a resumed run refills it with the current policy first.
"""

from __future__ import annotations

import contextlib
import dataclasses
import fnmatch
import functools
import json
import math
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any, cast

import numpy as np
import torch
from numpy.typing import NDArray
from torch import nn

from policies.config import GeneralistConfig
from policies.ddpg import soft_update
from policies.generalist import AgentReplay, SetNet, TD3Nets, clone_step, td3_update
from policies.generalist_init import init_states, keep_init
from policies.train import load_checkpoint, reward_upper_bound, save_checkpoint, summary_writer
from sim.arrays import BoolArray, FloatArray
from sim.config import STATE_TEACHERS, ScenarioConfig
from sim.encounters import Family, draw_episodes, family_scenario
from sim.env import episode_metrics
from sim.errors import ConfigError
from sim.evaluation import evaluation_seed
from sim.observation import ObservationLayout
from sim.oracle import oracle_actions
from sim.orca import HORIZON_S as ORCA_HORIZON_S
from sim.orca import orca_actions
from sim.scenarios import REAL_WORLD
from sim.shield import (
    NeighbourArcs,
    ShieldConfig,
    ShieldDecision,
    Vehicle,
    passing_side,
    shield_state,
    vehicle_of,
)
from sim.spawn import EpisodeStart, spawn_episodes
from sim.state import SwarmState, merge_where
from sim.suite import load_suite
from sim.swarm import SwarmSim

CHECKPOINT_SCHEMA = 1
"""Version of the generalist checkpoint layout."""

CHECKPOINT_MINUTES = 5.0
"""Wall-clock minutes between checkpoints of ``last.safetensors`` (besides each validation)."""

VALIDATION_SEED = evaluation_seed(suite="training", offset=7_777)
"""Seed of the validation episodes: neither the training stream nor a suite's."""

TIME_PARTS = ("simulator", "learner")
"""Where a run's wall time is counted (`RunBook.clock`): flying the worlds, with the teacher's
labels (on the CPU), and the networks' updates (on ``--device``). Validation and checkpoints
count in neither."""


def generalist_layout(cfg: GeneralistConfig, base: ScenarioConfig) -> ObservationLayout:
    """The version-2 layout of the generalist on scenarios with ``base``'s speed.

    Range and aperture are the run's (``sensing_range_m``, ``sensing_aperture_deg``) where it
    sets them, else ``base``'s sensing.
    """
    s = base.sensing
    range_m = cfg.sensing_range_m or s.range_m
    aperture = (
        math.radians(cfg.sensing_aperture_deg) if cfg.sensing_aperture_deg else s.aperture_rad
    )
    return ObservationLayout(
        cfg.max_intruders, range_m, aperture, base.uav.speed_m_s, cfg.max_neighbours, 2
    )


def with_layout(cfg: ScenarioConfig, layout: ObservationLayout) -> ScenarioConfig:
    """``cfg`` sensing with ``layout``'s version-2 observation (its rows, range and aperture)."""
    sensing = dataclasses.replace(
        cfg.sensing,
        observation=2,
        range_m=layout.range_m,
        aperture_rad=layout.aperture_rad,
        max_neighbours=layout.max_neighbours,
        max_obstacles=layout.max_obstacles,
    )
    return dataclasses.replace(cfg, sensing=sensing)


def separation_penalty(
    min_u2u_m: FloatArray, d_col_m: float, weight: float, factor: float
) -> FloatArray:
    """The separation term (B, N) of each UAV's closest approach d to another UAV this step.

    w_sep · clip((factor·d_col − d) / ((factor − 1)·d_col), 0, 1): w_sep at d_col, 0 from
    factor·d_col on.
    """
    start = factor * d_col_m
    closeness = np.clip((start - min_u2u_m) / max(start - d_col_m, 1e-9), 0.0, 1.0)
    out: FloatArray = weight * closeness
    return out


def predicted_closest_approach(
    state: SwarmState, present: BoolArray, horizon_s: float
) -> FloatArray:
    """(B, N) each UAV's closest approach to another vehicle within ``horizon_s``, metres.

    Both flying on at their present velocities, to every other UAV still ``present`` and every
    intruder already in view (its appear step passed; a pop-up is not yet there to avoid):
    the relative track's distance at t* = clip(−r·w/|w|², 0, horizon). +inf with no one else.
    """
    n = state.pos_m.shape[1]
    pos = np.concatenate([state.pos_m, state.obstacle_pos_m], axis=1)  # (B, N + M, 2)
    vel = np.concatenate([state.vel_m_s, state.obstacle_vel_m_s], axis=1)
    seen = state.obstacle_appear_step <= state.steps[:, None]
    other = np.concatenate([present, seen], axis=1)[:, None, :].repeat(n, axis=1)
    other[:, np.arange(n), np.arange(n)] = False  # not oneself
    r = pos[:, None, :, :] - state.pos_m[:, :, None, :]  # (B, N, N + M, 2)
    w = vel[:, None, :, :] - state.vel_m_s[:, :, None, :]
    ww = np.einsum("bnkd,bnkd->bnk", w, w)
    t = np.clip(-np.einsum("bnkd,bnkd->bnk", r, w) / np.maximum(ww, 1e-12), 0.0, horizon_s)
    miss = np.hypot(*np.moveaxis(r + w * t[..., None], -1, 0))
    out: FloatArray = np.where(other, miss, np.inf).min(axis=-1, initial=np.inf)
    return out


@dataclass
class World:
    """One family of the mixture and its environments.

    Attributes:
        family: what its episodes are. cfg: its scenario (version-2 sensing). real: flown in
        the real world. sim: its scored simulator. state: (B, N) environments. obs: (B, N, D)
        the current observations. drawn: episodes drawn so far (the next one's index).
    """

    family: Family
    cfg: ScenarioConfig
    real: bool
    sim: SwarmSim
    state: SwarmState
    obs: NDArray[np.float32]
    drawn: int

    @property
    def envs(self) -> int:
        """B."""
        return int(self.state.pos_m.shape[0])

    @functools.cached_property
    def teacher_vehicle(self) -> Vehicle:
        """The shield's vehicle for a teacher here: `teacher_vehicle` of the world's scenario.

        Resolved once per world (it reads the vehicle profiles' files): a teacher shields
        every step, and reading them at each took a tenth of a DAgger rollout.
        """
        return teacher_vehicle(self.cfg)


def draw(family: Family, cfg: ScenarioConfig, seed: int, first: int, count: int) -> EpisodeStart:
    """``count`` episodes of a family from index ``first`` of the stream ``seed``."""
    if family.encounter is None:  # a scenario's own spawn
        rng = np.random.default_rng([seed, first])
        return spawn_episodes(cfg, rng, count)
    return draw_episodes(family, cfg, seed, range(first, first + count))


def family_weight(cfg: GeneralistConfig, name: str) -> float:
    """The weight of a family in the mixture: the first matching `family_weights` pattern's."""
    return next((w for p, w in cfg.family_weights if fnmatch.fnmatchcase(name, p)), 1.0)


def swarm_peak(cfg: GeneralistConfig, family: Family) -> bool:
    """Whether the family's reward holds the swarm's peak Φ_s (``swarm_field``).

    A scenario's own spawn (the paper's scenarios) and "formation" encounters fly one
    formation; "swarms", "converging", "diverging" and "random" paths do not.
    """
    return (
        cfg.swarm_field == "all"
        or family.encounter is None
        or family.encounter.paths == "formation"
    )


def real_world(cfg: GeneralistConfig) -> dict[str, Any]:
    """The overrides of a real-world family (`REAL_WORLD`, errors as the run says).

    Its ADS-B errors are correlated over `GeneralistConfig.real_error_tau_s`, its tracks
    filtered if `GeneralistConfig.real_track_filter` says so, its arrived UAVs hovering if
    `GeneralistConfig.real_hover` does.
    """
    sensors = {
        **REAL_WORLD["sensors"],
        "adsb_error_tau_s": list(cfg.real_error_tau_s),
        "adsb_filter": cfg.real_track_filter,
    }
    arrival = {"arrival": "hover"} if cfg.real_hover else {}
    return {**REAL_WORLD, "sensors": sensors, **arrival}


def make_worlds(
    cfg: GeneralistConfig, layout: ObservationLayout, rng: np.random.Generator
) -> list[World]:
    """Every family of the configured suites, started (the real-world ones drawn by ``rng``)."""
    families = [f for name in cfg.suites for f in load_suite(name).families]
    worlds = []
    for family in families:
        real = bool(rng.random() < cfg.real_share)
        if real:
            family = dataclasses.replace(family, overrides={**family.overrides, **real_world(cfg)})
        scenario = with_layout(family_scenario(family), layout)
        if not swarm_peak(cfg, family):
            field = dataclasses.replace(scenario.field, swarm_peak=False)
            scenario = dataclasses.replace(scenario, field=field)
        n = scenario.uav.count
        envs = max(1, math.ceil(family_weight(cfg, family.name) * cfg.agents_per_family / n))
        sim = SwarmSim(scenario)
        state = sim.start(draw(family, scenario, cfg.seed, 0, envs), rng)
        obs = sim.observe(state).flat()
        worlds.append(World(family, scenario, real, sim, state, obs, envs))
    return worlds


@dataclass(frozen=True)
class WorldStep:
    """One step of a world, dense over its (B, N) UAVs.

    Attributes:
        obs: (B, N, D) the observations acted on. action: (B, N) the actions flown.
        reward: (B, N) the reward (reMARL minus the separation term). acted: (B, N) the UAVs
        that flew the step. terminal: (B, N) their trajectory ended (arrived, or the episode
        terminated). terminal_value: (B, N) the value after a terminal step (the goal's for an
        arrival, 0 after a collision). next_obs: (B, N, D) the observations after the step, of
        the old episodes where one ended. done: (B,) the environments whose episode ended (and
        restarted).
    """

    obs: NDArray[np.float32]
    action: NDArray[np.float32]
    reward: NDArray[np.float32]
    acted: BoolArray
    terminal: BoolArray
    terminal_value: NDArray[np.float32]
    next_obs: NDArray[np.float32]
    done: BoolArray

    def transitions(self) -> dict[str, NDArray[Any]]:
        """The transitions of the UAVs that acted, one row each (`AgentReplay.add`)."""
        acted = self.acted
        return {
            "obs": self.obs[acted],
            "action": self.action[acted],
            "reward": self.reward[acted],
            "next_obs": self.next_obs[acted],
            "terminal": self.terminal[acted],
            "terminal_value": self.terminal_value[acted],
        }


def advance_world(
    world: World,
    actions: NDArray[np.float32],
    cfg: GeneralistConfig,
    goal_value: float,
    rng: np.random.Generator,
) -> tuple[WorldStep, list[dict[str, Any]]]:
    """Step one world; returns the step and the metrics of the episodes that ended.

    Finished environments restart at once with the family's next episodes.
    """
    sim, c = world.sim, world.cfg
    state, result = sim.step(world.state, actions, rng)
    acted: BoolArray = result.acted
    closest = result.min_u2u_m
    if cfg.separation_horizon_s > 0:
        present = state.active | state.hovering(c.arrival)
        ahead = predicted_closest_approach(state, present, cfg.separation_horizon_s)
        closest = np.minimum(closest, ahead)
    reward = result.reward.total - separation_penalty(
        closest, c.d_col_m, cfg.separation_weight, cfg.separation_factor
    )
    next_obs = result.obs.flat()
    done = result.terminated | result.truncated
    step = WorldStep(
        obs=world.obs,
        action=actions,
        reward=reward.astype(np.float32),
        acted=acted,
        terminal=acted & (result.arrived | result.terminated[:, None]),
        terminal_value=np.where(result.arrived, goal_value, 0.0).astype(np.float32),
        next_obs=next_obs.copy() if done.any() else next_obs,
        done=done,
    )
    ended: list[dict[str, Any]] = []
    if done.any():
        metrics = episode_metrics(state, result, done)
        ended = [{k: v[i] for k, v in metrics.items()} for i in range(int(done.sum()))]
        count = int(done.sum())
        fresh = sim.start(draw(world.family, c, cfg.seed, world.drawn, count), rng)
        world.drawn += count
        state = merge_where(state, fresh, done)
        next_obs[done] = sim.observe(fresh).flat()
    world.state, world.obs = state, next_obs
    return step, ended


def step_world(
    world: World,
    actions: NDArray[np.float32],
    cfg: GeneralistConfig,
    goal_value: float,
    rng: np.random.Generator,
    teacher: NDArray[np.float32] | None = None,
) -> tuple[dict[str, NDArray[Any]], list[dict[str, Any]]]:
    """Step one world; returns its UAV transitions and the metrics of the episodes that ended.

    ``teacher`` (B, N): the teacher's actions at this step, stored with the transitions (for
    behaviour cloning).
    """
    step, ended = advance_world(world, actions, cfg, goal_value, rng)
    transitions = step.transitions()
    if teacher is not None:
        transitions["teacher"] = teacher[step.acted].astype(np.float32)
    return transitions, ended


TEACHER_TRACK_GROWTH_M_S = 0.5
"""The growth of an ADS-B track's required clearance the teachers' shield keeps, m/s
(`sim.shield.ShieldConfig.track_growth_m_s`): the shield's default when the shipped generalist
was taught, and what `tools/generalist_recipe.py`'s three hours are measured with. Since
2026-12-02 the shield behind a flying generalist keeps 1.5 m/s (docs/MODEL.md §21); a teacher
at 1.5 m/s is not measured."""

TEACHER_NOISE = 0.1
"""Std of the Gaussian noise on the teacher's normalised actions while it flies for cloning:
states a little off its own path, so the clone learns to come back to it."""


def teacher_actions(
    world: World, teacher: str, horizon_s: float = ORCA_HORIZON_S, *, truth: bool = False
) -> NDArray[np.float32]:
    """The teacher's actions (B, N) in a world (`GeneralistConfig.teacher`): `teacher_plan`.

    On the world's true state if ``truth`` (`GeneralistConfig.teacher_truth`).
    """
    state = teacher_state(world, truth)
    return teacher_plan(state, world.cfg, teacher, horizon_s, world.teacher_vehicle)


def teacher_state(world: World, truth: bool) -> SwarmState:
    """The state a teacher reads: the world's, or its truth (`SwarmState.exactly_sensed`)."""
    return world.state.exactly_sensed() if truth else world.state


def teacher_plan(
    state: SwarmState,
    cfg: ScenarioConfig,
    teacher: str,
    horizon_s: float = ORCA_HORIZON_S,
    vehicle: Vehicle | None = None,
) -> NDArray[np.float32]:
    """The teacher's actions (B, N) at a state of scenario ``cfg``.

    "orca-shield": ORCA through the shield. Heading changes only (the policy commands no
    speed), and ORCA reads the simulator's state, the true positions even where the UAVs'
    sensors are ADS-B: a privileged teacher, which the student, seeing only its observation,
    imitates as far as it can. The shield reads what ``state`` says the UAVs sense (its ADS-B
    tracks, if any; `SwarmState.exactly_sensed` is the truth). ``horizon_s`` is its τ_o
    against the intruders (`GeneralistConfig.teacher_horizon_s`). "oracle": the oracle's plan
    from the current state, replanned at every step (`sim.oracle.oracle_actions`), and ORCA
    through the shield in the environments where it finds no plan. ``vehicle``: the shield's
    (`teacher_vehicle` of ``cfg`` where None).
    """
    if teacher not in STATE_TEACHERS:
        raise ValueError(f"teacher {teacher!r} does not label from the state alone (RunBook.teach)")
    if teacher == "oracle":
        planned_actions, planned = oracle_actions(state, cfg)
        if planned.all():
            return planned_actions
        fallback = orca_shield_actions(state, cfg, horizon_s, vehicle)
        return np.where(planned[:, None], planned_actions, fallback)
    return orca_shield_actions(state, cfg, horizon_s, vehicle)


def orca_shield_actions(
    state: SwarmState,
    cfg: ScenarioConfig,
    horizon_s: float = ORCA_HORIZON_S,
    vehicle: Vehicle | None = None,
) -> NDArray[np.float32]:
    """The "orca-shield" teacher's actions (B, N).

    ORCA looking ``horizon_s`` ahead at the intruders it senses with ``cfg``, then the safety
    shield, turning only (`shielded`).
    """
    return shielded(state, cfg, orca_actions(state, cfg, horizon_s=horizon_s), vehicle)


def teacher_vehicle(cfg: ScenarioConfig) -> Vehicle:
    """The shield's vehicle for a teacher: `vehicle_of` ``cfg``, turning only (no speed)."""
    return dataclasses.replace(vehicle_of(cfg), can_slow=False)


def shielded(
    state: SwarmState,
    cfg: ScenarioConfig,
    proposed: NDArray[np.float32],
    vehicle: Vehicle | None = None,
    neighbour_arcs: NeighbourArcs = "proposals",
) -> NDArray[np.float32]:
    """Proposed actions (B, N) through the safety shield, turning only.

    A teacher commands no speed: the default `ShieldConfig` but for ``neighbour_arcs``,
    ``vehicle`` (`teacher_vehicle` of ``cfg`` where None; a `World` holds its own) and the
    track growth (`TEACHER_TRACK_GROWTH_M_S`).
    """
    return teacher_decision(state, cfg, proposed, vehicle, neighbour_arcs).action


def teacher_decision(
    state: SwarmState,
    cfg: ScenarioConfig,
    proposed: NDArray[np.float32],
    vehicle: Vehicle | None,
    neighbour_arcs: NeighbourArcs,
) -> ShieldDecision:
    """The shield's whole decision behind `shielded` and `shielded_sets`."""
    vehicle = vehicle or teacher_vehicle(cfg)
    shield_cfg = ShieldConfig(
        mode="on", neighbour_arcs=neighbour_arcs, track_growth_m_s=TEACHER_TRACK_GROWTH_M_S
    )
    return shield_state(shield_cfg, cfg, state, proposed, vehicle)


def shielded_sets(
    state: SwarmState,
    cfg: ScenarioConfig,
    proposed: NDArray[np.float32],
    vehicle: Vehicle | None = None,
    neighbour_arcs: NeighbourArcs = "proposals",
    side: bool = False,
) -> NDArray[np.float32]:
    """`shielded`'s labels with their safe sets: (B, N, 1 + K) float32.

    ``[..., 0]`` the label (`shielded`'s action); ``[..., 1:]`` 1 for each of the shield's K
    candidate headings (`sim.shield.candidate_grid`) that passes where the shield changed the
    proposal (`ShieldDecision.safe_headings`), all 0 where it let the proposal pass. ``side``:
    only those on the label's side, no failing heading between (`sim.shield.passing_side`).
    """
    decision = teacher_decision(state, cfg, proposed, vehicle, neighbour_arcs)
    safe = decision.safe_headings
    if side:
        safe = passing_side(safe, decision.action)
    return np.concatenate([decision.action[..., None], safe.astype(np.float32)], axis=-1)


def teach(
    worlds: list[World], cfg: GeneralistConfig, anchor: SetNet | None, device: str
) -> list[NDArray[np.float32]]:
    """The teacher's actions (B, N) at each world's state (`GeneralistConfig.teacher`).

    "self-shield": ``anchor``'s proposals (the ``init`` policy's actor, frozen) at the worlds'
    observations, all of them in one batch, each world's through the safety shield
    (`shielded`; with ``dagger_safe_set_weight`` > 0, `shielded_sets`: (B, N, 1 + K), the
    labels with their safe sets, cut to the label's side with ``dagger_safe_set_side``); any
    other teacher, where ``anchor`` is None:
    `teacher_actions`.
    """
    if anchor is not None:
        size = worlds[0].obs.shape[-1]
        proposals = per_world(actor_actions(anchor, joint_obs(worlds, size), device), worlds)
        arcs = cast(NeighbourArcs, cfg.teacher_neighbours)
        if cfg.dagger_safe_set_weight > 0:
            return [
                shielded_sets(
                    teacher_state(w, cfg.teacher_truth),
                    w.cfg,
                    proposed,
                    w.teacher_vehicle,
                    arcs,
                    cfg.dagger_safe_set_side,
                )
                for w, proposed in zip(worlds, proposals, strict=True)
            ]
        return [
            shielded(teacher_state(w, cfg.teacher_truth), w.cfg, proposed, w.teacher_vehicle, arcs)
            for w, proposed in zip(worlds, proposals, strict=True)
        ]
    return [
        teacher_actions(w, cfg.teacher, cfg.teacher_horizon_s, truth=cfg.teacher_truth)
        for w in worlds
    ]


def bc_weight(cfg: GeneralistConfig, frac: float) -> float:
    """α of the behaviour-cloning term at the run's fraction ``frac`` done (0 without teacher)."""
    if cfg.teacher == "none":
        return 0.0
    return cfg.bc_weight * max(0.0, 1.0 - frac / cfg.bc_fraction)


def learn_from_teacher(
    nets: TD3Nets,
    worlds: list[World],
    buffer: AgentReplay,
    cfg: GeneralistConfig,
    goal_value: float,
    rng: np.random.Generator,
    device: str,
) -> dict[str, float]:
    """Fly the teacher until ``teacher_transitions``, then clone it.

    The critics learn the teacher's values meanwhile. Returns the last losses and the
    teacher's success while it flew (with its exploration noise).
    """
    collected, episodes = 0, []
    while collected < cfg.teacher_transitions:
        for world in worlds:
            taught = teacher_actions(
                world, cfg.teacher, cfg.teacher_horizon_s, truth=cfg.teacher_truth
            )
            flown = np.clip(taught + rng.normal(0.0, TEACHER_NOISE, taught.shape), -1.0, 1.0)
            transitions, ended = step_world(
                world, flown.astype(np.float32), cfg, goal_value, rng, teacher=taught
            )
            buffer.add(**transitions)
            collected += len(transitions["obs"])
            episodes += [float(r["success"]) for r in ended]
    losses: dict[str, float] = {}
    for _ in range(cfg.bc_updates):
        batch = buffer.sample(cfg.batch_size, rng, device)
        losses["losses/clone"] = clone_step(nets, batch)
        losses |= td3_update(nets, batch, cfg, update_actor=False)
        soft_update(nets.critic_targets, nets.critics, cfg.tau)
        soft_update(nets.actor_target, nets.actor, cfg.tau)
    nets.actor_target.load_state_dict(nets.actor.state_dict())
    return {"teacher/success": float(np.mean(episodes)) if episodes else 0.0, **losses}


def joint_obs(worlds: list[World], size: int) -> NDArray[np.float32]:
    """Every UAV's observation of every world, in order, as one (ΣB·N, D) batch."""
    return np.concatenate([w.obs.reshape(-1, size) for w in worlds])


def per_world(values: NDArray[Any], worlds: list[World]) -> list[NDArray[Any]]:
    """Per-UAV values (ΣB·N,) in `joint_obs`' order as each world's (B, N)."""
    sizes = np.cumsum([w.obs.shape[0] * w.obs.shape[1] for w in worlds])[:-1]
    return [
        v.reshape(w.obs.shape[:2]) for v, w in zip(np.split(values, sizes), worlds, strict=True)
    ]


def actor_actions(actor: SetNet, obs: NDArray[np.float32], device: str) -> NDArray[np.float32]:
    """Deterministic actions (...,) of the actor for flat observations (..., D)."""
    with torch.no_grad():
        flat = torch.from_numpy(np.ascontiguousarray(obs.reshape(-1, obs.shape[-1]))).to(device)
        out = actor(flat).cpu().numpy()
    actions: NDArray[np.float32] = out.reshape(obs.shape[:-1]).astype(np.float32)
    return actions


def validate(
    actor: SetNet, worlds: list[World], layout: ObservationLayout, episodes: int, device: str
) -> dict[str, Any]:
    """Success per family on ``episodes`` validation episodes (ideal world, unscored)."""
    per_family: dict[str, float] = {}
    for world in worlds:
        if world.real:
            continue
        cfg = world.cfg
        sim = SwarmSim(cfg, scored=False)
        batch = draw(world.family, cfg, VALIDATION_SEED, 0, episodes)
        unused = np.random.default_rng(0)  # an unscored step draws nothing
        state = sim.start(batch, unused)
        success = np.zeros(episodes, dtype=bool)
        finished = np.zeros(episodes, dtype=bool)
        for _ in range(cfg.max_steps):
            actions = actor_actions(actor, sim.observe(state).flat(), device)
            state, result = sim.step(state, actions, unused)
            done = (result.terminated | result.truncated) & ~finished
            success |= done & result.success
            finished |= done
            if finished.all():
                break
        per_family[world.family.name] = float(success.mean())
    values = list(per_family.values())
    return {
        "success_mean": float(np.mean(values)) if values else float("nan"),
        "success_min": float(np.min(values)) if values else float("nan"),
        "families": per_family,
    }


def resolve_device(name: str) -> str:
    """The torch device of a `GeneralistConfig.device`: "auto" is cuda where available."""
    if name == "auto":
        return "cuda" if torch.cuda.is_available() else "cpu"
    if name == "cuda" and not torch.cuda.is_available():
        raise ConfigError(
            f"device: cuda was asked for but torch {torch.__version__} sees no CUDA device "
            "(a CPU build of torch, or no driver): train with --device cpu, or auto"
        )
    return name


@dataclass
class RunBook:
    """What both learners share: the worlds, the clock, checkpoints, validation and logs.

    ``nets`` is the learner's (`TD3Nets`, `policies.generalist_ppo.PPONets`): anything with
    an ``actor``, ``modules()`` and ``optimisers()``. The counters (``iteration``,
    ``updates``, ``transitions``) are the learner's to advance.
    """

    cfg: GeneralistConfig
    out_dir: Path
    nets: Any
    layout: ObservationLayout
    worlds: list[World]
    device: str
    rng: np.random.Generator
    goal_value: float
    resumed: bool
    writer: Any
    iteration: int = 0
    updates: int = 0
    transitions: int = 0
    best: float = -1.0
    elapsed_before: float = 0.0
    start: float = 0.0
    last_eval: float = 0.0
    last_save: float = 0.0
    validated_at: int = -1
    """The iteration whose networks the last validation flew (-1: none yet)."""
    seconds: dict[str, float] = dataclasses.field(
        default_factory=lambda: dict.fromkeys(TIME_PARTS, 0.0)
    )
    """Wall seconds of this sitting spent in each of `TIME_PARTS` (`clock`)."""
    summary: dict[str, Any] = dataclasses.field(default_factory=dict)
    run_state: Callable[[], dict[str, torch.Tensor]] | None = None
    """More of the run to keep in ``last.safetensors`` (the DAgger phase's labels), if any."""
    anchor: SetNet | None = None
    """The "self-shield" teacher's proposer: the ``init`` policy's actor, frozen (`teach`)."""

    @classmethod
    def open(
        cls,
        cfg: GeneralistConfig,
        out_dir: Path,
        create: Callable[[ObservationLayout, GeneralistConfig, str], Any],
        *,
        resume: bool,
    ) -> RunBook:
        """Start the run in ``out_dir`` (resuming ``last.safetensors`` if asked and there)."""
        device = resolve_device(cfg.device)  # before anything is written
        out_dir.mkdir(parents=True, exist_ok=True)
        torch.manual_seed(cfg.seed)
        rng = np.random.default_rng(cfg.seed)
        base = family_scenario(load_suite(cfg.suites[0]).families[0])
        layout = generalist_layout(cfg, base)
        worlds = make_worlds(cfg, layout, np.random.default_rng([cfg.seed, 1]))
        nets = create(layout, cfg, device)
        goal_value = reward_upper_bound(base, "remarl") / (1.0 - cfg.gamma)
        book = cls(cfg, out_dir, nets, layout, worlds, device, rng, goal_value, False, None)
        if cfg.init:  # the start's weights (a resumed run then loads its own over them)
            kept = keep_init(cfg, out_dir, resume=resume)
            actor_state, critic_state = init_states(cfg, layout, kept)
            nets.actor.load_state_dict(actor_state)
            if critic_state:
                nets.value.load_state_dict(critic_state)
            if cfg.teacher == "self-shield":
                book.anchor = SetNet(layout, cfg.hidden, critic=False, pooling=cfg.pooling)
                book.anchor.load_state_dict(actor_state)
                book.anchor.to(device).requires_grad_(False)
        last = out_dir / "last.safetensors"
        if resume and last.exists():
            meta = load_checkpoint(last, nets)
            book.iteration, book.updates = int(meta["iteration"]), int(meta["updates"])
            book.best, book.elapsed_before = float(meta["best_success"]), float(meta["elapsed_s"])
            book.validated_at = int(meta.get("validated_at", -1))
            book.resumed = book.iteration > 0
            book.rng = np.random.default_rng([cfg.seed, book.iteration])
            for world in worlds:  # new episodes: the stream goes on where the run left it
                world.drawn += int(meta.get("drawn", {}).get(world.family.name, 0))
        (out_dir / "config.json").write_text(
            json.dumps(
                {
                    "generalist": dataclasses.asdict(cfg),
                    "layout": dataclasses.asdict(layout),
                    "worlds": [
                        {
                            "family": w.family.name,
                            "uavs": w.cfg.uav.count,
                            "envs": w.envs,
                            "real": w.real,
                        }
                        for w in worlds
                    ],
                },
                indent=2,
            )
        )
        book.writer = summary_writer(out_dir)
        book.start = book.last_eval = book.last_save = time.monotonic()
        return book

    def teach(self, worlds: list[World]) -> list[NDArray[np.float32]]:
        """The teacher's actions (B, N) at each world's state: `teach` with the run's anchor."""
        return teach(worlds, self.cfg, self.anchor, self.device)

    def elapsed(self) -> float:
        """Seconds of the run, resumes included."""
        return self.elapsed_before + time.monotonic() - self.start

    def out_of_time(self) -> bool:
        """The budget (``minutes``) is spent."""
        return bool(self.cfg.minutes) and self.elapsed() >= 60 * self.cfg.minutes

    def fraction_done(self) -> float:
        """The run's fraction of its schedule, in [0, 1].

        `GeneralistConfig.fraction_of` its elapsed time; without a budget, of
        ``total_iterations``.
        """
        if not self.cfg.minutes:
            return min(self.iteration / self.cfg.total_iterations, 1.0)
        return self.cfg.fraction_of(self.elapsed())

    def checkpoint(self, path: Path, extra: dict[str, torch.Tensor] | None = None) -> None:
        """Networks, optimisers and counters to ``path`` (and ``extra`` tensors)."""
        save_checkpoint(
            path,
            self.nets,
            {
                "schema": CHECKPOINT_SCHEMA,
                "learner": self.cfg.learner,
                "iteration": self.iteration,
                "updates": self.updates,
                "best_success": self.best,
                "validated_at": self.validated_at,
                "elapsed_s": self.elapsed(),
                "layout": dataclasses.asdict(self.layout),
                "hidden": self.cfg.hidden,
                "drawn": {w.family.name: w.drawn for w in self.worlds},
            },
            extra,
        )

    def save_last(self) -> None:
        """``last.safetensors`` now, with the `run_state` there is."""
        extra = self.run_state() if self.run_state is not None else None
        self.checkpoint(self.out_dir / "last.safetensors", extra)

    @contextlib.contextmanager
    def clock(self, part: str) -> Iterator[None]:
        """Count the wall time of the block to ``part`` of `TIME_PARTS`."""
        start = time.perf_counter()
        try:
            yield
        finally:
            self.seconds[part] += time.perf_counter() - start

    def simulator_share(self) -> float:
        """The simulator's (and teacher's) share of the clocked time of this sitting."""
        return self.seconds["simulator"] / max(sum(self.seconds.values()), 1e-9)

    def log(
        self,
        recent: list[dict[str, Any]],
        scalars: dict[str, float],
        progress: Callable[[dict[str, float]], None] | None,
        every: int = 20,
    ) -> None:
        """Every ``every`` iterations: recent episodes' rates and ``scalars`` to the logs."""
        if self.iteration % every or not recent:
            return
        out = {
            "iteration": float(self.iteration),
            "charts/success": float(np.mean([float(r["success"]) for r in recent])),
            "charts/collision_u2u": float(np.mean([float(r["collision_u2u"]) for r in recent])),
            "charts/collision_u2o": float(np.mean([float(r["collision_u2o"]) for r in recent])),
            "charts/transitions": float(self.transitions),
            "perf/elapsed_min": self.elapsed() / 60,
            "perf/simulator_share": self.simulator_share(),
            **scalars,
        }
        if self.writer is not None:
            for key, value in out.items():
                if math.isfinite(value):
                    self.writer.add_scalar(key, value, self.iteration)
        if progress is not None:
            progress(out)

    def save_and_validate_if_due(self, *, now: bool = False) -> None:
        """Checkpoint and validate when due, keeping ``best.safetensors``.

        A checkpoint every `CHECKPOINT_MINUTES` (a crash loses at most that), a validation
        every ``eval_minutes`` (or ``now``).
        """
        if time.monotonic() - self.last_save >= 60 * CHECKPOINT_MINUTES:
            self.last_save = time.monotonic()
            self.save_last()
        if not now and time.monotonic() - self.last_eval < 60 * self.cfg.eval_minutes:
            return
        self.save_last()
        self.last_eval = time.monotonic()
        self.validated_at = self.iteration
        result = validate(
            self.nets.actor, self.worlds, self.layout, self.cfg.eval_episodes, self.device
        )
        record = {"iteration": self.iteration, "elapsed_s": self.elapsed(), **result}
        with (self.out_dir / "evals.jsonl").open("a") as f:
            f.write(json.dumps(record) + "\n")
        if self.writer is not None:
            self.writer.add_scalar("eval/success_mean", result["success_mean"], self.iteration)
            self.writer.add_scalar("eval/success_min", result["success_min"], self.iteration)
        if result["success_mean"] >= self.best:
            self.best = result["success_mean"]
            self.checkpoint(self.out_dir / "best.safetensors")
        self.save_last()
        self.summary["last_eval"] = record

    def finish(self) -> dict[str, Any]:
        """Validate the final networks, then the final checkpoints and the summary.

        The validation is skipped when the last one already flew these networks. Without it
        the training after the last periodic validation would never be flown: up to
        ``eval_minutes`` of a run's end, and every run shorter than ``eval_minutes``.
        """
        if self.validated_at != self.iteration:
            self.save_and_validate_if_due(now=True)
        else:
            self.save_last()
        if not (self.out_dir / "best.safetensors").exists():  # no ideal world to validate in
            self.checkpoint(self.out_dir / "best.safetensors")
        if self.writer is not None:
            self.writer.close()
        self.summary.update(
            {
                "learner": self.cfg.learner,
                "teacher": self.cfg.teacher,
                "iterations": self.iteration,
                "updates": self.updates,
                "transitions": self.transitions,
                "best_success": self.best,
                "elapsed_s": self.elapsed(),
                "simulator_s": self.seconds["simulator"],
                "learner_s": self.seconds["learner"],
                "out": str(self.out_dir),
            }
        )
        return self.summary


def train_generalist(
    cfg: GeneralistConfig,
    out_dir: Path,
    *,
    resume: bool = False,
    progress: Callable[[dict[str, float]], None] | None = None,
) -> dict[str, Any]:
    """Train (or resume) the generalist with ``cfg.learner``; returns the final summary.

    Ctrl-C saves ``last.safetensors`` before it propagates, so the run can be resumed.
    """
    if cfg.learner == "ppo":
        from policies.generalist_ppo import train_generalist_ppo

        return train_generalist_ppo(cfg, out_dir, resume=resume, progress=progress)
    book = RunBook.open(cfg, out_dir, TD3Nets.create, resume=resume)
    nets: TD3Nets = book.nets
    worlds, layout, device = book.worlds, book.layout, book.device
    buffer = AgentReplay(cfg.buffer_size, layout.size)
    warm = 0 if book.resumed else cfg.warmup_transitions
    recent: list[dict[str, Any]] = []
    if cfg.teacher != "none" and not book.resumed:
        scalars = learn_from_teacher(nets, worlds, buffer, cfg, book.goal_value, book.rng, device)
        warm = 0  # the clone explores from here
        if progress is not None:
            progress({"iteration": 0.0, "perf/elapsed_min": book.elapsed() / 60, **scalars})
        if book.writer is not None:
            for key, value in scalars.items():
                book.writer.add_scalar(key, value, 0)
        book.last_eval -= 60 * cfg.eval_minutes  # validate the clone at once
    try:
        while book.iteration < cfg.total_iterations and not book.out_of_time():
            frac = book.fraction_done()
            sigma = cfg.noise_start + (cfg.noise_end - cfg.noise_start) * frac
            rng = book.rng
            # ---- act in every world (one actor call for all of them), store, restart
            with book.clock("simulator"):
                if warm > 0:
                    actions = [
                        rng.uniform(-1, 1, w.obs.shape[:2]).astype(np.float32) for w in worlds
                    ]
                else:
                    out = actor_actions(nets.actor, joint_obs(worlds, layout.size), device)
                    out += rng.normal(0.0, sigma, out.shape).astype(np.float32)
                    np.clip(out, -1.0, 1.0, out=out)
                    actions = per_world(out, worlds)
                for world, act in zip(worlds, actions, strict=True):
                    transitions, ended = step_world(world, act, cfg, book.goal_value, rng)
                    buffer.add(**transitions)
                    count = len(transitions["obs"])
                    book.transitions += count
                    warm -= count
                    for row in ended:
                        recent.append({"family": world.family.name, **row})
            recent = recent[-2000:]
            book.iteration += 1

            # ---- learn
            losses: dict[str, float] = {}
            if warm <= 0 and buffer.size >= cfg.batch_size:
                bc = bc_weight(cfg, frac)
                with book.clock("learner"):
                    for _ in range(cfg.updates_per_iteration):
                        book.updates += 1
                        batch = buffer.sample(cfg.batch_size, rng, device)
                        update_actor = book.updates % cfg.policy_delay == 0
                        losses |= td3_update(nets, batch, cfg, update_actor, bc)

            # ---- log, checkpoint, validate
            book.log(recent, {"charts/noise": sigma, **losses}, progress)
            book.save_and_validate_if_due()
    except KeyboardInterrupt:
        book.save_last()
        raise
    return book.finish()


def export_generalist_run(
    run_dir: Path, out: Path, *, checkpoint: str = "best", metrics: dict[str, Any] | None = None
) -> dict[str, Any]:
    """Write the policy file of a generalist run folder; returns the metadata written.

    The actor and the first of the twin critics, the version-2 layout of the run, for 1 to
    ``max_uavs`` UAVs; the base scenario is the first family's of the first suite (the
    constants every family shares: speed, step, turn limit, d_col, sensing).
    """
    from policies.export import export_generalist

    config = json.loads((run_dir / "config.json").read_text())
    raw = dict(config["generalist"])
    raw["suites"] = tuple(raw["suites"])
    raw["family_weights"] = tuple(tuple(p) for p in raw.get("family_weights", ()))
    cfg = GeneralistConfig(**raw)
    base = family_scenario(load_suite(cfg.suites[0]).families[0])
    layout = generalist_layout(cfg, base)
    cpu = dataclasses.replace(cfg, device="cpu")
    if cfg.learner == "ppo":
        from policies.generalist_ppo import PPONets

        ppo = PPONets.create(layout, cpu, "cpu")
        meta = load_checkpoint(run_dir / f"{checkpoint}.safetensors", ppo)
        actor: nn.Module = ppo.actor
        critic: nn.Module = ppo.value  # the value network, of the critic's shape
    else:
        td3 = TD3Nets.create(layout, cpu, "cpu")
        meta = load_checkpoint(run_dir / f"{checkpoint}.safetensors", td3)
        actor, critic = td3.actor, td3.critics[0]
    return export_generalist(
        out,
        actor.state_dict(),
        critic.state_dict(),
        base_cfg=with_layout(base, layout),
        hidden=cfg.hidden,
        uav_range=(1, cfg.max_uavs),
        reward="remarl-separation",
        pooling=cfg.pooling,
        training={
            "steps": int(meta["updates"]),
            "seed": cfg.seed,
        },
        metrics=metrics,
    )

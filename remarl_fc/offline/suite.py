"""``remarl-fc eval --suite``: every method over every family of a benchmark suite.

A *method* is a hand-written controller (`HAND_WRITTEN`: "straight", "potential-field",
"orca"), "zoo" (per family, the zoo policy trained for that number of UAVs, where one exists),
or a policy file (zoo name or path). A policy runs only where it fits the family (its number of
UAVs, speed, turn limit and observation layout); elsewhere the family is "n/a" for it, with the
reason. A generalist fits every family whose number of UAVs is in its range, and observes with
its own layout (`remarl_fc.offline.rollout.observe_for`).

Each family runs as one batch of all its episodes in the unscored simulator (the flight and
every metric are those of training; only the reward is not computed), from the episodes
`sim.encounters.sample_family` draws. Metrics are `sim.evaluation.summarize`'s, the same for
every method, plus success over the episodes the oracle proved solvable (`sim.suite`) and the
reaction time of one decision for one swarm.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from multiprocessing import get_context
from typing import Any

import numpy as np
from numpy.typing import NDArray

from remarl_fc.errors import PolicyError
from remarl_fc.offline.evaluate import timed_decisions
from remarl_fc.offline.rollout import PolicyFileAct, observe_for, policy_by_name
from remarl_fc.offline.shielding import Shielded
from remarl_fc.policy_io import load_policy, zoo_names
from sim.arrays import BoolArray, FloatArray
from sim.config import ScenarioConfig
from sim.encounters import Family, sample_family
from sim.env import episode_metrics
from sim.errors import ConfigError
from sim.evaluation import summarize
from sim.parallel import run_on_ray
from sim.shield import ShieldConfig
from sim.spawn import EpisodeStart
from sim.state import SwarmState
from sim.suite import Suite, family_labels
from sim.swarm import SwarmSim

HAND_WRITTEN = ("straight", "potential-field", "orca")
"""The methods that need no policy file."""

METHODS = (*HAND_WRITTEN, "zoo")
"""Every ``--method`` name; a policy is given with ``--policy``."""

REACTION_SAMPLES = 30
"""Timed single-swarm decisions per family behind the reaction-time figures."""

Act = Callable[
    [NDArray[np.float32], SwarmState, ScenarioConfig],
    NDArray[np.float32] | tuple[NDArray[np.float32], FloatArray],
]
"""An act function: (observations, state, scenario) → actions (B, N), or (actions, speeds)
where it also chooses speeds (`remarl_fc.offline.shielding.Shielded`)."""


@dataclass(frozen=True)
class MethodSpec:
    """What to evaluate: ``kind`` "method" (a `METHODS` name) or "policy" (a name or path)."""

    kind: str
    name: str

    @property
    def label(self) -> str:
        """The column name in tables."""
        return self.name if self.kind == "method" else f"policy:{self.name}"

    @classmethod
    def from_label(cls, label: str) -> MethodSpec:
        """The spec of a `label`: ``policy:NAME`` or a method name."""
        kind, sep, name = label.partition(":")
        return cls("policy", name) if sep and kind == "policy" else cls("method", label)


def zoo_policy_for(family: Family, cfg: ScenarioConfig) -> str | None:
    """The zoo policy for a family: its own scenario's, else the one for N with most obstacles."""
    names = zoo_names()
    if family.encounter is None and family.scenario in names:
        return family.scenario
    mine = []
    for name in names:
        head, _, tail = name.partition("u")
        if head.isdigit() and int(head) == cfg.uav.count and tail.rstrip("o").isdigit():
            mine.append((int(tail.rstrip("o")), name))
    return max(mine)[1] if mine else None


def resolve_method(spec: MethodSpec, family: Family, cfg: ScenarioConfig) -> tuple[Act | None, str]:
    """The act function of ``spec`` on this family, or None and why it does not apply."""
    if spec.kind == "method" and spec.name in HAND_WRITTEN:
        return policy_by_name(spec.name), ""
    if spec.kind == "method" and spec.name != "zoo":
        raise ConfigError(f"unknown method {spec.name!r}; choose from {', '.join(METHODS)}")
    name = spec.name if spec.kind == "policy" else zoo_policy_for(family, cfg)
    if name is None:
        return None, f"no zoo policy for {cfg.uav.count} UAVs"
    policy = load_policy(name)
    try:
        policy.check_scenario(cfg)
    except PolicyError as exc:
        return None, str(exc)
    return PolicyFileAct(policy), name


def run_family(
    suite: Suite,
    family: Family,
    spec: MethodSpec,
    episodes: int | None = None,
    shield: ShieldConfig | None = None,
) -> dict[str, Any]:
    """Evaluate one method on one family: its metrics, JSON-ready.

    With the shield on, the family is flown twice, with and without it: the metrics are the
    shielded flights', and ``*_unshielded`` the same episodes without the shield. In monitor
    mode the actions are the method's own; the interventions are those the shield would have
    made.

    Raises:
        ConfigError: bad method. PolicyError: a policy file that cannot be loaded.
    """
    count = suite.episodes if episodes is None else episodes
    cfg, batch = sample_family(family, suite.seed, range(count))
    act, note = resolve_method(spec, family, cfg)
    head: dict[str, Any] = {"family": family.name, "method": spec.label, "uavs": cfg.uav.count}
    if act is None:
        return {**head, "applicable": False, "reason": note}
    solvable = family_labels(suite, family, count)
    shielded: dict[str, Any] = {"shield": "off"}
    if shield is not None and shield.mode != "off":
        if shield.mode == "on":
            plain = success_summary(fly_episodes(cfg, batch, act).rows, solvable)
            shielded |= {f"{k}_unshielded": v for k, v in plain.items()}
        act = Shielded(act, shield)
    t0 = time.perf_counter()
    rows = fly_episodes(cfg, batch, act).rows
    elapsed = time.perf_counter() - t0
    if isinstance(act, Shielded):
        shielded |= act.report()
    success = np.array([bool(r["success"]) for r in rows])
    closest = np.array([min(float(r["min_d_u2o_m"]), float(r["min_d_u2u_m"])) for r in rows])
    failed = np.flatnonzero(~success)
    worst = failed[np.argmin(closest[failed])] if failed.size else int(np.argmin(closest))
    return {
        **head,
        "applicable": True,
        "policy": note or None,
        "obstacles": cfg.obstacles.count,
        **summarize(rows),
        "solvable_episodes": int(solvable.sum()),
        "success_rate_solvable": (
            float(success[solvable].mean()) if solvable.any() else float("nan")
        ),
        "worst_episode": int(worst),
        "seconds": elapsed,
        **shielded,
        **reaction_time(cfg, batch.take(slice(0, 1)), act),
    }


def success_summary(rows: list[dict[str, Any]], solvable: BoolArray) -> dict[str, float]:
    """Success over all episodes and over the solvable ones, and the collision rates."""
    success = np.array([bool(r["success"]) for r in rows])
    summary = summarize(rows)
    return {
        "success_rate": float(success.mean()),
        "success_rate_solvable": float(success[solvable].mean()) if solvable.any() else math.nan,
        "collision_rate_u2o": summary["collision_rate_u2o"],
        "collision_rate_u2u": summary["collision_rate_u2u"],
        "energy_rad": summary["energy_rad"],
    }


@dataclass(frozen=True)
class Flown:
    """Episodes flown to their end.

    Attributes:
        rows: per-episode metrics (`sim.env.episode_metrics`), in episode order.
        final: the last state.
        trail_m: (T + 1, B, N, 2) UAV positions at the start and after each step (with
            ``trail=True``), else None.
    """

    rows: list[dict[str, Any]]
    final: SwarmState
    trail_m: FloatArray | None


def fly_episodes(
    cfg: ScenarioConfig, batch: EpisodeStart, act: Act, *, trail: bool = False
) -> Flown:
    """Fly every episode of ``batch`` to its end in the unscored simulator."""
    sim = SwarmSim(cfg, scored=False)
    rng = np.random.default_rng(0)  # unused when unscored (no PSO); kept for the signature
    state = sim.start(batch, rng)
    rows: list[dict[str, Any] | None] = [None] * batch.num_envs
    positions = [state.pos_m.copy()]
    for _ in range(cfg.max_steps):
        decided = act(observe_for(sim, state, act), state, cfg)
        actions, speeds = decided if isinstance(decided, tuple) else (decided, None)
        state, result = sim.step(state, actions, rng, speeds_m_s=speeds)
        if trail:
            positions.append(state.pos_m.copy())
        done = result.terminated | result.truncated
        if done.any():
            metrics = episode_metrics(state, result, done)
            for k, env in enumerate(np.flatnonzero(done)):
                rows[env] = {key: value[k] for key, value in metrics.items()}
        if all(r is not None for r in rows):
            break
    return Flown(
        [r for r in rows if r is not None], state, np.asarray(positions) if trail else None
    )


def reaction_time(cfg: ScenarioConfig, one: EpisodeStart, act: Act) -> dict[str, float]:
    """Median and p99 wall time (ms) of one decision for one swarm, at an episode's start."""
    sim = SwarmSim(cfg, scored=False)
    state = sim.start(one, np.random.default_rng(0))
    obs = observe_for(sim, state, act)
    return timed_decisions(lambda _: act(obs, state, cfg), REACTION_SAMPLES)


def _job(
    job: tuple[Suite, Family, MethodSpec, int | None, ShieldConfig | None],
) -> dict[str, Any]:
    return run_family(*job)


def evaluate_suite(
    suite: Suite,
    specs: list[MethodSpec],
    *,
    families: list[str] | None = None,
    episodes: int | None = None,
    workers: int = 1,
    ray_address: str | None = None,
    shield: ShieldConfig | None = None,
) -> list[dict[str, Any]]:
    """Every (method, family) cell; results in (method, family) order.

    ``shield``: every method behind the safety shield (`run_family`); None or "off": as is.

    Families spread over ``workers`` processes, or over the Ray cluster at ``ray_address``.
    The oracle labels are computed first, once per family, where they are not cached.
    """
    chosen = [suite.family(f) for f in families] if families else list(suite.families)
    count = suite.episodes if episodes is None else min(episodes, suite.episodes)
    for family in chosen:  # labels once, before workers race to cache them
        family_labels(suite, family, count)
    jobs = [(suite, f, spec, count, shield) for spec in specs for f in chosen]
    if ray_address is not None:
        return run_on_ray(_job, jobs, ray_address)
    if workers > 1:
        with ProcessPoolExecutor(workers, mp_context=get_context("spawn")) as pool:
            return list(pool.map(_job, jobs))
    return [_job(job) for job in jobs]

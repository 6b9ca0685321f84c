"""``remarl-fc eval``: run an exported policy for K episodes, report the metrics, plot one.

Inference is numpy (`remarl_fc.policy_io`); metrics are `sim.evaluation`'s, the same for every
method. Reaction time is the wall time of one decision for the whole swarm (all N UAVs),
measured on observations from the evaluation itself. A generalist observes with its own layout
(`remarl_fc.policy_io.Policy.layout`, version 2), built from the simulator's state.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from remarl_fc.offline.rollout import PolicyFileAct, observe_for
from remarl_fc.offline.shielding import Shielded
from remarl_fc.policy_io import Policy, load_policy
from sim.config import DynamicsRandomisation, ScenarioConfig
from sim.evaluation import run_episodes, summarize
from sim.scenarios import load_scenario
from sim.shield import ShieldConfig
from sim.state import SwarmState
from sim.swarm import SwarmSim

UNSHIELDED_KEYS = ("success_rate", "collision_rate_u2o", "collision_rate_u2u", "energy_rad")
"""The figures of a shielded evaluation repeated without the shield."""

REACTION_SAMPLES = 2000
"""Timed single-swarm decisions behind the reaction-time figures."""


def reaction_time_ms(policy: Policy, observations: NDArray[np.float32]) -> dict[str, float]:
    """Median and p99 wall time (ms) of one decision for a whole swarm (N, D)."""
    return timed_decisions(
        lambda k: policy.act(observations[k % len(observations)]), REACTION_SAMPLES
    )


def timed_decisions(decide: Callable[[int], object], samples: int) -> dict[str, float]:
    """Median and p99 wall time (ms) of ``decide(k)`` for k = 0 … samples − 1."""
    times = np.empty(samples)
    for k in range(samples):
        t0 = time.perf_counter()
        decide(k)
        times[k] = time.perf_counter() - t0
    return {
        "reaction_time_median_ms": float(np.median(times) * 1e3),
        "reaction_time_p99_ms": float(np.percentile(times, 99) * 1e3),
    }


class RecordingAct:
    """`evaluate_policy`'s act function for `sim.evaluation.run_episodes`.

    The policy's actions, the first `RECORDED` swarm observations kept (for the reaction time).
    A generalist reads its own observation layout, not the scenario's: it takes the state
    (``uses_state``) and observes it with `remarl_fc.offline.rollout.observe_for`.
    """

    RECORDED = 64

    def __init__(
        self, policy: Policy, cfg: ScenarioConfig, shield: ShieldConfig | None = None
    ) -> None:
        self.act = PolicyFileAct(policy)
        self.cfg = cfg
        on = shield is not None and shield.mode != "off"
        self.shielded = Shielded(self.act, shield) if on and shield is not None else None
        self.uses_state = self.act.layout is not None or self.shielded is not None
        self.sim = SwarmSim(cfg, scored=False) if self.act.layout is not None else None
        self.seen: list[NDArray[np.float32]] = []

    def __call__(
        self, obs: NDArray[np.float32], state: SwarmState | None = None
    ) -> NDArray[np.float32] | tuple[NDArray[np.float32], NDArray[np.float64]]:
        """Actions (B, N) for the observations (B, N, D) (a generalist: of the state).

        Behind the shield: (actions, speeds).
        """
        if self.sim is not None and state is not None:
            obs = observe_for(self.sim, state, self.act)
        if len(self.seen) < self.RECORDED:
            self.seen.append(obs[0].copy())
        if self.shielded is not None and state is not None:
            return self.shielded(obs, state, self.cfg)
        return self.act.policy.act(obs)


REAL_WORLD_FLOWN: tuple[str, str, str] = ("arducopter", "adsb", "hover")
"""(dynamics, sensors, arrival) of the real world policies are evaluated in (docs/RESULTS.md,
"Real vehicles and sensors"): the fitted ArduCopter response, ADS-B intruders with GPS noise,
arrived UAVs hovering (`world_overrides`, ``eval --dynamics arducopter --sensors adsb
--arrival hover``)."""


def world_overrides(
    dynamics: str | None = None,
    sensors: str | None = None,
    arrival: str | None = None,
    track_filter: bool | None = None,
) -> dict[str, Any]:
    """Scenario overrides that fly a scenario in another world (None: keep the scenario's).

    Args:
        dynamics: a vehicle profile every UAV flies, without randomisation ("ideal",
            "arducopter", "px4", ... or a profile file).
        sensors: "exact" or "adsb" (with the scenario's ADS-B and GPS settings).
        arrival: "hover" or "leave".
        track_filter: whether ADS-B tracks fuse their reports (`SensorConfig.adsb_filter`).
    """
    out: dict[str, Any] = {}
    if dynamics is not None:
        out["dynamics"] = dynamics
        out["dynamics_randomisation"] = {
            f.name: list(f.default) if isinstance(f.default, tuple) else f.default
            for f in dataclasses.fields(DynamicsRandomisation)
        }
    if sensors is not None:
        out["sensors"] = {"model": sensors}
    if track_filter is not None:
        out["sensors"] = {**out.get("sensors", {}), "adsb_filter": track_filter}
    if arrival is not None:
        out["arrival"] = arrival
    return out


def evaluation_scenario(
    policy: Policy, scenario: str | None, overrides: dict[str, Any] | None = None
) -> ScenarioConfig:
    """The scenario of an evaluation (default: the policy's own), in the world asked for."""
    cfg = load_scenario(scenario or policy.meta["scenario"], **(overrides or {}))
    policy.check_scenario(cfg)
    return cfg


def evaluate_policy(
    policy_name: str,
    scenario: str | None,
    episodes: int,
    seed: int,
    overrides: dict[str, Any] | None = None,
    shield: ShieldConfig | None = None,
) -> tuple[Policy, dict[str, Any]]:
    """Load, check against the scenario (default: the policy's own), run, summarise.

    ``overrides`` (`world_overrides`) change the scenario's world: vehicle response, sensing,
    arrival; the result records the world flown. ``shield``: behind the safety shield; with it
    on, the same episodes are flown without it too (``*_unshielded``).
    """
    policy = load_policy(policy_name)
    cfg = evaluation_scenario(policy, scenario, overrides)
    shielded: dict[str, Any] = {"shield": "off"}
    if shield is not None and shield.mode == "on":
        plain = summarize(run_episodes(RecordingAct(policy, cfg), cfg, episodes, seed))
        shielded |= {f"{k}_unshielded": plain[k] for k in UNSHIELDED_KEYS}
    act = RecordingAct(policy, cfg, shield)
    rows = run_episodes(act, cfg, episodes, seed)
    if act.shielded is not None:
        shielded |= act.shielded.report()
        shielded.pop("episodes_intervened")  # autoreset: environments are not episodes here
    result: dict[str, Any] = {
        "policy": policy.source,
        "scenario": cfg.name,
        "seed": seed,
        **summarize(rows),
        **shielded,
        **reaction_time_ms(policy, np.asarray(act.seen)),
        "uavs": cfg.uav.count,
        "dynamics": cfg.dynamics,
        "dynamics_randomised": cfg.dynamics_randomisation.randomised,
        "sensors": cfg.sensors.model,
        "track_filter": cfg.sensors.adsb_filter,
        "arrival": cfg.arrival,
    }
    return policy, result


def plot_episode(
    policy: Policy,
    scenario: str | None,
    seed: int,
    out: Path,
    overrides: dict[str, Any] | None = None,
) -> None:
    """Trajectories over the field's contours (paper Fig. 4a) and per-step Q-values (Fig. 4b)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from sim.render import draw_state

    cfg = evaluation_scenario(policy, scenario, overrides)
    sim = SwarmSim(cfg)
    act = PolicyFileAct(policy)
    rng = np.random.default_rng(seed)
    state = sim.initial_state(rng, 1)
    trail, q_rows = [state.pos_m[0].copy()], []
    for _ in range(cfg.max_steps):
        obs = observe_for(sim, state, act)
        actions = policy.act(obs)
        q = policy.q_values(obs, actions)[0] if policy.critic else np.full(cfg.uav.count, np.nan)
        q_rows.append(np.where(state.active[0], q, np.nan))
        state, result = sim.step(state, actions, rng)
        trail.append(state.pos_m[0].copy())
        if result.terminated[0] or result.truncated[0]:
            break
    fig, (ax_map, ax_q) = plt.subplots(1, 2, figsize=(12, 5.2), constrained_layout=True)
    draw_state(ax_map, cfg, state, 0, np.asarray(trail))
    ax_map.set_title(f"{cfg.name}: trajectories over the field's contours")
    q_arr = np.asarray(q_rows)
    colours = plt.get_cmap("tab10")(np.arange(cfg.uav.count) % 10)
    for k in range(cfg.uav.count):
        ax_q.plot(
            np.arange(1, len(q_arr) + 1),
            q_arr[:, k],
            marker="o",
            color=colours[k],
            label=f"UAV {k}",
        )
    ax_q.set_xlabel("decision step")
    ax_q.set_ylabel("Q(o, π(o))")
    ax_q.set_title("action value of each UAV")
    ax_q.legend(fontsize=8)
    ax_q.grid(alpha=0.3)
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_name(out.name + ".part")
    fig.savefig(tmp, dpi=110, format=out.suffix.lstrip(".") or "png")
    plt.close(fig)
    tmp.replace(out)

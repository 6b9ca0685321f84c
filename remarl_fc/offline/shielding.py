"""Any act function of the offline evaluation behind the safety shield (`sim.shield`).

`Shielded` wraps an act function (a hand-written method or a policy file): it asks it for its
actions, passes them through the shield with what each UAV knows of the simulator state, and
returns what to fly — heading changes and speeds — while it counts the decisions and the
interventions (in monitor mode, the ones the shield would have made).

It also applies the shield's last resort, which needs a memory of the steps before: where some
UAV of an environment has nothing that passes, that environment's swarm flies the oracle's
plan for `sim.shield.ShieldConfig.plan_steps` decisions (`sim.oracle.oracle_plan`), in the
simulator's exact world only; a plan found is held while the swarm flies it, and stands in
where the search from a later step finds none.
"""

from __future__ import annotations

import dataclasses
import time
from typing import Any

import numpy as np
from numpy.typing import NDArray

from sim.arrays import FloatArray
from sim.config import ScenarioConfig
from sim.observation import ObservationLayout
from sim.oracle import oracle_plan
from sim.shield import (
    ShieldConfig,
    ShieldDecision,
    Vehicle,
    give_way,
    shield_inputs,
    shield_state,
    vehicle_of,
)
from sim.state import SwarmState


class Shielded:
    """An act function (obs, state, cfg) → actions, behind the shield.

    Calls return (actions (B, N) float32, speeds (B, N) m/s). Attributes after a run:
    ``decisions`` (UAV decisions shielded), ``interventions`` (of them, those the shield
    changed or would have changed), ``planned`` (of them, those flown from the swarm planner's
    plan), ``plans`` (environment decisions the planner searched for) and ``plan_seconds``
    (its time), ``intervened_envs`` (B,) environments with at least one intervention since
    `reset`; ``last``, the shield's own decision at the latest call (before the planner).
    """

    def __init__(self, act: Any, cfg: ShieldConfig) -> None:
        self.inner = act
        self.cfg = cfg
        self._vehicle: tuple[ScenarioConfig, Vehicle] | None = None
        self.decisions = 0
        self.interventions = 0
        self.planned = self.plans = self.plans_kept = 0
        self.plan_seconds = 0.0
        self.intervened_envs: NDArray[np.bool_] | None = None
        # per environment: the planned steps still to fly, and the step of the last decision
        # (a smaller one is a new episode, which starts without a plan)
        self._plan_left: NDArray[np.int64] | None = None
        # per environment flown from a plan: the step that plan was found at, and the plan
        self._held: dict[int, tuple[int, NDArray[np.float32]]] = {}
        self._last_step: NDArray[np.int64] | None = None
        self.last: ShieldDecision | None = None  # the shield's decision of the latest call

    @property
    def layout(self) -> ObservationLayout | None:
        """The observation layout the wrapped act function reads (None: the scenario's)."""
        layout: ObservationLayout | None = getattr(self.inner, "layout", None)
        return layout

    def vehicle(self, cfg: ScenarioConfig) -> Vehicle:
        """`sim.shield.vehicle_of` the scenario, read once per scenario (it reads files)."""
        known = self._vehicle
        if known is None or (known[0] is not cfg and known[0] != cfg):
            known = self._vehicle = (cfg, vehicle_of(cfg))
        return known[1]

    def reset(self) -> None:
        """Forget the counts (a new batch of episodes)."""
        self.decisions = self.interventions = self.planned = self.plans = self.plans_kept = 0
        self.plan_seconds = 0.0
        self.intervened_envs = None
        self._plan_left = self._last_step = None
        self._held = {}

    def __call__(
        self, obs: NDArray[np.float32], state: SwarmState, cfg: ScenarioConfig
    ) -> tuple[NDArray[np.float32], FloatArray]:
        """(actions, speeds) to fly for the observations (B, N, D) of ``state``."""
        proposed = self.inner(obs, state, cfg)
        vehicle = self.vehicle(cfg)
        planner = self.cfg.mode == "on" and self.cfg.plan_steps > 0 and _exact(state)
        # where the planner runs, it is the last resort; giving way only where it finds nothing
        first = dataclasses.replace(self.cfg, give_way=0) if planner else self.cfg
        decision = self.last = shield_state(first, cfg, state, proposed, vehicle)
        action, speed, intervened = decision.action, decision.speed_m_s, decision.intervened
        if planner:
            action, speed, intervened = self._plan(state, cfg, decision, proposed, vehicle)
        self.decisions += int(state.active.sum())
        self.interventions += int(intervened.sum())
        hit: NDArray[np.bool_] = np.asarray(intervened.any(axis=-1))
        if self.intervened_envs is None or len(self.intervened_envs) != len(hit):
            self.intervened_envs = hit
        else:
            self.intervened_envs = self.intervened_envs | hit
        return action, speed

    def _plan(
        self,
        state: SwarmState,
        cfg: ScenarioConfig,
        decision: ShieldDecision,
        proposed: NDArray[np.floating],
        vehicle: Vehicle,
    ) -> tuple[NDArray[np.float32], FloatArray, NDArray[np.bool_]]:
        """The shield's decision, with the swarm planner's where an environment needs it.

        An environment where some flying UAV has nothing that passes flies the oracle's plan
        (`sim.oracle.oracle_plan`, every UAV of it at the cruise speed) from this step for
        `ShieldConfig.plan_steps` steps, replanned at each; where the planner finds no plan,
        the plan it found before flies on (`_held_plans`), else the shield's decision stands.
        In the environments left without a plan the neighbours of a boxed-in UAV give way
        (`sim.shield.give_way`, on those environments alone). Returns (actions, speeds,
        intervened), as the decision's.
        """
        b = state.num_envs
        steps = state.steps.astype(np.int64)
        left, last = self._plan_left, self._last_step
        if left is None or last is None or len(left) != b:
            left, last = np.zeros(b, dtype=np.int64), steps
        left = np.where(steps < last, 0, left)  # a new episode
        stuck = np.logical_or.reduce(state.active & ~decision.safe_exists, axis=-1)
        left = np.where(stuck, self.cfg.plan_steps, left)
        envs = np.flatnonzero((left > 0) & np.logical_or.reduce(state.active, axis=-1))
        self._plan_left, self._last_step = np.maximum(left - 1, 0), steps
        for env in set(self._held) - set(envs.tolist()):  # flown by its controller now
            del self._held[env]
        action, speed, intervened = decision.action, decision.speed_m_s, decision.intervened
        if not envs.size:
            return action, speed, intervened
        t0 = time.perf_counter()
        whole, found = oracle_plan(state, cfg, envs=envs)
        self.plan_seconds += time.perf_counter() - t0
        self.plans += len(envs)
        plans, kept = self._held_plans(state, envs, whole, found)
        self.plans_kept += int(kept.sum())
        found = found | kept
        alone = envs[~found]
        if self.cfg.give_way and alone.size:  # no plan: the neighbours of a boxed-in UAV give way
            seen = shield_inputs(self.cfg, cfg, state)
            gave = give_way(self.cfg, vehicle, *seen, proposed, decision, alone)
            action, speed, intervened = action.copy(), speed.copy(), intervened.copy()
            action[alone], speed[alone], intervened[alone] = (
                gave.action,
                gave.speed_m_s,
                gave.intervened,
            )
        envs, plans = envs[found], plans[found]
        flying = state.active[envs]
        action, speed = action.copy(), speed.copy()
        action[envs] = np.where(flying, plans, action[envs])
        speed[envs] = np.where(flying, vehicle.cruise_m_s, speed[envs])
        planned = np.zeros_like(intervened)
        planned[envs] = flying
        self.planned += int(planned.sum())
        # a planned UAV is intervened on where the plan is not its proposal, whatever the
        # shield had decided for it
        changed = action != np.asarray(proposed, dtype=np.float32)
        return action, speed, np.where(planned, changed, intervened)

    def _held_plans(
        self,
        state: SwarmState,
        envs: NDArray[np.intp],
        whole: NDArray[np.float32],
        found: NDArray[np.bool_],
    ) -> tuple[NDArray[np.float32], NDArray[np.bool_]]:
        """This step's plans for ``envs`` (E, N), and (E,) where a held plan stands in.

        A plan the planner found is held, its later steps still flyable while the environment
        flies it: in the exact world its UAVs fly it as the oracle flew it, and the intruders
        it knew fly straight. Where the search from a later state finds nothing (a beam search
        may miss a plan that exists), the held plan's step is flown instead, so long as every
        step since it was found was flown from a plan and no intruder has appeared since
        (`_plan` drops the plan of an environment its controller flies).
        """
        steps = state.steps.astype(np.int64)
        appear = state.obstacle_appear_step
        held, plans = self._held, whole[:, 0, :].copy()
        kept = np.zeros(len(envs), dtype=bool)
        for k, env in enumerate(envs.tolist()):
            now = int(steps[env])
            if found[k]:
                held[env] = (now, whole[k].copy())  # not a view that keeps the batch's plans
                continue
            since, plan = held.pop(env, (now, whole[k, :0]))
            ahead = now - since
            if 0 < ahead < len(plan) and not ((appear[env] > since) & (appear[env] <= now)).any():
                held[env] = (since, plan)
                plans[k], kept[k] = plan[ahead], True
        return plans, kept

    def report(self) -> dict[str, Any]:
        """The shield's figures of the run: mode, rate per UAV decision, episodes touched."""
        touched = self.intervened_envs
        return {
            "shield": self.cfg.mode,
            "shield_interventions": self.interventions,
            "shield_decisions": self.decisions,
            "intervention_rate": self.interventions / self.decisions if self.decisions else 0.0,
            "shield_planned": self.planned,
            "shield_plans": self.plans,
            "shield_plans_kept": self.plans_kept,
            "shield_plan_seconds": self.plan_seconds,
            "episodes_intervened": float(touched.mean()) if touched is not None else 0.0,
        }


def _exact(state: SwarmState) -> bool:
    """The simulator's exact world, where the swarm planner's plans are checked.

    Every intruder known exactly and every vehicle flying its arcs exactly: no ADS-B tracks,
    no GPS error (`SwarmState.exactly_sensed` is the state itself), no fitted response.
    """
    return state.response is None and state.exactly_sensed() is state

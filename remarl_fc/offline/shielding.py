"""Any act function of the offline evaluation behind the safety shield (`sim.shield`).

`Shielded` wraps an act function (a hand-written method or a policy file): it asks it for its
actions, passes them through the shield with what each UAV knows of the simulator state, and
returns what to fly — heading changes and speeds — while it counts the decisions and the
interventions (in monitor mode, the ones the shield would have made).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from sim.arrays import FloatArray
from sim.config import ScenarioConfig
from sim.observation import ObservationLayout
from sim.shield import ShieldConfig, Vehicle, shield_state, vehicle_of
from sim.state import SwarmState


class Shielded:
    """An act function (obs, state, cfg) → actions, behind the shield.

    Calls return (actions (B, N) float32, speeds (B, N) m/s). Attributes after a run:
    ``decisions`` (UAV decisions shielded), ``interventions`` (of them, those the shield
    changed or would have changed), ``intervened_envs`` (B,) environments with at least one
    intervention since `reset`.
    """

    def __init__(self, act: Any, cfg: ShieldConfig) -> None:
        self.inner = act
        self.cfg = cfg
        self._vehicle: tuple[ScenarioConfig, Vehicle] | None = None
        self.decisions = 0
        self.interventions = 0
        self.intervened_envs: NDArray[np.bool_] | None = None

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
        self.decisions = self.interventions = 0
        self.intervened_envs = None

    def __call__(
        self, obs: NDArray[np.float32], state: SwarmState, cfg: ScenarioConfig
    ) -> tuple[NDArray[np.float32], FloatArray]:
        """(actions, speeds) to fly for the observations (B, N, D) of ``state``."""
        proposed = self.inner(obs, state, cfg)
        decision = shield_state(self.cfg, cfg, state, proposed, self.vehicle(cfg))
        self.decisions += int(state.active.sum())
        self.interventions += int(decision.intervened.sum())
        hit: NDArray[np.bool_] = np.asarray(decision.intervened.any(axis=-1))
        if self.intervened_envs is None or len(self.intervened_envs) != len(hit):
            self.intervened_envs = hit
        else:
            self.intervened_envs = self.intervened_envs | hit
        return decision.action, decision.speed_m_s

    def report(self) -> dict[str, Any]:
        """The shield's figures of the run: mode, rate per UAV decision, episodes touched."""
        touched = self.intervened_envs
        return {
            "shield": self.cfg.mode,
            "shield_interventions": self.interventions,
            "shield_decisions": self.decisions,
            "intervention_rate": self.interventions / self.decisions if self.decisions else 0.0,
            "episodes_intervened": float(touched.mean()) if touched is not None else 0.0,
        }

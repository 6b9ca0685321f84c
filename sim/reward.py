"""The reMARL reward for every agent of every environment in one call (paper Eq. reward).

    r = −f(S, Φ) + r_form · r_collide

* the Contour part −f = −(w_int·internal − w_ext·external), from `sim.contour`;
* the Swarming part r_form·r_collide: r_form = cos∠(v, v̄), the cosine between the UAV's
  velocity after the step and v̄, the straight line from the UAV to its target; r_collide = 0
  if the UAV collided during the step (with an obstacle or another UAV), else 1.

Baselines train on the Swarming part alone; every method's learning curve plots it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sim.arrays import BoolArray, FloatArray
from sim.config import FieldConfig, PSOConfig, RewardConfig
from sim.contour import ArcWindow, window_terms
from sim.field import FieldSources, potential
from sim.pso import PSOResult, pso_separate


@dataclass(frozen=True)
class RewardTerms:
    """Every term of the reward, (B, N) each.

    Attributes:
        internal: non-dimensional bending energy of the window, in [0, 1].
        external: non-dimensional edge energy of the window, in [0, 1].
        contour: −(w_int·internal − w_ext·external), the Contour part.
        swarming: r_form·r_collide, the Swarming part, in [−1, 1].
        total: contour + swarming, the reMARL reward.
    """

    internal: FloatArray
    external: FloatArray
    contour: FloatArray
    swarming: FloatArray
    total: FloatArray


def preplanned_direction(pos_m: FloatArray, target_m: FloatArray) -> FloatArray:
    """Unit vector from each UAV to its target, (..., 2); zero where the UAV is on its target."""
    delta = target_m - pos_m
    norm = np.hypot(delta[..., 0], delta[..., 1])[..., None]
    return np.where(norm > 0, delta / np.where(norm > 0, norm, 1.0), 0.0)


def swarming_reward(
    heading_rad: FloatArray,
    pos_m: FloatArray,
    target_m: FloatArray,
    collided: BoolArray,
    heading_cos_sin: tuple[FloatArray, FloatArray] | None = None,
) -> FloatArray:
    """r_form·r_collide, (B, N): cos∠(v, v̄), zeroed for UAVs that collided.

    ``heading_cos_sin``: cos and sin of ``heading_rad``, where the caller has them.

    >>> swarming_reward(np.array([[0.0, np.pi / 2]]), np.zeros((1, 2, 2)),
    ...                 np.array([[[1.0, 0.0], [1.0, 0.0]]]), np.array([[False, False]])).round(6)
    array([[1., 0.]])
    """
    # `preplanned_direction`, component by component: the same numbers, on (B, N) arrays.
    dx = target_m[..., 0] - pos_m[..., 0]
    dy = target_m[..., 1] - pos_m[..., 1]
    norm = np.hypot(dx, dy)
    moving = norm > 0
    safe = np.where(moving, norm, 1.0)
    if heading_cos_sin is None:
        heading_cos_sin = np.cos(heading_rad), np.sin(heading_rad)
    cos_h, sin_h = heading_cos_sin
    r_form = cos_h * np.where(moving, dx / safe, 0.0)
    r_form += sin_h * np.where(moving, dy / safe, 0.0)
    return np.where(collided, 0.0, r_form)


def contour_levels(
    positions_m: FloatArray, src: FieldSources, field_cfg: FieldConfig
) -> FloatArray:
    """φ_i = Φ at each UAV's (PSO-adjusted) position: (B, N) from positions (B, N, 2)."""
    return potential(positions_m, src, field_cfg)


def assign_contour_levels(
    positions_m: FloatArray,
    src: FieldSources,
    field_cfg: FieldConfig,
    pso_cfg: PSOConfig,
    rng: np.random.Generator,
    active: BoolArray | None = None,
) -> tuple[FloatArray, PSOResult]:
    """Separate the UAVs' contours by PSO, then read each UAV's level φ_i off the field.

    Runs when levels must be (re)assigned — episode start, start of avoidance — never on every
    step with the same inputs.

    Args:
        positions_m: (B, N, 2) current positions.
        active: (B, N) UAVs still flying (others keep their place and play no part).

    Returns:
        (levels (B, N), the PSO result with the adjusted positions).
    """
    result = pso_separate(positions_m, pso_cfg, rng, active)
    return contour_levels(result.positions_m, src, field_cfg), result


def reward(
    window: ArcWindow,
    heading_rad: FloatArray,
    pos_m: FloatArray,
    target_m: FloatArray,
    collided: BoolArray,
    max_turn_rad: float,
    reward_cfg: RewardConfig,
    heading_cos_sin: tuple[FloatArray, FloatArray] | None = None,
) -> RewardTerms:
    """The reMARL reward of every UAV after a step, in one pass.

    Args:
        window: (B, N, K) arc windows that already include the arc just flown, each arc scored
            against the field when it was flown (`sim.contour.arc_external`).
        heading_rad: (B, N) headings after the step.
        pos_m: (B, N, 2) positions after the step.
        target_m: (B, N, 2) targets.
        collided: (B, N) whether each UAV collided during the step.
        max_turn_rad: a_max.
        heading_cos_sin: cos and sin of ``heading_rad``, where the caller has them.
    """
    terms = window_terms(window, max_turn_rad)
    contour = -(reward_cfg.w_internal * terms.internal - reward_cfg.w_external * terms.external)
    swarming = swarming_reward(heading_rad, pos_m, target_m, collided, heading_cos_sin)
    return RewardTerms(
        internal=terms.internal,
        external=terms.external,
        contour=contour,
        swarming=swarming,
        total=contour + swarming,
    )

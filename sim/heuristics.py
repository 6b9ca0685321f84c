"""Hand-written policies (no learning), acting on observations like a trained policy does.

* `straight_actions`: never turn (the pre-planned line, blind to obstacles).
* `potential_field_actions`: steer toward the target, pushed away from sensed obstacles by an
  inverse-square repulsion with a sideways component (so a head-on obstacle is not a dead
  centre). A sanity oracle for the simulator, not a contender.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from sim.observation import COLUMNS, ROW_OBSTACLES, ROW_SELF

REPULSION_GAIN = 0.5
"""Repulsion strength, in (sensing ranges)²: equal to the target's pull at 0.7 range."""


def straight_actions(obs_flat: NDArray[np.float32]) -> NDArray[np.float32]:
    """Zero heading change for every UAV: (..., N) from observations (..., N, D)."""
    return np.zeros(obs_flat.shape[:-1], dtype=np.float32)


def potential_field_actions(
    obs_flat: NDArray[np.float32], max_obstacles: int, max_turn_rad: float
) -> NDArray[np.float32]:
    """Normalised heading changes (..., N) in [−1, 1] from flat observations (..., N, D).

    The desired direction, in the UAV's heading frame, is the unit vector to the target plus,
    for each sensed obstacle at relative position r (in sensing ranges), the repulsion
    g·(−r̂ + side)/|r|², with ``side`` the unit normal pointing away from the obstacle's side.
    """
    m = max_obstacles
    rows = obs_flat[..., : (ROW_OBSTACLES + m) * COLUMNS].reshape(*obs_flat.shape[:-1], -1, COLUMNS)
    mask = obs_flat[..., -m:]
    target = rows[..., ROW_SELF, :2].astype(np.float64)
    desired = target / np.maximum(np.linalg.norm(target, axis=-1, keepdims=True), 1e-9)
    rel = rows[..., ROW_OBSTACLES:, :2].astype(np.float64)  # (..., N, m, 2)
    dist = np.maximum(np.linalg.norm(rel, axis=-1, keepdims=True), 1e-3)
    away = -rel / dist
    side = np.where(rel[..., 1:2] > 0, -1.0, 1.0) * np.array([0.0, 1.0])  # away from its side
    ahead = (rel[..., 0:1] > 0).astype(np.float64)  # only obstacles ahead push sideways
    push = REPULSION_GAIN * (away + ahead * side) / dist**2 * mask[..., None]
    desired = desired + push.sum(axis=-2)
    heading_error = np.arctan2(desired[..., 1], desired[..., 0])
    actions: NDArray[np.float32] = np.clip(heading_error / max_turn_rad, -1.0, 1.0).astype(
        np.float32
    )
    return actions

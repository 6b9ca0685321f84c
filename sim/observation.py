"""The observation builder: one function for the simulator, the SITL mock and the flight runtime.

Each UAV sees a (2 + m) × 4 array (the paper's minimum observation) and a mask of m obstacle rows,
everything relative to the UAV and rotated into its heading frame (x' ahead, y' to the left), so
a policy trained flying east works flying north over any origin:

| Row | Columns 0, 1                       | Columns 2, 3                           |
|-----|------------------------------------|----------------------------------------|
| 0   | (target − own position) / range    | own velocity / UAV speed               |
| 1   | (p* − own position) / range        | pre-planned velocity v̄ / UAV speed     |
| 2.. | (obstacle − own position) / range  | obstacle velocity / UAV speed          |

Obstacle rows hold the m nearest obstacles inside the sensing range and aperture, nearest first;
rows beyond those are zero and their mask entry is 0. Entries are clipped to ±`CLIP`. Units:
positions are divided by the sensing range (m / m), velocities by the UAV speed (m/s / m/s), so
every entry is dimensionless.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from sim.config import ScenarioConfig

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

ROW_SELF = 0
"""Row of the UAV's own properties."""
ROW_SWARM = 1
"""Row of the swarm's properties."""
ROW_OBSTACLES = 2
"""First obstacle row."""
COLUMNS = 4
"""Entries per row: (x, y, v_x, v_y) in the UAV's heading frame."""
CLIP = 10.0
"""Every entry is clipped to [−CLIP, CLIP]: 1 km at a 100 m sensing range, or 10× the UAV
speed; only targets and virtual centres far outside any arena reach it."""


@dataclass(frozen=True)
class ObservationLayout:
    """Shape and scales of the observation; exported with every policy.

    Attributes:
        max_obstacles: m, obstacle rows.
        range_m: sensing range; also the scale of positions.
        aperture_rad: full sensed sector, centred on the heading.
        speed_m_s: the UAV speed; the scale of velocities.
    """

    max_obstacles: int
    range_m: float
    aperture_rad: float
    speed_m_s: float

    @classmethod
    def from_scenario(cls, cfg: ScenarioConfig) -> ObservationLayout:
        """The layout of a scenario's observations."""
        s = cfg.sensing
        return cls(s.max_obstacles, s.range_m, s.aperture_rad, cfg.uav.speed_m_s)

    @property
    def rows(self) -> int:
        """2 + m."""
        return ROW_OBSTACLES + self.max_obstacles

    @property
    def size(self) -> int:
        """Length of the flat observation: (2 + m)·4 entries, then the m mask entries."""
        return self.rows * COLUMNS + self.max_obstacles


@dataclass(frozen=True)
class Observations:
    """Observations of B×N UAVs.

    Attributes:
        rows: (B, N, 2 + m, 4) float32.
        mask: (B, N, m) float32, 1 for a sensed obstacle row.
        sensed: (B, N, M) bool, which obstacles each UAV senses (before the top-m cut).
    """

    rows: NDArray[np.float32]
    mask: NDArray[np.float32]
    sensed: BoolArray

    def flat(self) -> NDArray[np.float32]:
        """(B, N, (2 + m)·4 + m): the rows, flattened, then the mask."""
        b, n = self.rows.shape[:2]
        return np.concatenate([self.rows.reshape(b, n, -1), self.mask], axis=-1)


def _rotate(vec: FloatArray, cos_h: FloatArray, sin_h: FloatArray) -> FloatArray:
    """Rotate world vectors (..., 2) into heading frames given cos/sin broadcastable to (...)."""
    x, y = vec[..., 0], vec[..., 1]
    return np.stack([cos_h * x + sin_h * y, cos_h * y - sin_h * x], axis=-1)


def build_observations(
    layout: ObservationLayout,
    own_pos_m: FloatArray,
    own_heading_rad: FloatArray,
    own_vel_m_s: FloatArray,
    target_m: FloatArray,
    centre_m: FloatArray,
    obstacle_pos_m: FloatArray,
    obstacle_vel_m_s: FloatArray,
    obstacle_valid: BoolArray | None = None,
) -> Observations:
    """Build every UAV's observation from plain arrays.

    Args:
        layout: rows and scales.
        own_pos_m: (B, N, 2) positions; own_heading_rad: (B, N); own_vel_m_s: (B, N, 2).
        target_m: (B, N, 2) each UAV's target.
        centre_m: (B, 2) the virtual centre p*.
        obstacle_pos_m, obstacle_vel_m_s: (B, M, 2).
        obstacle_valid: (B, M) False for obstacle slots that hold nothing.

    Returns:
        `Observations` (rows, mask, sensed).
    """
    b, n, _ = own_pos_m.shape
    m = layout.max_obstacles
    cos_h, sin_h = np.cos(own_heading_rad), np.sin(own_heading_rad)  # (B, N)
    inv_r, inv_v = 1.0 / layout.range_m, 1.0 / layout.speed_m_s

    to_target = target_m - own_pos_m
    dist_t = np.hypot(to_target[..., 0], to_target[..., 1])[..., None]
    vbar = layout.speed_m_s * to_target / np.where(dist_t > 0, dist_t, 1.0)
    rows = np.zeros((b, n, layout.rows, COLUMNS), dtype=np.float32)
    rows[:, :, ROW_SELF, :2] = _rotate(to_target, cos_h, sin_h) * inv_r
    rows[:, :, ROW_SELF, 2:] = _rotate(own_vel_m_s, cos_h, sin_h) * inv_v
    rows[:, :, ROW_SWARM, :2] = _rotate(centre_m[:, None] - own_pos_m, cos_h, sin_h) * inv_r
    rows[:, :, ROW_SWARM, 2:] = _rotate(vbar, cos_h, sin_h) * inv_v

    mask = np.zeros((b, n, m), dtype=np.float32)
    num_obstacles = obstacle_pos_m.shape[1]
    if num_obstacles == 0:
        np.clip(rows, -CLIP, CLIP, out=rows)
        return Observations(rows, mask, np.zeros((b, n, 0), dtype=bool))
    c, s = cos_h[..., None], sin_h[..., None]  # (B, N, 1)
    rel = _rotate(obstacle_pos_m[:, None] - own_pos_m[:, :, None], c, s)  # (B, N, M, 2)
    dist = np.hypot(rel[..., 0], rel[..., 1])  # (B, N, M)
    sensed = dist <= layout.range_m
    if layout.aperture_rad < 2 * math.pi:
        bearing = np.arctan2(rel[..., 1], rel[..., 0])
        sensed &= np.abs(bearing) <= 0.5 * layout.aperture_rad
    if obstacle_valid is not None:
        sensed &= obstacle_valid[:, None]
    keep = min(m, num_obstacles)
    order = np.argsort(np.where(sensed, dist, np.inf), axis=-1, kind="stable")[..., :keep]
    chosen = np.take_along_axis(sensed, order, axis=-1)  # (B, N, keep)
    rel_k = np.take_along_axis(rel, order[..., None], axis=-2)
    vel = _rotate(np.broadcast_to(obstacle_vel_m_s[:, None], rel.shape), c, s)
    vel_k = np.take_along_axis(vel, order[..., None], axis=-2)
    block = np.concatenate([rel_k * inv_r, vel_k * inv_v], axis=-1)  # (B, N, keep, 4)
    rows[:, :, ROW_OBSTACLES : ROW_OBSTACLES + keep] = np.where(chosen[..., None], block, 0.0)
    mask[..., :keep] = chosen
    np.clip(rows, -CLIP, CLIP, out=rows)
    return Observations(rows, mask, sensed)
